"""Splatting: every sample of the data is a reconstruction kernel, and GL draws each
kernel's footprint. Two kernels, chosen with ``kernel``.

About the tent kernel (``kernel="tent"``, grids, the default)
-------------------------------------------------------------
Image-aligned sheet-buffer splatting with post-classification (Mueller and Crawfis 1998;
Mueller, Moeller and Crawfis 1999, "Splatting without the blur"). Each grid sample carries
the trilinear "tent" kernel: ``h(x) = prod_a max(0, 1 - |x_a| / s_a)`` over the axes, one
spacing ``s`` wide on either side. Tents centred on the samples add up to trilinear
interpolation, so ``sum_i h(x - x_i) v_i`` is the contract's field itself, not a blurred
copy of it.

Sheets. Per view, planes perpendicular to the view direction (image-aligned, under
perspective too) sit ``sheet_spacing`` apart, at depths ``(j + 0.5) * sheet_spacing``
from the eye, the same planes as 3D slicing's. For each sheet, front to back:

1. *Splat.* Every sample whose tent reaches the sheet (its depth within ``r = sum_a
   |forward_a| s_a`` of the sheet's) is added into a float sheet buffer by a quad on the
   sheet covering the cut through the tent's support box. Each fragment rebuilds its
   pixel's ray, takes its point ``p`` on the sheet and adds ``(w v, w)`` with ``w =
   h(p - x_i)`` (additive blending). The buffer then holds, per pixel, ``sum w v`` and
   ``sum w``: the trilinear field where the pixel's ray crosses the sheet, and the
   weight of the samples drawn there. The samples are drawn in runs: maximal sequences
   of splatted neighbours along the axis whose runs make the fewest quads in this view
   (``run_axis``), one quad per run and sheet, its fragments adding the tents of the
   two samples of the run around ``p`` (the others are zero there). The sums are those
   of one quad per sample, for several times fewer quads (llvmpipe sets up about 3
   million a second) and half the fragments. A quad is the bounding rectangle, along
   the runs' direction on the sheet and across it, of the cut through the run's
   supports, grown by a sixteenth of a pixel: the bounds of the cut through one support
   are linear in the sheet's offset between the support box's corner depths, so a table
   of them at those 8 depths, made once per view (``section_table``), and the run's
   sweep (``run_quads``) place every quad exactly.
2. *Classify and composite.* The sheet's polygon inside the box is drawn over the image
   (3D slicing's CPU polygons). Each fragment reads its pixel of the sheet buffer, takes
   ``s = sum w v / sum w``, classifies it with the transfer function's table, corrects
   its opacity for the piece of its own ray the sheet stands for (from halfway to the
   nearer sheet to halfway to the farther one, or to the box's face where there is no
   neighbour: ``shaders/common/slabs.glsl``, whose length changes per pixel under
   perspective), lights it when the scene asks, and is blended front to back
   (``ONE_MINUS_DST_ALPHA, ONE``).

A pixel's image is then the midpoint rule along its ray with samples at the sheets: the
ray caster's error at a step of ``sheet_spacing``. What splatting adds is where the field
comes from (the kernels, not a 3D texture). Rays whose chord inside the box is shorter
than the sheet spacing may meet no sheet inside the box (at the box's silhouette); they
stay empty, in the reference too.

Empty space. A sample none of whose cells (the up to 8 cells it is a corner of) has a
value range with non-zero opacity (``raycast.brick_occupancy`` per cell, with its float32
widening) is not splatted (``skip_empty=True``). That changes no pixel: a cell that is
occupied has all its corners splatted, so there ``sum w = 1`` and the value is exact; in
an empty cell ``s`` is a weighted mean of some of its corners, so it stays inside the
cell's range, which classifies to zero opacity. Dividing by ``sum w`` is what makes this
exact. Non-finite samples (``mask_nonfinite``) are splatted into a third channel instead,
where they are corners of a cell with a splatted corner, and a pixel whose point has any
weight there is outside the domain, as the contract's masked cells are.

Lighting. Each splatted sample also carries its central-difference gradient (into a
second buffer, ``sum w g``). Interpolating those with the tent weights is exactly the
contract's gradient (central differences of the interpolated field, clamped at the box:
see ``model.field.sample_gradients``), so the lit sheets are the contract's too.

Clip planes and crop boxes. Each sheet's piece of a pixel's ray is cut to the part the
planes and the crop box keep (``clipRange`` in sheet.frag, as 3D slicing cuts its slabs,
and the gap pass is 3D slicing's, clipped the same way): each ray gets the midpoint rule
over its kept interval. The samples splatted are the same (near a cut the field comes
from samples on both sides of it, as the contract's does). The first piece of a ray
behind a cut (and the last before one) lies up to half a step off its sheet's centre;
classified at the sheet, that was a first-order error at a cut through opaque tissue
(1.012 times the unclipped error on the CT head with a crop box). Such a piece takes the
field at its middle from the volume's texture instead (``END_PIECES``), as 3D slicing
samples it (lit with its sheet's gradient): on the CT head at 48x48 and density 1 the
error against the clipped exact image is 0.79 and 0.62 of the unclipped one with one and
two oblique planes and 0.85 with a crop box (density 2: 0.86, 0.57, 0.78).

Opaque geometry (``Scene.geometry``): a pass before the sheets finds each pixel's first
surface, its lit colour and its ray parameter t_hit (``geometry.surface_pass``). Every
ray's kept range ends there, as at a clip (``GEOMETRY`` in sheet.frag and in the gap
pass): sheets behind it are no sheets for that ray, the piece straddling it runs to it
(classified at its middle, as at a cut), and a shortened chord that crosses no sheet is
the gap pass's. The surface's colour, opacity 1, is blended under everything last
(``ONE_MINUS_DST_ALPHA, ONE``: ``C + (1 - A) lit``, ``A = 1``). At 48x48 the error
against the exact image with the surfaces is 0.79 of the error without them on
Marschner-Lobb (a sphere and a square inside) and 0.96 on the CT head (a sphere)
(tests/test_geometry_splat.py).

``density=k`` puts the sheets ``k`` times closer (``min spacing / k`` apart); the
samples stay the data's, since tents on a ``k`` times finer trilinear resampling of the
field add up to the same field (trilinear interpolation reproduces a trilinear function),
so resampling would only multiply the splats by ``k^3``. ``sheet_spacing`` sets the
distance in world units instead.

About the Gaussian kernel (``kernel="gaussian"``, grids and meshes; a mesh's only one)
--------------------------------------------------------------------------------------
Pre-classified splatting (Westover 1990; elliptical kernels after Zwicker et al. 2001):
every classified sample is a Gaussian kernel that carries its share of the extinction,
and GL composites the kernels' footprints back to front.

The model. With samples ``x_i`` on a grid of spacing ``h`` (the data's, or ``density``
times finer per axis, resampled trilinearly) and an axis-aligned Gaussian kernel ``g`` of
standard deviation ``sigma = radius * h`` per axis (unit integral), the extinction is
reconstructed as ``tau(x) = sum_i tau(s_i) V_i g(x - x_i)`` (``V_i`` the sample's share
of the box: a cell's volume, halved per axis on the box's faces, the trapezoid rule).
Along a pixel's ray the kernel's optical depth is ``tau(s_i) V_i F_i``, with ``F_i`` the
kernel's integral along that ray, in closed form for a Gaussian:

    F = exp(-m^2 / 2) / (2 pi sqrt(det Sigma) sqrt(d' Sigma^-1 d))

(``m`` the ray's distance from the centre in standard deviations, ``d`` its direction).
The shader evaluates it per fragment along the fragment's own ray, which is what EWA
splatting approximates with an affine map: exact under perspective and for anisotropic
spacing. The kernel is truncated at ``cutoff`` standard deviations (``F = 0`` for rays
farther away; the rest renormalised). Each splat is composited over what is behind it,
with opacity ``1 - exp(-tau V_i F_i)`` and colour ``c(s_i)`` (the sample classified first,
then reconstructed: pre-classification, which blurs every feature narrower than a kernel).

Meshes: the samples are the mesh's points, each carrying its lumped volume (a quarter of
every cell it is a corner of: the integral of its linear basis function), its kernel
isotropic and ``radius`` times the mean length of the edges that meet there. (A tent on a
tetrahedral mesh, the linear "hat" of a point, is not a tensor product and has no
image-aligned cut of the same simple form; meshes keep the Gaussian kernel.)

Lighting (``Scene(shading=True)``): each splat carries the gradient at its centre (a
mesh's vertex: the volume-weighted mean of its cells' gradients), and its colour is lit
with it along each pixel's own ray before it is associated with the splat's opacity.

Clip planes and crop boxes: a kernel counts on a ray by its part in the ray's kept range
(``clipRange`` from the ray's start). Along the ray the kernel is a 1D Gaussian in ``t``
(mean ``-b / a``, standard deviation ``1 / sqrt(a)`` in the shader's terms), so its share
there is ``(erf(z1) - erf(z0)) / 2`` at the range's ends, in closed form per fragment
(erf to 1.5e-7, Abramowitz and Stegun 7.1.26): the reconstructed extinction integrated
over each ray's clipped interval, with no staircase of samples along the cut. Kernels
whose cutoff sphere misses the kept region are not drawn: along any ray their kept part
carries at most ``exp(-cutoff^2 / 2) / 2`` of the kernel's depth on its central ray (0.6 %
at the default), half of what the cutoff itself drops at its edge. On the CT
head at 48x48 the error against the clipped exact image is 0.62 to 0.91 of the unclipped
one; on a constant box with a crop box whose faces lie on sample planes, 0.49, where
keeping kernels by their centre gave 1.18 (those samples stand for half a cell outside).

Opaque geometry: the surface pass's colour is written into the target first, opaque (the
backmost layer, ``geometry.draw_surface_behind``), and each kernel counts by its erf share
of the ray up to t_hit (from the clip's start, or unclipped from minus infinity: the whole
kernel where no surface is met), in closed form as at a clip. On the same scenes the
error against the exact image is 0.95 and 0.87 of the error without the surfaces.

Order: per view the samples are sorted by depth, back to front (float32 argsort), and
drawn in that order (an index buffer); a splat counts only where its centre is ahead of
the ray's start. Samples with zero opacity are not drawn. Samples are made once per
volume, transfer function and density.

Options (same names in ``dvr_gl.reference.render``)
---------------------------------------------------
kernel : "tent" (grids' default) | "gaussian" (meshes' only kernel)
    the reconstruction kernel.
density : int from 1 to 8 (default 1). Tent: sheets per data spacing (the smallest);
    Gaussian: samples per data spacing along each axis (grids only).
sheet_spacing : tent only: the distance between sheets in world units (default: the
    smallest spacing over ``density``).
skip_empty : tent only (default True): leave out the samples whose cells are all
    transparent (the image is the same either way).
radius : Gaussian only: kernel standard deviation in sample spacings, or in mean edge
    lengths on a mesh (default 0.4: the balance of holes and blur measured in docs/guide/splat.md).
cutoff : Gaussian only
    truncation in standard deviations (default 3).
target : "rgba32f" (default) | "rgba16f" | "rgba8": blending happens in the target (the
    tent's sheet buffers are RGBA32F whatever the target).
brick_size : None (default) or N: a grid's samples made brick by brick from bricks of N
    cells a side, each from its own block (``point_bricks``): the same samples in the
    same order, so the same image.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ..util.cache import TableCache
from ..model.field import cell_is_valid, trilinear
from ..model.scene import Scene
from ..model.transfer import LookupTable
from . import proxy as proxy_geometry
from .common import (RepeatedIndices, SizedTarget, bind, camera_uniforms, check_flag, check_scene, check_step,
                     check_target, clip_defines, clip_uniforms,
                     cleared_target, data_projection, plane_projection, plane_triangles, point_shading_defines,
                     sample_term_uniforms, tf_uniforms, volume_uniforms)
from .geometry import draw_surface_behind, surface_pass
from .gpu import cell_valid_texture, proxy_vao, stream_vao, tf_texture, volume_texture
from .particle_sets import extinction
from .particles import pixels_per_unit
from . import point_bricks
from .bricks import check_brick_size

POINT_SPRITES = True  # the Gaussian kernel's splats are GL points, clipped by their centres (see Renderer.render)
MODES = ("composite",)
TAKES_STEP = False
DATA = ("volume", "mesh")
KERNELS = ("tent", "gaussian")
DEFAULT_RADIUS = 0.4
DEFAULT_CUTOFF = 3.0
QUAD_TRIANGLES = (0, 1, 2, 2, 1, 3)   # a quad's two triangles from its corners 0 .. 3
# Tent quads are grown by this many pixels on every side: many times the rasteriser's
# vertex snapping (1/256 pixel on llvmpipe, grow_pixels) and the float32 rounding of their
# corners, so every pixel centre inside a support is covered whatever the tile; pixels
# the margin adds lie outside it and add nothing.
QUAD_MARGIN = 1.0 / 16


def make_plan(scene, step=None, *, kernel=None, density=1, sheet_spacing=None, skip_empty=True, radius=None,
              cutoff=None, target="rgba32f", brick_size=None, tables=None):
    """Validate the options and plan the kernel's splats for this view (the samples are
    made once per volume and transfer function, the order once per view; with
    ``brick_size``, brick by brick: ``point_bricks``)."""
    tables = tables or TableCache()
    check_scene(scene, "splat", MODES, data=DATA)
    brick_size = check_brick_size(brick_size)
    if brick_size is not None:
        point_bricks.check_grid(scene, "splat")
    if step is not None:
        raise ValueError(f"splat takes no step (see density and sheet_spacing), got step={step!r}")
    if kernel is None:
        kernel = "gaussian" if scene.is_mesh else "tent"
    if kernel not in KERNELS:
        raise ValueError(f"kernel must be one of {', '.join(KERNELS)}, got {kernel!r}")
    if isinstance(density, bool) or not isinstance(density, (int, np.integer)) or not 1 <= density <= 8:
        raise ValueError(f"density must be an integer from 1 to 8, got {density!r}")
    skip_empty = check_flag("skip_empty", skip_empty)
    check_target(target)
    if kernel == "tent":
        if scene.is_mesh:
            raise ValueError("kernel 'tent' splats a grid's samples (trilinear tents); a TetMesh is splatted "
                             "with kernel 'gaussian'")
        given = [name for name, value in (("radius", radius), ("cutoff", cutoff)) if value is not None]
        if given:
            raise ValueError(f"{' and '.join(given)} size the Gaussian kernel (kernel='gaussian'); the tent "
                             "kernel is one sample spacing wide")
        return _tent_plan(scene, int(density), sheet_spacing, skip_empty, target, tables, brick_size)
    if sheet_spacing is not None:
        raise ValueError("sheet_spacing is the tent kernel's (kernel='tent'); the Gaussian kernel's splats "
                         "are composited one by one")
    if not skip_empty:
        raise ValueError("skip_empty is the tent kernel's: Gaussian splats with zero extinction add nothing "
                         "and are never drawn")
    radius = DEFAULT_RADIUS if radius is None else radius
    cutoff = DEFAULT_CUTOFF if cutoff is None else cutoff
    return _gaussian_plan(scene, density, radius, cutoff, target, tables, brick_size)


def draw(renderer, plan):
    """Render the plan into the renderer's target; returns that framebuffer."""
    return _draw_tent(renderer, plan) if plan.kernel == "tent" else _draw_gaussian(renderer, plan)


