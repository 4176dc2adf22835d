"""The volume-illustration terms of Ebert and Rheingans (2000) on composite samples:
boundary and silhouette enhancement (factors on the extinction), tone (an added
warm-to-cool colour) and depth cue (a factor on the colour), alone and together, lit and
unlit, in raycast, slice3d and slice2d. GL against the references with a derived bound,
closed forms on a planar ramp and a constant box (exact and GL), convergence against the
exact image, what a scene compiles, and the refusals."""

import math

import numpy as np
import pytest

import dvr_gl
from dvr_gl import metrics, reference
from dvr_gl.reference.common import box_rays
from dvr_gl.model.field import depth_range
from dvr_gl.model.scene import ILLUSTRATION_TERMS
from dvr_gl.techniques import get_technique

from test_raycast import derived_tolerance
from test_shading import (RAMP, TF, cameras, errors_as_the_step_halves, gradient_error, gradient_floor,
                          marschner_lobb_scene, planar_ramp)
from test_slicing import slice_tolerance

U32 = 2.0 ** -24
W, H = 40, 32
ALL = tuple(ILLUSTRATION_TERMS)
TERM_SETS = [("boundary",), ("silhouette",), ("tone",), ("depth_cue",), ALL]
TECHNIQUES = [("raycast", {"step": 0.7, "ert_transmittance": 0.0}), ("slice3d", {"step": 0.7}),
              ("slice2d", {}), ("raycast", {"step": 0.7, "ert_transmittance": 0.0, "gradients": "texture"})]


def terms_tolerance(plan, unlit, g_floor):
    """Bound on |GL - reference| with illustration terms (and lighting), from the unlit
    bound of the plan.

    A sample's colour is ``c F + O`` (F <= ka + kd sum I lit, else 1, times the depth cue
    <= 1; O <= ks sum I lit plus the brighter tone colour), so value and table errors cost
    (F + O) times the unlit bound. The normal moves by dn <= 2 |dg| / |g| + 16u
    (``test_shading.gradient_error``): lighting adds sum I (kd + ks n) dn and tone
    max|warm - cool| dn, both weighted by the ray's sample weights, which add up to at
    most 1. The extinction scale m (boundary kc + ks (|g|/g_max)^ke, silhouette
    kc + ks (1 - |n.V|)^ke, with ke >= 1 here) moves by a relative error r <= ks ke d|g| /
    g_max / kc (plus ks ke dn / kc); scaling the whole extinction of a ray by 1 + r
    changes its opacity by at most r / e and its colour by at most 2 r max(colour), whatever
    the ray's length (d/dr of the integrals, x e^(-x) <= 1/e). The depth cue's own
    position rounding is 16u of the box over its depth range."""
    scene = plan.scene
    ka, kd, ks, shininess = scene.phong
    terms = scene.illustration
    intensity = sum(light.intensity for light in scene.lights)
    dg = gradient_error(plan)
    dn = 2 * dg / g_floor + 16 * U32
    factor, offset, extra = 1.0, 0.0, 0.0
    if scene.shading:
        factor, offset = ka + kd * intensity, ks * intensity
        extra += intensity * (kd + ks * shininess) * dn
    if "tone" in terms:
        warm, cool = (np.array(c) for c in terms["tone"])
        offset += float(np.maximum(warm, cool).max())
        extra += float(np.abs(warm - cool).max()) * dn
    colour = factor + offset
    relative = 0.0
    if "boundary" in terms:
        kc, kg, ke = terms["boundary"]
        g_max = float(np.linalg.norm(dvr_gl.model.field.sample_gradients(
            scene.volume, scene.volume.values(np.float64)), axis=-1).max())
        relative += kg * ke * dg / g_max / kc
    if "silhouette" in terms:
        kc, kg, ke = terms["silhouette"]
        relative += kg * ke * dn / kc
    if "depth_cue" in terms:
        near, far = depth_range(scene)
        extra += colour * 16 * U32 * float(np.linalg.norm(scene.volume.extent) + far) / (far - near)
    return colour * unlit + extra + (2 * colour + 1 / math.e) * relative


