"""2D transfer functions over (value, gradient magnitude): GL against the NumPy references
with a derived bound in every sampling technique, lit and unlit; closed forms (a table
constant in the gradient is the 1D function; a product table on a planar ramp is the 1D
function at the ramp's slope, in the exact image); convergence against the exact image;
the widgets and Levoy's opacities against their formulas; refusals and the JSON file."""

import json
import math
import os

import numpy as np
import pytest

import dvr_gl
from dvr_gl import metrics, reference
from dvr_gl.model.field import gradient_max
from dvr_gl.techniques import get_technique
from dvr_gl.model.transfer2d import (Rectangle, Triangle, from_widgets, levoy_isocontours, levoy_region_boundaries,
                               load_tf2d_json)

from test_raycast import cameras
from test_shading import RAMP, TF, gradient_error, gradient_floor, lit_tolerance, planar_ramp, ramp_cameras

U32 = 2.0 ** -24
W, H = 40, 32
G_MAX = gradient_max(RAMP)


def widgets_tf(volume=RAMP, g_max=G_MAX, unit_distance=1.0):
    """An iso-contour at the middle of the ramp's values, a soft rectangle over its steep
    parts and a fainter one over the rest: colour and opacity vary along both axes."""
    lo, hi = volume.data_range
    mid = 0.5 * (lo + hi)
    return from_widgets([Triangle(mid, 1.5, (1.0, 0.6, 0.2), 0.9),
                         Rectangle((lo, hi), (0.7 * g_max, g_max), (0.2, 0.4, 1.0), 0.5, ramp=0.2),
                         Rectangle((lo + 0.1 * (hi - lo), mid), (0.0, 0.7 * g_max), (0.3, 0.9, 0.3), 0.15)],
                        (lo, hi), (0.0, g_max), resolution=(96, 24), unit_distance=unit_distance)


TF2 = widgets_tf()


def tf2d_tolerance(plan, samples):
    """Bound on |GL - reference| per channel for a 2D table, as ``test_raycast.
    derived_tolerance`` argues for a 1D one: a sample's value error (texture position
    rounding ~4u n * the largest jump, trilinear arithmetic ~16u max|s|) times the table's
    steepest slope along values, its gradient error (``test_shading.gradient_error``)
    times the steepest slope along gradient magnitudes, the two table indices' rounding
    (2u * entries each) and float32 storage of the table (u), and ~64u for opacity
    correction. Errors add at most linearly over ``samples`` per ray."""
    tf2 = plan.scene.tf_2d
    v = plan.scene.volume
    vals = v.values()
    jump = max(float(np.abs(np.diff(vals, axis=a)).max()) for a in range(3))
    value_err = 4 * U32 * float(v.dims.max()) * jump + 16 * U32 * float(np.abs(vals).max())
    n_g, n_v, _ = tf2.table.shape
    (v0, v1), (g0, g1) = tf2.value_range, tf2.gradient_range
    scale_v, scale_g = (n_v - 1) / (v1 - v0), (n_g - 1) / (g1 - g0)
    step_v = float(np.abs(np.diff(tf2.table, axis=1)).max())     # per entry
    step_g = float(np.abs(np.diff(tf2.table, axis=0)).max())
    per_sample = (step_v * scale_v * value_err + step_g * scale_g * gradient_error(plan)
                  + 2 * U32 * (n_v * step_v + n_g * step_g) + U32 + 64 * U32)
    return per_sample * samples


def samples_per_ray(technique, plan):
    return plan.max_segments if technique == "raycast" else plan.count + 2 * 4096 // plan.count


VARIANTS = [("raycast", {"step": 0.7, "ert_transmittance": 0.0}), ("slice3d", {"step": 0.7}),
            ("slice3d", {"step": 0.7, "shells": True}), ("slice2d", {}), ("slice2d", {"interpolate": 1})]


@pytest.mark.parametrize("technique,opts", VARIANTS, ids=lambda v: str(v))
@pytest.mark.parametrize("lit", [False, True], ids=["unlit", "lit"])
@pytest.mark.parametrize("gradients", ["on_the_fly", "texture"])
@pytest.mark.parametrize("camera", ["perspective", "ortho", "eye_inside"])
def test_gl_matches_reference(renderer, technique, opts, lit, gradients, camera):
    scene = dvr_gl.Scene(RAMP, TF2, cameras(RAMP)[camera], width=W, height=H, shading=lit)
    opts = dict(opts, gradients=gradients)
    gl = renderer.render(scene, technique=technique, **opts)
    ref = reference.render(scene, technique=technique, **opts)
    plan = get_technique(technique).make_plan(scene, **opts)
    assert ref[..., 3].max() > 0.05, "the scene must show something"
    bound = tf2d_tolerance(plan, samples_per_ray(technique, plan))
    if lit:
        bound = lit_tolerance(plan, bound, gradient_floor(RAMP))
    assert metrics.max_abs_error(gl, ref) <= bound


