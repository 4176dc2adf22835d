"""Shaded emission-absorption (contract section 6) in ray casting, 3D and 2D slicing: GL
against the NumPy references with a derived bound, closed forms of a planar ramp (exact
and GL), the hard cases (zero gradient, gradient orthogonal to the view, light behind the
surface), convergence against the exact integrator, and what a lit scene compiles and
allocates."""

import math

import numpy as np
import pytest

import dvr_gl
from dvr_gl import metrics, reference
from dvr_gl.data.phantoms import marschner_lobb, marschner_lobb_tf
from dvr_gl.model.field import trilinear, world_to_index
from dvr_gl.model.field import gradient, sample_gradients
from dvr_gl.techniques import get_technique

from test_raycast import cameras, derived_tolerance
from test_slicing import preintegrated_tolerance, slice_tolerance

U32 = 2.0 ** -24
W, H = 40, 32
RAMP_DIRECTION = np.array([40.0, 30.0, 20.0])   # world units per unit of the box


def tilted_ramp(shape=(16, 20, 24), spacing=(1.0, 0.8, 1.3), origin=(5.0, -2.0, 1.0)):
    """A ramp with ripples whose gradient never vanishes: its component along the ramp's
    direction is bounded away from 0 (the bound is computed in the test from the samples)."""
    nz, ny, nx = shape
    z, y, x = np.meshgrid(np.linspace(0, 1, nz), np.linspace(0, 1, ny), np.linspace(0, 1, nx), indexing="ij")
    a, b, c = RAMP_DIRECTION
    f = a * x + b * y + c * z + 4.0 * np.sin(7 * x + 3 * y) * np.cos(5 * z)
    return dvr_gl.Volume(f.astype(np.float32), spacing=spacing, origin=origin)


RAMP = tilted_ramp()
TF = dvr_gl.TransferFunction(color=[(0, 0.9, 0.3, 0.1), (40, 0.3, 0.9, 0.4), (90, 0.2, 0.4, 1.0)],
                             opacity=[(0, 0.0), (20, 0.3), (45, 0.05), (70, 0.5), (90, 0.1)], unit_distance=1.0)


def gradient_floor(volume):
    """A lower bound of |g| over the whole box: the gradient is the trilinear interpolant
    of the samples' gradients (``sample_gradients``), so its component along any fixed
    direction is at least the smallest of the samples' components."""
    g = sample_gradients(volume, volume.values(np.float64))
    u = RAMP_DIRECTION / volume.extent
    u /= np.linalg.norm(u)
    return float((g @ u).min())


def lit_tolerance(plan, unlit, g_floor):
    """Bound on |GL - reference| of a lit image, from the unlit bound ``unlit`` of the same
    plan. A lit associated colour is ``c a D + a S`` with D = ka + kd sum I |N.L| and
    S = ks sum I |N.H|^n (sums over the lights, intensities I), so value and table errors
    cost at most ka + (kd + ks) sum I times the unlit bound. On top, N.L and N.H move by at
    most 2 |dg| / |g| + 16u (L, H are exact), with |dg| from each of the six
    field lookups' value error over 2 spacings, the texture unit's position rounding on
    the gradient's own interpolant (4u * n * its largest jump) and its float32 storage.
    Sample i's colour then moves by at most a_i T_i sum I (kd + ks n) dN.L, and the weights
    a_i T_i of a ray add up to its opacity, at most 1."""
    ka, kd, ks, shininess = plan.scene.phong
    intensity = sum(light.intensity for light in plan.scene.lights)
    dndl = 2 * gradient_error(plan) / g_floor + 16 * U32
    return (ka + (kd + ks) * intensity) * unlit + intensity * (kd + ks * shininess) * dndl


def gradient_error(plan):
    """Bound on |g_GL - g| (see ``lit_tolerance``)."""
    v = plan.scene.volume
    vals = v.values()
    jump = max(float(np.abs(np.diff(vals, axis=a)).max()) for a in range(3))
    value_err = 4 * U32 * float(v.dims.max()) * jump + 16 * U32 * float(np.abs(vals).max())
    g = sample_gradients(v, vals.astype(np.float64))
    g_jump = max(float(np.abs(np.diff(g, axis=a)).max()) for a in range(3))
    return math.sqrt(3) * (value_err / v.min_spacing + 4 * U32 * float(v.dims.max()) * g_jump
                           + 16 * U32 * float(np.abs(g).max()))


