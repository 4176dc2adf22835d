"""Composite mode's optical models (Max 1995): absorption only and emission only beside
the default emission-absorption, in raycast, slice3d and slice2d. Closed forms of a
constant box (exact and GL), GL against the references with a derived bound, convergence
against the exact image, and the refusals."""

import math

import numpy as np
import pytest

import dvr_gl
from dvr_gl import metrics, reference
from dvr_gl.reference.common import box_rays
from dvr_gl.techniques import get_technique

from test_raycast import derived_tolerance
from test_slicing import slice_tolerance
from test_shading import RAMP, TF, cameras, errors_as_the_step_halves, marschner_lobb_scene

U32 = 2.0 ** -24
W, H = 40, 32
MODELS = ["absorption", "emission"]
TECHNIQUES = [("raycast", {"step": 0.5, "ert_transmittance": 0.0}), ("slice3d", {"step": 0.5}),
              ("slice3d", {"step": 0.5, "shells": True}), ("slice2d", {}), ("slice2d", {"interpolate": 1})]

COLOUR = np.array([0.2, 0.5, 0.9])
ALPHA, UNIT = 0.3, 2.0
BOX_TF = dvr_gl.TransferFunction(color=[(0, *COLOUR), (100, *COLOUR)], opacity=[(0, ALPHA), (100, ALPHA)],
                                 unit_distance=UNIT)


def constant_box():
    return dvr_gl.Volume(np.full((8, 9, 10), 50.0, np.float32), spacing=(1.0, 0.7, 1.2), origin=(3.0, -1.0, 2.0))


def box_cameras(volume):
    lo, hi = volume.bounds
    centre = (lo + hi) / 2
    return {"perspective": dvr_gl.default_camera(volume, azimuth=30, elevation=20),
            "ortho": dvr_gl.default_camera(volume, azimuth=-40, elevation=15, ortho=True),
            "eye_inside": dvr_gl.Camera(centre + [1.0, 0.5, 0.3], centre - [2.0, 1.0, 3.0], fov=70)}


def closed_form(scene):
    """A constant box seen along each pixel's chord L: absorption only (0, 1 - e^(-tau L)),
    emission only (c tau L, 0)."""
    _, _, t0, t1 = box_rays(scene)
    chord = np.maximum(t1 - t0, 0).reshape(scene.height, scene.width)
    tau = -math.log(1 - ALPHA) / UNIT
    out = np.zeros((scene.height, scene.width, 4))
    if scene.optical_model == "absorption":
        out[..., 3] = -np.expm1(-tau * chord)
    else:
        out[..., :3] = COLOUR * (tau * chord)[..., None]
    return out


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("camera", ["perspective", "ortho", "eye_inside"])
def test_exact_constant_box_is_the_closed_form(model, camera):
    volume = constant_box()
    scene = dvr_gl.Scene(volume, BOX_TF, box_cameras(volume)[camera], width=W, height=H, optical_model=model)
    expected = closed_form(scene)
    assert expected.max() > 0.3
    np.testing.assert_allclose(reference.exact(scene, cache=False), expected, rtol=0, atol=1e-12)


@pytest.mark.parametrize("technique,opts", TECHNIQUES, ids=lambda v: str(v))
@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("camera", ["perspective", "ortho", "eye_inside"])
def test_gl_constant_box_is_the_closed_form(renderer, technique, opts, model, camera):
    """A constant field makes every sample exact: only float32 arithmetic is left, at most
    64u relative per segment (opacity correction, log, products), added over the plan's
    segments, on values of at most the largest closed-form channel (or 1)."""
    volume = constant_box()
    scene = dvr_gl.Scene(volume, BOX_TF, box_cameras(volume)[camera], width=W, height=H, optical_model=model)
    gl = renderer.render(scene, technique=technique, **opts)
    expected = closed_form(scene)
    plan = get_technique(technique).make_plan(scene, **opts)
    segments = plan.max_segments if technique == "raycast" else 2 * plan.count + 2 * 4096 // plan.count
    assert metrics.max_abs_error(gl, expected) <= 64 * U32 * segments * max(1.0, expected.max())


