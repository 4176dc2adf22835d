"""Ray casting several volumes at once (``Scene.layers``): the scene's own volume and up
to three more, each on its own grid, placed by a rigid motion, classified by its own
transfer function (a scan) or label colours (a label volume), mixed into one medium or
added as separate images (``Scene.blend``; docs/contract.md, "Several volumes").

About this technique
--------------------
``raycast.make_plan`` hands a scene with layers to ``make_plan`` here and
``raycast.draw`` hands the plan to ``draw``; the NumPy twin is
``dvr_gl.reference.raycast_layers``.

Rays are the ray caster's pixel-centre rays (``common/camera_ray.glsl``), positions
relative to the scene's own volume's lower corner. Each layer sees the ray in its own
frame, ``q = M (x + lo) + m`` with ``M = R^T`` and ``m = -R^T t - lo_layer`` (rigid: t is
the same distance in every frame), and meets its own box at ``[enter_i, exit_i]``
(``intersectBox`` in that frame). The ray's interval is the union ``[min enter, max
exit]``, cut by the clip planes and the crop box (``clipRange``) and ended at the first
opaque surface (``GEOMETRY``, ``techniques.geometry.surface_pass``).

Segments: the ray is cut at every layer's entry and exit (clamped to the interval), the
cuts sorted; each stretch between consecutive cuts is one in which the same layers hold
every point, and it is divided into ``ceil(length / step)`` equal segments, each sampled
at its midpoint: the midpoint rule on pieces where the integrand is smooth, second order
in ``step``. A stretch no layer holds is passed over. Whether a layer holds a stretch is
read from the t-intervals (a stretch lies wholly inside or outside each), never from a
position test that rounding could flip.

At a midpoint each layer that holds it gives its value: a scan the trilinear field (the
texture unit's filter where its weights are float, ``TEXTURE_FILTER_EXACT``, else eight
texel fetches, as the ray caster), classified through its 4096-entry lookup table as the
ray caster classifies; a label volume the sample at the rounded index (halves upward),
classified by its row of the label table. Each gives ``tau_i = -log(1 - alpha_i) / u_i``
(``log1p`` where ``alpha <= 0.5``, the stored transparency above) and its colour ``c_i``.

- ``blend="mix"``: the segment's opacity is ``1 - exp(-len sum tau_i)`` and its colour
  ``sum c_i tau_i / sum tau_i``; an opaque layer there (alpha = 1) makes the segment
  opaque with the mean colour of the opaque layers; composited front to back.
- ``blend="add"``: each layer keeps its own (colour, opacity), composited from its own
  ``1 - exp(-len tau_i)`` (composite), or its own largest, smallest or length-weighted
  mean value classified at the end (mip, minip, average); the pixel is ``C = sum C_i``,
  ``A = 1 - prod (1 - A_i)``.

A surface goes behind the sum (``C + (1 - A) lit``, A = 1).

Options (those of ``raycast.make_plan``)
----------------------------------------
step : default ``raycast.default_step`` of the finest layer (half its smallest spacing).
target, ert_transmittance : as for one volume. Early ray termination ends a mixed ray
    once its transmittance is below the threshold, and stops compositing each added
    layer once its own is (the ray ends when all have): the dropped light is below the
    threshold per layer.
skip_empty : empty-space skipping (composite mode), the image identical with it on and
    off. Each layer is cut into bricks of ``BRICK`` cells, classified once per (volume,
    TF or label table): a scan's brick is empty when its value range (its samples and one
    more each side) has zero opacity (``bricks.brick_occupancy``), a label volume's when
    no label with opacity lies among those samples (``label_occupancy``). A segment that
    composited nothing looks up the brick of every layer holding its midpoint; where each
    is empty (or, added, its layer has ended) every midpoint before the nearest of their
    exits adds exactly nothing (the layers holding a point change only at stretch ends),
    and the ray goes on at the segment before the first midpoint past it. Segments are
    still counted from their stretch's start, so a jump moves no sample. Before the loop
    each ray meets every layer's box around its occupied bricks (grown by a sample); a
    stretch's segments whose midpoint lies before the first entry or after the last exit
    (one more each side, for rounding) are passed over. A layer with fewer than
    ``MIN_EMPTY_BRICKS`` of its bricks empty is treated as full (never looked up, no skip
    where it holds the ray); where every layer is (or off) the shader has none of this.
step_table, gradients : speed choices of the one-volume ray caster that do not change its
    image; accepted and without effect here (a stretch's segments are shorter than the
    step, each its own length, so every segment corrects its own opacity; no lighting).
jitter_seed, preintegrate, refine : not rendered with layers: a named error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np

from ..gl.resources import texture3d
from ..model.layers import MAX_LAYERS
from ..model.scene import Scene
from ..model.transfer import LookupTable
from ..util.cache import IdentityKey, TableCache
from .common import (TARGETS, bind, box_proxy, draw_ray_proxy, camera_uniforms, check_flag, check_scene, check_step, check_target,
                     clip_defines, clip_uniforms, grow_pixels)
from .bricks import brick_occupancy, partition, value_ranges
from .geometry import surface_pass
from .gpu import draw_ray_compute, pixel_stage, tf_texture, volume_texture

BRICK = 8     # brick edge in cells for empty-space skipping (as the one-volume ray caster's)
MIN_EMPTY_BRICKS = 0.2   # the share of empty bricks below which a layer is treated as full


@dataclass
class LayersPlan:
    """What the GL path and the NumPy twin share for a scene with layers."""
    scene: Scene
    step: float
    tables: tuple              # per layer: its LookupTable (scan) or LabelColors (labels)
    target: str = "rgba32f"
    ert_transmittance: float = 0.0
    defines: dict = field(default_factory=dict)
    occupancy: tuple | None = None   # per layer (bz, by, bx) bool, or None when not skipping
    stage: str = "auto"              # where the per-pixel shader runs (gpu.pixel_stage)

    @property
    def layers(self):
        return self.scene.all_layers

    @property
    def max_segments(self):
        """A bound on the segments of one ray: the union box's diagonal over the step, plus
        one per stretch."""
        lo, hi = self.scene.bounds
        diagonal = float(np.linalg.norm(np.asarray(hi) - np.asarray(lo)))
        return int(math.ceil(diagonal / self.step)) + 2 * len(self.layers) + 2


def layer_frames(scene):
    """Per layer, (M, m) float64: the map ``q = M p + m`` from the scene's box-relative
    coordinates (the rays') to the layer's own, relative to its volume's lower corner."""
    lo = np.asarray(scene.volume.bounds[0], np.float64)
    frames = []
    for layer in scene.all_layers:
        rotation_t = layer.rotation.T
        offset = rotation_t @ (lo - layer.translation) - np.asarray(layer.volume.bounds[0], np.float64)
        frames.append((np.array(rotation_t), offset))
    return frames


def layers_default_step(scene):
    """The ray caster's default step (half the smallest spacing) of the finest layer."""
    return min(0.5 * layer.volume.min_spacing for layer in scene.all_layers)


def make_plan(scene, step=None, *, target="rgba32f", jitter_seed=None, ert_transmittance=1e-3,
              skip_empty=True, preintegrate=False, refine=1, gradients="on_the_fly", step_table=True,
              stage="auto", tables=None):
    """Validate the options for a scene with layers (``raycast.make_plan``'s signature,
    which passes them all on)."""
    tables = tables or TableCache()
    check_scene(scene, "raycast")
    if not scene.layers:
        raise ValueError("raycast_layers renders scenes with layers; this scene has none (use raycast)")
    lo, hi = scene.bounds
    box = SimpleNamespace(extent=np.asarray(hi, np.float64) - np.asarray(lo, np.float64))
    step = layers_default_step(scene) if step is None else check_step(step, box)
    check_target(target)
    check_flag("skip_empty", skip_empty)
    check_flag("step_table", step_table)
    if check_flag("preintegrate", preintegrate):
        raise ValueError("preintegrate is not rendered for a scene with layers: segments of several volumes "
                         "are sampled at their midpoints (preintegrate=False)")
    if isinstance(refine, bool) or not isinstance(refine, (int, np.integer)) or refine != 1:
        raise ValueError(f"refine splits pre-integrated segments, which a scene with layers does not use; "
                         f"give refine=1 (got refine={refine!r})")
    if jitter_seed is not None:
        raise ValueError(f"jitter_seed is not rendered for a scene with layers (its stretches start at every "
                         f"layer's entry); give jitter_seed=None (got {jitter_seed!r})")
    if gradients not in ("on_the_fly", "texture"):
        raise ValueError(f"gradients must be one of on_the_fly, texture, got {gradients!r}")
    if isinstance(ert_transmittance, bool) or not isinstance(ert_transmittance, (int, float, np.floating)):
        raise TypeError(f"ert_transmittance must be a number, got {ert_transmittance!r}")
    if not 0 <= ert_transmittance < 1:
        raise ValueError(f"ert_transmittance must be in [0, 1), got {ert_transmittance!r}")
    layers = scene.all_layers
    classes = tuple(layer.tf if layer.is_labels else tables.get("lut", layer.tf, make=LookupTable)
                    for layer in layers)
    composite = scene.mode == "composite"
    defines = {f"MODE_{scene.mode.upper()}": 1, "N_LAYERS": len(layers),
               "BLEND_ADD": int(scene.blend == "add")}
    for i, layer in enumerate(layers):
        if layer.is_labels:
            defines[f"LAYER{i}_LABELS"] = 1
    if scene.camera.is_ortho:
        defines["ORTHO"] = 1
    ert = float(ert_transmittance) if composite else 0.0
    if ert > 0:
        defines["EARLY_RAY_TERMINATION"] = 1
    defines.update(clip_defines(scene))
    if scene.geometry:
        defines["GEOMETRY"] = 1
    for layer in layers:
        if layer.volume.has_nonfinite:
            raise ValueError("a scene with layers takes finite samples in every layer; masked (non-finite) "
                             "samples are rendered for one volume alone")
    occupancy = None
    if skip_empty and composite:
        occupancy = tuple(layer_occupancy(layer, table, tables) for layer, table in zip(layers, classes))
        # a layer with few empty bricks is taken as full: where it holds the ray nothing is
        # skipped, and its bricks are never looked up (on llvmpipe the look-ups of one
        # with 5 % empty cost more than its skips saved)
        full = [occupied.mean() > 1 - MIN_EMPTY_BRICKS for occupied in occupancy]
        if all(full):
            occupancy = None        # nothing worth skipping: the look-ups would only cost
        else:
            defines["SKIP_EMPTY"] = 1
            for i in np.flatnonzero(full):
                defines[f"LAYER{i}_OCCUPIED"] = 1
    return LayersPlan(scene=scene, step=float(step), tables=classes, target=target, ert_transmittance=ert,
                      defines=defines, occupancy=occupancy, stage=stage)


def brick_ranges(values):
    """Per brick of BRICK cells (bz, by, bx): (lo, hi) float64 of the samples its cells
    touch and one more on every side (``bricks.value_ranges``)."""
    bricks = partition(values.shape, BRICK, 0)
    lo, hi = value_ranges(SimpleNamespace(data=values, shape=values.shape), bricks)
    shape = tuple(b + 1 for b in bricks[-1].index)
    return lo.reshape(shape), hi.reshape(shape)


def label_occupancy(volume, colors):
    """Per brick: whether a label with non-zero opacity lies among the samples its cells
    touch or one beyond. A label is read at the rounded index of the sample's float32
    value; both roundings of a value near a half count."""
    v = volume.values(np.float32).astype(np.float64)
    visible = np.append(colors.table[:, 3] > 0, False)       # the last entry: every label beyond the table
    seen = np.zeros(v.shape, np.uint8)
    for shift in (-1e-6, 1e-6):
        index = np.floor(v + 0.5 + shift * (1.0 + np.abs(v)))
        index = np.where((index < 0) | (index >= len(colors.table)), len(colors.table), index).astype(np.int64)
        seen |= visible[index]
    return brick_ranges(seen)[1] > 0


def layer_occupancy(layer, table, tables):
    """Per brick of the layer: whether anything in it can have opacity (a scan:
    ``bricks.brick_occupancy`` of its value range; labels: ``label_occupancy``), made once
    per volume and (volume, TF or label table)."""
    if layer.is_labels:
        return tables.get("layer_label_occupancy", layer.volume, table, make=label_occupancy)
    ranges = tables.get("layer_brick_ranges", layer.volume, make=lambda volume: brick_ranges(volume.values(np.float32)))
    return tables.get("layer_occupancy", layer.volume, layer.tf,
                      make=lambda volume, tf: brick_occupancy(ranges, table))


def occupancy_texture(renderer, layer, table, occupied):
    """A layer's brick occupancy as a nearest-filtered 3-D texture, 255 where occupied."""
    store = renderer.resources

    def make():
        mask = occupied.astype(np.uint8) * 255
        return store.made("layer_occupancy", mask.shape, texture3d(renderer.ctx, mask, 1, "f1", linear=False))
    return store.get("layer_occupancy", IdentityKey(layer.volume, table), make, capacity=MAX_LAYERS)


def label_rows(colors):
    """(2, n, 4) float32 rows of a LabelColors table, as ``LookupTable.texture_rows``: row 0
    colour and opacity per label, row 1 the transparency ``1 - alpha`` (from float64)."""
    rows = np.zeros((2, len(colors.table), 4), np.float32)
    rows[0] = colors.table
    rows[1, :, 0] = 1.0 - colors.table[:, 3]
    return rows


def _layer_textures(renderer, plan):
    """(volume texture, class table texture) per layer."""
    ctx, store = renderer.ctx, renderer.resources
    out = []
    for i, (layer, table) in enumerate(zip(plan.layers, plan.tables)):
        volume = layer.volume
        if i == 0:
            vol_tex = volume_texture(renderer, volume)
        else:
            kind = "layer_labels" if layer.is_labels else "layer_volume"

            def make(volume=volume, linear=not layer.is_labels, kind=kind):
                values = volume.values(np.float32)
                return store.made(kind, values.shape, texture3d(ctx, values, 1, "f4", linear=linear))
            vol_tex = store.get(kind, IdentityKey(volume), make, capacity=MAX_LAYERS)
        if layer.is_labels:
            def make_rows(colors=table):
                rows = label_rows(colors)
                tex = ctx.texture((rows.shape[1], 2), 4, rows.tobytes(), dtype="f4")
                tex.filter = (ctx.NEAREST, ctx.NEAREST)
                return tex
            class_tex = store.for_objects("label_table", table, make=make_rows, capacity=MAX_LAYERS)
        else:
            class_tex = tf_texture(renderer, table)
        out.append((vol_tex, class_tex))
    return out


def layer_uniforms(plan):
    """The per-layer uniform arrays of ``shaders/raycast/layers.frag`` (float32 bytes)."""
    frames = layer_frames(plan.scene)
    to_layer = np.array([m.T.reshape(-1) for m, _ in frames], np.float32)     # column-major mat3
    offset, extent, dims, spacing, cls, inv_unit = [], [], [], [], [], []
    for (_, m), layer, table in zip(frames, plan.layers, plan.tables):
        volume = layer.volume
        offset.append(m)
        extent.append(volume.extent)
        dims.append([float(n) for n in volume.dims])
        spacing.append(volume.spacing)
        if layer.is_labels:
            cls.append((0.0, 1.0, float(len(table.table))))
        else:
            cls.append((table.lo, table.scale, float(table.size)))
        inv_unit.append(1.0 / layer.tf.unit_distance)

    def f32(rows):
        return np.ascontiguousarray(np.array(rows, np.float64).astype(np.float32)).tobytes()
    return {"u_to_layer": to_layer.tobytes(), "u_layer_offset": f32(offset), "u_layer_extent": f32(extent),
            "u_layer_dims": f32(dims), "u_layer_spacing": f32(spacing), "u_layer_class": f32(cls),
            "u_layer_inv_unit": f32(inv_unit)}


def occupied_boxes(plan, brick):
    """``u_occupied_lo``, ``u_occupied_hi``: per layer the box around its occupied bricks
    in its own frame, grown by one sample spacing (so that rounding of a sample's position
    cannot leave it); a point box far behind every ray where the layer has none."""
    lo, hi = [], []
    for layer, occupied in zip(plan.layers, plan.occupancy):
        spacing = np.asarray(layer.volume.spacing, np.float64)
        index = np.argwhere(occupied)[:, ::-1]          # brick x, y, z
        if len(index) == 0:
            lo.append((-1e30,) * 3)
            hi.append((-1e30,) * 3)
            continue
        lo.append(index.min(axis=0) * brick * spacing - spacing)
        hi.append((index.max(axis=0) + 1) * brick * spacing + spacing)
    return {"u_occupied_lo": np.array(lo, np.float32).tobytes(), "u_occupied_hi": np.array(hi, np.float32).tobytes()}


def union_proxy(scene, grow):
    """``box_proxy`` for the box around every layer (its corners relative to that box's
    own lower corner; the fragment shader rebuilds its ray, so only coverage matters)."""
    lo, hi = (np.asarray(b, np.float64) for b in scene.bounds)
    box = SimpleNamespace(camera=scene.camera, width=scene.width, height=scene.height, tile=scene.tile,
                          volume=SimpleNamespace(bounds=(lo, hi), extent=hi - lo))
    return box_proxy(box, grow_pixels=grow)


def draw(renderer, plan):
    """Render the plan into the renderer's target; returns that framebuffer."""
    ctx = renderer.ctx
    scene = plan.scene
    surfaces = surface_pass(renderer, scene) if scene.geometry else None
    compute = pixel_stage(renderer, plan.stage) == "compute"
    prog = (renderer.programs.compute("raycast/layers.frag", dict(plan.defines, IMAGE_FORMAT=plan.target))
            if compute else renderer.programs.get("raycast/raycast.vert", "raycast/layers.frag", plan.defines))
    textures = {}
    for i, (vol_tex, class_tex) in enumerate(_layer_textures(renderer, plan)):
        textures[f"t_layer{i}"] = vol_tex
        textures[f"t_class{i}"] = class_tex
    if plan.occupancy is not None:
        for i, (layer, table, occupied) in enumerate(zip(plan.layers, plan.tables, plan.occupancy)):
            textures[f"t_occupancy{i}"] = occupancy_texture(renderer, layer, table, occupied)
    if surfaces is not None:
        textures["t_surface"] = surfaces
    uniforms = {**camera_uniforms(scene), **clip_uniforms(scene), **layer_uniforms(plan),
                "u_step": plan.step, "u_max_segments": plan.max_segments}
    if plan.ert_transmittance > 0:
        uniforms["u_ert_transmittance"] = plan.ert_transmittance
    if plan.occupancy is not None:
        uniforms["u_brick"] = float(BRICK)
        uniforms.update(occupied_boxes(plan, BRICK))
    bind(prog, textures, uniforms)
    if compute:
        return draw_ray_compute(renderer, prog, scene, TARGETS[plan.target])
    kind, view_proj = union_proxy(scene, grow_pixels(ctx))
    return draw_ray_proxy(renderer, prog, scene, plan.target, kind, view_proj, surfaces)