VARIANTS = [("raycast", {"step": 0.7, "ert_transmittance": 0.0}), ("slice3d", {"step": 0.7}),
            ("slice3d", {"step": 0.7, "shells": True}), ("slice2d", {}), ("slice2d", {"interpolate": 1})]


@pytest.mark.parametrize("technique,opts", VARIANTS, ids=lambda v: str(v))
@pytest.mark.parametrize("classify", ["midpoint", "preintegrate"])
@pytest.mark.parametrize("gradients", ["on_the_fly", "texture"])
@pytest.mark.parametrize("camera", ["perspective", "ortho", "eye_inside"])
def test_gl_matches_reference(renderer, technique, opts, classify, gradients, camera):
    scene = dvr_gl.Scene(RAMP, TF, cameras(RAMP)[camera], width=W, height=H, shading=True)
    opts = dict(opts, gradients=gradients, preintegrate=classify == "preintegrate")
    gl = renderer.render(scene, technique=technique, **opts)
    ref = reference.render(scene, technique=technique, **opts)
    plan = get_technique(technique).make_plan(scene, **opts)
    assert ref[..., 3].max() > 0.05, "the scene must show something"
    unlit = renderer.render(scene.replace(shading=False), technique=technique, **opts)
    assert metrics.max_abs_error(gl, unlit) > 0.05, "the light must change the picture"
    if technique == "raycast":
        unlit_bound = (preintegrated_tolerance(plan, plan.max_segments) if plan.preint is not None
                       else derived_tolerance(plan))
    else:
        unlit_bound = (preintegrated_tolerance(plan, 2 * plan.count) if plan.preint is not None
                       else slice_tolerance(plan))
    assert metrics.max_abs_error(gl, ref) <= lit_tolerance(plan, unlit_bound, gradient_floor(RAMP))


# -- closed forms: a planar ramp has one normal, so each pixel's light is a constant ---------

def planar_ramp(axis=0, shape=(10, 12, 14), spacing=(0.9, 1.1, 0.7), slope=5.0):
    """f = slope * (world coordinate along ``axis``): the gradient points along that axis
    everywhere, also in the cells at the box faces, where clamping shortens it."""
    nz, ny, nx = shape
    coords = np.meshgrid(np.arange(nz) * spacing[2], np.arange(ny) * spacing[1], np.arange(nx) * spacing[0],
                         indexing="ij")[::-1]
    return dvr_gl.Volume((slope * coords[axis]).astype(np.float32), spacing=spacing, origin=(1.0, 2.0, 3.0))


RAMP_TF = dvr_gl.TransferFunction(color=[(0, 1, 0.2, 0.1), (30, 0.2, 0.9, 0.5), (60, 0.1, 0.3, 1)],
                                  opacity=[(0, 0.05), (25, 0.4), (40, 0.1), (60, 0.6)])


def ramp_cameras(volume):
    lo, hi = volume.bounds
    centre = (lo + hi) / 2
    return {
        "oblique": dvr_gl.default_camera(volume, azimuth=40, elevation=25),
        # the light from behind the lit face: two-sided shading gives the same factor
        "opposite": dvr_gl.default_camera(volume, azimuth=220, elevation=-25),
        # every ray at right angles to the gradient: N.L = 0, ambient only
        "orthogonal": dvr_gl.Camera(centre + [0, 0, 50], centre, ortho_height=20.0),
        "eye_inside": dvr_gl.Camera(centre + [1.0, 0.5, 0.2], centre - [3.0, 1.0, 1.0], fov=70),
    }


def relit(unlit, scene):
    """The unlit image lit by the headlight for a gradient along x: per pixel N.L is
    |dir_x|, so C_lit = D C + S A with D = ka + kd N.L and S = ks (N.L)^n."""
    ka, kd, ks, shininess = scene.phong
    _, dirs = scene.camera.rays(scene.width, scene.height)
    ndl = np.abs(dirs[..., 0])
    out = np.array(unlit, np.float64, copy=True)
    out[..., :3] = unlit[..., :3] * (ka + kd * ndl)[..., None] + (ks * ndl ** shininess)[..., None] * unlit[..., 3:4]
    return out