# ---------------------------------------------------------------------------------------
# The tent kernel: sheet buffers

@dataclass
class TentSamples:
    """The samples a tent plan splats, made once per volume, transfer function and
    ``skip_empty``: ``values`` (N,) float32 (0 for a non-finite sample); ``at`` (N, 3)
    int32, their indices (x, y, z); ``finite`` (N,) bool; ``mask`` (nz, ny, nx) bool,
    which of the volume's samples these are (in its C order)."""
    values: np.ndarray
    at: np.ndarray
    finite: np.ndarray
    mask: np.ndarray
    run_stats: list = field(default_factory=list)    # per axis: (runs, their extent in spacings)

    @property
    def count(self):
        return len(self.values)

    @cached_property
    def slots(self):
        """(nz, ny, nx) int64: each volume sample's row here, -1 where it is not splatted."""
        slot = np.full(self.mask.shape, -1, np.int64)
        slot[self.mask] = np.arange(self.count)
        return slot


@dataclass
class Runs:
    """The splatted samples in runs along ``axis`` (0 = x): maximal sequences of
    splatted neighbours along it. ``runs`` (R + 1, 4) int32: the first sample's indices
    (x, y, z) and the run's first row in the per-sample arrays, the last row only that
    offset (the total); ``ids`` (N,) the sample (row of ``TentSamples``) at each position
    in run order."""
    axis: int
    runs: np.ndarray
    ids: np.ndarray

    @property
    def count(self):
        return len(self.runs) - 1