def emission_tolerance(plan):
    """Bound on |GL - reference| for emission only. A segment L long emits c tau L with
    tau = -ln(1 - alpha) / u: a value error dv moves c and alpha by at most the table's
    slope times dv (plus the table index error, as for the lookup table), and tau by
    d(alpha) / (1 - alpha_max) / u; float32 adds 64u relative. Nothing absorbs, so errors
    add over the segments, whose lengths add up to at most the box diagonal."""
    scene = plan.scene
    v = scene.volume
    vals = v.values()
    jump = max(float(np.abs(np.diff(vals, axis=a)).max()) for a in range(3))
    value_err = 4 * U32 * float(v.dims.max()) * jump + 16 * U32 * float(np.abs(vals).max())
    table = plan.lut.table.astype(np.float64)
    slope = float(np.abs(np.diff(table, axis=0)).max()) * plan.lut.scale
    d_entry = slope * value_err + 2 * U32 * plan.lut.size * slope / plan.lut.scale
    alpha_max = float(table[:, 3].max())
    tau_max = -math.log1p(-alpha_max) / scene.tf.unit_distance
    per_length = d_entry * (tau_max + 1 / (1 - alpha_max) / scene.tf.unit_distance) + 64 * U32 * tau_max
    return per_length * float(np.linalg.norm(v.extent))


@pytest.mark.parametrize("technique,opts", TECHNIQUES, ids=lambda v: str(v))
@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("camera", ["perspective", "ortho", "eye_inside"])
def test_gl_matches_reference(renderer, technique, opts, model, camera):
    scene = dvr_gl.Scene(RAMP, TF, cameras(RAMP)[camera], width=W, height=H, optical_model=model)
    gl = renderer.render(scene, technique=technique, **opts)
    ref = reference.render(scene, technique=technique, **opts)
    plan = get_technique(technique).make_plan(scene, **opts)
    assert np.abs(ref).max() > 0.05, "the scene must show something"
    if model == "absorption":
        assert np.all(gl[..., :3] == 0)
        bound = derived_tolerance(plan) if technique == "raycast" else slice_tolerance(plan)
    else:
        assert np.all(gl[..., 3] == 0)
        bound = emission_tolerance(plan)
    assert metrics.max_abs_error(gl, ref) <= bound


def test_lit_emission_matches_reference(renderer):
    """Emission only lit by the headlight: the colour is lit before it is weighted by
    tau L, so the specular term glows too."""
    scene = dvr_gl.Scene(RAMP, TF, cameras(RAMP)["perspective"], width=W, height=H, optical_model="emission",
                         shading=True)
    opts = {"step": 0.5, "ert_transmittance": 0.0}
    gl = renderer.render(scene, **opts)
    ref = reference.render(scene, **opts)
    unlit = renderer.render(scene.replace(shading=False), **opts)
    assert metrics.max_abs_error(gl, unlit) > 0.05
    assert metrics.max_abs_error(gl, ref) <= 1e-4 * max(1.0, float(ref.max()))


@pytest.mark.parametrize("model", MODELS)
def test_error_against_exact_is_second_order(renderer, model):
    _, orders = errors_as_the_step_halves(renderer, marschner_lobb_scene(48, optical_model=model))
    assert orders.mean() > 1.7, orders