@pytest.mark.parametrize("camera", ["oblique", "opposite", "orthogonal", "eye_inside"])
def test_exact_lit_ramp_is_the_unlit_image_relit(camera):
    """The exact integrator lights every quadrature node with the gradient there; on a
    planar ramp that is the closed form of the unlit exact image relit (to its own
    accuracy, 1e-11)."""
    volume = planar_ramp()
    scene = dvr_gl.Scene(volume, RAMP_TF, ramp_cameras(volume)[camera], width=W, height=H, shading=True)
    lit = reference.exact(scene, cache=False)
    unlit = reference.exact(scene.replace(shading=False), cache=False)
    assert unlit[..., 3].max() > 0.3
    np.testing.assert_allclose(lit, relit(unlit, scene), rtol=0, atol=1e-11)
    if camera == "orthogonal":
        np.testing.assert_allclose(lit[..., :3], scene.phong[0] * unlit[..., :3], rtol=0, atol=1e-11)


@pytest.mark.parametrize("technique,opts", [("raycast", {"step": 0.3, "ert_transmittance": 0.0}),
                                            ("slice3d", {"step": 0.3}), ("slice2d", {}),
                                            ("raycast", {"step": 0.3, "preintegrate": True,
                                                         "ert_transmittance": 0.0})],
                         ids=lambda v: str(v))
@pytest.mark.parametrize("camera", ["oblique", "opposite", "orthogonal", "eye_inside"])
def test_gl_lit_ramp_is_its_unlit_image_relit(renderer, technique, opts, camera):
    """The same relation holds for every technique's own image: each sample's colour is
    c D + S in float32 (a few units of rounding, 8u with the products), accumulated over
    at most all of the plan's segments with weights <= 1 and colours <= 1 + ks."""
    volume = planar_ramp()
    scene = dvr_gl.Scene(volume, RAMP_TF, ramp_cameras(volume)[camera], width=W, height=H, shading=True)
    lit = renderer.render(scene, technique=technique, **opts)
    unlit = renderer.render(scene.replace(shading=False), technique=technique, **opts)
    plan = get_technique(technique).make_plan(scene, **opts)
    segments = plan.max_segments if technique == "raycast" else 2 * plan.count + 2 * 4096 // plan.count
    assert unlit[..., 3].max() > 0.3
    assert metrics.max_abs_error(lit, relit(unlit, scene)) <= 8 * U32 * (1 + scene.phong[2]) * segments


@pytest.mark.parametrize("technique,opts", [("raycast", {"step": 0.5}), ("slice3d", {"step": 0.5}),
                                            ("slice2d", {}), ("raycast", {"gradients": "texture"})],
                         ids=lambda v: str(v))
def test_zero_gradient_leaves_samples_unlit(renderer, technique, opts):
    """A constant field has no gradient: every sample keeps its colour, bit for bit, and
    the exact image is the unlit one."""
    volume = dvr_gl.Volume(np.full((8, 9, 10), 30.0, np.float32), spacing=(1.0, 0.7, 1.2))
    scene = dvr_gl.Scene(volume, RAMP_TF, dvr_gl.default_camera(volume, azimuth=30, elevation=20),
                         width=W, height=H, shading=True)
    lit = renderer.render(scene, technique=technique, **opts)
    unlit = renderer.render(scene.replace(shading=False), technique=technique, **opts)
    assert unlit[..., 3].max() > 0.3
    np.testing.assert_array_equal(lit, unlit)
    np.testing.assert_allclose(reference.exact(scene, cache=False),
                               reference.exact(scene.replace(shading=False), cache=False), rtol=0, atol=1e-14)


# -- lights ----------------------------------------------------------------------------------

LIGHTS = (dvr_gl.Light((1.0, 1.0, 0.5)), dvr_gl.Light((-0.3, 0.2, 1.0), space="view", intensity=0.6))