@dataclass
class SheetOrder:
    """One view's sheets and what each draws. Sheet ``k`` (0 the farthest) lies at depth
    ``far_depth - k * spacing``; the samples are drawn in ``runs`` along ``runs.axis``,
    and sheet k draws the runs ``order[first : first + n]`` with ``first, n = ranges[k]``
    (besides those that reach it, at most one sheet's worth more, which the vertex shader
    drops)."""
    far_depth: float
    count: int
    spacing: float
    runs: Runs | None
    order: np.ndarray
    ranges: np.ndarray


@dataclass
class TentPlan:
    scene: Scene
    samples: TentSamples
    sheets: SheetOrder
    lut: LookupTable
    density: int = 1
    skip_empty: bool = True
    target: str = "rgba32f"
    defines: dict = field(default_factory=dict)        # the sheet (classification) pass's
    splat_defines: dict = field(default_factory=dict)  # the splat pass's
    gradients: np.ndarray | None = None   # lit: (N, 3) float32, the gradient at each sample
    kernel: str = "tent"
    gap: object = None      # the slice3d plan of the same planes: its gap pass fills the
                            # rays that cross no sheet inside the box

    @property
    def step(self):
        """The distance between sheets."""
        return self.sheets.spacing

    @property
    def far_depth(self):
        return self.sheets.far_depth

    @property
    def count(self):
        return self.sheets.count


def _tent_plan(scene, density, sheet_spacing, skip_empty, target, tables, brick_size=None):
    volume = scene.volume
    if sheet_spacing is None:
        sheet_spacing = volume.min_spacing / density
    else:
        if density != 1:
            raise ValueError(f"give density or sheet_spacing, not both (got density={density!r}, "
                             f"sheet_spacing={sheet_spacing!r})")
        sheet_spacing = check_step(sheet_spacing, volume, "sheet_spacing")
    lut = tables.get("lut", scene.tf, make=LookupTable)
    if brick_size is None:
        samples = tables.get(f"tent_samples:{int(skip_empty)}", volume, lut,
                             make=lambda v, table: tent_samples(v, table, skip_empty))
    else:
        samples = tables.get(f"tent_samples:{int(skip_empty)}:bricks {brick_size}", volume, lut,
                             make=lambda v, table: bricked_tent_samples(v, table, skip_empty, brick_size))
    axis = run_axis(samples, volume, scene.camera.forward)
    runs = None if samples.count == 0 else tables.get("tent_runs", samples, axis,
                                                      make=lambda s, a: runs_along(s, a))
    # the sheets are 3D slicing's planes, so its gap pass fills the rays that cross none
    from . import slice3d
    gap = slice3d.make_plan(scene, float(sheet_spacing), target=target, tables=tables)
    sheets = tables.get("tent_sheets", samples, scene.camera, float(sheet_spacing),
                        make=lambda s, camera, spacing: sheet_order(scene, runs, spacing, gap.far_depth, gap.count))
    splat_defines = {"ORTHO": 1} if scene.camera.is_ortho else {}
    if scene.shading:
        splat_defines["SHADING"] = 1
    if volume.has_nonfinite:
        splat_defines["MASK_NONFINITE"] = 1
    defines = {**splat_defines, **point_shading_defines(scene), **clip_defines(scene)}   # the sheets' segments clip
    if scene.geometry:
        defines["GEOMETRY"] = 1            # and end at the first surface
    gradients = None
    if scene.shading and brick_size is not None:    # each from its brick's block
        gradients = tables.get("tent_gradients", samples, volume,
                               make=lambda s, v: point_bricks.tent_gradients_bricked(s, v, brick_size))
    elif scene.shading:      # once per set of samples
        gradients = tables.get("tent_gradients", samples, volume, make=tent_gradients)
    return TentPlan(scene=scene, samples=samples, sheets=sheets, lut=lut, density=density, skip_empty=skip_empty,
                    target=target, defines=defines, splat_defines=splat_defines, gradients=gradients, gap=gap)


