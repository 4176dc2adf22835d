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
skip_empty, step_table, gradients : speed choices of the one-volume ray caster that do not
    change its image; accepted and without effect here (no brick skipping, every segment
    corrects its own opacity, no lighting).
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
from .common import (bind, box_proxy, draw_ray_proxy, camera_uniforms, check_flag, check_scene, check_step, check_target,
                     clip_defines, clip_uniforms, grow_pixels)
from .geometry import surface_pass
from .gpu import tf_texture, volume_texture


@dataclass
class LayersPlan:
    """What the GL path and the NumPy twin share for a scene with layers."""
    scene: Scene
    step: float
    tables: tuple              # per layer: its LookupTable (scan) or LabelColors (labels)
    target: str = "rgba32f"
    ert_transmittance: float = 0.0
    defines: dict = field(default_factory=dict)

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
              tables=None):
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
    return LayersPlan(scene=scene, step=float(step), tables=classes, target=target, ert_transmittance=ert,
                      defines=defines)


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
    prog = renderer.programs.get("raycast/raycast.vert", "raycast/layers.frag", plan.defines)
    textures = {}
    for i, (vol_tex, class_tex) in enumerate(_layer_textures(renderer, plan)):
        textures[f"t_layer{i}"] = vol_tex
        textures[f"t_class{i}"] = class_tex
    if surfaces is not None:
        textures["t_surface"] = surfaces
    uniforms = {**camera_uniforms(scene), **clip_uniforms(scene), **layer_uniforms(plan),
                "u_step": plan.step, "u_max_segments": plan.max_segments}
    if plan.ert_transmittance > 0:
        uniforms["u_ert_transmittance"] = plan.ert_transmittance
    bind(prog, textures, uniforms)
    kind, view_proj = union_proxy(scene, grow_pixels(ctx))
    return draw_ray_proxy(renderer, prog, scene, plan.target, kind, view_proj, surfaces)
