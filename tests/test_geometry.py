"""Opaque geometry (``Scene.geometry``): the exact image against closed forms, the
ray-triangle test on its own, the ray caster against its NumPy twin and against the exact
image, the checks, and the front ends (``dvr_gl.render``, ``--geometry``).

The closed forms: a constant volume (value 7, TF opacity a per unit distance u, colour c)
seen orthographically along -z, with squares of two triangles parallel to the image
(normal +-z). A ray through a square at height zq inside the box gathers the box from
its top face z1 down to zq, ``L = z1 - zq``, ``T = (1 - a)^(L / u)``, and the pixel is
``C = c (1 - T) + T lit``, ``A = 1``; with the headlight ``|N.L| = 1``, so ``lit = colour
(ka + kd) + ks``. A ray through a square beyond the data's edge sees the square alone."""

import os

import numpy as np
import pytest

import dvr_gl
from dvr_gl import metrics, reference
from dvr_gl.data import ct_head, ct_head_tf
from dvr_gl.data.phantoms import marschner_lobb, marschner_lobb_tf
from dvr_gl.reference import exact_geometry
from dvr_gl.reference.exact_geometry import ray_triangle_hits, surface_hits
from dvr_gl.techniques import raycast
from test_raycast import derived_tolerance

U32 = 2.0 ** -24
BOX = (20, 12, 16)        # (nz, ny, nx) samples, spacing 1: the box is 15 x 11 x 19
ALPHA, UNIT, COLOR = 0.2, 2.0, np.array([0.9, 0.5, 0.25])


def square(x0, x1, y0, y1, z, color=(0.2, 0.6, 0.4)):
    """An axis-aligned square at height z, two triangles."""
    return dvr_gl.Surface([(x0, y0, z), (x1, y0, z), (x1, y1, z), (x0, y1, z)], [(0, 1, 2), (0, 2, 3)], color=color)