def occupied_cells(volume, lut):
    """(nz - 1, ny - 1, nx - 1) bool: the cells whose value range (the least and greatest
    of their 8 corners, which bound the trilinear field inside them) has non-zero opacity
    in the lookup table somewhere, by ``raycast.brick_occupancy`` (once per distinct
    range), so with its allowance for float32 rounding. Cells with a non-finite corner
    are outside the domain: never occupied."""
    from .raycast import brick_occupancy
    v = volume.values(np.float32)
    nz, ny, nx = v.shape
    eight = [v[z:z + nz - 1, y:y + ny - 1, x:x + nx - 1] for z in (0, 1) for y in (0, 1) for x in (0, 1)]
    lo, hi = np.minimum.reduce(eight).ravel(), np.maximum.reduce(eight).ravel()
    key = (lo.view(np.uint32).astype(np.uint64) << np.uint64(32)) | hi.view(np.uint32).astype(np.uint64)
    ranges, inverse = np.unique(key, return_inverse=True)
    lo = (ranges >> np.uint64(32)).astype(np.uint32).view(np.float32).astype(np.float64)
    hi = (ranges & np.uint64(0xFFFFFFFF)).astype(np.uint32).view(np.float32).astype(np.float64)
    occupied = brick_occupancy((lo, hi), lut)[inverse.ravel()].reshape(nz - 1, ny - 1, nx - 1)
    if volume.cell_valid is not None:
        occupied &= volume.cell_valid
    return occupied


def _corners_of(cells):
    """The samples that are a corner of some cell set in ``cells``."""
    nz, ny, nx = cells.shape
    out = np.zeros((nz + 1, ny + 1, nx + 1), bool)
    for z in (0, 1):
        for y in (0, 1):
            for x in (0, 1):
                out[z:z + nz, y:y + ny, x:x + nx] |= cells
    return out


def _cells_with_a_corner(samples):
    """The cells that have some sample set in ``samples`` as a corner."""
    nz, ny, nx = samples.shape
    return np.logical_or.reduce([samples[z:z + nz - 1, y:y + ny - 1, x:x + nx - 1]
                                 for z in (0, 1) for y in (0, 1) for x in (0, 1)])


def tent_samples(volume, lut, skip_empty=True):
    """The samples to splat: with ``skip_empty``, the corners of occupied cells (see
    ``occupied_cells``) and the non-finite corners of cells that have one of those; else
    every sample."""
    finite = np.isfinite(volume.data) if volume.has_nonfinite else None
    if skip_empty:
        mask = _corners_of(occupied_cells(volume, lut))
        if finite is not None:
            mask &= finite
            mask |= _corners_of(_cells_with_a_corner(mask)) & ~finite
    else:
        mask = np.ones(volume.shape, bool)
    at = np.argwhere(mask)[:, ::-1].astype(np.int32)           # x, y, z; the order of mask's True
    flags = np.ones(len(at), bool) if finite is None else finite[mask]
    return TentSamples(volume.values(np.float32)[mask], at, flags, mask, _run_stats(mask))


def bricked_tent_samples(volume, lut, skip_empty, brick_size):
    """``tent_samples`` made brick by brick (``point_bricks.tent_bricks``): the same."""
    splatted = (lambda block: _corners_of(occupied_cells(block, lut))) if skip_empty else None
    values, at, mask = point_bricks.tent_bricks(volume, splatted, brick_size)
    return TentSamples(values, at, np.ones(len(at), bool), mask, _run_stats(mask))


def _run_stats(mask):
    """Per axis x, y, z: (number of runs, their total extent in spacings)."""
    stats = []
    for axis in range(3):
        m = np.moveaxis(mask, 2 - axis, -1)
        starts = int((m[..., 1:] & ~m[..., :-1]).sum() + m[..., 0].sum())
        stats.append((starts, int(mask.sum()) - starts))
    return stats


def run_axis(samples, volume, forward):
    """The axis whose runs make the fewest quads in this view: a run reaches as many
    sheets as its depth extent, ``length * s_a |forward_a|``, plus the tent's own,
    ``2 sum_a |forward_a| s_a``, so the count is about ``extent * s_a |f_a| + runs * 2r``."""
    if samples.count == 0:
        return 0
    reach = kernel_reach(volume, forward)
    cost = [extent * volume.spacing[a] * abs(forward[a]) + starts * 2 * reach
            for a, (starts, extent) in enumerate(samples.run_stats)]
    return int(np.argmin(cost))


def runs_along(samples, axis):
    """The samples' ``Runs`` along ``axis``."""
    moved = np.moveaxis(samples.slots, 2 - axis, -1)                     # the run axis fastest
    flat = np.flatnonzero(moved.ravel() >= 0)
    ids = moved.ravel()[flat]
    n = moved.shape[-1]
    start = np.ones(flat.size, bool)
    start[1:] = (flat[1:] != flat[:-1] + 1) | (flat[1:] % n == 0)
    first = np.flatnonzero(start)
    runs = np.zeros((first.size + 1, 4), np.int32)
    runs[:-1, :3] = samples.at[ids[first]]
    runs[:-1, 3] = first
    runs[-1, 3] = flat.size
    return Runs(axis, runs, ids.astype(np.int64))


def tent_gradients(samples, volume):
    """(N, 3) float32: each splatted sample's central differences (see
    ``model.field.sample_gradients``)."""
    from ..model.field import sample_gradients
    return sample_gradients(volume, volume.values(np.float64), at=samples.at).astype(np.float32)


