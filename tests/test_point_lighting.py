"""Lighting the point primitives (particles and splats, ``Scene(shading=True)``): GL
against the NumPy references, the closed form of a field with one normal (the lit image
is the unlit one relit per pixel, grids and meshes), a constant field left unlit, and the
lit images converging to the exact lit image."""

import numpy as np
import pytest

import dvr_gl
from dvr_gl import Scene, metrics, reference
from dvr_gl import data as bundled
from dvr_gl.techniques import get_technique

from test_shading import RAMP_TF, planar_ramp, ramp_cameras, relit
from test_splat import bound as splat_bound

U32 = 2.0 ** -24


def lighting_error(scene):
    """What float32 lighting adds per pixel: the gradient is stored in float32 (relative
    error u) and N.L, N.H and the products carry ~16u more, so dN.L <= 20u and the colour
    moves by sum I (kd + ks n) dN.L, n the shininess."""
    ka, kd, ks, shininess = scene.phong
    return sum(light.intensity for light in scene.lights) * (kd + ks * shininess) * 20 * U32


def brightest(scene):
    """A lit colour is at most its colour times ka + kd sum I plus ks sum I."""
    ka, kd, ks, _ = scene.phong
    intensity = sum(light.intensity for light in scene.lights)
    return ka + (kd + ks) * intensity


def head_scene(camera=None, w=64, h=56, **kw):
    vol = bundled.ct_head()
    return Scene(vol, bundled.ct_head_tf(), camera or dvr_gl.default_camera(vol, azimuth=30, elevation=15), w, h,
                 shading=True, **kw)


def ball_scene(**kw):
    mesh = bundled.delaunay_ball()
    return Scene(mesh, bundled.synthetic_tf(), dvr_gl.default_camera(mesh, azimuth=20, elevation=10), 64, 64,
                 shading=True, **kw)


LIGHTS = (dvr_gl.Light((1.0, 0.5, 0.3)), dvr_gl.Light((-0.2, 1.0, 0.5), space="view", intensity=0.5))


@pytest.mark.parametrize("scene", ["head", "head_lights", "ball"])
def test_lit_particles_match_the_reference(renderer, scene):
    """As test_particles: the same particles, the first sphere per pixel; a pixel may pick
    another particle where two entries tie (0.2 % of the covered pixels allowed); the
    colour now also carries the lighting's float32 error."""
    scene = {"head": head_scene, "head_lights": lambda: head_scene(lights=LIGHTS), "ball": ball_scene}[scene]()
    opts = {"repetitions": 2, "seed": 1}
    gl = renderer.render(scene, technique="particles", **opts)
    ref = reference.render(scene, technique="particles", **opts)
    unlit = renderer.render(scene.replace(shading=False), technique="particles", **opts)
    assert metrics.max_abs_error(gl, unlit) > 0.05, "the light must change the picture"
    tol = 1e-6 + lighting_error(scene)
    differ = (np.abs(gl - ref).max(-1) > tol).sum()
    covered = (ref[..., 3] > 0).sum()
    assert covered > 50 and differ <= 0.002 * covered, (differ, covered)


@pytest.mark.parametrize("scene", ["head", "head_lights", "ball"])
def test_lit_splats_match_the_reference(renderer, scene):
    """test_splat's bound for the kernel (the tent's per pixel, the Gaussian splats'
    opacities), times the brightest lit colour, plus the lighting's own float32 error (the
    sheets' or splats' weights add up to at most 1)."""
    scene = {"head": head_scene, "head_lights": lambda: head_scene(lights=LIGHTS), "ball": ball_scene}[scene]()
    gl = renderer.render(scene, technique="splat")
    ref = reference.render(scene, technique="splat")
    plan = get_technique("splat").make_plan(scene)
    assert ref[..., 3].max() > 0.1
    assert metrics.max_abs_error(gl, renderer.render(scene.replace(shading=False), technique="splat")) > 0.05
    assert np.all(np.abs(gl - ref) <= splat_bound(scene, plan) * brightest(scene) + lighting_error(scene))


def linear_blocks(slope=5.0):
    from test_shading import linear_blocks as blocks
    return blocks(slope)


@pytest.mark.parametrize("technique,opts", [("particles", {"repetitions": 2}), ("splat", {}),
                                            ("splat", {"density": 2})], ids=str)