def test_the_models_are_refused_where_they_are_not_defined():
    camera = cameras(RAMP)["perspective"]
    opaque = dvr_gl.TransferFunction(color=[(0, 1, 1, 1), (90, 1, 1, 1)], opacity=[(0, 0.0), (60, 1.0)])
    with pytest.raises(ValueError, match="optical_model must be one of emission_absorption, absorption, emission"):
        dvr_gl.Scene(RAMP, TF, camera, optical_model="scattering")
    with pytest.raises(ValueError, match="optical_model='emission' needs opacities below 1 .* at s = 60"):
        dvr_gl.Scene(RAMP, opaque, camera, optical_model="emission")
    with pytest.raises(ValueError, match="nothing to light"):
        dvr_gl.Scene(RAMP, TF, camera, optical_model="absorption", shading=True)
    with pytest.raises(ValueError, match="optical_model applies to mode 'composite'"):
        dvr_gl.Scene(RAMP, TF, camera, mode="mip", optical_model="emission")
    scene = dvr_gl.Scene(RAMP, TF, camera, width=16, height=16, optical_model="emission")
    with pytest.raises(ValueError, match="preintegrate tables emission-absorption segments"):
        get_technique("raycast").make_plan(scene, preintegrate=True)
    for name in ("particles", "splat"):
        with pytest.raises(ValueError, match=f"{name} renders optical_model 'emission_absorption' only"):
            get_technique(name).make_plan(scene)
    assert scene.digest() != scene.replace(optical_model="emission_absorption").digest()
    assert get_technique("slice3d").make_plan(scene).defines.get("OPTICAL_MODEL") == 2
    assert "OPTICAL_MODEL" not in get_technique("slice3d").make_plan(
        scene.replace(optical_model="emission_absorption")).defines


# -- Sabella (1988) -----------------------------------------------------------------------------

@pytest.mark.parametrize("camera", ["perspective", "ortho", "eye_inside"])
def test_sabella_matches_reference(renderer, camera):
    """Sabella's opacity is absorption only's, within its derived bound. Its colour comes
    from the ray's peak sample: a pixel whose two highest samples differ by less than
    the float32 value error may take the other one, whose depth is a step away, so all
    but a few pixels (none here) must agree to 1e-4."""
    scene = dvr_gl.Scene(RAMP, TF, cameras(RAMP)[camera], width=W, height=H, optical_model="sabella")
    opts = {"step": 0.5}
    gl = renderer.render(scene, **opts)
    ref = reference.render(scene, **opts)
    plan = get_technique("raycast").make_plan(scene, **opts)
    assert plan.occupancy is None and plan.ert_transmittance == 0   # the peak needs every sample
    assert ref[..., 3].max() > 0.5 and ref[..., :3].max() > 0.3
    assert np.abs(gl[..., 3] - ref[..., 3]).max() <= derived_tolerance(plan)
    assert (np.abs(gl - ref).max(axis=-1) > 1e-4).sum() <= 2


@pytest.mark.parametrize("camera", ["perspective", "ortho", "eye_inside"])
def test_exact_sabella_of_a_constant_box_is_the_closed_form(camera):
    """Every point ties for the peak, so the peak is where the ray enters: its depth
    gives the saturation; the intensity is 1 - e^(-tau L)."""
    from dvr_gl.reference.common import sabella_color
    from dvr_gl.model.field import depth_range
    volume = constant_box()
    scene = dvr_gl.Scene(volume, BOX_TF, box_cameras(volume)[camera], width=W, height=H, optical_model="sabella")
    o, d, t0, t1 = box_rays(scene)
    lo, _ = volume.bounds
    near, far = depth_range(scene)
    depth = ((o + lo - scene.camera.eye) @ scene.camera.forward + t0 * (d @ scene.camera.forward) - near) / (far - near)
    tau = -math.log(1 - ALPHA) / UNIT
    intensity = -np.expm1(-tau * np.maximum(t1 - t0, 0))
    hit = t1 > t0
    expected = np.zeros((H * W, 4))
    expected[hit] = sabella_color(np.broadcast_to(COLOUR, (hit.sum(), 3)), intensity[hit], depth[hit])
    assert expected[..., :3].max() > 0.2 and len(np.unique(np.round(expected[hit, 0], 6))) > 10
    np.testing.assert_allclose(reference.exact(scene, cache=False), expected.reshape(H, W, 4), rtol=0, atol=1e-12)


def test_sabella_error_against_exact_shrinks(renderer):
    """The peak's value converges at second order, its position (hence the saturation)
    at first order: the error falls at least like the step."""
    _, orders = errors_as_the_step_halves(renderer, marschner_lobb_scene(48, optical_model="sabella"))
    assert orders.mean() > 0.8, orders