def kernel_reach(volume, forward):
    """How far the tent's support reaches in depth from its centre: sum_a |forward_a| s_a."""
    return float(np.abs(np.asarray(forward, np.float64)) @ volume.spacing)


def sheet_order(scene, runs, spacing, far_depth, count):
    """The sheets of this view (``count`` planes ``spacing`` apart, the farthest at depth
    ``far_depth``: 3D slicing's) and, for each, the runs whose tents may reach it (those
    whose support's depth range holds the sheet's depth, give or take a sheet), listed
    sheet by sheet."""
    cam = scene.camera
    volume = scene.volume
    eye = cam.eye - volume.bounds[0]
    if count == 0 or runs is None or runs.count == 0:
        return SheetOrder(far_depth, count, spacing, runs, np.zeros(0, np.int32), np.zeros((count, 2), np.int64))
    reach = kernel_reach(volume, cam.forward)
    starts = runs.runs[:-1, :3].astype(np.float64) * volume.spacing
    lengths = np.diff(runs.runs[:, 3]).astype(np.float64)
    z0 = (starts - eye) @ cam.forward
    z1 = z0 + (lengths - 1) * volume.spacing[runs.axis] * cam.forward[runs.axis]
    near = np.minimum(z0, z1) - reach
    far = np.maximum(z0, z1) + reach
    # sheet k's depth far_depth - k * spacing lies in (near, far) for k in (k0, k1); one
    # sheet more on each side covers the rounding
    k0 = np.maximum(np.floor((far_depth - far) / spacing), 0).astype(np.int64)
    k1 = np.minimum(np.ceil((far_depth - near) / spacing), count - 1).astype(np.int64)
    n = np.maximum(k1 - k0 + 1, 0)
    run = np.repeat(np.arange(runs.count), n)
    sheet = np.repeat(k0 - np.cumsum(n) + n, n) + np.arange(int(n.sum()))
    key = sheet.astype(np.uint16 if count <= 65536 else np.uint32)
    by_sheet = np.argsort(key, kind="stable")
    order = run[by_sheet].astype(np.int32)
    per_sheet = np.bincount(sheet, minlength=count)
    first = np.concatenate([[0], np.cumsum(per_sheet)[:-1]])
    return SheetOrder(far_depth, count, spacing, runs, order, np.stack([first, per_sheet], axis=1).astype(np.int64))


def run_frame(forward, axis, right):
    """The quads' axes in the sheet plane: ``u`` along the runs' direction seen on the
    sheet (``right`` if the view runs along them, when any frame does), ``v`` across
    it, so that a long run's cut is a long thin strip along ``u`` with a tight rectangle."""
    f = np.asarray(forward, np.float64)
    e = np.zeros(3)
    e[axis] = 1.0
    u = e - f[axis] * f
    u = np.asarray(right, np.float64) if np.linalg.norm(u) < 1e-6 else u / np.linalg.norm(u)
    return u, np.cross(f, u)


def section_table(spacing, forward, u, v):
    """The tent's support (the box of half-widths ``spacing`` about its centre) cut by
    the planes perpendicular to ``forward``: at each of its 8 corners' depths (ascending,
    relative to the centre), the bounding rectangle (u min, u max, v min, v max) of the
    cut along the axes ``u`` and ``v`` of the plane. Between two consecutive corner depths
    each bound is linear in the plane's depth (the cut's extreme point slides along one
    edge of the box and changes edge only at a corner), so interpolating this table gives
    the rectangle of any cut exactly. Returns (depths (8,), rects (8, 4))."""
    corners = proxy_geometry.box_corners(-np.asarray(spacing, np.float64), np.asarray(spacing, np.float64))
    d = corners @ np.asarray(forward, np.float64)
    depths = np.sort(d)
    rects = np.empty((8, 4))
    a, b = proxy_geometry.EDGES[:, 0], proxy_geometry.EDGES[:, 1]
    for j, delta in enumerate(depths):
        cross = (d[a] - delta) * (d[b] - delta) < 0
        t = (delta - d[a][cross]) / (d[b][cross] - d[a][cross])
        points = np.concatenate([corners[d == delta],
                                 corners[a[cross]] + t[:, None] * (corners[b[cross]] - corners[a[cross]])])
        pu, pv = points @ np.asarray(u, np.float64), points @ np.asarray(v, np.float64)
        rects[j] = pu.min(), pu.max(), pv.min(), pv.max()
    return depths, rects


def section_rect(table, delta):
    """The interpolated rectangle of the cut at offsets ``delta`` (..., 4), NaN outside
    the support (the table lookup of shaders/splat/tent.vert)."""
    depths, rects = table
    delta = np.asarray(delta, np.float64)
    j = np.clip(np.searchsorted(depths, delta, side="left") - 1, 0, 6)
    lo, hi = depths[j], depths[j + 1]
    f = np.clip((delta - lo) / np.where(hi > lo, hi - lo, 1.0), 0.0, 1.0)[..., None]
    out = rects[j] * (1 - f) + rects[j + 1] * f
    return np.where(((delta >= depths[0]) & (delta <= depths[-1]))[..., None], out, np.nan)


def run_quads(table, forward, axis, u, v, spacing, lengths, delta0):
    """NumPy twin of shaders/splat/tent.vert's rectangle (without its margin):
    for runs whose first sample's centre lies ``delta0`` in front of the sheet, the
    bounding rectangle (u min, u max, v min, v max) along ``u`` and ``v`` (relative to
    that centre moved onto the sheet) of the sheet's cut through the union of the run's
    supports; NaN where it misses them. The union is the support swept along the run:
    over the run's centres ``x e_a`` the cut at offset ``delta0 - x f_a`` moved by
    ``x (e_a . u, e_a . v)``, whose bounds are piecewise linear in x with corners where
    the offset meets a table depth, so their extremes lie at the ends or at those
    corners."""
    depths, rects = table
    fa = float(forward[axis])
    shift = np.array([u[axis], u[axis], v[axis], v[axis]], np.float64)
    extent = (np.asarray(lengths, np.float64) - 1) * spacing[axis]
    delta0 = np.asarray(delta0, np.float64)
    lo, hi = np.zeros_like(delta0), extent.copy()
    if fa != 0.0:
        ends = np.sort(np.stack([(delta0 - depths[-1]) / fa, (delta0 - depths[0]) / fa]), axis=0)
        lo, hi = np.maximum(lo, ends[0]), np.minimum(hi, ends[1])
    candidates = [lo, hi] + ([] if fa == 0.0 else [np.clip((delta0 - d) / fa, lo, hi) for d in depths])
    out = np.full(delta0.shape + (4,), np.nan)
    for x in candidates:
        r = section_rect(table, np.clip(delta0 - x * fa, depths[0], depths[-1]))
        r = r + x[..., None] * shift
        out = np.stack([np.fmin(out[..., 0], r[..., 0]), np.fmax(out[..., 1], r[..., 1]),
                        np.fmin(out[..., 2], r[..., 2]), np.fmax(out[..., 3], r[..., 3])], axis=-1)
    return np.where((lo <= hi)[..., None], out, np.nan)


