"""2D texture slicing: axis-aligned stacks.

About this technique
--------------------
The volume is kept as up to three stacks of 2-D slices, one per axis (a float32 texture
array each, one layer per sample plane). A view uses the stack whose axis is closest to
its direction (the largest component of the camera's forward vector; ties go to the
lower axis), built the first time a view needs it and kept. Its slices are drawn far to
near with the over operator (``ONE, ONE_MINUS_SRC_ALPHA`` on associated colour), each
sampled bilinearly in its layer. Under perspective "far" means far from the eye along the
stack axis, so with the eye between slices each ray still meets its slices far to near.

The sample distance is fixed by the data: the spacing along the stack axis divided by
``interpolate + 1``. Option ``interpolate=k`` adds k slices between each pair of sample
planes, each blended from its two neighbouring layers in the fragment shader (bilinear in
the layer, then linear across: trilinear sampling, as Rezk-Salama et al. 2000).

Per-fragment opacity correction. The slices are where the samples are, so each fragment
stands for the slab halfway to its neighbouring slices *along its own ray*: a length of
``spacing / |cos theta|`` with theta the angle between that ray and the stack axis,
different per pixel under perspective. Where a neighbour's point lies outside the box
(the ray enters or leaves through a side face, or the slice is the stack's first or last)
the slab runs to the box entry or exit instead, so no partial segment is lost or counted
twice: there is no systematic transparency bias. Such a partial slab is sampled at its
midpoint, from the two layers around that point (as for an intermediate slice). Along the
stack axis the samples on the slices with half slabs at both ends make the trapezoidal
rule, whose error constant is twice the midpoint rule's. Coverage is decided per fragment (the slice quads are
drawn slightly enlarged and the shader discards what lies outside the slice's rectangle).

Rays that meet no slice inside the box (a chord between two sample planes, at the
silhouette, or a ray parallel to the slices) are found by a second pass over the box's
back faces, with the slice fragments' own test, and their whole chord is integrated there
in pieces of at most one slice distance (``shaders/common/slice_gap.glsl``).

Clip planes and a crop box (``Scene(clip_planes=..., crop_box=...)``): each fragment's
slab is cut to its ray's kept interval (``clipRange`` of the box range), and a slice whose
point the clip cuts away is no slice for that ray, so its neighbours' slabs (and the gap
pass, for a kept part that holds no slice) run to the kept interval's ends. Along the stack
axis the cut is decided once per slice, in the plan (``kept_slice_range``: the crop box's
faces across the axis and the planes parallel to the slices): a face on a slice plane then
keeps that slice for every pixel, as the box's own faces do, and only the slices it keeps
are drawn.

Opaque geometry (``Scene.geometry``): a pass before the slices finds each pixel's first
surface and its lit colour (``techniques.geometry.surface_pass``); its colour is written
into the target first, with opacity 1 (``geometry.draw_surface_behind``: the backmost
layer under back-to-front blending), and each ray ends at its surface (``GEOMETRY``): a
slice point behind it is no slice for that ray, the slab that straddles it runs to it
(``range.y = min(range.y, t_hit)``), and the gap pass integrates a shortened chord that
holds no slice, as for a clip.

The stack switch: at 45 degrees two stacks are equally close and the image jumps between
them; ``bench`` and the tests measure the jump (docs/notes/slicing.md has the numbers).

Options (same names in ``dvr_gl.reference.render``)
---------------------------------------------------
interpolate : int >= 0 (default 0)
    intermediate slices per cell.
target : "rgba32f" (default) | "rgba16f" | "rgba8"
    blending rounds in the target.
preintegrate : classify the segment between consecutive slices with the pre-integrated
    table; the partial segments at the box entry and exit take the field at the entry or
    exit point from the two layers around it.
gradients : "on_the_fly" (default) | "texture": with ``Scene(shading=True)`` each slab is lit
    with the gradient where its sample was taken (the slice point, or the midpoint of a
    partial slab or pre-integrated segment), computed from the stack's two layers around
    each point (the trilinear field itself) or read from a gradient texture.

``step`` is not an option: passing it is an error, since the data fixes the distance.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..util.cache import IdentityKey, TableCache
from ..model.scene import Scene
from ..model.transfer import LookupTable
from .common import (cleared_target, add_optional_inputs, shading_defines, bind, box_depth_range, camera_uniforms, near_plane, check_flag,
                     draw_box_instances,
                     check_scene, check_target, clip_defines, clip_uniforms, eye_view_projection,
                     preintegration_table, tf_uniforms,
                     volume_uniforms)
from .geometry import draw_surface_behind, surface_pass
from .gpu import stream_vao, tf_texture

INFLATE = 1e-3  # slice quads are grown by this fraction of the box diagonal

MODES = ("composite",)
DATA = "volume"
TAKES_STEP = False

@dataclass
class Slice2DPlan:
    scene: Scene
    lut: LookupTable
    axis: int                      # 0, 1, 2: the stack's axis (x, y, z)
    interpolate: int
    slice_distance: float          # distance between slices along the axis
    count: int                     # slices in the stack (with the intermediate ones)
    order: np.ndarray              # slice indices in drawing order, far to near
    min_depth: float               # slice points nearer the eye than this are not drawn
    target: str = "rgba32f"
    kept_slices: tuple = None      # (first, last) slice the clip keeps along the axis; None: unclipped
    preint: object = None
    defines: dict = field(default_factory=dict)

    @property
    def other_axes(self):
        return [a for a in range(3) if a != self.axis]


def stack_axis(forward):
    """The axis closest to the view direction (ties go to the lower axis)."""
    return int(np.argmax(np.abs(np.asarray(forward, np.float64))))


def make_plan(scene, step=None, *, target="rgba32f", interpolate=0, preintegrate=False, gradients="on_the_fly",
              tables=None):
    tables = tables or TableCache()
    check_scene(scene, "slice2d", modes=MODES)
    if step is not None:
        raise ValueError(f"slice2d takes no step (got step={step!r}): its sample distance is the "
                         f"spacing along the stack axis / (interpolate + 1); pass interpolate=k instead")
    if isinstance(interpolate, bool) or not isinstance(interpolate, (int, np.integer)) or interpolate < 0:
        raise ValueError(f"interpolate must be an integer >= 0, got {interpolate!r}")
    if interpolate > 64:
        raise ValueError(f"interpolate must be at most 64 (slices per cell), got {interpolate!r}")
    check_target(target)
    preintegrate = check_flag("preintegrate", preintegrate)
    volume, cam = scene.volume, scene.camera
    axis = stack_axis(cam.forward)
    per_cell = int(interpolate) + 1
    slice_distance = float(volume.spacing[axis]) / per_cell
    count = (int(volume.dims[axis]) - 1) * per_cell + 1
    lut = tables.get("lut", scene.tf, make=LookupTable)
    preint = preintegration_table(scene, slice_distance, tables) if preintegrate else None

    lo, _ = volume.bounds
    eye_w = float(cam.eye[axis] - lo[axis])
    z = np.arange(count) * slice_distance
    if cam.is_ortho:
        order = np.arange(count)[::-1] if cam.forward[axis] > 0 else np.arange(count)
        min_depth = 0.0
    else:
        order = np.argsort(-np.abs(z - eye_w), kind="stable")
        # twice the GL near plane: fragments between the two are discarded by the shader's
        # own test, so clipping never removes one that the neighbouring slices count on
        min_depth = 2 * _near_plane(scene)
    defines = {"ORTHO": 1} if cam.is_ortho else {}
    if preint is not None:
        defines["PREINTEGRATE"] = 1
    if volume.has_nonfinite:
        defines["MASK_NONFINITE"] = 1
    defines.update(shading_defines(scene, gradients))
    defines.update(clip_defines(scene))
    if scene.geometry:
        defines["GEOMETRY"] = 1
    kept_slices = None
    if scene.clips:
        kept_slices = kept_slice_range(scene, axis, z)
        order = order[(order >= kept_slices[0]) & (order <= kept_slices[1])]
    return Slice2DPlan(scene=scene, lut=lut, axis=axis, interpolate=int(interpolate),
                       slice_distance=slice_distance, count=count, order=order, min_depth=min_depth,
                       target=target, preint=preint, defines=defines, kept_slices=kept_slices)


def across_stack(normal, axis):
    """Whether a clip plane's unit ``normal`` is perpendicular to the slices of the stack
    along ``axis``, as the shader sees it (its other two components 0 in float32): such a
    plane keeps or cuts whole slices, decided in the plan (``kept_slice_range``)."""
    u, v = [a for a in range(3) if a != axis]
    return np.float32(normal[u]) == 0 and np.float32(normal[v]) == 0


def kept_slice_range(scene, axis, w):
    """(first, last) index of the slices at box coordinates ``w`` along ``axis`` that the
    crop box's faces across the axis and the clip planes parallel to the slices keep
    (first > last: none). Decided once, in float64, for the GL path and the twin alike: a
    face on a slice plane keeps that slice for every pixel (the shader tests each
    fragment against the other clips only)."""
    planes, crop = scene.clip_in_box()
    kept = np.ones(len(w), bool)
    if crop is not None:
        kept &= (w >= crop[0][axis]) & (w <= crop[1][axis])
    for normal, offset in planes:
        if across_stack(normal, axis):
            kept &= normal[axis] * w - offset >= 0
    index = np.flatnonzero(kept)
    return (int(index[0]), int(index[-1])) if index.size else (0, -1)


def _far_plane(scene):
    _, dmax = box_depth_range(scene)
    return max(dmax, 0.0) * 1.01 + 1e-3 * float(np.linalg.norm(scene.volume.extent))


def _near_plane(scene):
    return near_plane(scene, _far_plane(scene))


# ---------------------------------------------------------------------------------------
# GL path

def slice_quads(plan):
    """Two triangles per slice, in drawing order: positions (6 * count, 3) float32 and
    each vertex's slice index."""
    extent = plan.scene.volume.extent
    margin = INFLATE * float(np.linalg.norm(extent))
    u, v = plan.other_axes
    corners = np.array([(0, 0), (1, 0), (1, 1), (0, 0), (1, 1), (0, 1)], np.float64)
    quad = np.zeros((6, 3))
    quad[:, u] = -margin + corners[:, 0] * (extent[u] + 2 * margin)
    quad[:, v] = -margin + corners[:, 1] * (extent[v] + 2 * margin)
    positions = np.repeat(quad[None], len(plan.order), axis=0)
    positions[:, :, plan.axis] = (plan.order * plan.slice_distance)[:, None]
    indices = np.repeat(plan.order, 6).astype(np.int32)
    return positions.reshape(-1, 3).astype(np.float32), indices