def icosphere(centre, radius, subdivisions=3, color=(0.9, 0.3, 0.2)):
    """A sphere of 20 * 4^subdivisions triangles, vertices on the sphere."""
    t = (1 + 5 ** 0.5) / 2
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
         (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
             (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11),
             (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    points = [np.array(p, float) / np.linalg.norm(p) for p in v]
    for _ in range(subdivisions):
        middle, finer = {}, []

        def mid(a, b):
            key = (min(a, b), max(a, b))
            if key not in middle:
                m = points[a] + points[b]
                points.append(m / np.linalg.norm(m))
                middle[key] = len(points) - 1
            return middle[key]
        for a, b, c in faces:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            finer += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = finer
    return dvr_gl.Surface(np.asarray(centre, float) + radius * np.array(points), faces, color=color)


def constant_scene(size=24, values=None, **kwargs):
    data = np.full(BOX, 7.0, np.float32) if values is None else values
    vol = dvr_gl.Volume(data)
    tf = dvr_gl.TransferFunction(color=[(0.0, *COLOR), (20.0, *COLOR)], opacity=[(0.0, ALPHA), (20.0, ALPHA)],
                                 unit_distance=UNIT)
    lo, hi = vol.bounds
    centre = (lo + hi) / 2
    # wider than the box, so some rays miss the data: 7.5 +- 9 in x, 5.5 +- 9 in y
    cam = dvr_gl.Camera(centre + [0.0, 0.0, 100.0], centre, up=(0, 1, 0), ortho_height=18.0)
    return dvr_gl.Scene(vol, tf, cam, size, size, **kwargs)


def pixel_xy(scene):
    origins, _ = scene.camera.rays(scene.width, scene.height)
    return origins[..., 0], origins[..., 1]


def inside(x, y, x0, x1, y0, y1):
    return (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)


def headlight_lit(scene, surface):
    ka, kd, ks, _ = scene.phong
    return np.asarray(surface.color) * (ka + kd) + ks


# ---------------------------------------------------------------------------- closed forms

@pytest.mark.parametrize("data_kind", ["grid", "mesh"])
@pytest.mark.parametrize("clipped", [False, True])
def test_exact_composite_matches_the_closed_form(clipped, data_kind):
    """A square at z = 6.5 reaching beyond the data in x; clipped, a plane keeps x <= 10 of
    the data and leaves the square whole (the contract: clips cut the data only). The same
    box as tetrahedra (the exact image's mesh path) gives the same image."""
    from dvr_gl.model.cell_split import grid_to_tets
    sq = square(4.0, 30.0, 2.0, 9.0, 6.5)
    clip = dict(clip_planes=[((10.0, 0.0, 0.0), (-1.0, 0.0, 0.0))]) if clipped else {}
    scene = constant_scene(geometry=[sq], **clip)
    if data_kind == "mesh":
        coarse = dvr_gl.Volume(np.full((6, 5, 5), 7.0, np.float32), spacing=(15 / 4, 11 / 4, 19 / 5))
        scene = scene.replace(volume=grid_to_tets(coarse))
    x, y = pixel_xy(scene)
    data = inside(x, y, 0, 10 if clipped else 15, 0, 11)
    on = inside(x, y, 4, 30, 2, 9)
    length = np.where(data, np.where(on, 19.0 - 6.5, 19.0), 0.0)
    T = (1 - ALPHA) ** (length / UNIT)
    lit = headlight_lit(scene, sq)
    C = COLOR * (1 - T)[..., None] + np.where(on, T, 0.0)[..., None] * lit
    A = np.where(on, 1.0, 1 - T)
    image = reference.exact(scene, cache=False)
    assert (on & ~data).any() and (on & data).any() and (data & ~on).any() and (~on & ~data).any()
    np.testing.assert_allclose(image, np.concatenate([C, A[..., None]], axis=-1), rtol=0, atol=1e-9)


def test_exact_mip_with_a_directional_light_and_a_square_in_front_of_the_data():
    """mip over the shortened ray (the constant 7: (c a, a)) with the surface behind,
    ``C = c a + (1 - a) lit``, A = 1; a second square above the box (z = 25) hides
    everything behind it. One directional light L = (0.6, 0, 0.8): diffuse ``kd |N.L|``,
    specular ``ks |N.H|^n`` with H the unit half vector of L and V = +z."""
    inner = square(4.0, 30.0, 2.0, 9.0, 6.5)
    front = square(-5.0, 5.0, -5.0, 4.0, 25.0, color=(0.8, 0.7, 0.1))
    light = dvr_gl.Light((0.6, 0.0, 0.8))
    scene = constant_scene(geometry=[inner, front], mode="mip", lights=[light])
    ka, kd, ks, n = scene.phong
    h = np.array([0.6, 0.0, 1.8]) / np.linalg.norm([0.6, 0.0, 1.8])
    terms = (ka + kd * 0.8, ks * h[2] ** n)

    def lit(surface):
        return np.asarray(surface.color) * terms[0] + terms[1]
    x, y = pixel_xy(scene)
    data = inside(x, y, 0, 15, 0, 11)
    on_front = inside(x, y, -5, 5, -5, 4)
    on_inner = inside(x, y, 4, 30, 2, 9) & ~on_front
    a = np.where(data & ~on_front, ALPHA, 0.0)
    C = COLOR * a[..., None]
    C = np.where(on_inner[..., None], C + (1 - a)[..., None] * lit(inner), C)
    C = np.where(on_front[..., None], lit(front), C)
    A = np.where(on_front | on_inner, 1.0, a)
    assert (on_front & data).any() and (on_inner & data).any() and (on_inner & ~data).any()
    np.testing.assert_allclose(reference.exact(scene, cache=False), np.concatenate([C, A[..., None]], axis=-1),
                               rtol=0, atol=1e-9)


def test_exact_isosurface_shows_the_first_of_the_two_surfaces():
    """A ramp f = z (world), iso 12.5: a square at z = 15 (x < 7) lies in front of the
    level set, one at z = 6 (x >= 7) behind it. The level set's gradient is +z, so it is lit
    like the squares: ``c(12.5) (ka + kd) + ks``."""
    z = np.arange(BOX[0], dtype=np.float32)[:, None, None] * np.ones(BOX, np.float32)
    high, low = square(-5.0, 7.0, -5.0, 20.0, 15.0), square(7.0, 30.0, -5.0, 20.0, 6.0, color=(0.1, 0.2, 0.9))
    scene = constant_scene(values=z, geometry=[high, low], mode="isosurface", iso_value=12.5)
    ka, kd, ks, _ = scene.phong
    x, y = pixel_xy(scene)
    data = inside(x, y, 0, 15, 0, 11)
    on_high = inside(x, y, -5, 7, -5, 20)
    on_low = inside(x, y, 7, 30, -5, 20) & ~on_high
    iso = scene.tf.color(np.array([12.5]))[0] * (ka + kd) + ks
    C = np.zeros(x.shape + (3,))
    C[on_low] = headlight_lit(scene, low)
    C[on_low & data] = iso
    C[on_high] = headlight_lit(scene, high)
    A = (on_high | on_low).astype(float)
    assert (on_high & data).any() and (on_low & data).any() and (on_low & ~data).any()
    np.testing.assert_allclose(reference.exact(scene, cache=False), np.concatenate([C, A[..., None]], axis=-1),
                               rtol=0, atol=1e-9)


def test_the_raycaster_gives_the_closed_form_to_its_float32_rounding(renderer):
    """A constant box: every full segment is the same, so GL matches the closed form as
    its midpoint composite does without geometry (test_raycast's constant box)."""
    sq = square(4.0, 30.0, 2.0, 9.0, 6.5)
    scene = constant_scene(geometry=[sq])
    gl = renderer.render(scene, ert_transmittance=0.0)
    exact = reference.exact(scene, cache=False)
    assert metrics.max_abs_error(gl, exact) < 1e-5


# ---------------------------------------------------------------------------- the ray-triangle test

def test_ray_triangle_hits_solve_the_barycentric_system():
    rng = np.random.default_rng(1)
    tri = rng.normal(size=(40, 3, 3))
    o = rng.normal(size=(300, 3)) * 3
    d = rng.normal(size=(300, 3)) * 0.5 - o          # towards the triangles, about the origin
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t, face = ray_triangle_hits(o, d, tri)
    best = np.full(len(o), np.inf)
    for k, (a, b, c) in enumerate(tri):             # o + t d = a + u (b - a) + v (c - a)
        m = np.stack([np.broadcast_to(-d.T, (3, len(o))).T, np.broadcast_to(b - a, (len(o), 3)),
                      np.broadcast_to(c - a, (len(o), 3))], axis=2)
        tuv = np.linalg.solve(m, (o - a)[..., None])[..., 0]
        ok = (tuv[:, 0] > 0) & (tuv[:, 1] >= 0) & (tuv[:, 2] >= 0) & (tuv[:, 1] + tuv[:, 2] <= 1)
        best = np.where(ok, np.minimum(best, tuv[:, 0]), best)
    assert np.isfinite(t).sum() > 50
    np.testing.assert_allclose(t, best, rtol=1e-9)
    assert np.all((face >= 0) == np.isfinite(t))


def test_ray_triangle_hits_rules_and_chunks(monkeypatch):
    tri = np.array([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]])
    o = np.array([[0.2, 0.2, 1.0], [0.2, 0.2, -1.0], [0.5, 0.5, 1.0], [2.0, 0.2, 1.0], [0.2, 0.2, 1.0]])
    d = np.array([[0, 0, -1.0], [0, 0, -1.0], [0, 0, -1.0], [0, 0, -1.0], [1.0, 0, 0]])
    t, face = ray_triangle_hits(o, d, tri)
    # hit; behind the origin (t < 0); on the edge u + v = 1 (counted); beside; parallel
    np.testing.assert_array_equal(t, [1.0, np.inf, 1.0, np.inf, np.inf])
    np.testing.assert_array_equal(face, [0, -1, 0, -1, -1])
    rng = np.random.default_rng(2)
    tris, oo, dd = rng.normal(size=(37, 3, 3)), rng.normal(size=(101, 3)) * 2, rng.normal(size=(101, 3))
    whole = ray_triangle_hits(oo, dd, tris)
    monkeypatch.setattr(exact_geometry, "_PAIRS", 50)    # chunks of a few rays and triangles
    chunked = ray_triangle_hits(oo, dd, tris)
    np.testing.assert_array_equal(whole[0], chunked[0])
    np.testing.assert_array_equal(whole[1], chunked[1])


# ---------------------------------------------------------------------------- GL against its twin

def _offset_rays(camera, width, height, dx, dy):
    """Camera.rays through the points (dx, dy) pixels from the pixel centres (y down)."""
    sx, sy = camera.screen_scale(width, height)
    x = (2 * (np.arange(width) + 0.5 + dx) / width - 1) * sx
    y = (1 - 2 * (np.arange(height) + 0.5 + dy) / height) * sy
    xx, yy = np.meshgrid(x, y)
    offset = xx[..., None] * camera.right + yy[..., None] * camera.true_up
    if camera.is_ortho:
        origins = camera.eye + offset
        dirs = np.broadcast_to(camera.forward, origins.shape)
    else:
        dirs = camera.forward + offset
        dirs = dirs / np.linalg.norm(dirs, axis=-1, keepdims=True)
        origins = np.broadcast_to(camera.eye, dirs.shape)
    return origins.reshape(-1, 3), dirs.reshape(-1, 3)


#: how far from the pixel centre the coverage test looks, in pixels: llvmpipe snaps
#: vertices to 2^-8 of a pixel (GL_SUBPIXEL_BITS 8), moving each by at most 2^-9 per axis
#: and so an edge by at most 2^-9 sqrt(2) < 0.0028 px; rays 2^-7 px away along x and y
#: see every edge within 2^-7 / sqrt(2) = 0.0055 px of the centre
REACH = 2.0 ** -7


def coverage_and_reach(scene):
    """Per pixel: whether its coverage is ambiguous under the rasteriser's snapping (a ray
    ``REACH`` px from the centre along x or y meets another face of any surface, or none,
    or the centre ray none where one of them does), whether the centre ray meets a
    surface, and ``spread``: how far t moves over those rays (the rasterised t's
    sensitivity to the snapping), 0 where ambiguous or missed."""
    triangles = np.concatenate([s.triangles() for s in scene.geometry])
    W, H = scene.width, scene.height
    t, face = ray_triangle_hits(*_offset_rays(scene.camera, W, H, 0.0, 0.0), triangles)
    ambiguous = np.zeros(t.shape, bool)
    spread = np.zeros(t.shape)
    for dx, dy in ((REACH, 0.0), (-REACH, 0.0), (0.0, REACH), (0.0, -REACH)):
        tp, fp = ray_triangle_hits(*_offset_rays(scene.camera, W, H, dx, dy), triangles)
        ambiguous |= fp != face
        same = (fp == face) & (face >= 0)
        spread[same] = np.maximum(spread[same], np.abs(tp[same] - t[same]))
    return ambiguous.reshape(H, W), (face >= 0).reshape(H, W), spread.reshape(H, W), t.reshape(H, W)


def band_area(scene):
    """The area in pixels (so about the number of pixel centres) within ``REACH`` px,
    along x or y, of an edge of the surfaces: at most REACH on each side of the edge's
    projected length, and the ends. The coverage test excludes about this many pixels."""
    cam = scene.camera
    sx, sy = cam.screen_scale(scene.width, scene.height)
    length = 0.0
    for surface in scene.geometry:
        f = surface.faces
        edges = np.unique(np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1), axis=0)
        rel = surface.vertices - cam.eye
        x, y, z = rel @ cam.right, rel @ cam.true_up, rel @ cam.forward
        scale = np.ones_like(z) if cam.is_ortho else np.where(z > 0, z, np.nan)
        px = np.stack([x / scale / sx * scene.width / 2, y / scale / sy * scene.height / 2], axis=1)
        step = np.linalg.norm(px[edges[:, 0]] - px[edges[:, 1]], axis=1)
        length += float(np.nansum(step)) + 2 * REACH * len(edges)
    return 2 * REACH * length