class _TentTextures:
    """A set of tent samples on the GPU in runs along one axis, uploaded once: the runs,
    and per sample in run order its value and non-finite flag, and (lit) its gradient;
    plus the view's order of runs (rewritten when the view changes)."""

    def __init__(self, ctx, samples, runs, gradients):
        from .tetra import _OrderTexture
        self.ctx = ctx
        self.runs = _rows_texture(ctx, runs.runs, "i4")
        values = np.stack([samples.values[runs.ids], ~samples.finite[runs.ids]], axis=1)
        self.values = _rows_texture(ctx, values, "f4")
        self.gradients = None if gradients is None else _rows_texture(ctx, gradients[runs.ids], "f4")
        self.order = _OrderTexture()
        self.order_of = None

    def ordered(self, sheets):
        if self.order_of is not sheets:
            self.order.write(self.ctx, sheets.order if sheets.order.size else np.zeros(1, np.int32))
            self.order_of = sheets
        return self.order.tex

    def release(self):
        for tex in (self.runs, self.values, self.gradients):
            if tex is not None:
                tex.release()
        self.order.release()


def _rows_texture(ctx, array, dtype):
    from .tetra import _texture
    return _texture(ctx, np.asarray(array, np.int32 if dtype == "i4" else np.float32), dtype)


def _draw_tent(renderer, plan):
    ctx = renderer.ctx
    scene = plan.scene
    sheets = plan.sheets
    surfaces = surface_pass(renderer, scene) if scene.geometry else None   # each pixel's first surface
    fbo = cleared_target(renderer, scene, plan.target)
    if sheets.count == 0 or not sheets.ranges[:, 1].any():
        return _draw_tent_gap(renderer, plan, fbo, surfaces)
    lit = plan.gradients is not None
    runs = sheets.runs
    splat = renderer.programs.get("splat/tent.vert", "splat/tent.frag", plan.splat_defines)
    classify = renderer.programs.get("common/slice_polygons.vert", "splat/sheet.frag", plan.defines)
    gpu = renderer.resources.for_objects("splat_tent", plan.samples, runs, plan.gradients, capacity=3,  # an axis each
                                         make=lambda: _TentTextures(ctx, plan.samples, runs, plan.gradients))
    # (sum w v, sum w) and, for masked data, the non-finite weight; (sum w g) when lit
    channels = (4 if scene.volume.has_nonfinite else 2,) + ((4,) if lit else ())
    buffers = renderer.resources.for_objects("splat_sheet", *channels, capacity=2,
                                             make=lambda: SizedTarget(ctx, components=channels)).get(*scene.target_size)

    cam = scene.camera
    u, v = run_frame(cam.forward, runs.axis, cam.right)
    depths, rects = section_table(scene.volume.spacing, cam.forward, u, v)
    slabs = {"u_far_depth": sheets.far_depth, "u_step": sheets.spacing, "u_slice_count": sheets.count}
    view_proj = plane_projection(plan).astype("f4").tobytes()      # every quad lies on a sheet
    splat_textures = {"t_order": gpu.ordered(sheets), "t_runs": gpu.runs, "t_values": gpu.values}
    if lit:
        splat_textures["t_gradients"] = gpu.gradients
    bind(splat, splat_textures, {**camera_uniforms(scene), **slabs, "u_spacing": tuple(scene.volume.spacing),
                                 "u_axis": runs.axis, "u_u": tuple(u), "u_v": tuple(v),
                                 "u_section_depth": tuple(depths), "u_section_rect": [tuple(r) for r in rects],
                                 "u_margin": QUAD_MARGIN / pixels_per_unit(scene)})
    splat["u_view_proj"].write(view_proj)
    sheet_textures = {"t_tf": tf_texture(renderer, plan.lut), "t_sheet": buffers.color_attachments[0]}
    if lit:
        sheet_textures["t_sheet_gradient"] = buffers.color_attachments[1]
    if surfaces is not None:
        sheet_textures["t_surface"] = surfaces
    uniforms = {**camera_uniforms(scene), **slabs, **tf_uniforms(plan.lut, scene.tf),
                **volume_uniforms(scene.volume), **clip_uniforms(scene)}
    if scene.clips or scene.geometry:     # END_PIECES: pieces at a cut take the field at their middle
        sheet_textures["t_volume"] = volume_texture(renderer, scene.volume)
        if scene.volume.has_nonfinite:
            sheet_textures["t_cell_valid"] = cell_valid_texture(renderer, scene.volume)
    if lit:
        uniforms.update(sample_term_uniforms(renderer, scene, plan.defines))
    bind(classify, sheet_textures, uniforms, first_unit=len(splat_textures))
    classify["u_view_proj"].write(view_proj)
    positions, index, polygon = plane_triangles(scene, sheets.far_depth, sheets.spacing, sheets.count)
    polygons = stream_vao(renderer, classify, "splat_sheets", positions, index)
    # two triangles per quad; quad q's corners are vertices 4q .. 4q + 3 (tent.vert)
    quads = renderer.resources.for_objects(
        "splat_quads", make=lambda: RepeatedIndices(ctx, QUAD_TRIANGLES, minimum=1024), capacity=1).vao(
        splat, int(sheets.ranges[:, 1].max()))

    ctx.disable(ctx.DEPTH_TEST | ctx.CULL_FACE)
    ctx.enable(ctx.BLEND)
    ctx.blend_equation = ctx.FUNC_ADD
    try:
        for k in range(sheets.count - 1, -1, -1):        # front to back
            first, n = (int(x) for x in sheets.ranges[k])
            start, vertices = (int(x) for x in polygon[k])
            if n == 0 or vertices == 0:
                continue
            buffers.use()
            buffers.clear(0.0, 0.0, 0.0, 0.0)
            ctx.blend_func = ctx.ONE, ctx.ONE                  # the tents add up
            splat["u_slice"].value = k
            splat["u_first"].value = first
            quads.render(ctx.TRIANGLES, vertices=6 * n)       # 4 vertices per quad, indexed
            fbo.use()
            ctx.blend_func = ctx.ONE_MINUS_DST_ALPHA, ctx.ONE  # the sheet goes behind what is there
            polygons.render(ctx.TRIANGLES, first=start, vertices=vertices)
    finally:
        ctx.disable(ctx.BLEND)
        ctx.blend_func = ctx.ONE, ctx.ONE_MINUS_SRC_ALPHA
    return _draw_tent_gap(renderer, plan, fbo, surfaces)