@pytest.mark.parametrize("technique,opts", TECHNIQUES, ids=lambda v: str(v))
@pytest.mark.parametrize("terms", TERM_SETS, ids=lambda t: "+".join(t))
@pytest.mark.parametrize("lit", [False, True], ids=["unlit", "lit"])
@pytest.mark.parametrize("camera", ["perspective", "ortho", "eye_inside"])
def test_gl_matches_reference(renderer, technique, opts, terms, lit, camera):
    scene = dvr_gl.Scene(RAMP, TF, cameras(RAMP)[camera], width=W, height=H, shading=lit, illustration=terms)
    gl = renderer.render(scene, technique=technique, **opts)
    ref = reference.render(scene, technique=technique, **opts)
    plan = get_technique(technique).make_plan(scene, **opts)
    plain = renderer.render(scene.replace(illustration=None), technique=technique, **opts)
    assert metrics.max_abs_error(gl, plain) > 0.02, "the terms must change the picture"
    unlit = derived_tolerance(plan) if technique == "raycast" else slice_tolerance(plan)
    assert metrics.max_abs_error(gl, ref) <= terms_tolerance(plan, unlit, gradient_floor(RAMP))


# -- closed forms ------------------------------------------------------------------------------

SLOPE = 5.0


def inner_tf(volume, unit=1.0):
    """Transparent in the first and last cells along x of the planar x-ramp, where the
    clamped central differences shorten the gradient, and a band of colours between."""
    sx = volume.spacing[0]
    top = SLOPE * sx * (volume.shape[2] - 1)
    lo, hi = SLOPE * sx * 1.01, top - SLOPE * sx * 1.01
    return dvr_gl.TransferFunction(
        color=[(lo, 1, 0.2, 0.1), ((lo + hi) / 2, 0.2, 0.9, 0.5), (hi, 0.1, 0.3, 1)],
        opacity=[(lo - 1e-3, 0.0), (lo, 0.3), ((lo + hi) / 2, 0.1), (hi, 0.5), (hi + 1e-3, 0.0)],
        unit_distance=unit)


@pytest.mark.parametrize("technique,opts", [(None, None), ("raycast", {"step": 0.3, "ert_transmittance": 0.0}),
                                            ("slice3d", {"step": 0.3}), ("slice2d", {})],
                         ids=lambda v: str(v))
@pytest.mark.parametrize("term", ["boundary", "silhouette"])
def test_an_extinction_scale_is_a_shorter_unit_distance(renderer, technique, opts, term):
    """On the planar ramp, orthographic: where the TF is opaque at all, |g| is the ramp's
    slope and |n.V| one number for the image, so the scale m is one number and the image
    is that of the plain scene with unit distance u / m (exact to 1e-11; GL to float32)."""
    volume = planar_ramp(slope=SLOPE)
    lo, hi = volume.bounds
    centre = (lo + hi) / 2
    camera = dvr_gl.Camera(centre + np.array([30.0, 12.0, 25.0]), centre, ortho_height=25.0)
    kc, ks, ke = 0.3, 0.9, 2.0
    if term == "boundary":
        m = kc + ks * 1.0 ** ke       # |g| = g_max: the slope
    else:
        facing = abs(camera.forward[0])
        m = kc + ks * (1 - facing) ** ke
    scene = dvr_gl.Scene(volume, inner_tf(volume), camera, width=W, height=H, illustration={term: (kc, ks, ke)})
    shorter = scene.replace(tf=inner_tf(volume, unit=1.0 / m), illustration=None)
    if technique is None:
        expected = reference.exact(shorter, cache=False)
        assert expected[..., 3].max() > 0.3
        np.testing.assert_allclose(reference.exact(scene, cache=False), expected, rtol=0, atol=1e-11)
    else:
        got = renderer.render(scene, technique=technique, **opts)
        expected = renderer.render(shorter, technique=technique, **opts)
        plan = get_technique(technique).make_plan(scene, **opts)
        segments = plan.max_segments if technique == "raycast" else 2 * plan.count + 2 * 4096 // plan.count
        assert metrics.max_abs_error(got, expected) <= 64 * U32 * segments