def surface_tolerance(plan, spread, t):
    """A bound per pixel on |GL - twin| with geometry: the ray caster's own
    (``test_raycast.derived_tolerance``), plus what the rasterised ray end moves, plus the
    float32 lit colour.

    Where both test the same face (``coverage_and_reach`` excludes the rest) the ray's end
    t differs from the twin's by float32 rounding alone: vertex snapping decides coverage,
    while llvmpipe interpolates attributes from the float positions (measured: the
    rasterised t within 3 u (t + |eye| + the box's diagonal) of the float64 hit on every
    unambiguous pixel of these scenes). The rounding is that of the window position the
    position is interpolated at, 16 u of the image's size in pixels, which moves t by the
    ``spread`` over ``REACH`` px scaled down to it, and that of the box-relative position and
    the dot product, 8 u (t + |eye| + diagonal).

    Moving the end by dt changes a composite pixel by at most
    ``(1 + lit) (tau_max + step/u (max|alpha'| + max|c'|) G / (2 (1 - alpha_max))) dt``: the
    last segment's length (its opacity by at most tau dt) and its midpoint (by dt/2, its
    value by G dt/2, G the trilinear field's largest gradient), and the surface behind it by
    lit times the opacity change. mip/minip/average: one value moves by G dt, classified
    with the TF's slopes. The lit colour: 64 u (lit + ks n), the pow's rounding."""
    scene = plan.scene
    tf, vol = scene.tf, scene.volume
    ka, kd, ks, n = scene.phong
    lit = max(float(np.max(s.color)) for s in scene.geometry) * (ka + kd) + ks
    knots = tf.knots
    if len(knots) > 1:
        slope_a = float(np.abs(np.diff(tf.opacity(knots)) / np.diff(knots)).max())
        slope_c = float(np.abs(np.diff(tf.color(knots), axis=0) / np.diff(knots)[:, None]).max())
    else:
        slope_a = slope_c = 0.0
    a_max = float(tf.opacity(knots).max())
    tau = -np.log1p(-a_max) / tf.unit_distance
    values = vol.values(np.float64)
    G = float(np.sqrt(sum((np.abs(np.diff(values, axis=2 - a)).max() / vol.spacing[a]) ** 2 for a in range(3))))
    if scene.mode == "composite":
        rate = (1 + lit) * (tau + plan.step / tf.unit_distance * (slope_a + slope_c) * G / (2 * (1 - a_max)))
    else:
        rate = (1 + lit) * (slope_a + slope_c) * G
    eye = float(np.linalg.norm(scene.camera.eye - vol.bounds[0]))
    window = 16 * U32 * max(scene.width, scene.height)          # pixels
    dt = spread * window / REACH + 8 * U32 * (np.where(np.isfinite(t), t, 0.0) + eye + float(np.linalg.norm(vol.extent)))
    return derived_tolerance(plan) + rate * dt + 64 * U32 * (lit + ks * n)