@pytest.mark.parametrize("technique,opts", VARIANTS, ids=lambda v: str(v))
@pytest.mark.parametrize("camera", ["perspective", "ortho", "eye_inside"])
def test_gl_matches_reference_with_lights(renderer, technique, opts, camera):
    """A world light and a dimmer view-space light, GL against the reference."""
    scene = dvr_gl.Scene(RAMP, TF, cameras(RAMP)[camera], width=W, height=H, shading=True, lights=LIGHTS)
    gl = renderer.render(scene, technique=technique, **opts)
    ref = reference.render(scene, technique=technique, **opts)
    plan = get_technique(technique).make_plan(scene, **opts)
    assert plan.defines.get("LIGHTS") == 1
    headlight = renderer.render(scene.replace(lights=dvr_gl.Light()), technique=technique, **opts)
    assert metrics.max_abs_error(gl, headlight) > 0.05, "the lights must change the picture"
    unlit_bound = derived_tolerance(plan) if technique == "raycast" else slice_tolerance(plan)
    assert metrics.max_abs_error(gl, ref) <= lit_tolerance(plan, unlit_bound, gradient_floor(RAMP))


def relit_by(unlit, scene, direction, intensity):
    """The planar x-ramp's unlit image lit by one directional light towards ``direction``
    (world, unit): |N.L| = |L_x| everywhere, H per pixel from L and the pixel's ray."""
    ka, kd, ks, shininess = scene.phong
    _, dirs = scene.camera.rays(scene.width, scene.height)
    h = direction - dirs
    ndh = np.abs(h[..., 0]) / np.linalg.norm(h, axis=-1)
    out = np.array(unlit, np.float64, copy=True)
    out[..., :3] = (unlit[..., :3] * (ka + kd * intensity * abs(direction[0]))
                    + (ks * intensity * ndh ** shininess)[..., None] * unlit[..., 3:4])
    return out


@pytest.mark.parametrize("camera", ["oblique", "opposite", "eye_inside"])
def test_a_world_light_on_a_ramp_is_the_unlit_image_relit(renderer, camera):
    """Closed form for a directional light: exact to 1e-11, GL to float32 rounding."""
    volume = planar_ramp()
    direction = np.array([0.6, 0.48, 0.64])
    light = dvr_gl.Light(direction, intensity=0.8)
    scene = dvr_gl.Scene(volume, RAMP_TF, ramp_cameras(volume)[camera], width=W, height=H, shading=True,
                         lights=light)
    unlit = reference.exact(scene.replace(shading=False), cache=False)
    np.testing.assert_allclose(reference.exact(scene, cache=False), relit_by(unlit, scene, direction, 0.8),
                               rtol=0, atol=1e-11)
    opts = {"step": 0.3, "ert_transmittance": 0.0}
    gl = renderer.render(scene, **opts)
    gl_unlit = renderer.render(scene.replace(shading=False), **opts)
    segments = get_technique("raycast").make_plan(scene, **opts).max_segments
    assert metrics.max_abs_error(gl, relit_by(gl_unlit, scene, direction, 0.8)) <= 8 * U32 * 2 * segments


def test_a_view_light_along_the_view_is_the_headlight_in_orthographic_views(renderer):
    """View-space (0, 0, 1) points back along every orthographic ray: the headlight."""
    scene = dvr_gl.Scene(RAMP, TF, cameras(RAMP)["ortho"], width=W, height=H, shading=True)
    view = scene.replace(lights=dvr_gl.Light((0, 0, 1), space="view"))
    assert view.digest() != scene.digest()
    assert metrics.max_abs_error(renderer.render(view), renderer.render(scene)) <= 1e-5
    np.testing.assert_allclose(reference.render(view), reference.render(scene), rtol=0, atol=1e-12)


# -- accuracy against exact ------------------------------------------------------------------

def marschner_lobb_scene(size=64, **options):
    """The Marschner-Lobb phantom, oblique, with the scene options given."""
    volume = marschner_lobb(41)
    return dvr_gl.Scene(volume, marschner_lobb_tf(), dvr_gl.default_camera(volume, azimuth=30, elevation=20),
                        width=size, height=size, **options)


def lit_marschner_lobb(size=64):
    return marschner_lobb_scene(size, shading=True)


