"""Splatting (Westover 1990; elliptical kernels after Zwicker et al. 2001): every
classified grid sample is a Gaussian kernel that carries its share of the extinction,
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
then reconstructed: pre-classification).

Meshes: the samples are the mesh's points, each carrying its lumped volume (a quarter of
every cell it is a corner of: the integral of its linear basis function), its kernel
isotropic and ``radius`` times the mean length of the edges that meet there.

Lighting (``Scene(shading=True)``): each splat carries the gradient at its centre (a
mesh's vertex: the volume-weighted mean of its cells' gradients), and its colour is lit
with it along each pixel's own ray before it is associated with the splat's opacity.

Order: per view the samples are sorted by depth, back to front (float32 argsort), and
drawn in that order (an index buffer); a splat counts only where its centre is ahead of
the ray's start. Samples with zero opacity are not drawn. Samples are made once per
volume, transfer function and density.

Options (same names in ``dvr_gl.reference.render``)
---------------------------------------------------
density : int from 1 to 8 (default 1), samples per data spacing along each axis (grids only).
radius : kernel standard deviation in sample spacings, or in mean edge lengths on a mesh
    (default 0.4: the balance of holes and blur measured in the README).
cutoff : truncation in standard deviations (default 3).
target : "rgba32f" (default) | "rgba16f" | "rgba8": blending happens in the target.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..cache import TableCache
from ..reference.common import cell_is_valid, trilinear
from ..scene import Scene
from .common import (cleared_target, bind, camera_uniforms, check_scene, check_target, data_projection,
                     point_shading_defines, sample_term_uniforms)
from ..particles import extinction
from .particles import pixels_per_unit

POINT_SPRITES = True  # drawn as GL points, which are clipped by their centres (see Renderer.render)
MODES = ("composite",)
TAKES_STEP = False
DATA = ("volume", "mesh")
DEFAULT_RADIUS = 0.4
DEFAULT_CUTOFF = 3.0


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
        # trapezoid weights: a sample on a face of the box stands for half a cell along
        # that axis, so the kernels carry the trapezoid rule's integral of tau over the box
        weight = np.prod(np.where((idx == 0) | (idx == dims - 1), 0.5, 1.0), axis=1)
        points.append((idx * volume.spacing).astype(np.float32))
        samples.append(np.concatenate([tf.color(s).reshape(-1, 3), (tau * weight * cell)[:, None]],
                                      axis=1).astype(np.float32))
    if not points:
        return Splats(np.zeros((0, 3), np.float32), np.zeros((0, 4), np.float32), np.zeros(0, np.float32), spacing)
    points = np.concatenate(points)
    return Splats(points, np.concatenate(samples), np.ones(len(points), np.float32), spacing)


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


def make_plan(scene, step=None, *, density=1, radius=DEFAULT_RADIUS, cutoff=DEFAULT_CUTOFF, target="rgba32f",
              tables=None):
    """Validate the options, get the samples (once per volume, TF and density) and their
    order for this view."""
    tables = tables or TableCache()
    check_scene(scene, "splat", MODES, data=DATA)
    if step is not None:
        raise ValueError(f"splat takes no step (see density), got step={step!r}")
    if isinstance(density, bool) or not isinstance(density, (int, np.integer)) or not 1 <= density <= 8:
        raise ValueError(f"density must be an integer from 1 to 8, got {density!r}")
    for name, value in (("radius", radius), ("cutoff", cutoff)):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a positive number, got {value!r}")
    check_target(target)
    if scene.is_mesh:
        if density != 1:
            raise ValueError(f"density applies to grids (a mesh is splatted at its points), got density={density!r}")
        splats = tables.get("splats:mesh", scene.volume, scene.tf, make=make_mesh_splats)
    else:
        splats = tables.get(f"splats:{int(density)}", scene.volume, scene.tf,
                            make=lambda volume, tf: make_splats(volume, tf, int(density)))
    order = tables.get("splat_order", splats, scene.camera,
                       make=lambda s, camera: back_to_front(scene, s))
    defines = {"ORTHO": 1} if scene.camera.is_ortho else {}
    defines.update(point_shading_defines(scene))
    gradients = None
    if scene.shading:      # once per set of splats
        gradients = tables.get("splat_gradients", splats, scene.volume, make=splat_gradients)
    return SplatPlan(scene=scene, splats=splats, order=order, density=int(density), radius=float(radius),
                     cutoff=float(cutoff), target=target, defines=defines, gradients=gradients)


def splat_gradients(splats, data):
    """(N, 3) float32: the gradient at each splat's centre (a mesh's vertices: the
    volume-weighted mean of their cells')."""
    from ..reference.shading import point_gradients
    return point_gradients(data, splats.points, vertices=splats.vertices).astype(np.float32)


def draw(renderer, plan):
    """Render the plan into the renderer's target; returns that framebuffer."""
    ctx = renderer.ctx
    scene = plan.scene
    fbo = cleared_target(renderer, scene, plan.target)
    if plan.splats.count == 0:
        return fbo
    prog = renderer.programs.get("splat/splat.vert", "splat/splat.frag", plan.defines)
    uniforms = {**camera_uniforms(scene), **plan.kernel_uniforms(), "u_pixels_per_unit": pixels_per_unit(scene)}
    if scene.shading:
        uniforms.update(sample_term_uniforms(renderer, scene, plan.defines))
    bind(prog, {}, uniforms)
    prog["u_view_proj"].write(data_projection(scene).astype("f4").tobytes())
    gpu = renderer.resource("splat_vbo", plan.splats, prog,
                            make=lambda: _SplatBuffers(ctx, prog, plan.splats, plan.gradients), capacity=1)
    vao = gpu.ordered(plan.order)
    ctx.disable(ctx.DEPTH_TEST)
    ctx.enable(ctx.BLEND | ctx.PROGRAM_POINT_SIZE)
    ctx.blend_func = ctx.ONE, ctx.ONE_MINUS_SRC_ALPHA
    ctx.blend_equation = ctx.FUNC_ADD
    vao.render(ctx.POINTS, vertices=int(plan.order.size))
    ctx.disable(ctx.BLEND | ctx.PROGRAM_POINT_SIZE)
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
