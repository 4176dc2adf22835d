"""Particle-based volume rendering (PBVR; Sakamoto and Koyamada 2007, Kawamura et al.
2010 for tetrahedra): the field becomes opaque spheres whose density follows the
transfer function's extinction (``dvr_gl.techniques.particle_sets`` derives it), and GL draws them with
a depth test only: no visibility order and no blending. The first sphere each pixel's
ray meets gives the pixel its colour; averaged over ``repetitions`` independent particle
sets, the image converges to the emission-absorption integral (noise falling like
``1 / sqrt(repetitions)``).

Particles are made on the CPU (vectorised NumPy), each set once per data set, transfer
function, radius, seed and sampler, and reused for every view (turning the camera makes
none) and by larger repetition counts (set k is the same whatever the count). Grids (per cell) and tetrahedral meshes (per tetrahedron) alike.

Options (same names in ``dvr_gl.reference.render``)
---------------------------------------------------
repetitions : int >= 1 (default 1)
    independent particle sets averaged.
seed : int (default 0)
    set k draws from ``numpy.random.default_rng([seed, k])``.
radius : world units (default: half a pixel at the data's centre, at most half a cell;
    ``particles.default_radius``).
    The particle count grows as 1 / radius^2, the bias as radius^2.
sampler : "rejection"
    Poisson candidates per cell thinned by tau(s) / tau_max: exact.
target : "rgba32f" (default) | "rgba16f" | "rgba8"
    the averaged image's target.
brick_size : None (default) or N: a grid's particles made brick by brick, from bricks of
    N cells a side, each from its own block of samples (``point_bricks``): the same
    particles, so the same image.

Particles are drawn as point sprites; a particle whose centre lies outside the view's
clip volume is not drawn (GL clips points by their centre).

Clip planes and crop boxes (``Scene(clip_planes=..., crop_box=...)``). The particle sets
are the data's whatever the clip (moving a plane makes none). A particle counts on a
pixel's ray where its centre's projection on the ray, ``t = (centre - origin) . dir``,
lies in the part of the ray the planes and the crop box keep (``clipRange`` from the ray's
start, tested per fragment); spheres that miss the kept region altogether are dropped in
the vertex shader (``insideClip`` with the radius as margin: such a sphere's projections
all lie outside, so no pixel changes). Why by projection: the derivation of
``particle_sets`` counts, along a stretch ``dt`` of the ray, the particles whose
projection falls in it, so keeping those of the kept interval makes each ray see the
Poisson process of intensity ``tau / A`` over its clipped interval, and the expected
image is the contract over the clipped domain. The cut adds no bias: what remains is the
technique's noise and its ``r^2`` bias. Keeping particles by their centre instead would
blur every cut by a disc (a ray passing within ``r`` outside a crop face meets the
particles just inside it, and one inside misses those just outside): measured on a
cropped constant box (tests/test_clip_points.py), a bias of 0.055 RMSE that no repetition
count removes; the per-ray rule's error there is the estimator's noise alone. On the CT
head at 48x48 and one set, the error against the clipped exact image is 0.61 to 0.87 of
the unclipped one.

Lighting (``Scene(shading=True)``): each particle carries the gradient at its centre (a
mesh's particle, its cell's), computed once per set; a pixel's colour is the particle's
colour lit with that gradient along the pixel's own ray (``shadeBlinnPhong``), so the
averaged image converges to the lit emission-absorption integral.

Opaque geometry (``Scene(geometry=[Surface, ...])``): a pass before the particles finds
each pixel's first surface, its lit colour and its ray parameter t_hit
(``techniques.geometry.surface_pass``). The rule is the clip rule's with t_hit as the kept
interval's end: a particle counts on a pixel's ray where its centre's projection lies at
``t <= t_hit`` (``GEOMETRY``, tested per fragment), so each ray sees the Poisson process
over ``[0, t_hit]`` and the expected image is the contract's over the shortened ray. Each
set's image then has the surface's colour composited behind it with opacity 1 (a pixel
no particle covers shows the surface), before the sets are averaged.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from . import particle_sets as pbvr
from . import point_bricks
from .bricks import check_brick_size
from ..util.cache import TableCache
from ..gl.context import current
from ..util.progress import Progress
from ..model.scene import Scene
from .common import (cleared_target, SizedTarget, bind, camera_uniforms, check_scene, check_target, clip_defines,
                     clip_uniforms, data_projection, point_shading_defines, sample_term_uniforms)
from .geometry import surface_pass
from .gpu import empty_vao

POINT_SPRITES = True  # drawn as GL points, which are clipped by their centres (see Renderer.render)
MODES = ("composite",)
PROGRESS_CANDIDATES = 5_000_000    # generation this large (all sets) shows a progress bar
TAKES_STEP = False
DATA = ("volume", "mesh")


@dataclass
class ParticlesPlan:
    scene: Scene
    sets: list                      # ParticleSet per repetition
    radius: float
    repetitions: int = 1
    seed: int = 0
    sampler: str = "rejection"
    target: str = "rgba32f"
    defines: dict = field(default_factory=dict)
    generate_seconds: float = 0.0   # spent making particles for this plan (0 when cached)
    gradients: list = None          # lit: (N, 3) float32 per set, the gradient at each particle

    @property
    def count(self):
        return sum(s.count for s in self.sets)


def _check_int(name, value, lowest):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < lowest:
        raise ValueError(f"{name} must be an integer >= {lowest}, got {value!r}")
    return int(value)


def make_plan(scene, step=None, *, repetitions=1, seed=0, radius=None, sampler="rejection",
              target="rgba32f", brick_size=None, tables=None):
    """Validate the options and get the particle sets (made once per data, TF, radius,
    seed, repetitions and sampler; ``tables`` keeps them between frames). ``brick_size``:
    made brick by brick from bricks of that many cells a side (``point_bricks``)."""
    tables = tables or TableCache()
    check_scene(scene, "particles", MODES, data=DATA)
    brick_size = check_brick_size(brick_size)
    if brick_size is not None:
        point_bricks.check_grid(scene, "particles")
    if step is not None:
        raise ValueError(f"particles takes no step (the particles' density follows the TF), got step={step!r}")
    repetitions = _check_int("repetitions", repetitions, 1)
    seed = _check_int("seed", seed, 0)
    if sampler not in pbvr.SAMPLERS:
        raise ValueError(f"sampler must be one of {', '.join(pbvr.SAMPLERS)}, got {sampler!r}")
    if radius is None:
        radius = pbvr.default_radius(scene)
    elif isinstance(radius, bool) or not isinstance(radius, (int, float)) or not (math.isfinite(radius) and radius > 0):
        raise ValueError(f"radius must be a positive number (world units), got {radius!r}")
    radius = float(radius)
    check_target(target)
    data, tf = scene.volume, scene.tf
    # every set is made once: a larger repetition count (the viewer's accumulation, a
    # bench series) reuses the sets a smaller one made
    bricked = "" if brick_size is None else f":bricks {brick_size}:{int(scene.shading)}"
    pool = tables.get(f"particles:{radius!r}:{seed}:{sampler}{bricked}", data, tf, make=lambda data, tf: {})
    missing = [k for k in range(repetitions) if k not in pool]
    t0 = time.perf_counter()
    progress = None
    if missing and brick_size is None and \
            len(missing) * pbvr.candidate_count(data, tf, radius) >= PROGRESS_CANDIDATES:
        progress = Progress(len(missing))
    for n, k in enumerate(missing, 1):
        if progress is not None:
            progress.begin(f"particles: set {n} of {len(missing)}")
        if brick_size is None:
            pool[k] = pbvr.generate(data, tf, radius, seed, k, sampler)
        else:       # each brick's particles, lit with gradients from its own block
            pool[k] = point_bricks.particle_bricks(data, tf, radius, seed, k, sampler, brick_size, scene.shading)
        if progress is not None:
            progress.advance(f"particles: set {n} of {len(missing)}")
    if progress is not None:
        progress.close()
    sets = [pool[k] for k in range(repetitions)]
    timing = {"generate": time.perf_counter() - t0} if missing else {}
    defines = {"ORTHO": 1} if scene.camera.is_ortho else {}
    defines.update(point_shading_defines(scene))
    defines.update(clip_defines(scene))     # particles whose centre is clipped away are not drawn
    if scene.geometry:
        defines["GEOMETRY"] = 1             # particles behind the first surface are not drawn
    gradients = None
    if scene.shading and brick_size is None:      # once per set, with the set (bricks: with each brick's)
        gradients = [tables.get("particle_gradients", s, data, make=pbvr.particle_gradients) for s in sets]
    return ParticlesPlan(scene=scene, sets=sets, radius=radius, repetitions=repetitions,
                         seed=seed, sampler=sampler, target=target, defines=defines,
                         generate_seconds=timing.get("generate", 0.0), gradients=gradients)


def far_distance(scene):
    """A distance along any pixel ray beyond every point of the data's bounding box."""
    lo, hi = scene.volume.bounds
    corners = np.array([[a, b, c] for a in (lo[0], hi[0]) for b in (lo[1], hi[1]) for c in (lo[2], hi[2])])
    cam = scene.camera
    if cam.is_ortho:
        return float(((corners - cam.eye) @ cam.forward).max()) + 1e-3 * float(np.linalg.norm(hi - lo)) + 1e-30
    return float(np.linalg.norm(corners - cam.eye, axis=1).max()) * 1.01 + 1e-30