def test_hsv_twins_round_trip():
    from dvr_gl.reference.common import hsv_to_rgb, rgb_to_hsv
    rgb = np.random.default_rng(1).random((500, 3))
    rgb[:5] = [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0.5, 0.5, 0.5], [0, 0, 0]]
    np.testing.assert_allclose(hsv_to_rgb(rgb_to_hsv(rgb)), rgb, rtol=0, atol=1e-12)


def test_sabella_is_refused_where_it_is_not_defined():
    camera = cameras(RAMP)["perspective"]
    with pytest.raises(ValueError, match="shading and illustration terms do not apply"):
        dvr_gl.Scene(RAMP, TF, camera, optical_model="sabella", shading=True)
    scene = dvr_gl.Scene(RAMP, TF, camera, width=16, height=16, optical_model="sabella")
    for name in ("slice3d", "slice2d", "particles"):
        with pytest.raises(ValueError, match="optical_model 'sabella' is rendered by raycast"):
            get_technique(name).make_plan(scene)


# -- projected tetrahedra: absorption and emission only, in closed form per linear cell ------

def constant_block_mesh():
    from test_tetra import blocks_mesh
    mesh = blocks_mesh([(x, y, z) for x in range(3) for y in range(2) for z in range(2)])
    return dvr_gl.TetMesh(mesh.points * [1.0, 0.7, 1.2] + [3.0, -1.0, 2.0], mesh.tets, np.full(len(mesh.points), 50.0))


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("camera", ["perspective", "ortho", "eye_inside"])
def test_tetra_constant_block_is_the_closed_form(renderer, model, camera):
    """A constant block of Kuhn-split cubes: GL, its reference and the exact image are the
    constant box's closed form (GL to float32 rounding over the cells a ray crosses)."""
    mesh = constant_block_mesh()
    scene = dvr_gl.Scene(mesh, BOX_TF, box_cameras(mesh)[camera], width=W, height=H, optical_model=model)
    want = closed_form(scene)
    assert np.abs(want).max() > 0.2
    np.testing.assert_allclose(reference.exact(scene, cache=False), want, rtol=0, atol=1e-11)
    np.testing.assert_allclose(reference.render(scene, technique="tetra"), want, rtol=0, atol=1e-12)
    assert metrics.max_abs_error(renderer.render(scene, technique="tetra"), want) <= 1e-5


@pytest.mark.parametrize("changes", [{"optical_model": "absorption"}, {"optical_model": "emission"},
                                     {"optical_model": "emission", "shading": True, "illustration": "tone"}], ids=str)
def test_tetra_models_match_the_reference_and_the_exact_image(renderer, changes):
    """The Delaunay ball: GL against its reference within test_tetra's bound (scaled by the
    largest colour, which emission lets exceed 1), the reference against the exact image
    (emission only is in closed form per cell; absorption is the emission-absorption
    integral's opacity) within the same."""
    from dvr_gl import data as bundled
    from test_tetra import GL_TOL
    mesh = bundled.delaunay_ball()
    lo, hi = float(mesh.scalars.min()), float(mesh.scalars.max())
    tf = dvr_gl.TransferFunction(color=[(lo, 0.9, 0.3, 0.1), (0.5 * (lo + hi), 0.2, 0.9, 0.4), (hi, 0.2, 0.4, 1.0)],
                                 opacity=[(lo, 0.05), (lo + 0.4 * (hi - lo), 0.6), (hi, 0.2)],
                                 unit_distance=0.2 * float(np.linalg.norm(mesh.extent)))
    scene = dvr_gl.Scene(mesh, tf, dvr_gl.default_camera(mesh, azimuth=20, elevation=10), width=48, height=40,
                         **changes)
    gl = renderer.render(scene, technique="tetra")
    ref = reference.render(scene, technique="tetra")
    assert np.abs(ref).max() > 0.1
    bound = GL_TOL * max(1.0, float(np.abs(ref).max()))
    assert metrics.max_abs_error(gl, ref) <= bound
    assert metrics.max_abs_error(ref, reference.exact(scene, cache=False)) <= bound
    if scene.optical_model == "emission":
        assert np.all(gl[..., 3] == 0)