def _ml_scenes(size):
    vol = marschner_lobb(41)
    tf = marschner_lobb_tf()
    sphere = icosphere((0.3, -0.2, 0.1), 0.55)
    # a tilted square through the box and beyond it (its corner at x, y = -1.4 is outside)
    tilted = dvr_gl.Surface([(-1.4, -1.3, -0.5), (0.6, -1.3, -0.9), (0.6, 0.7, 0.4), (-1.4, 0.7, 0.8)],
                            [(0, 1, 2), (0, 2, 3)], color=(0.3, 0.8, 0.4))
    persp = dvr_gl.default_camera(vol, azimuth=30, elevation=20)
    both = [sphere, tilted]
    return {
        "perspective": dvr_gl.Scene(vol, tf, persp, size, size, geometry=both),
        "ortho": dvr_gl.Scene(vol, tf, dvr_gl.default_camera(vol, azimuth=-40, elevation=10, ortho=True), size, size,
                              geometry=both),
        "eye inside, lit": dvr_gl.Scene(vol, tf, dvr_gl.Camera((0.9, 0.8, -0.7), (0.0, -0.3, 0.3), fov=70), size,
                                        size, geometry=both, shading=True),
        "mip": dvr_gl.Scene(vol, tf, persp, size, size, mode="mip", geometry=both),
        "average": dvr_gl.Scene(vol, tf, persp, size, size, mode="average", geometry=both),
        "clipped": dvr_gl.Scene(vol, tf, persp, size, size, geometry=both,
                                clip_planes=[((0.2, 0.0, 0.0), (-1.0, 0.2, 0.1))]),
    }