def draw(renderer, plan):
    """Render the plan into the renderer's target; returns that framebuffer."""
    ctx = renderer.ctx
    scene = plan.scene
    volume = scene.volume
    surfaces = surface_pass(renderer, scene) if scene.geometry else None   # each pixel's first surface
    prog = renderer.programs.get("common/slice_polygons.vert", "slice2d/slice2d.frag", plan.defines)
    u, v = plan.other_axes
    textures = {"t_stack": stack_texture(renderer, volume, plan.axis), "t_tf": tf_texture(renderer, plan.lut)}
    uniforms = {**camera_uniforms(scene), **volume_uniforms(volume), **tf_uniforms(plan.lut, scene.tf),
                **clip_uniforms(scene), "u_axes": (plan.axis, u, v), "u_slice_distance": plan.slice_distance,
                "u_slice_count": plan.count, "u_per_cell": plan.interpolate + 1,
                "u_min_depth": plan.min_depth}
    if plan.kept_slices is not None:
        uniforms["u_kept_slices"] = plan.kept_slices
    add_optional_inputs(renderer, plan, textures, uniforms)
    if surfaces is not None:
        textures["t_surface"] = surfaces

    dmin, dmax = box_depth_range(scene)
    margin = 1e-3 * float(np.linalg.norm(volume.extent))
    if scene.camera.is_ortho:
        view_proj = eye_view_projection(scene, -margin, dmax + margin)
    else:
        view_proj = eye_view_projection(scene, _near_plane(scene), _far_plane(scene))
    prog["u_view_proj"].write(view_proj.astype("f4").tobytes())

    fbo = cleared_target(renderer, scene, plan.target)
    if surfaces is not None:
        draw_surface_behind(renderer, surfaces)
    bind(prog, textures, uniforms)
    positions, indices = slice_quads(plan)
    ctx.disable(ctx.DEPTH_TEST | ctx.CULL_FACE)
    ctx.enable(ctx.BLEND)
    ctx.blend_func = ctx.ONE, ctx.ONE_MINUS_SRC_ALPHA
    ctx.blend_equation = ctx.FUNC_ADD
    try:
        stream_vao(renderer, prog, "slice2d", positions, indices).render(ctx.TRIANGLES)
        gap = renderer.programs.get("common/box_instances.vert", "slice2d/slice2d.frag", {**plan.defines, "GAP": 1})
        bind(gap, textures, uniforms)
        draw_box_instances(renderer, gap, scene, 1)
    finally:
        ctx.disable(ctx.BLEND)
    return fbo


def stack_texture(renderer, volume, axis):
    """The stack along ``axis`` (0 = x, 1 = y, 2 = z): a texture array with one float32
    layer per sample plane, each layer the plane's samples with the lower of the other
    two axes varying fastest. Made when a view first needs it; the 3 most recent kept."""
    store = renderer.resources

    def make():
        values = volume.values(np.float32)  # (z, y, x)
        layers = {0: values.transpose(2, 0, 1), 1: values.transpose(1, 0, 2), 2: values}[axis]
        layers = np.ascontiguousarray(layers)  # (layer, v, u)
        n, h, w = layers.shape
        tex = renderer.ctx.texture_array((w, h, n), 1, layers.tobytes(), dtype="f4")
        tex.filter = (renderer.ctx.LINEAR, renderer.ctx.LINEAR)
        tex.repeat_x = tex.repeat_y = False
        return store.made("stack", (axis, n, h, w), tex)
    return store.get("stack", IdentityKey(volume, axis), make, capacity=3)
