"""Single-pass ray casting.

About this technique
--------------------
The proxy geometry is the volume box's back faces (front faces culled, so each pixel runs
the fragment shader once even with the eye close to the box), grown by twice the
rasteriser's vertex snapping so that a ray grazing the box is never dropped (the shader
decides coverage), or one full-screen triangle when the eye is inside or nearly on the
box. The fragment shader ignores the
proxy's interpolated values: it rebuilds the pixel-centre ray from ``gl_FragCoord`` and
the camera basis, so pixels match the NumPy reference's rays exactly in construction.

Each ray is clipped to the box ``[t0, t1]`` (t0 >= 0: rays start at the eye, or on the
plane through it for orthographic cameras) and cut into segments ``step`` long,
starting at ``t0`` (or at ``t0 + jitter * step`` with a partial first segment), the last
segment shorter. Each segment is sampled at its midpoint and composited with its true
length: the midpoint rule, second order in ``step``.

Positions are world units relative to the box's lower corner (computed in float64 on the
CPU), which keeps float32 precision independent of where the volume sits in the world.
Texel centres are the samples: texture coordinate ``(p / spacing + 0.5) / n``.

Options (same names in ``dvr_gl.reference.render``)
---------------------------------------------------
target : "rgba32f" (default) | "rgba16f" | "rgba8"
    render target.
jitter_seed : None, or an int: the ray start is offset by a fraction of a step taken from
    a 64x64 table of uniform numbers drawn from ``numpy.random.default_rng(seed)`` and
    tiled over the image (uploaded as a texture; the reference reads the same table).
ert_transmittance : early ray termination once the transmittance falls below this
    (0 disables; composite mode only). Everything behind the stop point could at most
    have added colour ``c * T <= T`` per channel and opacity ``T``, so the dropped light
    is below ``ert_transmittance`` in every channel of the pixel.
skip_empty : empty-space skipping (composite mode only). The volume is cut into bricks
    of ``BRICK`` cells; each brick's value range (with a one-sample margin, so rounding in
    the texture unit cannot leave it) is classified once per transfer function. A sample
    that comes out fully transparent looks up its brick; if the brick's whole range has
    zero opacity, every midpoint in it contributes exactly nothing and the ray jumps to
    the brick's exit. The image is identical with it on and off. With pre-integration a
    brick is empty when no value within one table cell of its range has opacity (the
    table's bilinear nodes around any value in it are then all zero); a transparent
    segment in such a brick lets the ray jump over every later segment with both ends
    in it, each exactly zero, and the one after starts with a fresh front sample.
    Before the ray casting a pass finds, per pixel, where its ray first enters and last
    leaves the occupied bricks (``occupied_range``: the faces between occupied and empty
    bricks, each brick grown by a margin, drawn with MIN blending; each fragment gives
    its distance along the pixel's ray as an entry or an exit), and the ray's segments
    start and stop one segment beyond: all the segments outside lie in empty bricks,
    which the per-sample skip would have passed over one SIMD group at a time. With the
    eye inside or nearly on the box the pass is left out.
preintegrate : composite mode: classify each segment as a whole from the field at its two
    ends with the pre-integrated table (``dvr_gl.model.preintegration``; its segment length is
    the step, and the shorter first and last segments are corrected as that module
    says) instead of one midpoint sample.
refine : 1 (default) or an integer from 2 to 64, with ``preintegrate=True``: adaptive
    sampling where the transfer function has detail. Pre-integration takes the field as
    linear between a segment's ends; the trilinear field is not, and a narrow opacity
    feature (a spike a few per cent of the range wide) is then misplaced by a fraction of
    a step, which converges only at first order. Along a segment of length L the field
    stays within ``G L / 2`` of the mean of its ends (G: a bound on the gradient's
    magnitude over the segment's block of cells (``reach_block``: single cells unless
    that makes more than MAX_REACH_BOUNDS bounds) and the blocks half a step around it,
    from the largest sample differences of each cell, made once per volume), so when that
    reachable interval holds no knot at which the TF's opacity bends (with opacity on one
    side), the TF is one line over everything the segment can see. Otherwise the segment
    is cut into ``refine`` even parts and at every cell face it crosses (between two cuts
    the field is one smooth cubic, so the straight line errs at second order), each part
    sampled, read from a second table made for its length and lit at its own midpoint:
    the extra samples go only where a narrow feature may be crossed.
refine_walk : "even" (default): a refined segment's parts as above; "reach": each part is
    as long as the field cannot reach the TF's detail from its front (value distance /
    G), at least 1/``refine`` of the segment, and cut at cell faces only where shorter
    (``shaders/common/reach_walk.glsl``); "crossings": cell by cell, see ``crossing_walk``.
step_table : True (default): a full-length segment (all but a ray's first and last) reads
    its premultiplied, opacity-corrected segment from a table made once per TF and step
    (``LookupTable.step_table``) instead of correcting each sample's opacity (a log and an
    exp): 1.5x the samples per second for plain, lit, toned or depth-cued emission-
    absorption; the two differ by ``LookupTable.step_table_error`` per segment (about 1e-8
    to 2e-7 on the bench's TFs). Boundary and silhouette terms, other optical models, 2D
    TFs and pre-integration correct each sample as before.
gradients : "on_the_fly" (default) | "texture": where a lit sample's gradient comes from
    (``Scene(shading=True)`` and isosurface mode): six lookups of the field, or one of a
    gradient texture made once per volume (``techniques.common.shading_defines``).
brick_size : None (default) or a whole number N: draw the volume in bricks of N cells a
    side, each its own texture with a halo of samples (``techniques.bricks``); with None,
    bricks only where a side exceeds GL_MAX_3D_TEXTURE_SIZE. Rays keep their samples (a
    brick's pass takes the segments whose midpoint it owns) and their sums (each pass goes
    on from the image of the bricks in front), so the image is the single texture's up to
    the rounding of texture coordinates. Composite, mip, minip and average modes; not yet
    isosurfaces, pre-integration, geometry, gradient textures or masked samples (named errors).
    A LazyVolume (a store) is always drawn in bricks, of its summary's size by default,
    empty bricks known from the summary and never read (``techniques.lazy_bricks``).
stage : "auto" (default) | "fragment" | "compute": where the per-pixel shader runs
    (``gpu.pixel_stage``; auto: what the renderer measured faster on its GPU).
interpolation : "exact" (default) | "texture_unit": where the texture unit's linear filter
    quantises its weights (GPUs), "exact" interpolates eight fetches in the shader;
    "texture_unit" takes the unit's filter anyway (1.1x to 2.6x faster on a GPU, its error
    measured by ``tolerance=``, which takes it where it stays within the request).
memory : a LazyVolume's budget for brick samples held at once, bytes or a size such as
    "2GB" (default: a quarter of the memory available); smaller than one brick: an error.

Opaque geometry (``Scene.geometry``): a pass before the ray casting finds each pixel's
first surface and its lit colour (``techniques.geometry.surface_pass``); the ray ends
there (``GEOMETRY``: ``t1 = min(t1, t_hit)``) and the colour is composited behind, and the
proxy is then the full-screen triangle, so that surfaces outside the box show too.

Shading (``Scene(shading=True)``, composite): each midpoint sample's colour is lit by the
headlight with the gradient at the sample (``shaders/common/shading.glsl``) before it is
associated with its opacity; a pre-integrated segment is lit as a whole with the
gradient at its midpoint. Samples with zero opacity never look up a gradient.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from ..util.cache import TableCache
from ..gl.resources import texture3d
from ..model.scene import Scene
from ..model.transfer import LookupTable
from .common import (TARGETS, draw_ray_proxy, bind, box_proxy, box_view, camera_uniforms, check_flag,
                     check_scene, clip_defines, clip_uniforms, grow_pixels, shading_defines,
                     check_step, check_target, preintegration_applies, preintegration_table, tf_uniforms, volume_uniforms)
from .geometry import surface_pass
from . import crossing_walk, raycast_layers
from .bricks import (brick_occupancy, brick_size_for, bricked_defines, check_bricking, draw as draw_bricked,
                     halo_for, unsupported)
from .lazy_bricks import plan_lazy
from .gpu import (check_interpolation, check_stage, draw_ray_compute, jitter_texture, occupancy_texture,
                  pixel_stage, table_texture, target_fbo, tf_texture, volume_texture)

BRICK = 8            # brick edge in cells, for empty-space skipping
MAX_REFINE = 64
REFINE_WALKS = ("even", "reach", "crossings")   # how a refined segment is cut (refine_walk)
MAX_REACH_BOUNDS = 1 << 24   # gradient bounds per volume at most (float32: 64 MB)
JITTER_TABLE = 64    # jitter table edge in pixels

MODES = ("composite", "mip", "minip", "average", "isosurface")
DATA = "volume"
TAKES_STEP = True

@dataclass
class RaycastPlan:
    """Everything both the GL path and the NumPy reference need, decided once."""
    scene: Scene
    step: float
    lut: LookupTable
    target: str = "rgba32f"
    jitter: np.ndarray | None = None       # (64, 64) float32 in [0, 1), or None
    ert_transmittance: float = 0.0
    occupancy: np.ndarray | None = None    # (bz, by, bx) bool, or None when not skipping
    preint: object = None                  # a preintegration.PreintegrationTable, or None
    refine: int = 1                        # parts per refined pre-integrated segment
    preint_fine: object = None             # the table for step / refine, or None
    bricks: np.ndarray | None = None       # pre-integration with skipping: (bz, by, bx) float32 occupied
    reach: np.ndarray | None = None        # refine: gradient bounds per reach_block cells, float32
    reach_block: int = 1                   # their block's edge in cells
    detail: np.ndarray | None = None       # refine: (n, 2) value intervals of the TF's detail
    defines: dict = field(default_factory=dict)
    step_rows: np.ndarray | None = None    # LookupTable.step_table for this step, or None
    brick_size: int | None = None          # cells per brick side (bricks.py), None: as the volume needs
    lazy: object = None                    # a LazyVolume's lazy_bricks.LazyBricking, else None
    stage: str = "auto"                    # where the per-pixel shader runs (gpu.pixel_stage)
    crossings: object = None               # refine_walk='crossings': a crossing_walk.CrossingPlan

    @property
    def max_segments(self):
        diagonal = float(np.linalg.norm(self.scene.volume.extent))
        return int(math.ceil(diagonal / self.step)) + 2


def default_step(volume):
    """Half the smallest spacing."""
    return 0.5 * volume.min_spacing


def make_plan(scene, step=None, *, target="rgba32f", jitter_seed=None, ert_transmittance=1e-3,
              skip_empty=True, preintegrate=False, refine=1, gradients="on_the_fly", step_table=True,
              brick_size=None, memory=None, stage="auto", interpolation="exact", refine_walk="even",
              tables=None):
    """Validate the options and decide what the scene needs. ``tables`` (a
    ``dvr_gl.util.cache.TableCache``) keeps the TF's lookup table and the volume's brick
    ranges between frames."""
    if isinstance(scene, Scene) and scene.layers:   # several volumes: raycast_layers plans them (same options)
        check_bricking(scene, brick_size, preintegrate, gradients)    # (not bricked yet: a named error)
        check_stage(stage)
        for name, value, only in (("interpolation", interpolation, ("exact",)), ("refine_walk", refine_walk, ("even",))):
            if value not in only:
                raise ValueError(f"several volumes (Scene.layers) do not yet take {name}={value!r}")
        return raycast_layers.make_plan(**{k: v for k, v in locals().items()
                                           if k not in ("brick_size", "memory", "interpolation", "refine_walk",
                                                        "name", "value", "only")})
    tables = tables or TableCache()
    check_scene(scene, "raycast")
    step = default_step(scene.volume) if step is None else check_step(step, scene.volume)
    check_target(target)
    if jitter_seed is not None and (isinstance(jitter_seed, bool) or not isinstance(jitter_seed, (int, np.integer))):
        raise TypeError(f"jitter_seed must be None or an integer, got {jitter_seed!r}")
    if isinstance(ert_transmittance, bool) or not isinstance(ert_transmittance, (int, float, np.floating)):
        raise TypeError(f"ert_transmittance must be a number, got {ert_transmittance!r}")
    if not 0 <= ert_transmittance < 1:
        raise ValueError(f"ert_transmittance must be in [0, 1), got {ert_transmittance!r}")
    check_flag("skip_empty", skip_empty)
    check_stage(stage)
    check_interpolation(interpolation, brick_size or scene.is_lazy)
    brick_size = check_bricking(scene, brick_size, preintegrate, gradients)
    lazy = None
    if scene.is_lazy:      # always bricked, emptiness from the summary (lazy_bricks)
        unsupported(scene, preintegrate, gradients)
        brick_size, lazy = plan_lazy(scene, brick_size, memory, skip_empty, halo_for(scene))
    elif memory is not None:
        raise ValueError(f"memory bounds the bricks read from a LazyVolume; this scene's volume is in memory "
                         f"(got memory={memory!r})")
    if check_flag("preintegrate", preintegrate) and scene.mode != "composite":
        raise ValueError(f"preintegrate applies to mode 'composite' only, got mode {scene.mode!r}")

    if isinstance(refine, bool) or not isinstance(refine, (int, np.integer)):
        raise TypeError(f"refine must be an integer (parts per refined segment), got {refine!r}")
    if not 1 <= refine <= MAX_REFINE:
        raise ValueError(f"refine must be from 1 to {MAX_REFINE}, got {refine!r}")
    if refine_walk not in REFINE_WALKS:
        raise ValueError(f"refine_walk must be one of {', '.join(REFINE_WALKS)}, got {refine_walk!r}")
    if refine > 1 and not preintegrate:
        raise ValueError(f"refine splits pre-integrated segments; give preintegrate=True (got refine={refine})")
    composite = scene.mode == "composite"
    sabella = scene.optical_model == "sabella"   # the peak is over every sample: no skipping, no early end
    lut = tables.get("lut", scene.tf, make=LookupTable)
    jitter = None if jitter_seed is None else jitter_table(int(jitter_seed))
    preint = fine = bricks = detail = reach = crossings = None
    block = 1
    if preintegrate:
        size = crossing_walk.TABLE_SIZE if refine > 1 and refine_walk == "crossings" else None   # (its own)
        preint = preintegration_table(scene, step, tables, size)
        if refine > 1:
            fine = preintegration_table(scene, step / refine, tables, size)
            detail = tables.get("tf_detail", scene.tf, make=detail_intervals)
            # blocks around the midpoint's that half a segment can reach, along any axis
            block = reach_block(scene.volume)
            radius = max(1, math.ceil(0.5 * step / (block * scene.volume.min_spacing)))
            reach = tables.get(f"gradient_bounds:{block}:{radius}", scene.volume,
                               make=lambda v: gradient_bounds(v, radius, block))
        if skip_empty:
            ranges = tables.get("brick_ranges", scene.volume, make=brick_value_ranges)
            bricks = tables.get("preint_occupancy", scene.volume, scene.tf, preint,
                                make=lambda volume, tf, table: preint_occupancy(ranges, tf, table))
    occupancy = None
    if skip_empty and composite and preint is None and not sabella and lazy is None:
        # once per volume and once per (volume, TF) respectively, never per frame
        ranges = tables.get("brick_ranges", scene.volume, make=brick_value_ranges)
        occupancy = tables.get("occupancy", scene.volume, scene.tf,
                               make=lambda volume, tf: brick_occupancy(ranges, lut))
    defines = {f"MODE_{scene.mode.upper()}": 1}
    if scene.camera.is_ortho:
        defines["ORTHO"] = 1
    if jitter is not None:
        defines["JITTER"] = 1
    if occupancy is not None:
        defines["SKIP_EMPTY"] = 1
    ert = float(ert_transmittance) if composite and not sabella else 0.0
    if ert > 0:
        defines["EARLY_RAY_TERMINATION"] = 1
    if scene.volume.has_nonfinite:
        defines["MASK_NONFINITE"] = 1
    if preint is not None:
        defines["PREINTEGRATE"] = 1
        if skip_empty:
            defines["SKIP_EMPTY"] = 1
        if refine > 1:
            defines["REFINE"] = 1
            # a compile-time count: a uniform one cost the spike's frame 10 % (docs/notes/raycast.md)
            defines["DETAIL_COUNT"] = max(len(detail), 1)
            crossings = crossing_walk.plan_walk(scene, step, refine, fine, tables, defines, refine_walk, preint_occupancy)
    defines.update(shading_defines(scene, gradients))
    defines.update(clip_defines(scene))
    if scene.geometry:
        defines["GEOMETRY"] = 1
    if interpolation == "texture_unit":
        defines["TEXTURE_FILTER_EXACT"] = 1      # every filtered read from the texture unit
    step_rows = None
    if check_flag("step_table", step_table) and uses_step_table(scene, preint):
        step_rows = tables.get("step_table", lut, step / scene.tf.unit_distance,
                               make=lambda table, length_over_unit: table.step_table(length_over_unit))
        defines["STEP_TABLE"] = 1
    return RaycastPlan(scene=scene, step=step, lut=lut, target=target, jitter=jitter, ert_transmittance=ert,
                       occupancy=occupancy, preint=preint, defines=defines, step_rows=step_rows, refine=int(refine),
                       preint_fine=fine, bricks=bricks, detail=detail, reach=reach, reach_block=block,
                       brick_size=brick_size, lazy=lazy, stage=stage, crossings=crossings)


def uses_step_table(scene, preint):
    """Whether full-length segments can read the step table: where a pre-integrated table
    could stand (emission-absorption composite samples of the 1D TF whose length no term
    scales; colour terms, lighting included, apply to the premultiplied segment as
    ``litSegment`` does), when none is used."""
    return preint is None and preintegration_applies(scene)


@functools.lru_cache(maxsize=8)
def jitter_table(seed):
    """The 64x64 jitter offsets in [0, 1) for ``seed`` (read-only; made once per seed)."""
    table = np.random.default_rng(seed).random((JITTER_TABLE, JITTER_TABLE)).astype(np.float32)
    table.setflags(write=False)
    return table


def _block_reduce(a, axis, reduce):
    """Reduce ``a`` over blocks of BRICK samples along ``axis``, each block including the
    next block's first sample (the cells of a brick touch BRICK + 1 samples)."""
    n = a.shape[axis]
    nb = max(1, math.ceil((n - 1) / BRICK))
    idx = np.minimum(np.arange(nb * BRICK + 1), n - 1)
    a = np.take(a, idx, axis=axis)
    body = np.take(a, np.arange(nb * BRICK), axis=axis)
    shape = list(body.shape)
    shape[axis:axis + 1] = [nb, BRICK]
    r = reduce(body.reshape(shape), axis=axis + 1)
    edge = np.take(a, np.arange(1, nb + 1) * BRICK, axis=axis)
    return reduce(np.stack([r, edge]), axis=0)


