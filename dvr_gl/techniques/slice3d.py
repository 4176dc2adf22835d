"""3D texture slicing with view-aligned proxy planes.

About this technique
--------------------
Planes perpendicular to the view direction, ``step`` apart, are cut against the volume
box into convex polygons (3 to 6 vertices) and drawn far to near; each fragment samples
the 3-D texture and is blended with the over operator (``ONE, ONE_MINUS_SRC_ALPHA`` on
associated colour). The planes sit at depths ``(j + 0.5) * step`` from the eye (depth =
distance along the view direction; for orthographic cameras from the plane through the
eye), so they are the midplanes of slabs ``[j * step, (j + 1) * step]``. Nothing behind
the eye is drawn: with the eye inside the box the slices start where the rays do.

Per-fragment opacity correction. A pixel's ray meets plane k at ``t_k = depth_k / cos``
(``cos`` = its direction's component along the view direction), so under perspective the
distance between planes differs per pixel. Each fragment rebuilds its ray from
``gl_FragCoord`` and takes the segment halfway to the neighbouring planes' points on the
same ray; where a neighbour's point lies outside the box the segment runs to the ray's
entry or exit instead, so the partial slabs at both ends are accounted for. The segment
is sampled at its midpoint and its opacity corrected for its true length: the midpoint
rule, as in ray casting, with plane-defined segment ends. A pixel whose ray crosses the
box between two planes without meeting one inside it (a chord shorter than one step, at
the silhouette, through edges and corners) is found by a second pass over the box's back
faces, with the slice fragments' own test, and its whole chord is integrated there
(``shaders/common/slice_gap.glsl``).

Clip planes and a crop box (``Scene(clip_planes=..., crop_box=...)``) cut each ray's box
range to its kept interval (``clipRange``) before anything else: the planes are tested
against that interval, the partial slabs run to its ends, and a ray whose kept part holds
no plane goes through the gap pass.

Opaque geometry (``Scene.geometry``): a pass before the slices finds each pixel's first
surface and its lit colour (``techniques.geometry.surface_pass``); the surface colour is
written into the target first, with opacity 1 (``geometry.draw_surface_behind``: under back-to-
front blending it is the backmost layer), and every ray's kept interval ends at its
surface (``GEOMETRY``: ``range.y = min(range.y, t_hit)``), exactly as a clip cuts it: the
planes behind the surface are no planes for that ray, the slab that straddles it runs to
it, and a ray whose shortened interval holds no plane goes through the gap pass.

Coverage is decided by that per-fragment test, never by rasterisation: the polygons are
cut from a box inflated by a small margin and fragments outside the true box are
discarded. So the CPU and vertex-shader proxies, whose vertices round differently,
produce the same image bit for bit.

Options (same names in ``dvr_gl.reference.render``)
---------------------------------------------------
target : "rgba32f" (default) | "rgba16f" | "rgba8": blending happens in the target, so a
    low-precision target rounds once per slice (the banding error; see docs/notes/slicing.md).
proxy : "cpu" (default): polygons computed on the CPU for all slices at once
    (``techniques.proxy``) and drawn in one call. "vertex": each slice is 12 vertices
    (four fan triangles over six polygon slots) placed by the vertex shader, one
    instanced draw (Rezk-Salama and Kolb 2005).
shells : slice along spherical shells around the eye (radii ``(j + 0.5) * step``) instead
    of planes; every ray then meets the shells ``step`` apart. Drawn as instances of the
    box's back faces (or a full-screen triangle with the eye inside).
preintegrate : classify whole segments between consecutive slices with the pre-integrated
    table (``dvr_gl.model.preintegration``) instead of midpoint samples.
gradients : "on_the_fly" (default) | "texture": as for ray casting; with
    ``Scene(shading=True)`` every segment is lit with the gradient at its midpoint, the
    gap pass's pieces too.
brick_size : None (default) or a whole number N: slice the volume in bricks of N cells a
    side, each its own texture (``techniques.slice3d_bricks``); with None, bricks only
    where a side exceeds GL_MAX_3D_TEXTURE_SIZE. The planes, samples and blending order
    are the single texture's, so the image is too, up to the texture coordinate's
    rounding. Not with preintegrate=True, gradients="texture" or non-finite samples (a
    ValueError names it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..util.cache import TableCache
from ..model.scene import Scene
from ..model.transfer import LookupTable
from . import proxy as proxy_geometry
from . import slice3d_bricks
from .bricks import bricked_defines
from .common import (cleared_target, add_optional_inputs, shading_defines, bind, camera_uniforms, draw_box_instances, check_flag, check_scene,
                     clip_defines, clip_uniforms,
                     check_step, check_target, inflated_corners, plane_projection, plane_triangles, preintegration_table,
                     tf_uniforms, volume_uniforms)
from .geometry import draw_surface_behind, surface_pass
from .gpu import empty_vao, stream_vao, tf_texture, volume_texture as single_texture

PROXIES = ("cpu", "vertex")

MODES = ("composite",)
DATA = "volume"
TAKES_STEP = True

@dataclass
class Slice3DPlan:
    scene: Scene
    step: float
    lut: LookupTable
    target: str = "rgba32f"
    proxy: str = "cpu"
    shells: bool = False
    preint: object = None          # a preintegration.PreintegrationTable, or None
    far_depth: float = 0.0         # depth (or radius) of slice 0; slice k is far_depth - k * step
    count: int = 0                 # number of slices
    defines: dict = field(default_factory=dict)
    brick_size: int | None = None  # cells per brick side (slice3d_bricks), None: as the volume needs

    def depths(self):
        return self.far_depth - np.arange(self.count) * self.step


def default_step(volume):
    """Half the smallest spacing, as for ray casting."""
    return 0.5 * volume.min_spacing


def make_plan(scene, step=None, *, target="rgba32f", proxy="cpu", shells=False, preintegrate=False,
              gradients="on_the_fly", brick_size=None, tables=None):
    tables = tables or TableCache()
    check_scene(scene, "slice3d", modes=MODES)
    volume = scene.volume
    step = default_step(volume) if step is None else check_step(step, volume)
    check_target(target)
    if proxy not in PROXIES:
        raise ValueError(f"proxy must be one of {', '.join(PROXIES)}, got {proxy!r}")
    shells = check_flag("shells", shells)
    preintegrate = check_flag("preintegrate", preintegrate)
    if shells and proxy != "cpu":
        raise ValueError(f"shells=True draws instanced box faces; proxy must be left as 'cpu', got {proxy!r}")
    brick_size = slice3d_bricks.check_bricking(scene, brick_size, preintegrate, gradients)
    lut = tables.get("lut", scene.tf, make=LookupTable)
    preint = preintegration_table(scene, step, tables) if preintegrate else None

    cam = scene.camera
    lo, _ = volume.bounds
    eye = cam.eye - lo
    if shells:
        far_depth, count = shell_radii(volume.extent, eye, step)
    else:
        corners = proxy_geometry.box_corners(np.zeros(3), volume.extent)
        far_depth, count = proxy_geometry.slice_depths(corners, cam.forward, eye, step)
    defines = {}
    if cam.is_ortho:
        defines["ORTHO"] = 1
    if shells:
        defines["SHELLS"] = 1
    if preint is not None:
        defines["PREINTEGRATE"] = 1
    if volume.has_nonfinite:
        defines["MASK_NONFINITE"] = 1
    defines.update(shading_defines(scene, gradients))
    defines.update(clip_defines(scene))
    if scene.geometry:
        defines["GEOMETRY"] = 1
    return Slice3DPlan(scene=scene, step=step, lut=lut, target=target, proxy=proxy, shells=shells,
                       preint=preint, far_depth=float(far_depth), count=int(count), defines=defines,
                       brick_size=brick_size)


def shell_radii(extent, eye, step):
    """Radii ``(j + 0.5) * step`` of the shells that can meet the box [0, extent] as seen
    from ``eye``: (largest radius, count), far to near."""
    extent = np.asarray(extent, np.float64)
    gap = np.maximum(np.maximum(-eye, eye - extent), 0.0)
    r_min = float(np.linalg.norm(gap))
    corners = proxy_geometry.box_corners(np.zeros(3), extent)
    r_max = float(np.linalg.norm(corners - eye, axis=1).max())
    j_lo = max(0, math.floor(r_min / step - 0.5))
    j_hi = math.ceil(r_max / step - 0.5)
    return (j_hi + 0.5) * step, j_hi - j_lo + 1


# ---------------------------------------------------------------------------------------
# GL path

def draw(renderer, plan):
    """Render the plan into the renderer's target; returns that framebuffer."""
    ctx = renderer.ctx
    scene = plan.scene
    volume = scene.volume
    cam = scene.camera
    if plan.shells:
        vertex_shader = "common/box_instances.vert"
    elif plan.proxy == "vertex":
        vertex_shader = "slice3d/proxy_vertex.vert"
    else:
        vertex_shader = "common/slice_polygons.vert"
    brick_size = slice3d_bricks.brick_size_for(renderer, plan)     # None: the volume in one texture
    defines = dict(plan.defines, **bricked_defines(renderer, volume)) if brick_size else plan.defines
    prog = renderer.programs.get(vertex_shader, "slice3d/slice3d.frag", defines)

    surfaces = surface_pass(renderer, scene) if scene.geometry else None   # each pixel's first surface
    textures, uniforms = slice_inputs(renderer, plan, volume_texture=not brick_size)
    if surfaces is not None:
        textures["t_surface"] = surfaces
    bind(prog, textures, uniforms)

    fbo = cleared_target(renderer, scene, plan.target)
    if surfaces is not None:
        draw_surface_behind(renderer, surfaces)
        bind(prog, textures, uniforms)
    ctx.disable(ctx.DEPTH_TEST | ctx.CULL_FACE)
    ctx.enable(ctx.BLEND)
    ctx.blend_func = ctx.ONE, ctx.ONE_MINUS_SRC_ALPHA
    ctx.blend_equation = ctx.FUNC_ADD
    try:
        if brick_size:
            gap = renderer.programs.get("common/box_instances.vert", "slice3d/slice3d.frag", {**defines, "GAP": 1})
            slice3d_bricks.draw(renderer, plan, prog, gap, textures, uniforms, brick_size)
            return fbo
        # with no plane inside the box (a box thinner along the view than a step), every
        # ray is the gap pass's
        if plan.count == 0:
            pass
        elif plan.shells:
            draw_box_instances(renderer, prog, scene, plan.count)
        elif plan.proxy == "vertex":
            corners = inflated_corners(volume)
            tables = proxy_geometry.vertex_path_tables(cam.forward)
            bind(prog, {}, {"u_corners": [tuple(c) for c in corners], "u_normal": tuple(cam.forward),
                            **tables})
            prog["u_view_proj"].write(plane_projection(plan).astype("f4").tobytes())
            empty_vao(renderer, prog).render(ctx.TRIANGLES, vertices=12, instances=plan.count)
        else:
            positions, slices, _ = plane_triangles(scene, plan.far_depth, plan.step, plan.count)
            prog["u_view_proj"].write(plane_projection(plan).astype("f4").tobytes())
            stream_vao(renderer, prog, "slice3d_cpu", positions, slices).render(ctx.TRIANGLES)
        draw_gap(renderer, plan, (textures, uniforms))
    finally:
        ctx.disable(ctx.BLEND | ctx.CULL_FACE)
    return fbo