def test_tone_on_a_ramp_adds_one_colour_times_the_opacity():
    """Tone on the planar ramp (headlight, orthographic): t = |n.V| is one number, so the
    image is the plain one plus (t warm + (1 - t) cool) A."""
    volume = planar_ramp(slope=SLOPE)
    lo, hi = volume.bounds
    centre = (lo + hi) / 2
    camera = dvr_gl.Camera(centre + np.array([30.0, 12.0, 25.0]), centre, ortho_height=25.0)
    warm, cool = (0.5, 0.3, 0.0), (0.0, 0.1, 0.6)
    scene = dvr_gl.Scene(volume, inner_tf(volume), camera, width=W, height=H, illustration={"tone": (warm, cool)})
    plain = reference.exact(scene.replace(illustration=None), cache=False)
    t = abs(camera.forward[0])
    expected = plain.copy()
    expected[..., :3] += (t * np.array(warm) + (1 - t) * np.array(cool)) * plain[..., 3:4]
    np.testing.assert_allclose(reference.exact(scene, cache=False), expected, rtol=0, atol=1e-11)


@pytest.mark.parametrize("technique,opts", [(None, None), ("raycast", {"step": 0.1, "ert_transmittance": 0.0}),
                                            ("slice3d", {"step": 0.1})], ids=lambda v: str(v))