def brick_value_ranges(volume):
    """Per brick (bz, by, bx): min and max of the samples its cells touch, widened by one
    sample on every side. Depends only on the volume: computed once per volume."""
    from scipy.ndimage import maximum_filter, minimum_filter
    v = volume.values(np.float32)
    lo, hi = minimum_filter(v, size=3, mode="nearest"), maximum_filter(v, size=3, mode="nearest")
    for axis in range(3):
        lo = _block_reduce(lo, axis, np.min)
        hi = _block_reduce(hi, axis, np.max)
    return lo.astype(np.float64), hi.astype(np.float64)


def reach_block(volume):
    """The edge in cells of the blocks refinement's gradient bounds cover: 1 (a bound per
    cell: on the narrow spike at 1.73 voxel 12 % faster than blocks of 2 cells, as
    fewer segments refine), doubled until the volume has at most MAX_REACH_BOUNDS."""
    cells = np.maximum(np.array(volume.shape) - 1, 1)
    block = 1
    while np.prod(np.ceil(cells / block)) > MAX_REACH_BOUNDS:
        block *= 2
    return block


def gradient_bounds(volume, radius=1, block=1):
    """Per block of ``block`` cells (bz, by, bx), float32: a bound on the magnitude of
    the trilinear field's gradient over the block and the blocks within ``radius`` of it
    along each axis (26 neighbours for 1; a segment whose midpoint is in the block and
    whose half length is at most ``radius`` blocks' smallest side stays among them). In a cell each
    partial derivative is a convex combination of the differences along that axis's four
    edges, so the cell's ``sqrt(sum over axes of (largest edge difference / spacing)^2)``
    bounds it (rounded up to float32). Once per volume (non-finite samples count as 0;
    masked cells add nothing anyway)."""
    from scipy.ndimage import maximum_filter
    v = np.nan_to_num(volume.values(np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    sx, sy, sz = volume.spacing
    squares = np.zeros(tuple(max(n - 1, 1) for n in v.shape))
    for axis, h in ((2, sx), (1, sy), (0, sz)):
        if v.shape[axis] < 2:
            continue
        edge = np.abs(np.diff(v, axis=axis)) / h
        for a in (a for a in range(3) if a != axis):    # the largest of the cell's four edges
            if edge.shape[a] > 1:
                edge = np.maximum(np.take(edge, np.arange(edge.shape[a] - 1), axis=a),
                                  np.take(edge, np.arange(1, edge.shape[a]), axis=a))
        squares += edge ** 2
    cells = np.sqrt(squares)
    nb = [max(1, math.ceil((n - 1) / block)) for n in v.shape]
    padded = np.zeros([b * block for b in nb])
    padded[:cells.shape[0], :cells.shape[1], :cells.shape[2]] = cells
    per_block = padded.reshape(nb[0], block, nb[1], block, nb[2], block).max(axis=(1, 3, 5))
    bound = maximum_filter(per_block, size=2 * int(radius) + 1, mode="nearest") * (1 + 2.0 ** -20)
    return bound.astype(np.float32)


def preint_occupancy(ranges, tf, table):
    """(bz, by, bx) float32 for pre-integration's skipping: 1 where some value within one
    table cell (and float rounding) of the brick's range has non-zero opacity in the
    exact TF (the table's bilinear nodes around any value of an empty brick are then all
    zero, and so is every segment with both ends in it)."""
    lo, hi = ranges
    rel = 64 * 2.0 ** -24
    cell = 1.0 / table.scale
    a = lo - rel * np.abs(lo) - 1.01 * cell
    b = hi + rel * np.abs(hi) + 1.01 * cell
    knots = tf.knots
    nonzero = np.concatenate([[0], np.cumsum(tf.opacity(knots) > 0)])
    inside = nonzero[np.searchsorted(knots, b, side="right")] - nonzero[np.searchsorted(knots, a, side="left")]
    return ((inside > 0) | (tf.opacity(a) > 0) | (tf.opacity(b) > 0)).astype(np.float32)


def detail_knots(tf):
    """The knots at which refinement looks: every knot of the TF with non-zero opacity
    at it or on either neighbouring interval (where the opacity or the colour it weighs
    may bend)."""
    knots = tf.knots
    alpha = tf.opacity(knots) > 0
    near = alpha.copy()
    near[1:] |= alpha[:-1]
    near[:-1] |= alpha[1:]
    return knots[near]


MAX_DETAIL = 8         # detail intervals the shader tests (DETAIL_COUNT, compiled in)


def detail_intervals(tf):
    """(n, 2) float64, n <= MAX_DETAIL: value intervals that hold every detail knot,
    widened by float32 rounding (GLSL ``touchesDetail`` tests overlap with each). More
    than MAX_DETAIL knots are grouped by closing the smallest gaps first (which can only
    refine more segments, never fewer)."""
    knots = detail_knots(tf)
    if knots.size == 0:
        return np.zeros((0, 2))
    groups = [[k, k] for k in knots]
    while len(groups) > MAX_DETAIL:
        gaps = [groups[i + 1][0] - groups[i][1] for i in range(len(groups) - 1)]
        i = int(np.argmin(gaps))
        groups[i:i + 2] = [[groups[i][0], groups[i + 1][1]]]
    out = np.array(groups, np.float64)
    pad = 4 * 2.0 ** -24 * np.maximum(np.abs(out), np.abs(knots).max())
    return out + np.stack([-pad[:, 0], pad[:, 1]], axis=1)


def refine_cuts(plan):
    """A bound on a refined segment's cuts: its even parts and the cell faces it can
    cross (the shader's loop bound)."""
    faces = np.ceil(plan.step / np.asarray(plan.scene.volume.spacing, np.float64)) + 1
    return int(plan.refine + faces.sum() + 1)


def touches_detail(intervals, lo, hi):
    """NumPy twin of GLSL ``touchesDetail``."""
    lo, hi = np.asarray(lo)[..., None], np.asarray(hi)[..., None]
    return ((hi >= intervals[:, 0]) & (lo <= intervals[:, 1])).any(axis=-1)


def block_of(volume, points, shape, block):
    """Indices (z, y, x order, for indexing) of the blocks of ``block`` cells holding
    box-relative points, clamped to ``shape``."""
    idx = np.floor(points / volume.spacing / block).astype(np.int64)
    idx = np.clip(idx, 0, np.array(shape[:3][::-1]) - 1)
    return idx[:, 2], idx[:, 1], idx[:, 0]


def occupied_faces(occupied, volume, margin):
    """The faces of the occupied bricks (``occupied``, (bricks z, y, x) booleans) that
    border an empty brick or the volume's edge, as triangles: (6 n, 6) float32 rows of
    (vertex, outward normal), positions relative to the volume's lower corner. Each face
    is one of its brick's box grown by ``margin`` world units on every side. A ray first
    meets the union of the grown boxes on such a face, facing it, and last leaves it
    through one facing away: a neighbour's grown box holds the face between two occupied
    bricks."""
    occupied = np.asarray(occupied, bool)
    spacing = np.asarray(volume.spacing, np.float64)
    extent = np.asarray(volume.extent, np.float64)
    idx = np.argwhere(occupied)[:, ::-1]                       # (n, 3) brick x, y, z
    lo = idx * BRICK * spacing - margin
    hi = np.minimum((idx + 1) * BRICK * spacing, extent) + margin
    padded = np.pad(occupied, 1)
    quads = []
    for axis in range(3):                                       # x, y, z
        for side in (0, 1):
            shift = np.zeros(3, int)
            shift[axis] = 1 if side else -1
            x, y, z = (idx + 1 + shift).T
            open_face = ~padded[z, y, x]
            if not open_face.any():
                continue
            a, b = lo[open_face], hi[open_face]
            u, v = (axis + 1) % 3, (axis + 2) % 3
            corners = np.repeat(a[:, None, :], 4, axis=1)
            corners[:, :, axis] = (b if side else a)[:, axis][:, None]
            corners[:, 1:3, u] = b[:, None, u]
            corners[:, 2:4, v] = b[:, None, v]
            tris = corners[:, [0, 1, 2, 0, 2, 3], :]
            normals = np.broadcast_to(shift.astype(np.float64), tris.shape)
            quads.append(np.concatenate([tris, normals], axis=2).reshape(-1, 6))
    if not quads:
        return np.zeros((0, 6), np.float32)
    return np.concatenate(quads).astype(np.float32)


def occupied_range(renderer, plan):
    """The pixels' (least entry, -greatest exit) into the occupied bricks' grown boxes
    along their rays (``occupied_faces``, blended with MIN), as an RG32F texture the
    size of the plan's target (3e38 in both where the ray meets none); None where the
    pass does not apply (no skipping, no empty brick, or the eye inside or nearly on the
    box)."""
    occupied = plan.occupancy if plan.occupancy is not None else plan.bricks
    scene = plan.scene
    if occupied is None or occupied.all():      # every ray's range is then the box's own
        return None
    ctx = renderer.ctx
    volume = scene.volume
    _, _, grow = box_view(scene, grow_pixels(ctx))
    # well beyond float rounding of a sample's brick and of the interpolated face position
    # (a few 1e-7 of the coordinate), and four times the rasteriser's vertex snapping, so
    # a ray that a snapped face misses passes at least `margin - grow` from its brick;
    # rounded up to a power of two, so that the faces serve every view that needs no more
    margin = 2.0 ** math.ceil(math.log2(max(0.25 * volume.min_spacing, 4.0 * grow)))
    kind, view_proj, _ = box_view(scene, grow_pixels(ctx), pad=margin)
    if kind != "box":
        return None

    def make():
        faces = occupied_faces(occupied, volume, margin)
        return ctx.buffer(faces.tobytes()) if len(faces) else None
    mesh = renderer.resources.for_objects("occupied_faces", occupied, volume, margin, make=make)
    defines = {"ORTHO": 1} if scene.camera.is_ortho else {}
    prog = renderer.programs.get("raycast/occupied_range.vert", "raycast/occupied_range.frag", defines)
    bind(prog, {}, camera_uniforms(scene))
    prog["u_view_proj"].write(view_proj.astype("f4").tobytes())
    fbo = target_fbo(renderer, *scene.target_size, "f4", kind="occupied_range", components=2)
    fbo.use()
    fbo.clear(3e38, 3e38, 0.0, 0.0)
    if mesh is not None:
        vao = renderer.resources.for_objects("occupied_faces_vao", mesh, prog, make=lambda: ctx.vertex_array(
            prog, [(mesh, "3f 3f", "a_position", "a_normal")]))
        ctx.disable(ctx.DEPTH_TEST | ctx.CULL_FACE)
        ctx.enable(ctx.BLEND)
        ctx.blend_equation = ctx.MIN
        vao.render(vertices=mesh.size // 24)
        ctx.blend_equation = ctx.FUNC_ADD
        ctx.disable(ctx.BLEND)
    return fbo.color_attachments[0]


# ---------------------------------------------------------------------------------------
# GL path

def draw(renderer, plan):
    """Render the plan into the renderer's target for its size and format; returns that
    framebuffer (premultiplied RGBA, GL's row order: row 0 at the bottom)."""
    if isinstance(plan, raycast_layers.LayersPlan):   # several volumes
        return raycast_layers.draw(renderer, plan)
    ctx, scene, volume = renderer.ctx, plan.scene, plan.scene.volume
    brick_size = brick_size_for(renderer, plan)     # None: the volume in one texture
    compute = not brick_size and pixel_stage(renderer, plan.stage) == "compute"
    # no raster pass for the occupied range in the compute stage (docs/notes/gpu.md: it cost
    # more than it saved), with segments one at a time, nor for the walk by crossings, which
    # passes over empty cells by itself (the same image, 1 to 4 ms less on llvmpipe)
    occupied = None if compute or plan.crossings is not None else occupied_range(renderer, plan)
    surfaces = surface_pass(renderer, scene) if scene.geometry else None   # each pixel's first surface
    defines = dict(plan.defines, OCCUPIED_RANGE=1) if occupied is not None else plan.defines
    if compute:
        prog = renderer.programs.compute("raycast/raycast.frag", dict(defines, IMAGE_FORMAT=plan.target,
                                                                       SEGMENT_GROUP=1))
    else:
        prog = renderer.programs.get("raycast/raycast.vert", "raycast/raycast.frag",
                                     dict(defines, **bricked_defines(renderer, volume)) if brick_size else defines)
    textures = {} if brick_size else {"t_volume": volume_texture(renderer, volume)}
    textures["t_tf"] = tf_texture(renderer, plan.lut)
    if occupied is not None:
        textures["t_occupied_range"] = occupied
    if surfaces is not None:
        textures["t_surface"] = surfaces
    if plan.jitter is not None:
        textures["t_jitter"] = jitter_texture(renderer, plan.jitter)
    if plan.occupancy is not None:
        textures["t_occupancy"] = occupancy_texture(renderer, volume, scene.tf, plan.occupancy)
    if plan.step_rows is not None:
        textures["t_step_tf"] = renderer.resources.for_objects("step_tf", plan.step_rows, make=lambda: table_texture(
            renderer.ctx, plan.step_rows))
    uniforms = {**camera_uniforms(scene), **volume_uniforms(volume), **tf_uniforms(plan.lut, scene.tf),
                **clip_uniforms(scene), "u_step": plan.step, "u_max_segments": plan.max_segments}
    if plan.occupancy is not None or plan.bricks is not None:
        uniforms["u_brick"] = float(BRICK)
    crossing_walk.add_inputs(renderer, plan, textures, uniforms)   # (and add_optional_inputs')
    if plan.bricks is not None:
        textures["t_occupancy"] = renderer.resources.for_objects(
            "preint_occupancy", plan.bricks, make=lambda: texture3d(ctx, plan.bricks, 1, "f4", linear=False))
    if plan.reach is not None:
        textures["t_reach"] = renderer.resources.for_objects(
            "gradient_bounds", plan.reach, make=lambda: texture3d(ctx, plan.reach, 1, "f4", linear=False))
        uniforms["u_reach_block"] = float(plan.reach_block)
    if plan.refine > 1:     # (no detail: one interval no value meets)
        detail = np.array(plan.detail if len(plan.detail) else [[np.inf, -np.inf]], np.float32)
        uniforms.update({"u_refine": plan.refine, "u_pi_fine_length": plan.preint_fine.length,
                         "u_refine_cuts": refine_cuts(plan)})
    if plan.ert_transmittance > 0:
        uniforms["u_ert_transmittance"] = plan.ert_transmittance
    if scene.mode == "isosurface":
        uniforms["u_iso"] = scene.iso_value
    if scene.optical_model == "sabella":
        from ..model.field import depth_range
        uniforms["u_depth_range"] = depth_range(scene)
    bind(prog, textures, uniforms)
    if plan.refine > 1 and "u_detail" in prog:
        prog["u_detail"].write(detail.tobytes())
    if brick_size:
        return draw_bricked(renderer, plan, prog, textures, brick_size)
    if compute:
        return draw_ray_compute(renderer, prog, scene, TARGETS[plan.target])
    kind, view_proj = box_proxy(scene, grow_pixels=grow_pixels(renderer.ctx))
    return draw_ray_proxy(renderer, prog, scene, plan.target, kind, view_proj, surfaces)