def slice_inputs(renderer, plan, volume_texture=True):
    """The slicing pass's textures and uniforms (splat's gap pass binds them too); without
    the volume's texture for bricks, which bind their own."""
    scene = plan.scene
    volume = scene.volume
    textures = {"t_volume": single_texture(renderer, volume)} if volume_texture else {}
    textures["t_tf"] = tf_texture(renderer, plan.lut)
    uniforms = {**camera_uniforms(scene), **volume_uniforms(volume), **tf_uniforms(plan.lut, scene.tf),
                **clip_uniforms(scene), "u_far_depth": plan.far_depth, "u_step": plan.step, "u_slice_count": plan.count}
    add_optional_inputs(renderer, plan, textures, uniforms)
    return textures, uniforms


def draw_gap(renderer, plan, inputs=None):
    """The gap pass into the bound target, blending over it: every ray that meets no
    plane inside the box gets its whole chord (``shaders/common/slice_gap.glsl``). Sheet-
    buffer splatting, whose sheets are these planes, draws it too."""
    textures, uniforms = inputs or slice_inputs(renderer, plan)
    gap = renderer.programs.get("common/box_instances.vert", "slice3d/slice3d.frag", {**plan.defines, "GAP": 1})
    bind(gap, textures, uniforms)
    draw_box_instances(renderer, gap, plan.scene, 1)