def pixels_per_unit(scene):
    """Pixels per world unit at unit depth (perspective) or anywhere (orthographic)."""
    return scene.height / (2.0 * scene.camera.screen_scale(scene.width, scene.height)[1])


def point_size_step(ctx):
    """GL_POINT_SIZE_GRANULARITY: a GPU may round a point's size to a multiple of it (one
    measured here lost pixel centres at sprite edges), so sprites are that much larger."""
    with current(ctx):
        return float(ctx.info.get("GL_POINT_SIZE_GRANULARITY") or 0.0)


def draw(renderer, plan):
    """Render the plan into the renderer's target; returns that framebuffer."""
    ctx = renderer.ctx
    scene = plan.scene
    fbo = cleared_target(renderer, scene, plan.target)
    if plan.count == 0 and not scene.geometry:
        return fbo
    surfaces = surface_pass(renderer, scene) if scene.geometry else None   # each pixel's first surface
    scratch = renderer.resources.for_objects("particles_scratch", make=lambda: SizedTarget(ctx, depth=True),
                                             capacity=1).get(*scene.target_size)
    prog = renderer.programs.get("particles/particles.vert", "particles/particles.frag", plan.defines)
    average = renderer.programs.get("tetra/fullscreen.vert", "particles/average.frag",
                                    {"GEOMETRY": 1} if surfaces is not None else {})
    surface_textures = {} if surfaces is None else {"t_surface": surfaces}
    uniforms = {**camera_uniforms(scene), "u_radius": plan.radius, "u_pixels_per_unit": pixels_per_unit(scene),
                "u_inv_far": 1.0 / far_distance(scene), "u_size_step": point_size_step(ctx), **clip_uniforms(scene)}
    if scene.shading:
        uniforms.update(sample_term_uniforms(renderer, scene, plan.defines))
    bind(prog, surface_textures, uniforms, first_unit=2)     # units 0, 1: the averaging pass's
    prog["u_view_proj"].write(data_projection(scene).astype("f4").tobytes())
    ctx.enable(ctx.PROGRAM_POINT_SIZE)
    for k, particle_set in enumerate(plan.sets):
        if particle_set.count == 0 and surfaces is None:
            continue
        gradients = None if plan.gradients is None else plan.gradients[k]
        scratch.use()
        scratch.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        if particle_set.count > 0:
            # a bricked set: each brick's particles in a buffer of their own, all into
            # the same depth test (the nearest sphere wins whatever the order)
            pieces = getattr(particle_set, "pieces", [particle_set])
            piece_gradients = getattr(particle_set, "gradients", None) or [gradients] * len(pieces)
            ctx.enable(ctx.DEPTH_TEST)
            ctx.depth_func = "<"
            for piece, g in zip(pieces, piece_gradients):
                if piece.count == 0:
                    continue
                vao = renderer.resources.for_objects("particles_vbo", piece, prog,
                                                     make=lambda s=piece, g=g: _Points(ctx, prog, s, g),
                                                     capacity=max(plan.repetitions * len(pieces), 2)).vao
                vao.render(ctx.POINTS)
            ctx.disable(ctx.DEPTH_TEST)
        fbo.use()
        ctx.enable(ctx.BLEND)
        ctx.blend_func = ctx.ONE, ctx.ONE
        ctx.blend_equation = ctx.FUNC_ADD
        bind(average, {"t_image": scratch.color_attachments[0], **surface_textures}, {"u_weight": 1.0 / plan.repetitions})
        empty_vao(renderer, average).render(ctx.TRIANGLES, vertices=3)
        ctx.disable(ctx.BLEND)
    ctx.disable(ctx.PROGRAM_POINT_SIZE)
    return fbo


class _Points:
    """One particle set on the GPU: position and colour, 6 float32 per particle, and the
    gradient when lit (9)."""

    def __init__(self, ctx, prog, particle_set, gradients=None):
        parts = [particle_set.points, particle_set.colors] + ([] if gradients is None else [gradients])
        data = np.concatenate(parts, axis=1).astype(np.float32)
        self.vbo = ctx.buffer(np.ascontiguousarray(data).tobytes())
        if gradients is None:
            self.vao = ctx.vertex_array(prog, [(self.vbo, "3f 3f", "a_position", "a_color")])
        else:
            self.vao = ctx.vertex_array(prog, [(self.vbo, "3f 3f 3f", "a_position", "a_color", "a_gradient")])

    def release(self):
        self.vao.release()
        self.vbo.release()