def test_depth_cue_of_a_constant_box_is_the_closed_form(renderer, technique, opts):
    """A constant box: along a ray the cue is linear in t, so C = c int (a - b t) tau
    e^(-tau t) dt in closed form. Exact to 1e-12; GL to its midpoint rule's second-order
    error (the cue varies along each segment): tau b h^2 / 24 per unit of colour."""
    volume = dvr_gl.Volume(np.full((8, 9, 10), 50.0, np.float32), spacing=(1.0, 0.7, 1.2))
    colour, alpha, strength = np.array([0.9, 0.6, 0.2]), 0.25, 0.7
    tf = dvr_gl.TransferFunction(color=[(0, *colour), (100, *colour)], opacity=[(0, alpha), (100, alpha)])
    camera = dvr_gl.default_camera(volume, azimuth=35, elevation=25)
    scene = dvr_gl.Scene(volume, tf, camera, width=W, height=H, illustration={"depth_cue": strength})
    o, d, t0, t1 = box_rays(scene)
    near, far = depth_range(scene)
    lo, _ = volume.bounds
    depth0 = (o + lo - camera.eye) @ camera.forward + t0 * (d @ camera.forward)
    a = 1 - strength * (depth0 - near) / (far - near)
    b = strength * (d @ camera.forward) / (far - near)
    tau = -math.log(1 - alpha)
    L = np.maximum(t1 - t0, 0)
    e = np.exp(-tau * L)
    weight = a * (1 - e) - b * (1 - e * (1 + tau * L)) / tau
    expected = np.zeros((H * W, 4))
    expected[:, :3] = colour * weight[:, None]
    expected[:, 3] = 1 - e
    expected = expected.reshape(H, W, 4)
    if technique is None:
        np.testing.assert_allclose(reference.exact(scene, cache=False), expected, rtol=0, atol=1e-12)
    else:
        got = renderer.render(scene, technique=technique, **opts)
        plan = get_technique(technique).make_plan(scene, **opts)
        bound = tau * float(b.max()) * opts["step"] ** 2 / 24 * float(L.max()) + 64 * U32 * plan.max_segments \
            if technique == "raycast" else tau * float(b.max()) * opts["step"] ** 2 / 24 * float(L.max()) \
            + 64 * U32 * (2 * plan.count + 8192 // plan.count)
        assert metrics.max_abs_error(got, expected) <= bound


def test_error_against_exact_is_second_order_with_every_term(renderer):
    _, orders = errors_as_the_step_halves(renderer, marschner_lobb_scene(48, shading=True, illustration=ALL))
    assert orders.mean() > 1.7, orders


# -- what a scene builds, and what is refused ---------------------------------------------------

def test_each_term_compiles_only_itself():
    camera = cameras(RAMP)["perspective"]
    tech = get_technique("raycast")
    plain = tech.make_plan(dvr_gl.Scene(RAMP, TF, camera, width=16, height=16)).defines
    assert not {"SAMPLE_TERMS", "TONE", "DEPTH_CUE", "BOUNDARY", "SILHOUETTE", "SHADING"} & set(plain)
    for name in ILLUSTRATION_TERMS:
        defines = tech.make_plan(dvr_gl.Scene(RAMP, TF, camera, width=16, height=16, illustration=name)).defines
        assert defines.get(name.upper()) == 1 and defines.get("SAMPLE_TERMS") == 1
        assert not {n.upper() for n in ILLUSTRATION_TERMS if n != name} & set(defines)
        assert "SHADING" not in defines


@pytest.mark.parametrize("value,message", [
    ("halo", "illustration terms are boundary, silhouette, tone, depth_cue, got 'halo'"),
    ({"boundary": (0.0, 1.0, 1.0)}, "boundary needs a positive constant term"),
    ({"silhouette": (0.2, 1.0)}, "silhouette must be 3 finite numbers"),
    ({"depth_cue": 1.5}, "depth_cue strength must be in"),
    ({"tone": ((1, 0, 0), (0, 0))}, "tone must be two RGB triples"),
])
def test_bad_terms_are_refused(value, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(")):
        dvr_gl.Scene(RAMP, TF, cameras(RAMP)["perspective"], illustration=value)


def test_terms_are_refused_where_they_are_not_defined():
    camera = cameras(RAMP)["perspective"]
    with pytest.raises(ValueError, match="illustration terms apply to mode 'composite'"):
        dvr_gl.Scene(RAMP, TF, camera, mode="mip", illustration="tone")
    scene = dvr_gl.Scene(RAMP, TF, camera, width=16, height=16, illustration=("boundary", "tone"))
    with pytest.raises(ValueError, match="boundary enhancement scales it per sample"):
        get_technique("slice3d").make_plan(scene, preintegrate=True)
    for name in ("particles", "splat"):
        with pytest.raises(ValueError, match=f"{name} has no illustration terms yet"):
            get_technique(name).make_plan(scene)
    # colour-only terms do combine with pre-integration
    toned = scene.replace(illustration="tone")
    assert get_technique("raycast").make_plan(toned, preintegrate=True).defines.get("TONE") == 1


def test_the_variants_compiled_and_the_textures_made_are_exactly_what_the_scenes_use():
    """A fresh renderer, four scenes in turn: each compiles the one variant its terms name
    and makes only the textures it reads (the gradient texture only for a lit scene that
    asks for it; the volume, tables and brick occupancy once)."""
    from dvr_gl import Renderer
    camera = cameras(RAMP)["perspective"]
    base = dvr_gl.Scene(RAMP, TF, camera, width=16, height=16)
    # every brick is occupied: skipping's occupied-range pass has nothing to shorten
    plain = {"MODE_COMPOSITE": 1, "SKIP_EMPTY": 1, "EARLY_RAY_TERMINATION": 1, "STEP_TABLE": 1}
    steps = [(base, {}, plain, {"volume", "tf", "occupancy", "step_tf", "target"}),
             (base.replace(shading=True), {}, {**plain, "SAMPLE_TERMS": 1, "SHADING": 1}, set()),
             (base.replace(shading=True), {"gradients": "texture"},
              {**plain, "SAMPLE_TERMS": 1, "SHADING": 1, "GRADIENT_TEXTURE": 1}, {"gradient"}),
             (base.replace(illustration="tone"), {}, {**plain, "SAMPLE_TERMS": 1, "TONE": 1}, set())]
    with Renderer() as r:
        seen = set()
        for scene, opts, defines, textures in steps:
            before = len(r.created)
            r.render(scene, step=0.7, **opts)
            compiled = {dict(key[2]).__repr__() for key in r.programs.sources if key[1] == "raycast/raycast.frag"}
            assert compiled - seen == {repr(dict(sorted(defines.items())))}, (compiled - seen, defines)
            seen |= compiled
            assert {kind for kind, _ in r.created[before:]} == textures


# -- projected tetrahedra: the depth cue integrated along each cell's segment ---------------

def cued_box_closed_form(scene, colour, tau):
    """A constant block with a depth cue: along a chord [t0, t1] the cue q(t) = a + b t is
    linear (depth is), so C = c tau integral of q(t) e^(-tau (t - t0)) dt in closed form."""
    from dvr_gl.reference.common import box_rays
    from dvr_gl.model.field import depth_range
    o, d, t0, t1 = box_rays(scene)
    cam = scene.camera
    lo, _ = scene.volume.bounds
    near, far = depth_range(scene)
    strength = scene.illustration.get("depth_cue", (0.0,))[0]
    depth0 = (o + t0[:, None] * d + lo - cam.eye) @ cam.forward
    rate = d @ cam.forward
    a = 1 - strength * (depth0 - near) / (far - near)
    b = -strength * rate / (far - near)
    L = np.maximum(t1 - t0, 0)
    e = np.exp(-tau * L)
    integral = a * (1 - e) / tau + b * (1 - e * (1 + tau * L)) / tau ** 2
    out = np.zeros((scene.height * scene.width, 4))
    out[:, :3] = np.outer(tau * integral, colour)
    out[:, 3] = 1 - e
    return out.reshape(scene.height, scene.width, 4)


@pytest.mark.parametrize("camera", ["perspective", "ortho", "eye_inside"])
def test_tetra_depth_cue_on_a_constant_block_is_the_closed_form(renderer, camera):
    """Exact image, tetra reference and GL against the closed form (GL to float32 over the
    cells a ray crosses)."""
    from test_optical_models import BOX_TF, COLOUR, ALPHA, UNIT, box_cameras, constant_block_mesh
    mesh = constant_block_mesh()
    scene = dvr_gl.Scene(mesh, BOX_TF, box_cameras(mesh)[camera], width=W, height=H,
                         illustration={"depth_cue": 0.7})
    want = cued_box_closed_form(scene, COLOUR, -math.log(1 - ALPHA) / UNIT)
    plain = cued_box_closed_form(scene.replace(illustration=None), COLOUR, -math.log(1 - ALPHA) / UNIT)
    assert metrics.max_abs_error(want, plain) > 0.05, "the cue must change the picture"
    np.testing.assert_allclose(reference.exact(scene, cache=False), want, rtol=0, atol=1e-10)
    np.testing.assert_allclose(reference.render(scene, technique="tetra"), want, rtol=0, atol=1e-9)
    assert metrics.max_abs_error(renderer.render(scene, technique="tetra"), want) <= 1e-5


@pytest.mark.parametrize("lit", [False, True])
def test_tetra_depth_cue_matches_the_reference_and_the_exact_image(renderer, lit):
    """The Delaunay ball, depth-cued (and lit with tone): GL against its reference and the
    reference against the exact image within test_tetra's bound times the brightest
    colour."""
    from dvr_gl import data as bundled
    from test_tetra import GL_TOL
    mesh = bundled.delaunay_ball()
    scene = dvr_gl.Scene(mesh, bundled.synthetic_tf(), dvr_gl.default_camera(mesh, azimuth=20, elevation=10),
                         width=48, height=40, shading=lit,
                         illustration=("depth_cue", "tone") if lit else ("depth_cue",))
    gl = renderer.render(scene, technique="tetra")
    ref = reference.render(scene, technique="tetra")
    plain = reference.render(scene.replace(illustration=("tone",) if lit else None), technique="tetra")
    assert metrics.max_abs_error(ref, plain) > 0.02, "the cue must change the picture"
    ka, kd, ks, _ = scene.phong
    bound = GL_TOL * ((ka + kd + ks + 0.4) if lit else 1.0)
    assert metrics.max_abs_error(gl, ref) <= bound
    assert metrics.max_abs_error(ref, reference.exact(scene, cache=False)) <= bound