def _head_scenes(size):
    head = ct_head()
    lo, hi = head.bounds
    sphere = icosphere((lo + hi) / 2 + [10.0, -20.0, 5.0], 45.0, color=(0.3, 0.5, 0.9))
    return {
        "head": dvr_gl.Scene(head, ct_head_tf(), dvr_gl.default_camera(head, azimuth=30, elevation=20), size, size,
                             geometry=[sphere]),
        "head, lit from behind": dvr_gl.Scene(head, ct_head_tf(), dvr_gl.default_camera(head, azimuth=200, elevation=-20),
                                              size, size, shading=True, geometry=[sphere],
                                              lights=[dvr_gl.Light(), dvr_gl.Light((0.0, 1.0, 0.5), intensity=0.6)]),
    }


def _check_against_twin(renderer, scene):
    opts = dict(ert_transmittance=0.0)
    gl = renderer.render(scene, **opts)
    twin = reference.render(scene, **opts)
    ambiguous, hit, spread, t = coverage_and_reach(scene)
    tol = surface_tolerance(raycast.make_plan(scene, **opts), spread, t)
    error = np.abs(gl - twin).max(axis=-1)
    # silhouettes: surface pixels with a 4-neighbour that misses every surface, and back
    edge = np.zeros_like(hit)
    for axis in (0, 1):
        change = np.diff(hit, axis=axis)
        lead = [slice(None)] * 2
        lead[axis] = slice(0, -1)
        trail = [slice(None)] * 2
        trail[axis] = slice(1, None)
        edge[tuple(lead)] |= change
        edge[tuple(trail)] |= change
    compared = ~ambiguous
    assert hit.sum() > 0.03 * hit.size
    assert (edge & compared).sum() >= 20                      # silhouette pixels are compared
    assert ambiguous.sum() <= 2 * band_area(scene) + 5, (ambiguous.sum(), band_area(scene))
    return error, tol, compared, gl, twin