def _draw_tent_gap(renderer, plan, fbo, surfaces=None):
    """Rays whose chord through the box crosses no sheet (at the silhouette, through
    edges and corners, a box thinner than the spacing) get their whole chord, as in 3D
    slicing, whose planes the sheets are; those pixels hold nothing yet. Then the
    surfaces (``surfaces``: ``geometry.surface_pass``'s texture, None without geometry)
    go under everything, the last layer front to back."""
    from . import slice3d
    ctx = renderer.ctx
    fbo.use()
    ctx.disable(ctx.DEPTH_TEST | ctx.CULL_FACE)
    ctx.enable(ctx.BLEND)
    ctx.blend_func = ctx.ONE, ctx.ONE_MINUS_SRC_ALPHA
    ctx.blend_equation = ctx.FUNC_ADD
    try:
        inputs = None
        if surfaces is not None:      # the gap's chords end at the surface too
            inputs = slice3d.slice_inputs(renderer, plan.gap)
            inputs[0]["t_surface"] = surfaces
        slice3d.draw_gap(renderer, plan.gap, inputs)
        if surfaces is not None:
            _draw_surface_under(renderer, surfaces)
    finally:
        ctx.disable(ctx.BLEND)
        ctx.blend_func = ctx.ONE, ctx.ONE_MINUS_SRC_ALPHA
    return fbo


def _draw_surface_under(renderer, surfaces):
    """Each pixel's first surface, lit colour with opacity 1, blended under what the
    sheets left (``ONE_MINUS_DST_ALPHA, ONE``): ``C + (1 - A) lit``, ``A = 1``, the
    contract's surface behind the ray. The slicing techniques draw it first instead
    (``geometry.draw_surface_behind``, the same fragment shader), under back-to-front
    blending."""
    ctx = renderer.ctx
    prog = renderer.programs.get("common/box_instances.vert", "geometry/surface_behind.frag", {})
    bind(prog, {"t_surface": surfaces}, {})
    prog["u_view_proj"].write(np.eye(4, dtype="f4").tobytes())
    ctx.blend_func = ctx.ONE_MINUS_DST_ALPHA, ctx.ONE
    proxy_vao(renderer, prog, "fullscreen").render(ctx.TRIANGLES)


# ---------------------------------------------------------------------------------------
# The Gaussian kernel: pre-classified footprints, back to front

@dataclass
class Splats:
    """The drawn samples: ``points`` (N, 3) float32 relative to the data's lower corner,
    ``samples`` (N, 4) float32 (colour, extinction times the sample's volume share),
    ``scales`` (N,) float32 and ``spacing`` (3,): sample i's kernel has standard
    deviation ``radius * spacing * scales[i]`` per axis (grids: the sample spacing, every
    scale 1; meshes: spacing 1, the scale the point's mean edge length)."""
    points: np.ndarray
    samples: np.ndarray
    scales: np.ndarray
    spacing: np.ndarray
    vertices: np.ndarray | None = None    # a mesh's: the vertex each splat is

    @property
    def count(self):
        return len(self.points)


@dataclass
class SplatPlan:
    scene: Scene
    splats: Splats
    order: np.ndarray                # int32 indices into splats, back to front
    density: int = 1
    radius: float = DEFAULT_RADIUS
    cutoff: float = DEFAULT_CUTOFF
    target: str = "rgba32f"
    defines: dict = field(default_factory=dict)
    gradients: np.ndarray | None = None   # lit: (N, 3) float32, the gradient at each splat's centre
    kernel: str = "gaussian"

    @property
    def sigma(self):
        """The kernel's standard deviations at scale 1 (each splat's times its scale)."""
        return self.radius * self.splats.spacing

    def kernel_uniforms(self):
        sigma = self.sigma
        mass = 1.0 - math.exp(-0.5 * self.cutoff ** 2)
        return {"u_inv_var": tuple(1.0 / sigma ** 2), "u_cutoff2": self.cutoff ** 2,
                "u_norm": 1.0 / (2.0 * math.pi * float(np.prod(sigma)) * mass),
                "u_reach": self.cutoff * float(sigma.max())}


def make_splats(volume, tf, density):
    """The classified samples of ``volume`` at ``density`` samples per spacing (those
    with non-zero opacity), made a plane of samples at a time (bounded memory)."""
    dims = volume.dims
    n = (dims - 1) * density + 1
    values = volume.values(np.float64)
    spacing = volume.spacing / density
    cell = float(np.prod(spacing))
    yy, xx = np.meshgrid(np.arange(n[1]) / density, np.arange(n[0]) / density, indexing="ij")
    points, samples = [], []
    for k in range(n[2]):
        idx = np.stack([xx.ravel(), yy.ravel(), np.full(xx.size, k / density)], axis=1)   # x, y, z indices
        s = trilinear(values, idx)
        tau = extinction(tf, s)
        keep = tau > 0
        if volume.cell_valid is not None:
            keep &= cell_is_valid(volume, idx)
        if not keep.any():
            continue
        idx, s, tau = idx[keep], s[keep], tau[keep]
        at, rows = point_bricks.splat_rows(idx, s, tau, dims, volume.spacing, tf, cell)
        points.append(at)
        samples.append(rows)
    if not points:
        return Splats(np.zeros((0, 3), np.float32), np.zeros((0, 4), np.float32), np.zeros(0, np.float32), spacing)
    points = np.concatenate(points)
    return Splats(points, np.concatenate(samples), np.ones(len(points), np.float32), spacing)


def bricked_splats(volume, tf, density, brick_size):
    """(``make_splats``'s Splats made brick by brick, each one's place in their order:
    ``point_bricks.splat_bricks``)."""
    points, samples, key = point_bricks.splat_bricks(volume, tf, density, brick_size)
    return Splats(points, samples, np.ones(len(points), np.float32), volume.spacing / density), key