@pytest.mark.parametrize("camera", ["oblique", "opposite", "eye_inside"])
def test_one_normal_makes_the_lit_image_the_unlit_one_relit(renderer, technique, opts, camera):
    """On a planar ramp every point has a gradient along x (halved, not turned, at the
    faces), so a pixel's light depends on its ray alone: lit = D C + S A per pixel, D and
    S the headlight's terms for that ray; for particles and splats alike, since a pixel is
    a weighted sum of point colours whose weights add up to A."""
    volume = planar_ramp()
    assert_relit(renderer, Scene(volume, RAMP_TF, ramp_cameras(volume)[camera], width=40, height=32, shading=True),
                 technique, opts)


def assert_relit(renderer, scene, technique, opts):
    """The lit image is the unlit one relit per pixel, to float32 lighting."""
    lit = renderer.render(scene, technique=technique, **opts)
    unlit = renderer.render(scene.replace(shading=False), technique=technique, **opts)
    assert unlit[..., 3].max() > 0.3
    assert metrics.max_abs_error(lit, relit(unlit, scene)) <= 1e-5 + lighting_error(scene)


@pytest.mark.parametrize("technique", ["particles", "splat"])
def test_a_mesh_of_one_gradient_is_relit_too(renderer, technique):
    mesh = linear_blocks()
    camera = dvr_gl.default_camera(mesh, azimuth=35, elevation=25)
    tf = dvr_gl.TransferFunction(color=[(0, 1, 0.2, 0.1), (15, 0.1, 0.3, 1)], opacity=[(0, 0.3), (15, 0.8)],
                                 unit_distance=0.5)
    assert_relit(renderer, Scene(mesh, tf, camera, width=40, height=32, shading=True), technique,
                 {"repetitions": 2} if technique == "particles" else {})


@pytest.mark.parametrize("technique", ["particles", "splat"])
def test_a_constant_field_stays_unlit(renderer, technique):
    volume = dvr_gl.Volume(np.full((8, 9, 10), 30.0, np.float32), spacing=(1.0, 0.7, 1.2))
    scene = Scene(volume, RAMP_TF, dvr_gl.default_camera(volume, azimuth=30, elevation=20), 40, 32, shading=True)
    lit = renderer.render(scene, technique=technique)
    np.testing.assert_array_equal(lit, renderer.render(scene.replace(shading=False), technique=technique))
    assert lit[..., 3].max() > 0.3


def test_lit_particles_converge_to_the_exact_lit_image(renderer):
    """The lit particles' noise falls with the repetitions towards the exact lit image:
    RMSE at R = 16 below half of R = 1's (1/sqrt(16) = 1/4 for pure noise)."""
    scene = head_scene(w=48, h=48)
    exact = reference.exact(scene)
    errors = [metrics.rmse(renderer.render(scene, technique="particles", repetitions=r), exact) for r in (1, 16)]
    assert errors[1] < 0.5 * errors[0], errors


def test_lit_splats_add_no_error_of_their_own(renderer):
    """Lighting adds no error of its own to splatting. The tent's lit sheets are the lit
    midpoint rule at the sheets' distance: against the exact lit image within 1.1x of the
    ray caster at that step (a lit integrand varies more than an unlit one, so both
    errors are about three times their unlit ones). The Gaussian kernel's blur dominates
    both its errors: lit within 1.5x of unlit."""
    scene = head_scene(w=48, h=48)
    exact = reference.exact(scene)
    tent = metrics.rmse(renderer.render(scene, technique="splat"), exact)
    ray = metrics.rmse(renderer.render(scene, technique="raycast", step=scene.volume.min_spacing), exact)
    assert tent <= 1.1 * ray, (tent, ray)
    lit = metrics.rmse(renderer.render(scene, technique="splat", kernel="gaussian"), exact)
    plain = scene.replace(shading=False)
    unlit = metrics.rmse(renderer.render(plain, technique="splat", kernel="gaussian"), reference.exact(plain))
    assert lit <= 1.5 * unlit, (lit, unlit)


def test_points_refuse_what_they_do_not_model():
    scene = head_scene()
    for name in ("particles", "splat"):
        with pytest.raises(ValueError, match=f"{name} has no illustration terms yet"):
            get_technique(name).make_plan(scene.replace(illustration="tone"))