def errors_as_the_step_halves(renderer, scene, steps=(1.0, 0.5, 0.25, 0.125), technique="raycast"):
    """RMSE against the exact image at each step (voxels), and the observed orders; the
    errors must fall at every halving."""
    exact = reference.exact(scene)
    h = scene.volume.min_spacing
    opts = {"ert_transmittance": 0.0} if technique == "raycast" else {}
    errors = [metrics.rmse(renderer.render(scene, technique, step=k * h, **opts), exact) for k in steps]
    assert all(e1 < e0 for e0, e1 in zip(errors, errors[1:])), errors
    return errors, np.log2(np.array(errors[:-1]) / np.array(errors[1:]))


@pytest.mark.parametrize("technique", ["raycast", "slice3d"])
def test_lit_quarter_voxel_is_as_accurate_as_an_ideal_marcher(renderer, technique):
    """Acceptance: at 0.25 voxel, within 1.5x the error of the float64 midpoint marcher
    with the exact transfer function and the same gradient rule; and second order over
    four halvings of the step."""
    scene = lit_marschner_lobb()
    h = scene.volume.min_spacing
    ideal = metrics.rmse(reference.render(scene, "raycast", step=0.25 * h, lut_exact=True, ert_transmittance=0.0),
                         reference.exact(scene))
    errors, orders = errors_as_the_step_halves(renderer, scene, (1.0, 0.5, 0.25, 0.125, 0.0625), technique)
    assert errors[2] <= 1.5 * ideal, (errors[2], ideal)
    assert orders.mean() > 1.7, orders


def test_exact_lit_agrees_with_a_fine_float64_marcher():
    """The exact integrator's lit image, against the float64 midpoint marcher at 1/32 and
    1/64 voxel: the marcher's error falls by 4x per halving towards it (second order),
    so both converge to the same image."""
    scene = lit_marschner_lobb(24)
    h = scene.volume.min_spacing
    exact = reference.exact(scene, cache=False)
    errors = [metrics.rmse(reference.render(scene, "raycast", step=k * h, lut_exact=True, ert_transmittance=0.0),
                           exact) for k in (1 / 16, 1 / 32, 1 / 64)]
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert errors[-1] < 5e-6 and np.all(orders > 1.8), (errors, orders)


# -- gradients: the texture holds the same gradient ------------------------------------------

def test_interpolated_sample_gradients_are_the_contract_gradient():
    """Trilinear interpolation of the samples' central differences is the central
    difference of the trilinear field, at any point, the clamped faces included."""
    rng = np.random.default_rng(3)
    volume = dvr_gl.Volume(rng.random((6, 7, 8)).astype(np.float32) * 50, spacing=(1.0, 0.6, 1.4),
                           origin=(2.0, -1.0, 0.5))
    values = volume.values(np.float64)
    lo, hi = volume.bounds
    points = lo + rng.random((4000, 3)) * (hi - lo)
    points[:500, 0] = lo[0]                          # on the faces and in their cells
    points[500:1000, 2] = hi[2] - 1e-3 * rng.random(500)
    g = sample_gradients(volume, values)
    idx = world_to_index(volume, points)
    interpolated = np.stack([trilinear(g[..., a], idx) for a in range(3)], axis=-1)
    np.testing.assert_allclose(interpolated, gradient(volume, values, points), rtol=0, atol=1e-12)


def test_a_lit_scene_compiles_and_allocates_only_what_it_uses():
    """Unlit scenes compile no shading and make no gradient texture; the texture exists
    only for gradients='texture' on a lit scene, once per volume."""
    from dvr_gl import Renderer
    scene = dvr_gl.Scene(RAMP, TF, cameras(RAMP)["perspective"], width=16, height=16)
    lit = scene.replace(shading=True)
    for name in ("raycast", "slice3d", "slice2d"):
        tech = get_technique(name)
        assert not {"SHADING", "GRADIENT_TEXTURE"} & set(tech.make_plan(scene, gradients="texture").defines)
        assert tech.make_plan(lit).defines.get("SHADING") == 1
        assert "GRADIENT_TEXTURE" not in tech.make_plan(lit).defines
        assert tech.make_plan(lit, gradients="texture").defines.get("GRADIENT_TEXTURE") == 1
    with Renderer() as r:
        r.render(scene, gradients="texture")
        r.render(lit)
        assert not [c for c in r.created if c[0] == "gradient"]
        r.render(lit, gradients="texture")
        r.render(lit, technique="slice3d", gradients="texture")
        assert [c for c in r.created if c[0] == "gradient"] == [("gradient", ("Volume",))]