@pytest.mark.parametrize("name", list(_ml_scenes(8)))
def test_raycast_with_geometry_matches_its_twin_in_marschner_lobb(renderer, name):
    scene = _ml_scenes(64)[name]
    error, tol, compared, gl, _ = _check_against_twin(renderer, scene)
    assert np.all(error[compared] <= tol[compared]), (error[compared] / tol[compared]).max()
    plain = renderer.render(scene.replace(geometry=()), ert_transmittance=0.0)
    assert metrics.max_abs_error(gl, plain) > 0.3                  # the surfaces are there


@pytest.mark.parametrize("opts", [dict(jitter_seed=3), dict(preintegrate=True, refine=4), dict(skip_empty=False)])
def test_raycast_options_with_geometry_match_the_twin(renderer, opts):
    """The ray's shortened end is the box exit's rule: jittered starts, pre-integrated
    (and refined) last segments and empty-space skipping end there alike."""
    scene = _ml_scenes(48)["perspective"]
    opts = dict(opts, ert_transmittance=0.0)
    gl = renderer.render(scene, **opts)
    twin = reference.render(scene, **opts)
    ambiguous, _, spread, t = coverage_and_reach(scene)
    tol = surface_tolerance(raycast.make_plan(scene, **opts), spread, t)
    error = np.abs(gl - twin).max(axis=-1)
    assert np.all(error[~ambiguous] <= tol[~ambiguous])
    if "skip_empty" in opts:        # skipping leaves out exact zeros only: the same image
        assert np.array_equal(gl, renderer.render(scene, ert_transmittance=0.0))


def test_raycast_isosurface_with_geometry_matches_its_twin(renderer):
    """Isosurfaces: the bound of test_raycast (1e-3, a bisected hit's shading), and as there
    a ray grazing the level set may find the crossing in one arithmetic only (2 pixels)."""
    scene = _ml_scenes(64)["perspective"].replace(mode="isosurface", iso_value=0.5)
    error, _, compared, _, _ = _check_against_twin(renderer, scene)
    assert (error[compared] > derived_tolerance(raycast.make_plan(scene))).sum() <= 2


@pytest.mark.parametrize("name", list(_head_scenes(8)))
def test_raycast_with_geometry_matches_its_twin_in_the_ct_head(renderer, name):
    scene = _head_scenes(64)[name]
    error, tol, compared, _, _ = _check_against_twin(renderer, scene)
    assert np.all(error[compared] <= tol[compared]), (error[compared] / tol[compared]).max()


def test_error_against_exact_falls_at_second_order(renderer, tmp_path):
    """Midpoint samples with a true-length last segment, now ending at the surface: second
    order as without geometry (measured 1.96, unlit and lit 2.10; the plain scene 1.91)."""
    scene = _ml_scenes(48)["perspective"]
    exact = reference.exact(scene, cache_dir=tmp_path)
    steps = np.array([0.1, 0.05, 0.025, 0.0125])
    errors = np.array([metrics.rmse(renderer.render(scene, step=d, ert_transmittance=0.0), exact) for d in steps])
    order = np.polyfit(np.log(steps), np.log(errors), 1)[0]
    assert 1.8 < order < 2.5, (errors, order)
    assert errors[-1] < 1e-3


def test_tiles_match_the_twin_as_the_whole_image_does():
    """The surface pass is drawn per tile, like the ray casting; each tile rasterises the
    surfaces anew (snapped in its own frame), so the same bound holds, not bit equality."""
    scene = _ml_scenes(40)["perspective"]
    with dvr_gl.Renderer(max_tile=16) as tiled:
        error, tol, compared, _, _ = _check_against_twin(tiled, scene)
    assert np.all(error[compared] <= tol[compared]), (error[compared] / tol[compared]).max()