def make_mesh_splats(mesh, tf):
    """A tetrahedral mesh's classified points: each point's kernel carries its lumped
    share of the volume (a quarter of every cell it is a corner of: the integral of its
    linear basis function) and is as wide as the edges that meet there, on average."""
    tets = mesh.tets
    share = np.bincount(tets.ravel(), np.repeat(np.abs(mesh.signed_volumes()) / 4.0, 4), minlength=mesh.n_points)
    pairs = tets[:, [0, 0, 0, 1, 1, 2, 1, 2, 3, 2, 3, 3]].reshape(-1, 2, 6).transpose(0, 2, 1).reshape(-1, 2)
    length = np.linalg.norm(mesh.points[pairs[:, 0]] - mesh.points[pairs[:, 1]], axis=1)
    ends = pairs.ravel()
    total = np.bincount(ends, np.repeat(length, 2), minlength=mesh.n_points)
    count = np.bincount(ends, minlength=mesh.n_points)
    s = mesh.scalars
    tau = extinction(tf, s)
    keep = (tau > 0) & (share > 0) & (count > 0)
    tau = tau[keep]
    samples = np.concatenate([tf.color(s[keep]).reshape(-1, 3), (tau * share[keep])[:, None]], axis=1)
    return Splats((mesh.points[keep] - mesh.bounds[0]).astype(np.float32), samples.astype(np.float32),
                  (total[keep] / count[keep]).astype(np.float32), np.ones(3), np.flatnonzero(keep))


def back_to_front(scene, splats):
    """Indices of the splats, farthest first: by distance from the eye (perspective) or
    depth along the view (orthographic)."""
    cam = scene.camera
    eye = (cam.eye - scene.volume.bounds[0]).astype(np.float32)
    rel = splats.points - eye
    key = rel @ cam.forward.astype(np.float32) if cam.is_ortho else np.einsum("ij,ij->i", rel, rel)
    return np.argsort(-key, kind="stable").astype(np.int32)


def _gaussian_plan(scene, density, radius, cutoff, target, tables, brick_size=None):
    """Check the Gaussian kernel's options, get the samples (once per volume, TF and
    density) and their order for this view."""
    for name, value in (("radius", radius), ("cutoff", cutoff)):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a positive number, got {value!r}")
    if scene.is_mesh:
        if density != 1:
            raise ValueError(f"density applies to grids (a mesh is splatted at its points), got density={density!r}")
        splats = tables.get("splats:mesh", scene.volume, scene.tf, make=make_mesh_splats)
    elif brick_size is not None:      # brick by brick, in the single texture's order
        splats, key = tables.get(f"splats:{int(density)}:bricks {brick_size}", scene.volume, scene.tf,
                                 make=lambda volume, tf: bricked_splats(volume, tf, int(density), brick_size))
    else:
        splats = tables.get(f"splats:{int(density)}", scene.volume, scene.tf,
                            make=lambda volume, tf: make_splats(volume, tf, int(density)))
    if brick_size is None:
        order = tables.get("splat_order", splats, scene.camera, make=lambda s, camera: back_to_front(scene, s))
    else:
        order = tables.get("splat_order", splats, scene.camera,
                           make=lambda s, camera: point_bricks.splat_order(scene, s, key))
    defines = {"ORTHO": 1} if scene.camera.is_ortho else {}
    defines.update(point_shading_defines(scene))
    defines.update(clip_defines(scene))     # splats whose centre is clipped away are not drawn
    if scene.geometry:
        defines["GEOMETRY"] = 1             # a kernel counts by its part in front of the first surface
    gradients = None
    if scene.shading and brick_size is not None:    # each from its brick's block
        gradients = tables.get("splat_gradients", splats, scene.volume, make=lambda s, v: point_bricks.
                               splat_gradients_bricked(v, s, key, int(density), brick_size))
    elif scene.shading:      # once per set of splats
        gradients = tables.get("splat_gradients", splats, scene.volume, make=splat_gradients)
    return SplatPlan(scene=scene, splats=splats, order=order, density=int(density), radius=float(radius),
                     cutoff=float(cutoff), target=target, defines=defines, gradients=gradients)


def splat_gradients(splats, data):
    """(N, 3) float32: the gradient at each splat's centre (a mesh's vertices: the
    volume-weighted mean of their cells')."""
    from ..model.field import point_gradients
    return point_gradients(data, splats.points, vertices=splats.vertices).astype(np.float32)


def _draw_gaussian(renderer, plan):
    ctx = renderer.ctx
    scene = plan.scene
    surfaces = surface_pass(renderer, scene) if scene.geometry else None   # each pixel's first surface
    fbo = cleared_target(renderer, scene, plan.target)
    if surfaces is not None:       # the backmost layer: the splats are blended over it
        draw_surface_behind(renderer, surfaces)
    if plan.splats.count == 0:
        return fbo
    prog = renderer.programs.get("splat/splat.vert", "splat/splat.frag", plan.defines, geometry="splat/splat.geom")
    uniforms = {**camera_uniforms(scene), **plan.kernel_uniforms(), "u_pixels_per_unit": pixels_per_unit(scene),
                "u_target_size": tuple(float(x) for x in fbo.size), **clip_uniforms(scene)}
    if scene.shading:
        uniforms.update(sample_term_uniforms(renderer, scene, plan.defines))
    bind(prog, {} if surfaces is None else {"t_surface": surfaces}, uniforms)
    prog["u_view_proj"].write(data_projection(scene).astype("f4").tobytes())
    gpu = renderer.resources.for_objects("splat_vbo", plan.splats, prog,
                                         make=lambda: _SplatBuffers(ctx, prog, plan.splats, plan.gradients), capacity=1)
    vao = gpu.ordered(plan.order)
    ctx.disable(ctx.DEPTH_TEST | ctx.CULL_FACE)
    ctx.enable(ctx.BLEND)
    ctx.blend_func = ctx.ONE, ctx.ONE_MINUS_SRC_ALPHA
    ctx.blend_equation = ctx.FUNC_ADD
    vao.render(ctx.POINTS, vertices=int(plan.order.size))      # splat.geom makes each a square
    ctx.disable(ctx.BLEND)
    return fbo


class _SplatBuffers:
    """The samples on the GPU (uploaded once) and the per-view order (an index buffer)."""

    def __init__(self, ctx, prog, splats, gradients=None):
        self.ctx = ctx
        parts = [splats.points, splats.samples, splats.scales[:, None]] + ([] if gradients is None else [gradients])
        data = np.concatenate(parts, axis=1).astype(np.float32)
        self.vbo = ctx.buffer(np.ascontiguousarray(data).tobytes())
        self.ibo = ctx.buffer(reserve=max(4 * splats.count, 4))
        layout = [(self.vbo, "3f 4f 1f", "a_position", "a_sample", "a_scale")] if gradients is None else \
            [(self.vbo, "3f 4f 1f 3f", "a_position", "a_sample", "a_scale", "a_gradient")]
        self.vao = ctx.vertex_array(prog, layout, index_buffer=self.ibo, index_element_size=4)
        self.last = None

    def ordered(self, order):
        if self.last is not order:           # a new view: its order
            self.ibo.write(np.ascontiguousarray(order, np.int32).tobytes())
            self.last = order
        return self.vao

    def release(self):
        self.vao.release()
        self.ibo.release()
        self.vbo.release()