def test_the_gradient_axis_changes_the_picture(renderer):
    """The same table read at a fixed gradient magnitude (every row the middle one) gives
    another image: the gradient is really looked up."""
    scene = dvr_gl.Scene(RAMP, TF2, cameras(RAMP)["perspective"], width=W, height=H)
    flat = TF2.table[TF2.table.shape[0] // 2][None].repeat(TF2.table.shape[0], axis=0)
    flat_tf = dvr_gl.TransferFunction2D(flat, TF2.value_range, TF2.gradient_range)
    assert metrics.max_abs_error(renderer.render(scene), renderer.render(scene.replace(tf=flat_tf))) > 0.05


# -- closed forms ------------------------------------------------------------------------------

def rows_of(tf, n_g=3, g_range=(0.0, 50.0)):
    """A 2D table whose every row is ``tf`` at its control points (which ``tf`` has evenly
    spaced): constant in the gradient magnitude, it is ``tf`` itself."""
    s = tf.knots
    rgba = np.concatenate([tf.color(s), tf.opacity(s)[:, None]], axis=1)
    return dvr_gl.TransferFunction2D(np.repeat(rgba[None], n_g, axis=0), (s[0], s[-1]), g_range, tf.unit_distance)


EVEN_TF = dvr_gl.TransferFunction(color=[(0, 0.9, 0.3, 0.1), (30, 0.3, 0.9, 0.4), (60, 0.2, 0.4, 1.0),
                                         (90, 0.8, 0.8, 0.2)],
                                  opacity=[(0, 0.0), (30, 0.3), (60, 0.05), (90, 0.5)], unit_distance=1.0)


@pytest.mark.parametrize("technique,opts", [("raycast", {"step": 0.7, "ert_transmittance": 0.0}),
                                            ("slice3d", {"step": 0.7}), ("slice2d", {})], ids=lambda v: str(v))
def test_a_table_constant_in_the_gradient_is_the_1d_function(renderer, technique, opts):
    """GL and reference images of a table whose rows are all one 1D function equal that
    function's images (GL: up to the two tables' float32 arithmetic)."""
    scene = dvr_gl.Scene(RAMP, EVEN_TF, cameras(RAMP)["perspective"], width=W, height=H)
    flat = scene.replace(tf=rows_of(EVEN_TF))
    plan = get_technique(technique).make_plan(scene, **opts)
    one_d, two_d = renderer.render(scene, technique=technique, **opts), renderer.render(flat, technique=technique, **opts)
    assert one_d[..., 3].max() > 0.3
    # Both tables hold the function exactly (its knots fall on entries of each) and both
    # shaders sample the same values: only the index arithmetic (2u * entries times the
    # step per entry), the lerps and opacity correction (64u each) differ, per sample.
    step_1d = float(np.abs(np.diff(plan.lut.table, axis=0)).max())
    step_2d = float(np.abs(np.diff(flat.tf_2d.table, axis=1)).max())
    per_sample = 2 * U32 * (plan.lut.size * step_1d + flat.tf_2d.table.shape[1] * step_2d) + 128 * U32
    assert metrics.max_abs_error(one_d, two_d) <= per_sample * samples_per_ray(technique, plan)
    # the references in float64 with the functions themselves (no float32 1D table)
    np.testing.assert_allclose(reference.render(flat, technique=technique, lut_exact=True, **opts),
                               reference.render(scene, technique=technique, lut_exact=True, **opts),
                               rtol=0, atol=1e-12)


def test_exact_table_constant_in_the_gradient_is_the_1d_image():
    scene = dvr_gl.Scene(RAMP, EVEN_TF, cameras(RAMP)["perspective"], width=24, height=20)
    np.testing.assert_allclose(reference.exact(scene.replace(tf=rows_of(EVEN_TF)), cache=False),
                               reference.exact(scene, cache=False), rtol=0, atol=1e-10)


@pytest.mark.parametrize("camera", ["oblique", "orthogonal", "eye_inside"])
def test_exact_product_table_on_a_ramp_is_the_1d_function_at_its_slope(camera):
    """On f = 5 x the gradient magnitude is 5 everywhere but in the cells at the two x faces
    (clamping halves it there). A table A(s) B(g), A zero over those cells' values and B
    linear in g, has the bilinear interpolant A(s) B(g) exactly, so the exact image is the
    1D function with opacity A(s) B(5), to the integrator's accuracy."""
    volume = planar_ramp()                          # f = 5 x, x in [0, 11.7]: values 0 .. 58.5
    s = np.arange(0.0, 61.0, 3.0)
    a = np.interp(s, [0, 6, 20, 35, 52, 60], [0, 0, 0.7, 0.2, 0, 0])
    c = np.stack([np.interp(s, [0, 60], [1, 0.1]), np.interp(s, [0, 30, 60], [0.2, 0.9, 0.3]),
                  np.full_like(s, 0.5)], axis=1)
    b = np.array([0.2, 1.0])                        # at g = 0 and g = 10: B(5) = 0.6
    table = np.concatenate([np.repeat(c[None], 2, axis=0), (b[:, None] * a[None])[..., None]], axis=-1)
    tf2 = dvr_gl.TransferFunction2D(table, (0.0, 60.0), (0.0, 10.0))
    tf1 = dvr_gl.TransferFunction(np.column_stack([s, c]), np.column_stack([s, 0.6 * a]))
    scene = dvr_gl.Scene(volume, tf1, ramp_cameras(volume)[camera], width=W, height=H)
    one_d = reference.exact(scene, cache=False)
    assert one_d[..., 3].max() > 0.2
    np.testing.assert_allclose(reference.exact(scene.replace(tf=tf2), cache=False), one_d, rtol=0, atol=1e-10)


def errors_as_the_step_halves(renderer, scene, technique, steps):
    exact = reference.exact(scene)
    h = scene.volume.min_spacing
    opts = {"ert_transmittance": 0.0} if technique == "raycast" else {}
    return [metrics.rmse(renderer.render(scene, technique, step=k * h, **opts), exact) for k in steps]


@pytest.mark.parametrize("technique", ["raycast", "slice3d"])
def test_error_against_exact_shrinks_with_the_step(renderer, technique):
    """Lit, with a Levoy iso-contour and a region boundary on the ripples: each halving of
    the step cuts the error against the exact image by at least 2.5x (second order: 4x),
    and at 1/4 voxel it is within 1.5x of the float64 midpoint marcher's."""
    lo, hi = RAMP.data_range
    tf2 = from_widgets([Triangle(0.5 * (lo + hi), 1.0, (1.0, 0.7, 0.3), 0.8),
                        Rectangle((lo, hi), (0.6 * G_MAX, G_MAX), (0.3, 0.5, 1.0), 0.3, ramp=0.3)],
                       (lo, hi), (0.0, G_MAX), resolution=(64, 16))
    scene = dvr_gl.Scene(RAMP, tf2, cameras(RAMP)["perspective"], width=32, height=24, shading=True)
    errors = errors_as_the_step_halves(renderer, scene, technique, (1.0, 0.5, 0.25))
    assert errors[0] / errors[1] > 2.5 and errors[1] / errors[2] > 2.5, errors
    h = RAMP.min_spacing
    ideal = metrics.rmse(reference.render(scene, "raycast", step=0.25 * h, ert_transmittance=0.0),
                         reference.exact(scene))
    assert errors[2] <= 1.5 * ideal, (errors[2], ideal)


# -- the widgets and Levoy's opacities --------------------------------------------------------

def test_triangle_is_levoys_isocontour_opacity():
    """alpha = alpha_v (1 - |f_v - f| / (r |g|)) inside the wedge, 0 outside, alpha_v at
    the value itself where the field is flat; several combine as 1 - prod(1 - alpha)."""
    t = Triangle(50.0, 2.0, (1, 0, 0), 0.8)
    g = np.array([0.0, 1.0, 4.0, 4.0, 4.0, 10.0])
    s = np.array([50.0, 50.0, 54.0, 46.0, 58.0, 30.0])
    np.testing.assert_allclose(t.opacity_at(s, g), [0.8, 0.8, 0.4, 0.4, 0.0, 0.0], rtol=0, atol=1e-15)
    assert t.opacity_at(np.array([50.5]), np.array([0.0]))[0] == 0
    tf2 = levoy_isocontours([(20.0, 1.0, (1, 0, 0), 0.5), (24.0, 1.0, (0, 0, 1), 0.5)], (0.0, 40.0), (0.0, 8.0),
                            resolution=(41, 9))
    rgba, _ = tf2.lookup(np.array([22.0]), np.array([4.0]))       # both at half: 1 - 0.75^2
    np.testing.assert_allclose(rgba[0], [0.5, 0, 0.5, 1 - 0.75 ** 2], rtol=0, atol=1e-15)


def test_region_boundaries_scale_the_opacity_by_the_gradient():
    tf2 = levoy_region_boundaries([(0.0, (0, 0, 0), 0.0), (100.0, (1, 0.5, 0), 0.6), (200.0, (1, 1, 1), 1.0)],
                                  (0.0, 40.0), resolution=(21, 5))
    rgba, _ = tf2.lookup(np.array([100.0, 100.0, 150.0, 150.0, 0.0]), np.array([40.0, 10.0, 40.0, 20.0, 40.0]))
    np.testing.assert_allclose(rgba[:, 3], [0.6, 0.15, 0.8, 0.4, 0.0], rtol=0, atol=1e-14)
    np.testing.assert_allclose(rgba[2, :3], [1, 0.75, 0.5], rtol=0, atol=1e-14)


def test_lookup_is_the_bilinear_interpolant_clamped_at_the_edges():
    table = np.random.default_rng(1).random((3, 4, 4))
    tf2 = dvr_gl.TransferFunction2D(table, (10.0, 40.0), (0.0, 2.0))
    rgba, clear = tf2.lookup(np.array([10.0, 25.0, 100.0, -5.0]), np.array([0.0, 1.5, 2.0, 9.0]))
    fx = 0.5                                        # s = 25 lies half way between columns 1 and 2
    expect = 0.5 * ((1 - fx) * table[1, 1] + fx * table[1, 2]) + 0.5 * ((1 - fx) * table[2, 1] + fx * table[2, 2])
    np.testing.assert_allclose(rgba, [table[0, 0], expect, table[2, 3], table[2, 0]], rtol=0, atol=1e-15)
    np.testing.assert_allclose(clear, 1 - rgba[:, 3], rtol=0, atol=1e-15)
    np.testing.assert_allclose(tf2.envelope.opacity(tf2.values), np.minimum(table[:, :, 3].max(axis=0), 1 - 1e-16),
                               rtol=0, atol=1e-15)


# -- refusals, what a scene compiles, the JSON file ------------------------------------------

def test_bad_input_names_the_field():
    with pytest.raises(ValueError, match=r"table must have shape \(n_gradient >= 2, n_value >= 2, 4\)"):
        dvr_gl.TransferFunction2D(np.zeros((1, 4, 4)), (0, 1), (0, 1))
    with pytest.raises(ValueError, match="table entries must lie in \\[0, 1\\], got 1.5"):
        dvr_gl.TransferFunction2D(np.full((2, 2, 4), 1.5), (0, 1), (0, 1))
    with pytest.raises(ValueError, match="value_range must be two finite numbers with low < high"):
        dvr_gl.TransferFunction2D(np.zeros((2, 2, 4)), (1, 1), (0, 1))
    with pytest.raises(ValueError, match="gradient_range must start at 0 or above"):
        dvr_gl.TransferFunction2D(np.zeros((2, 2, 4)), (0, 1), (-1, 1))
    with pytest.raises(ValueError, match="triangle thickness must be positive"):
        Triangle(1.0, 0.0, (1, 1, 1), 0.5)
    with pytest.raises(ValueError, match="rectangle opacity must lie in \\[0, 1\\], got 2"):
        Rectangle((0, 1), (0, 1), (1, 1, 1), 2)
    with pytest.raises(ValueError, match="material values must be finite and strictly increasing"):
        levoy_region_boundaries([(1.0, (0, 0, 0), 0.1), (1.0, (1, 1, 1), 0.2)], (0, 1))


def test_a_2d_function_is_refused_where_it_is_not_defined():
    camera = cameras(RAMP)["perspective"]
    with pytest.raises(ValueError, match="a TransferFunction2D classifies composite samples"):
        dvr_gl.Scene(RAMP, TF2, camera, mode="mip")
    with pytest.raises(ValueError, match="optical_model='sabella' colours a ray from its peak value alone"):
        dvr_gl.Scene(RAMP, TF2, camera, optical_model="sabella")
    scene = dvr_gl.Scene(RAMP, TF2, camera, width=16, height=16)
    for name in ("particles", "splat"):
        with pytest.raises(ValueError, match=f"{name} classifies by value alone"):
            get_technique(name).make_plan(scene)
    with pytest.raises(ValueError, match="a TransferFunction2D also needs the gradient"):
        get_technique("raycast").make_plan(scene, preintegrate=True)
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    mesh = dvr_gl.TetMesh(points, np.array([[0, 1, 2, 3]]), np.array([0.0, 1.0, 2.0, 3.0]))
    with pytest.raises(ValueError, match="a TetMesh scene takes a 1D TransferFunction"):
        dvr_gl.Scene(mesh, TF2, dvr_gl.default_camera(mesh))


def test_a_2d_scene_compiles_and_allocates_what_it_uses():
    """TF_2D with the sample terms it needs; its table once per function; the gradient
    texture only when asked for; a 1D scene compiles neither."""
    scene = dvr_gl.Scene(RAMP, TF2, cameras(RAMP)["perspective"], width=16, height=16)
    for name in ("raycast", "slice3d", "slice2d"):
        defines = get_technique(name).make_plan(scene).defines
        assert defines.get("TF_2D") == 1 and defines.get("SAMPLE_TERMS") == 1 and "SHADING" not in defines
        assert "TF_2D" not in get_technique(name).make_plan(scene.replace(tf=TF)).defines
    with dvr_gl.Renderer() as r:
        r.render(scene)
        r.render(scene, technique="slice3d")
        assert [c for c in r.created if c[0] in ("tf2d", "gradient")] == [("tf2d", ("TransferFunction2D",))]
        r.render(scene, gradients="texture")
        assert [c for c in r.created if c[0] == "gradient"] == [("gradient", ("Volume",))]


def test_json_widgets_and_table(tmp_path):
    spec = {"widgets": [{"type": "triangle", "value": 40, "thickness": 1.5, "color": [1, 0.5, 0], "opacity": 0.7},
                        {"type": "rectangle", "value": [10, 60], "gradient": [5, 30], "color": [0, 0, 1],
                         "opacity": 0.2}],
            "unit_distance": 2.0, "resolution": [64, 16]}
    path = tmp_path / "tf2d.json"
    path.write_text(json.dumps(spec))
    tf2 = load_tf2d_json(path, value_range=(0.0, 90.0), gradient_range=(0.0, 30.0))
    assert tf2.table.shape == (16, 64, 4) and tf2.unit_distance == 2.0 and tf2.value_range == (0.0, 90.0)
    rgba, _ = tf2.lookup(np.array([40.0]), np.array([20.0]))
    assert math.isclose(rgba[0, 3], 1 - 0.3 * 0.8, rel_tol=1e-12)
    path.write_text(json.dumps({"widgets": [{"type": "circle"}]}))
    with pytest.raises(ValueError, match=r"widgets\[0\] needs a 'type' of rectangle, triangle"):
        load_tf2d_json(path, (0, 1), (0, 1))
    path.write_text(json.dumps({"table": np.zeros((2, 3, 4)).tolist(), "value_range": [0, 1]}))
    with pytest.raises(ValueError, match="gradient_range is missing"):
        load_tf2d_json(path)


@pytest.mark.parametrize("changes", [{"optical_model": "absorption"},
                                     {"illustration": ("boundary", "tone", "depth_cue")},
                                     {"illustration": ("silhouette",), "shading": True}], ids=str)
def test_optical_models_and_illustration_terms_take_a_2d_function(renderer, changes):
    """The other optical models and the illustration terms with a 2D table: GL against the
    reference within test_illustration's bound built on the 2D table's unlit one."""
    from test_illustration import terms_tolerance
    scene = dvr_gl.Scene(RAMP, TF2, cameras(RAMP)["perspective"], width=W, height=H, **changes)
    opts = {"step": 0.7, "ert_transmittance": 0.0}
    gl, ref = renderer.render(scene, **opts), reference.render(scene, **opts)
    plan = get_technique("raycast").make_plan(scene, **opts)
    assert np.abs(ref).max() > 0.05
    bound = terms_tolerance(plan, tf2d_tolerance(plan, plan.max_segments), gradient_floor(RAMP))
    assert metrics.max_abs_error(gl, ref) <= bound


def test_cli_renders_a_2d_json_file(tmp_path):
    from dvr_gl.frontends.cli import main
    out = tmp_path / "head2d.png"
    spec = os.path.join(os.path.dirname(__file__), os.pardir, "docs", "tf", "ct_skin_bone_2d.json")
    assert main(["render", "builtin:ct_head", "--tf", spec, "--size", "48x40",
                 "-o", str(out)]) == 0
    from PIL import Image
    rgb = np.asarray(Image.open(out), np.float64)
    assert rgb.shape == (40, 48, 3) and (rgb < 200).any()     # something drawn over the white