def test_nothing_is_made_again_per_frame(renderer):
    scene = _ml_scenes(32)["perspective"]
    renderer.render(scene)
    made = len(renderer.created)
    renderer.render(scene)
    renderer.render(scene.replace(camera=dvr_gl.default_camera(scene.volume, azimuth=80)))
    assert len(renderer.created) == made


def test_surface_twin_hits_are_the_exact_images():
    scene = _ml_scenes(16)["ortho"]
    t, color = surface_hits(scene)
    o, d = scene.camera.rays(16, 16)
    t_all, face = ray_triangle_hits(o.reshape(-1, 3), d.reshape(-1, 3),
                                    np.concatenate([s.triangles() for s in scene.geometry]))
    np.testing.assert_array_equal(t, t_all)
    assert np.all(color[np.isinf(t)] == 0) and np.all(color[np.isfinite(t)] > 0)


# ---------------------------------------------------------------------------- checks

@pytest.mark.parametrize("kwargs, error, message", [
    (dict(vertices=[(0, 0, 0), (1, 0, 0)], faces=[(0, 1, 1)]), ValueError, r"vertices must be an \(n, 3\) array"),
    (dict(vertices=[(0, 0, np.nan), (1, 0, 0), (0, 1, 0)], faces=[(0, 1, 2)]), ValueError, "vertices must be finite"),
    (dict(vertices="abc", faces=[(0, 1, 2)]), (TypeError, ValueError), "vertices"),
    (dict(vertices=[(0, 0, 0), (1, 0, 0), (0, 1, 0)], faces=[(0, 1, 3)]), ValueError, r"faces index vertices 0\.\.2"),
    (dict(vertices=[(0, 0, 0), (1, 0, 0), (0, 1, 0)], faces=[(0.0, 1.0, 2.0)]), TypeError, "integer vertex indices"),
    (dict(vertices=[(0, 0, 0), (1, 0, 0), (0, 1, 0)], faces=[(0, 1, 2, 0)]), ValueError, r"faces must be an \(m, 3\)"),
    (dict(vertices=[(0, 0, 0), (1, 0, 0), (0, 1, 0)], faces=[(0, 1, 2)], color=(1.5, 0, 0)), ValueError,
     r"color must be three numbers in \[0, 1\]"),
])
def test_bad_surfaces_are_named_errors(kwargs, error, message):
    with pytest.raises(error, match=message):
        dvr_gl.Surface(**kwargs)


def test_bad_geometry_in_a_scene_is_named():
    with pytest.raises(TypeError, match=r"geometry\[1\] must be a dvr_gl.Surface"):
        constant_scene(geometry=[square(0, 1, 0, 1, 2), "sphere.obj"])


def test_every_technique_draws_geometry():
    from dvr_gl.techniques import common, names
    assert set(common.GEOMETRY_TECHNIQUES) == set(names())


@pytest.mark.parametrize("technique", ["splat"])
def test_techniques_that_do_not_draw_geometry_say_so(renderer, technique, monkeypatch):
    """Every technique draws geometry; the check stays for one that would not (taken off
    the list here)."""
    from dvr_gl.techniques import common
    monkeypatch.setattr(common, "GEOMETRY_TECHNIQUES", tuple(t for t in common.GEOMETRY_TECHNIQUES if t != technique))
    scene = constant_scene(geometry=[square(4.0, 30.0, 2.0, 9.0, 6.5)])
    with pytest.raises(ValueError, match=f"{technique} does not draw geometry yet: .* rendered by raycast"):
        renderer.render(scene, technique=technique)
    with pytest.raises(ValueError, match="does not draw geometry yet"):
        reference.render(scene, technique)


def test_geometry_is_part_of_the_scene():
    plain = constant_scene()
    a = constant_scene(geometry=[square(4.0, 30.0, 2.0, 9.0, 6.5)])
    b = constant_scene(geometry=[square(4.0, 30.0, 2.0, 9.0, 6.5, color=(0.2, 0.6, 0.5))])
    assert len({plain.digest(), a.digest(), b.digest()}) == 3
    assert a.replace(width=32).geometry == a.geometry


# ---------------------------------------------------------------------------- front ends

@pytest.fixture
def sphere_file(tmp_path):
    """The CT head's sphere as an .obj file."""
    import meshio
    sphere = _head_scenes(8)["head"].geometry[0]
    path = tmp_path / "sphere.obj"
    meshio.write(str(path), meshio.Mesh(sphere.vertices, [("triangle", sphere.faces)]))
    return path, sphere


