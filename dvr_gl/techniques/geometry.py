"""Opaque geometry (``Scene.geometry``) for the techniques that draw it: a pass before
the volume that finds, per pixel, the first surface its ray meets.

The surfaces' triangles are drawn with a depth test (the nearest fragment wins) into an
RGBA32F target with a depth attachment, the size of the image's target (a tile's, with
tiles): each fragment writes its surface's lit colour (two-sided Blinn-Phong with the
face's flat normal, the scene's ``phong`` and lights, ``shaders/geometry/surface.frag``)
and its ray parameter t, the distance along the pixel-centre ray the ray caster builds
(``common/camera_ray.glsl``) to the fragment's interpolated position. Pixels no surface
covers keep t = ``NO_SURFACE``. The ray caster reads the texture per pixel, ends its
ray at t and composites the colour behind (``RAYCAST`` switch ``GEOMETRY``).

Rasterisation decides coverage at pixel centres, as the NumPy twin's ray-triangle test
(``reference.exact_geometry``) does; the two differ only for a pixel centre within the
rasteriser's vertex snapping (half a subpixel, 2^-9 of a pixel on llvmpipe) of a
triangle's edge, where a neighbouring face (or, on a silhouette, nothing) may take the
pixel instead. Positions are relative to the volume box's lower corner, as the ray
caster's (float64 on the CPU, then float32).
"""

from __future__ import annotations

import numpy as np

from .common import NEAR_FRACTION, bind, camera_uniforms, eye_view_projection, light_uniforms
from .gpu import proxy_vao

NO_SURFACE = 3e38     # t where a pixel's ray meets no surface


def surface_vertices(scene):
    """(3 m, 9) float32 rows of every face of every surface: corner (relative to the
    volume box's lower corner), the face's unit normal, the surface's colour."""
    lo = scene.volume.bounds[0]
    rows = []
    for surface in scene.geometry:
        corners = surface.triangles() - lo                                   # (m, 3, 3)
        normals = np.repeat(surface.normals()[:, None, :], 3, axis=1)
        colors = np.broadcast_to(surface.color, corners.shape)
        rows.append(np.concatenate([corners, normals, colors], axis=2).reshape(-1, 9))
    return np.concatenate(rows).astype(np.float32)


def surface_projection(scene, positions):
    """The view-projection of box-relative ``positions`` (the surfaces' corners) whose
    near and far planes keep every one of them in front of the eye: near at half the
    nearest depth where all lie in front (perspective), else ``NEAR_FRACTION`` of the far
    plane; orthographic near at the rays' start plane (depth 0)."""
    cam = scene.camera
    depth = (positions.astype(np.float64) - (cam.eye - scene.volume.bounds[0])) @ cam.forward
    span = float(depth.max() - min(depth.min(), 0.0)) or 1.0
    far = max(float(depth.max()), 0.0) * 1.01 + 1e-3 * span
    if cam.is_ortho:
        near = 0.0
    elif depth.min() > 0:
        near = 0.5 * float(depth.min())
    else:
        near = NEAR_FRACTION * far
    return eye_view_projection(scene, near, far)


def surface_light_uniforms(scene):
    """Uniforms of ``phongTerms`` (shaders/common/shading.glsl) for surfaces: the scene's
    ``phong`` and lights, no gradient threshold (a unit normal is always lit)."""
    out = {"u_phong": scene.phong, "u_gradient_epsilon": 0.0}
    if not scene.headlight_only:
        out.update(light_uniforms(scene))
    return out


class SurfaceTarget:
    """An RGBA32F colour texture and a depth texture of one size; ``idle`` is bound
    before they are released."""

    def __init__(self, ctx, width, height, idle):
        self.tex = ctx.texture((width, height), 4, dtype="f4")
        self.tex.filter = (ctx.NEAREST, ctx.NEAREST)
        self.depth = ctx.depth_texture((width, height))
        self.fbo = ctx.framebuffer([self.tex], self.depth)
        self.idle = idle

    def release(self):
        self.idle.use()
        self.fbo.release()
        self.tex.release()
        self.depth.release()


def surface_pass(renderer, scene):
    """Draw the scene's surfaces; returns the texture of (lit colour, t) per pixel of the
    scene's target (t = ``NO_SURFACE`` where none is met). The vertices (``renderer.tables``)
    and their buffer are kept with the surfaces and the volume, the target per size."""
    ctx, store = renderer.ctx, renderer.resources
    defines = {"ORTHO": 1} if scene.camera.is_ortho else {}
    if not scene.headlight_only:
        defines["LIGHTS"] = 1
    prog = renderer.programs.get("geometry/surface.vert", "geometry/surface.frag", defines)
    vertices = renderer.tables.get("surface_vertices", scene.volume, *scene.geometry,
                                   make=lambda *objects: surface_vertices(scene))
    vbo = store.for_objects("surface_vbo", vertices, make=lambda: ctx.buffer(vertices.tobytes()), capacity=2)
    vao = store.for_objects("surface_vao", vbo, prog, make=lambda: ctx.vertex_array(
        prog, [(vbo, "3f 3f 3f", "a_position", "a_normal", "a_color")]), capacity=4)
    bind(prog, {}, {**camera_uniforms(scene), **surface_light_uniforms(scene)})
    prog["u_view_proj"].write(surface_projection(scene, vertices[:, :3]).astype("f4").tobytes())
    width, height = scene.target_size
    target = store.get("surface_target", (width, height),
                       lambda: store.made("surface_target", (height, width), SurfaceTarget(ctx, width, height,
                                                                                         store.idle)), capacity=2)
    target.fbo.use()
    target.fbo.clear(0.0, 0.0, 0.0, NO_SURFACE, depth=1.0)
    ctx.disable(ctx.BLEND | ctx.CULL_FACE)
    ctx.enable(ctx.DEPTH_TEST)
    ctx.depth_func = "<"
    try:
        vao.render(vertices=len(vertices))
    finally:
        ctx.disable(ctx.DEPTH_TEST)
    return target.tex


def draw_surface_behind(renderer, surfaces):
    """Write each pixel's first surface (``surfaces``: ``geometry.surface_pass``'s
    texture) into the bound target, lit colour with opacity 1, before the slices or cells
    are blended over it: the backmost layer. Pixels no surface covers are left as they are.
    The slicing techniques and projected tetrahedra draw it."""
    ctx = renderer.ctx
    prog = renderer.programs.get("common/box_instances.vert", "geometry/surface_behind.frag", {})
    surfaces.use(location=0)
    prog["t_surface"].value = 0
    prog["u_view_proj"].write(np.eye(4, dtype="f4").tobytes())
    ctx.disable(ctx.BLEND | ctx.DEPTH_TEST | ctx.CULL_FACE)
    proxy_vao(renderer, prog, "fullscreen").render(ctx.TRIANGLES)