def test_shading_is_refused_where_it_is_not_defined():
    with pytest.raises(ValueError, match="gradients must be one of on_the_fly, texture, got 'sobel'"):
        get_technique("raycast").make_plan(dvr_gl.Scene(RAMP, TF, cameras(RAMP)["perspective"], shading=True),
                                           gradients="sobel")
    lit = dvr_gl.Scene(RAMP, TF, cameras(RAMP)["perspective"], width=16, height=16, shading=True)
    for name in ("particles", "splat"):     # the point primitives light each point (test_point_lighting)
        assert get_technique(name).make_plan(lit).defines.get("SHADING") == 1
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    mesh = dvr_gl.TetMesh(points, np.array([[0, 1, 2, 3]]), np.array([0.0, 1.0, 2.0, 3.0]))
    mesh_scene = dvr_gl.Scene(mesh, TF, dvr_gl.default_camera(mesh), width=16, height=16, shading=True)
    assert get_technique("tetra").make_plan(mesh_scene).defines.get("SHADING") == 1   # cells light
    assert get_technique("tetra").make_plan(mesh_scene.replace(illustration="tone")).defines.get("TONE") == 1
    assert get_technique("tetra").make_plan(mesh_scene.replace(illustration="depth_cue")).defines.get("DEPTH_CUE") == 1
    with pytest.raises(ValueError, match="tetra integrates depth_cue along each cell's segment"):
        get_technique("tetra").make_plan(mesh_scene.replace(illustration="depth_cue", shading=False,
                                                            optical_model="emission"))


# -- meshes: each cell lit with its own (constant) gradient ----------------------------------

def linear_blocks(slope=5.0):
    """Unit cubes (3 x 2 x 2, Kuhn split) carrying f = slope * x: every cell has the
    gradient (slope, 0, 0)."""
    from test_tetra import blocks_mesh
    cubes = blocks_mesh([(x, y, z) for x in range(3) for y in range(2) for z in range(2)])
    return dvr_gl.TetMesh(cubes.points, cubes.tets, slope * cubes.points[:, 0])


MESH_TF = dvr_gl.TransferFunction(color=[(0, 1, 0.2, 0.1), (15, 0.1, 0.3, 1)], opacity=[(0, 0.1), (15, 0.5)],
                                  unit_distance=1.0)


@pytest.mark.parametrize("view", ["perspective", "opposite", "eye_inside"])
def test_a_lit_mesh_of_a_linear_field_is_its_unlit_image_relit(renderer, view):
    """One gradient everywhere: exact (1e-11) and projected tetrahedra (float32 of the
    products) both equal their unlit image relit per pixel."""
    mesh = linear_blocks()
    lo, hi = mesh.bounds
    centre = (lo + hi) / 2
    camera = {"perspective": dvr_gl.default_camera(mesh, azimuth=40, elevation=25),
              "opposite": dvr_gl.default_camera(mesh, azimuth=220, elevation=-25),
              "eye_inside": dvr_gl.Camera(centre + [0.3, 0.2, 0.1], centre - [2.0, 0.5, 1.0], fov=70)}[view]
    scene = dvr_gl.Scene(mesh, MESH_TF, camera, width=W, height=H, shading=True)
    exact_lit = reference.exact(scene, cache=False)
    exact_unlit = reference.exact(scene.replace(shading=False), cache=False)
    assert exact_unlit[..., 3].max() > 0.3
    np.testing.assert_allclose(exact_lit, relit(exact_unlit, scene), rtol=0, atol=1e-11)
    gl = renderer.render(scene, "tetra")
    gl_unlit = renderer.render(scene.replace(shading=False), "tetra")
    assert metrics.max_abs_error(gl, relit(gl_unlit, scene)) <= 8 * U32 * (1 + scene.phong[2]) * 12