def test_load_surface_keeps_triangles_and_splits_quadrilaterals(tmp_path):
    import meshio
    from dvr_gl.formats import InputError, MissingFileError, load_surface
    points = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0]], float)
    path = tmp_path / "mixed.vtk"
    meshio.write(str(path), meshio.Mesh(points, [("quad", np.array([[0, 1, 2, 3]])), ("line", np.array([[0, 4]])),
                                                 ("triangle", np.array([[1, 4, 2]]))]))
    surface = load_surface(path, color=(0.1, 0.2, 0.3))
    assert surface.n_faces == 3 and tuple(surface.color) == (0.1, 0.2, 0.3)
    assert sorted(map(tuple, np.sort(surface.faces, axis=1))) == [(0, 1, 2), (0, 2, 3), (1, 2, 4)]
    lines = tmp_path / "lines.vtk"
    meshio.write(str(lines), meshio.Mesh(points, [("line", np.array([[0, 4]]))]))
    with pytest.raises(InputError, match="lines.vtk' holds no triangles or quadrilaterals"):
        load_surface(lines)
    with pytest.raises(MissingFileError):
        load_surface(tmp_path / "absent.obj")


def test_dvr_gl_render_takes_geometry(sphere_file):
    path, sphere = sphere_file
    head = _head_scenes(8)["head"].volume
    kwargs = dict(size=(48, 48), azimuth=30, elevation=20)
    image = dvr_gl.render(head, geometry=dvr_gl.Surface(sphere.vertices, sphere.faces), **kwargs)
    from_file = dvr_gl.render(head, geometry=[path], **kwargs)      # the same, default colour
    plain = dvr_gl.render(head, **kwargs)
    assert metrics.max_abs_error(image, from_file) < 1e-6
    assert metrics.max_abs_error(image, plain) > 0.3
    assert (image[..., 3] == 1).sum() > 100          # the sphere's pixels are opaque


def test_cli_render_and_view_take_geometry(renderer, sphere_file, tmp_path, capsys):
    from dvr_gl.frontends import cli
    from dvr_gl.frontends.viewer.settings import build_parser, settings_from_args
    path, sphere = sphere_file
    out = tmp_path / "head.png"
    argv = ["render", "builtin:ct_head", "--size", "32x32", "--out", str(out), "--geometry", str(path),
            "--geometry-color", "0.3,0.5,0.9", "--no-shading"]
    assert cli.main(argv) == 0, capsys.readouterr().err
    assert os.path.exists(out)
    args = build_parser().parse_args(["builtin:ct_head", "--geometry", str(path)])
    settings = settings_from_args(args)
    assert len(settings.geometry) == 1 and settings.geometry[0].n_faces == sphere.n_faces


@pytest.mark.parametrize("extra, fragment", [
    (["--technique", "splat"], "--geometry: is drawn by --technique raycast, "),
    (["--technique", "splat"], ", not splat"),
    (["--geometry-color", "2,0,0"], "--geometry-color"),
])
def test_cli_geometry_errors_name_the_option(sphere_file, tmp_path, capsys, monkeypatch, extra, fragment):
    from dvr_gl.frontends import cli
    from dvr_gl.techniques import common      # every technique draws geometry: take splat off the list
    monkeypatch.setattr(common, "GEOMETRY_TECHNIQUES", tuple(t for t in common.GEOMETRY_TECHNIQUES if t != "splat"))
    path, _ = sphere_file
    argv = ["render", "builtin:ct_head", "--size", "16x16", "--out", str(tmp_path / "x.png"),
            "--geometry", str(path)] + extra
    assert cli.main(argv) == 2
    assert fragment in capsys.readouterr().err
    assert not os.path.exists(tmp_path / "x.png")


def test_cli_geometry_file_without_triangles_names_the_file(tmp_path, capsys):
    import meshio
    from dvr_gl.frontends import cli
    bad = tmp_path / "points.vtk"
    meshio.write(str(bad), meshio.Mesh(np.eye(3), [("vertex", np.array([[0], [1], [2]]))]))
    assert cli.main(["render", "builtin:ct_head", "--size", "16x16", "--out", str(tmp_path / "x.png"),
                     "--geometry", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "--geometry" in err and "points.vtk" in err and "no triangles" in err