def test_a_lit_mesh_matches_its_reference(renderer):
    """The Delaunay ball lit, with a world light beside the headlight: GL against the
    reference within test_tetra's bound times the largest lit colour (ka + (kd + ks) sum I),
    plus the normal's float32 error (the cells' gradients are stored as float32: a few
    1e-7 relative, times kd + ks n); and the exact image agrees as closely."""
    from dvr_gl.data import delaunay_ball, synthetic_tf
    from test_tetra import GL_TOL
    mesh = delaunay_ball()
    scene = dvr_gl.Scene(mesh, synthetic_tf(), dvr_gl.default_camera(mesh, azimuth=30, elevation=20), width=48,
                         height=48, shading=True, lights=(dvr_gl.Light(), dvr_gl.Light((1, 1, 0), intensity=0.5)))
    gl = renderer.render(scene, "tetra")
    ref = reference.render(scene, "tetra")
    ka, kd, ks, n = scene.phong
    bound = GL_TOL * (ka + (kd + ks) * 1.5) + 1.5 * (kd + ks * n) * 4e-7
    assert metrics.max_abs_error(gl, renderer.render(scene.replace(shading=False), "tetra")) > 0.05
    assert metrics.max_abs_error(gl, ref) <= bound
    assert metrics.max_abs_error(ref, reference.exact(scene, cache=False)) <= bound


@pytest.mark.parametrize("term", ["boundary", "silhouette"])
def test_a_mesh_cells_extinction_scale_is_a_shorter_unit_distance(renderer, term):
    """The linear blocks, orthographic: |g| is the slope (the largest gradient) in every
    cell and |n.V| one number, so the scale m is one number: the image is the plain one
    with unit distance u / m (exact to 1e-11; GL to float32 over at most 12 cells)."""
    mesh = linear_blocks()
    lo, hi = mesh.bounds
    centre = (lo + hi) / 2
    camera = dvr_gl.Camera(centre + np.array([20.0, 9.0, 15.0]), centre, ortho_height=6.0)
    kc, ks, ke = 0.3, 0.9, 2.0
    m = kc + ks * (1.0 if term == "boundary" else (1 - abs(camera.forward[0]))) ** ke
    scene = dvr_gl.Scene(mesh, MESH_TF, camera, width=W, height=H, illustration={term: (kc, ks, ke)})
    tf_short = dvr_gl.TransferFunction(MESH_TF.color_points, MESH_TF.opacity_points,
                                       unit_distance=MESH_TF.unit_distance / m)
    shorter = scene.replace(tf=tf_short, illustration=None)
    expected = reference.exact(shorter, cache=False)
    assert expected[..., 3].max() > 0.3
    np.testing.assert_allclose(reference.exact(scene, cache=False), expected, rtol=0, atol=1e-11)
    assert metrics.max_abs_error(renderer.render(scene, "tetra"), renderer.render(shorter, "tetra")) <= 64 * U32 * 12


def test_mesh_tone_and_terms_match_the_reference(renderer):
    """Tone, boundary and silhouette with the light on the Delaunay ball: GL against the
    reference (as the lit case, with the extinction scale's float32 error), and the
    reference against the exact image."""
    from dvr_gl.data import delaunay_ball, synthetic_tf
    from test_tetra import GL_TOL
    mesh = delaunay_ball()
    scene = dvr_gl.Scene(mesh, synthetic_tf(), dvr_gl.default_camera(mesh, azimuth=30, elevation=20), width=48,
                         height=48, shading=True, illustration=("boundary", "silhouette", "tone"))
    gl = renderer.render(scene, "tetra")
    ref = reference.render(scene, "tetra")
    ka, kd, ks, n = scene.phong
    colour = ka + kd + ks + 0.4      # the brightest lit colour plus the tone's warmest channel
    bound = GL_TOL * colour + (kd + ks * n) * 4e-7 + (2 * colour + 1 / math.e) * 1e-6
    assert metrics.max_abs_error(gl, renderer.render(scene.replace(illustration=None), "tetra")) > 0.02
    assert metrics.max_abs_error(gl, ref) <= bound
    assert metrics.max_abs_error(ref, reference.exact(scene, cache=False)) <= bound
