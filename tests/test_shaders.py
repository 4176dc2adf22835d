"""Each function of shaders/common, evaluated on its own in a shader over a grid of inputs
(edge values included) and compared with its NumPy twin.

Tolerances: the shader computes in float32 (unit roundoff u = 2**-24 ~ 6e-8); the NumPy
twins in float64. Each bound below is a small multiple of u times the condition of the
computation, stated next to it."""

import numpy as np
import pytest

import dvr_gl
from dvr_gl.gl import harness
from dvr_gl.gl.programs import ShaderSourceError, apply_defines, build_source, resolve_includes, resolve_text
from dvr_gl.reference import common
from dvr_gl.reference.raycast import refine_iso_bisection
from dvr_gl.model.field import gradient
from dvr_gl.reference.shading import shade_blinn_phong
from dvr_gl.model.transfer import LookupTable
from dvr_gl.techniques.gpu import tf_texture, volume_texture

U32 = 2.0 ** -24


def _made(renderer, make, *args):
    """Renderer resources are made with its context current."""
    with renderer.ctx:
        return make(*args)


# -- the source loader ------------------------------------------------------------------

def test_includes_are_inlined_once_with_markers():
    src = resolve_text('#version 330 core\n#include "common/shading.glsl"\n#include "common/sampling.glsl"\n')
    assert src.count('// --- start of "common/sampling.glsl" ---') == 1
    assert src.count('// --- start of "common/shading.glsl" ---') == 1
    assert "#line 3" in src  # line numbers resume after the include


def test_circular_include_is_refused(tmp_path):
    (tmp_path / "a.glsl").write_text('#include "b.glsl"\n')
    (tmp_path / "b.glsl").write_text('#include "a.glsl"\n')
    with pytest.raises(ShaderSourceError, match="circular #include: a.glsl -> b.glsl -> a.glsl"):
        resolve_includes("a.glsl", tmp_path)


def test_defines_override_declared_defaults_and_unknown_names_raise():
    src = build_source("raycast/raycast.frag", {"MODE_MIP": 1})
    lines = src.splitlines()
    version = next(i for i, line in enumerate(lines) if line.startswith("#version"))
    assert "#define MODE_MIP 1" in lines[version + 1:version + 3]
    with pytest.raises(ShaderSourceError, match="unknown shader switches \\['MODE_FANCY'\\]"):
        apply_defines(resolve_includes("raycast/raycast.frag"), {"MODE_FANCY": 1})


# -- ray_box.glsl -----------------------------------------------------------------------

def test_intersect_box(ctx):
    rng = np.random.default_rng(1)
    lo, hi = np.array([0.0, 0.0, 0.0]), np.array([3.0, 2.0, 1.5])
    origins = rng.uniform(-2, 5, (400, 3))
    dirs = rng.normal(size=(400, 3))
    # edge cases: rays parallel to faces (inside and outside the slab), origin on a face,
    # origin on a corner, origin inside
    dirs[:60, 0] = 0
    dirs[30:90, 2] = 0
    origins[90:100] = [0.0, 1.0, 0.75]
    origins[100:110] = [3.0, 2.0, 1.5]
    origins[110:120] = [1.5, 1.0, 0.7]
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    o32, d32 = origins.astype(np.float32), dirs.astype(np.float32)
    gl = harness.evaluate(ctx, ["common/ray_box.glsl"],
                          "out0 = vec4(intersectBox(in0.xyz, in1.xyz, vec3(0.0), vec3(3.0, 2.0, 1.5)), 0.0, 0.0);",
                          [np.c_[o32, np.zeros(400)], np.c_[d32, np.zeros(400)]])
    t0, t1 = common.ray_box(o32.astype(np.float64), d32.astype(np.float64), lo, hi)
    hit = t1 > t0
    gl_hit = gl[:, 1] > gl[:, 0]
    # hits must agree except where the segment is within rounding of zero length
    margin = np.abs(t1 - t0) > 1e-5
    assert np.array_equal(hit[margin], gl_hit[margin])
    assert hit.sum() > 40 and (~hit).sum() > 40  # the grid covers both cases
    # |t| <= ~10 here; each t is one subtraction and one product in float32: <= 4u|t|
    np.testing.assert_allclose(gl[hit, 0], t0[hit], rtol=4 * U32, atol=1e-6)
    np.testing.assert_allclose(gl[hit, 1], t1[hit], rtol=4 * U32, atol=1e-6)
    assert np.all(gl[:, 0] >= 0)


# -- compositing.glsl -------------------------------------------------------------------

def test_correct_opacity_edge_values(ctx):
    alphas = np.array([0.0, 1e-7, 1e-4, 0.01, 0.3, 0.5, 0.9, 0.999, 1 - 2 ** -23, 1.0])
    lengths = np.array([0.0, 1e-6, 1e-3, 0.25, 0.5, 1.0, 3.0, 100.0, 1e4])
    a, x = [g.ravel() for g in np.meshgrid(alphas, lengths)]
    a32, x32 = a.astype(np.float32), x.astype(np.float32)
    b32 = (1 - a).astype(np.float32)  # transparency, precise near alpha = 1
    gl = harness.evaluate(ctx, ["common/compositing.glsl"], "out0 = vec4(correctOpacity(in0.x, in0.z, in0.y));",
                          [np.c_[a32, x32, b32, np.zeros(a.size)]])[:, 0]
    ref = common.correct_opacity(a32.astype(np.float64), x32.astype(np.float64), b32.astype(np.float64))
    assert np.all(gl[x == 0] == 0) and np.all(gl[(a == 1) & (x > 0)] == 1)
    # -expm1(x * log1p(-a)): log1p, the product and expm1 each keep relative error within
    # a few u (the tricks cancel the rounding of 1 + x); the product's error is amplified
    # by x*log1p(-a)/expm1(...) which is <= 1 + |x log1p(-a)|, bounded here by ~16 for the
    # largest argument that still gives a result below 1. 64u relative covers that.
    np.testing.assert_allclose(gl, ref, rtol=64 * U32, atol=1e-30)


def test_log1p_expm1_keep_relative_precision(ctx):
    x = np.array([-0.5, -1e-3, -1e-6, -1e-9, 0.0, 1e-9, 1e-6, 1e-3, 0.5, 2.0], np.float32)
    gl = harness.evaluate(ctx, ["common/compositing.glsl"],
                          "out0 = vec4(log1pAccurate(in0.x), expm1Accurate(in0.x), 0.0, 0.0);",
                          [np.c_[x, np.zeros((x.size, 3))]])
    np.testing.assert_allclose(gl[:, 0], np.log1p(x.astype(np.float64)), rtol=8 * U32, atol=1e-37)
    np.testing.assert_allclose(gl[:, 1], np.expm1(x.astype(np.float64)), rtol=8 * U32, atol=1e-37)


def test_composite_front_to_back(ctx):
    rng = np.random.default_rng(2)
    rgb = rng.random((200, 3)).astype(np.float32)
    alpha = rng.random(200).astype(np.float32)
    alpha[:20], alpha[20:40] = 0.0, 1.0
    acc = rng.random((200, 3)).astype(np.float32) * 0.5
    acc_alpha = rng.random(200).astype(np.float32)
    acc_alpha[40:50] = 1.0
    acc_alpha[50:60] = 0.0
    body = ("vec3 c = in0.rgb; float a = in0.a; compositeFrontToBack(c, a, in1.rgb, in1.a);"
            " out0 = vec4(c, a);")
    gl = harness.evaluate(ctx, ["common/compositing.glsl"], body, [np.c_[acc, acc_alpha], np.c_[rgb, alpha]])
    c, a = common.composite_front_to_back(acc.astype(np.float64), acc_alpha.astype(np.float64),
                                          rgb.astype(np.float64), alpha.astype(np.float64))
    np.testing.assert_allclose(gl[:, :3], c, rtol=0, atol=4 * U32)   # values <= 1.5: a few roundings
    np.testing.assert_allclose(gl[:, 3], a, rtol=0, atol=4 * U32)
    assert np.all(gl[20:40, 3] == 1)  # alpha 1 makes the pixel exactly opaque
    assert np.all(gl[40:50, 3] == 1)  # and an opaque pixel stays opaque


# -- classification.glsl ----------------------------------------------------------------

def test_apply_tf_matches_lookup_table(ctx, renderer):
    tf = dvr_gl.TransferFunction(color=[(-100, 0, 0, 1), (0, 1, 0.5, 0), (250.5, 1, 1, 1)],
                                 opacity=[(-50, 0), (10, 0.8), (11, 0.1), (300, 1)])
    lut = LookupTable(tf)
    s = np.concatenate([[-1e6, -100, -50, 0, 10, 10.5, 11, 250.5, 300, 1e6],
                        np.linspace(-120, 320, 500)]).astype(np.float32)
    gl = harness.evaluate(ctx, ["common/classification.glsl"], "out0 = vec4(applyTF(in0.x).rgb, transparencyTF(in0.x));",
                          [np.c_[s, np.zeros((s.size, 3))]], textures={"t_tf": _made(renderer, tf_texture, renderer, lut)},
                          uniforms={"u_tf_lo": lut.lo, "u_tf_scale": lut.scale, "u_tf_size": lut.size})
    ref = lut.lookup(s.astype(np.float64))
    ref[:, 3] = lut.lookup_transparency(s.astype(np.float64))
    # the table index u = (s - lo) * scale has absolute error <= ~2u * |s - lo| * scale
    # (<= 4096 * 2u ~ 5e-4 of one entry); one entry changes a value by at most the TF's
    # steepest slope per entry (here 0.7 between 10 and 11 spread over ~10 entries: 0.07).
    bound = 4096 * 2 * U32 * 0.07 + 4 * U32
    np.testing.assert_allclose(gl, ref, rtol=0, atol=bound)


def test_classified_segment(ctx, renderer):
    """classifiedSegment = TF lookup then opacity correction, premultiplied. A lookup
    error e (previous test) in alpha moves 1 - (1 - alpha)^x by at most x * e, x the
    length in unit distances (up to 50 here); correctOpacity adds ~64u (tested above)
    and the product with the colour one more rounding."""
    tf = dvr_gl.TransferFunction(color=[(0, 1, 0, 0), (255, 0, 0, 1)],
                                 opacity=[(0, 0.0), (10, 0.0), (11, 0.7), (250, 1.0)], unit_distance=2.0)
    lut = LookupTable(tf)
    rng = np.random.default_rng(5)
    s = np.concatenate([[-5.0, 0, 10, 10.5, 11, 249.9, 250, 300], rng.uniform(-20, 280, 300)])
    lengths = np.concatenate([[0.0, 1e-6, 0.5, 1.0, 3.0, 100.0, 2.0, 0.25], rng.uniform(0, 4, 300)])
    inputs = np.c_[s, lengths, np.zeros((s.size, 2))].astype(np.float32)
    gl = harness.evaluate(ctx, ["common/classification.glsl"], "out0 = classifiedSegment(in0.x, in0.y);",
                          [inputs], textures={"t_tf": _made(renderer, tf_texture, renderer, lut)},
                          uniforms={"u_tf_lo": lut.lo, "u_tf_scale": lut.scale, "u_tf_size": lut.size})
    ref = common.classified_segment(lut.lookup, lut.lookup_transparency, inputs[:, 0].astype(np.float64),
                                    inputs[:, 1].astype(np.float64))
    assert ref[:, 3].max() > 0.9 and (ref[:, 3] == 0).any()
    bound = float(lengths.max() / tf.unit_distance) * (4096 * 2 * U32 * 0.07 + 4 * U32) + 128 * U32
    np.testing.assert_allclose(gl, ref, rtol=0, atol=bound)


# -- sampling.glsl, shading.glsl, isosurface.glsl --------------------------------------

@pytest.fixture(scope="module")
def small_volume():
    rng = np.random.default_rng(3)
    data = rng.uniform(-5, 20, (5, 6, 7)).astype(np.float32)
    return dvr_gl.Volume(data, spacing=(0.5, 1.0, 2.0), origin=(10.0, -3.0, 2.0))


def _volume_uniforms(v):
    return {"u_dims": tuple(float(n) for n in v.dims), "u_spacing": tuple(v.spacing)}


def _filter_path(ctx, texture_filter):
    """Both ways of interpolating textures: texel fetches in the shader (GPUs, whose filter
    weights are quantised), and the texture unit where the context's probe finds its
    weights exact (llvmpipe), as the program cache sets it."""
    from dvr_gl.gl.capabilities import linear_filter_is_exact
    if texture_filter and not linear_filter_is_exact(ctx):
        pytest.skip("this context's filter weights are quantised; the cache never sets the switch here")
    return {"TEXTURE_FILTER_EXACT": texture_filter}


@pytest.mark.parametrize("texture_filter", [0, 1])
def test_sample_volume_is_trilinear(ctx, renderer, small_volume, texture_filter):
    v = small_volume
    rng = np.random.default_rng(4)
    p = rng.uniform(-0.5, 1.5, (500, 3)) * v.extent  # inside and outside (clamped)
    p[:8] = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)]) * v.extent  # corners
    p32 = p.astype(np.float32)
    gl = harness.evaluate(ctx, ["common/sampling.glsl"], "out0 = vec4(sampleVolume(in0.xyz));",
                          [np.c_[p32, np.zeros(500)]], textures={"t_volume": _made(renderer, volume_texture, renderer, v)},
                          uniforms=_volume_uniforms(v), defines=_filter_path(ctx, texture_filter))[:, 0]
    ref = common.trilinear(v.values(), p32.astype(np.float64) / v.spacing)
    # llvmpipe filters float textures in float32: the texel position n*tc - 0.5 carries
    # ~n * 2u of absolute error (n <= 7 here), times the largest jump between neighbours (25);
    # the fetch path's p / spacing carries less. An 8-bit weight would err by up to 25/512.
    np.testing.assert_allclose(gl, ref, rtol=0, atol=7 * 4 * U32 * 25 + 8 * U32 * 20)
    corner_values = [v.values()[-1 if z else 0, -1 if y else 0, -1 if x else 0]
                     for x in (0, 1) for y in (0, 1) for z in (0, 1)]
    np.testing.assert_allclose(gl[:8], corner_values, atol=1e-5)  # texel centres are the samples


@pytest.mark.parametrize("texture_filter", [0, 1])
def test_gradient_central_differences(ctx, renderer, small_volume, texture_filter):
    v = small_volume
    rng = np.random.default_rng(5)
    p = rng.uniform(-0.1, 1.1, (300, 3)) * v.extent
    p32 = p.astype(np.float32)
    gl = harness.evaluate(ctx, ["common/shading.glsl"], "out0 = vec4(gradient(in0.xyz), 0.0);",
                          [np.c_[p32, np.zeros(300)]], textures={"t_volume": _made(renderer, volume_texture, renderer, v)},
                          uniforms=_volume_uniforms(v), defines=_filter_path(ctx, texture_filter))[:, :3]
    ref = gradient(v, v.values(), p32.astype(np.float64) + v.origin)
    # each difference of two samples (error as above, ~1e-4) over 2 * spacing (>= 1)
    np.testing.assert_allclose(gl, ref, rtol=0, atol=2e-4)


def test_shade_blinn_phong_including_zero_gradient(ctx):
    rng = np.random.default_rng(6)
    color = rng.random((300, 3))
    grad = rng.normal(size=(300, 3)) * rng.choice([1e-3, 1.0, 100.0], (300, 1))
    grad[:30] = 0.0  # constant field: left unshaded, no NaN
    ray = rng.normal(size=(300, 3))
    ray /= np.linalg.norm(ray, axis=1, keepdims=True)
    phong = (0.3, 0.7, 0.2, 32.0)
    c32, g32, r32 = (a.astype(np.float32) for a in (color, grad, ray))
    gl = harness.evaluate(ctx, ["common/shading.glsl"], "out0 = vec4(shadeBlinnPhong(in0.rgb, in1.xyz, in2.xyz), 0.0);",
                          [np.c_[c32, np.zeros(300)], np.c_[g32, np.zeros(300)], np.c_[r32, np.zeros(300)]],
                          uniforms={"u_phong": phong, "u_gradient_epsilon": 1e-6})[:, :3]
    ref = shade_blinn_phong(c32.astype(np.float64), g32.astype(np.float64), r32.astype(np.float64), phong, 1e-6)
    assert np.all(np.isfinite(gl))
    np.testing.assert_array_equal(gl[:30], c32[:30])
    # |N.L|^32 amplifies the relative error of N.L (a few u) 32-fold: <= 0.2 * 32 * 8u
    np.testing.assert_allclose(gl, ref, rtol=0, atol=0.2 * 32 * 8 * U32 + 8 * U32)


def test_refine_iso_bisection(ctx, renderer, small_volume):
    v = small_volume
    rng = np.random.default_rng(7)
    o = (rng.uniform(0.1, 0.9, (200, 3)) * v.extent).astype(np.float32)
    d = rng.normal(size=(200, 3))
    d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
    iso = 7.5
    values = v.values()

    def sample(t, rows=slice(None)):
        return common.trilinear(values, (o[rows] + np.asarray(t)[..., None] * d[rows]).astype(np.float64) / v.spacing)

    # intervals whose ends straddle the iso value
    ta, tb = np.zeros(200), np.full(200, 0.6)
    straddle = (sample(ta) >= iso) != (sample(tb) >= iso)
    assert straddle.sum() > 20
    o, d, ta, tb = o[straddle], d[straddle], ta[straddle], tb[straddle]
    gl = harness.evaluate(ctx, ["common/isosurface.glsl"],
                          "out0 = vec4(refineIsoBisection(in0.xyz, in1.xyz, in0.w, in1.w, 7.5));",
                          [np.c_[o, ta], np.c_[d, tb]], textures={"t_volume": _made(renderer, volume_texture, renderer, v)},
                          uniforms=_volume_uniforms(v))[:, 0]
    ref = refine_iso_bisection(lambda t: sample(t), ta, tb, iso)
    # both end within 0.6 / 2**16 of a crossing; where a midpoint sample lands within
    # rounding of the iso value the two may keep different halves, but the field there is
    # within that rounding of iso, so compare the field at both answers instead of t
    assert np.all(np.abs(gl - ref) <= 0.6 / 2 ** 15 + 1e-6) or np.all(
        np.abs(sample(gl.astype(np.float64)) - iso) < 1e-2)
    assert np.all(np.abs(sample(ref) - iso) < 25 * 0.6 / 2 ** 16 * 4)


@pytest.mark.parametrize("technique, options", [
    ("raycast", {"step": 0.4}),
    ("raycast", {"step": 0.4, "shading": True}),
    ("raycast", {"step": 0.4, "shading": True, "gradients": "texture"}),
    ("raycast", {"step": 0.4, "mode": "mip"}),
    ("slice3d", {"step": 0.5}),
    ("slice2d", {"interpolate": 1}),
    ("slice2d", {"shading": True}),
])
def test_both_filter_paths_render_the_same_image(technique, options):
    """Texel fetches interpolated in the shader (what a GPU with quantised filter weights
    runs) and the texture unit's filter (llvmpipe) give the same images, to float
    rounding: every technique that reads the volume, its gradients or its stacks."""
    exact_here = linear_filter_probe()
    options = dict(options)
    shading, mode = options.pop("shading", False), options.pop("mode", "composite")
    volume = dvr_gl.Volume(np.random.default_rng(3).random((9, 10, 11)).astype(np.float32) ** 2,
                           spacing=(1.0, 0.8, 1.2))
    tf = dvr_gl.TransferFunction(color=[(0.0, 0.2, 0.4, 1.0), (0.5, 1.0, 0.5, 0.2), (1.0, 1.0, 1.0, 1.0)],
                                 opacity=[(0.0, 0.0), (0.3, 0.1), (0.6, 0.8), (1.0, 0.4)], unit_distance=1.0)
    scene = dvr_gl.Scene(volume, tf, dvr_gl.default_camera(volume, azimuth=30, elevation=20), 24, 20,
                         shading=shading, mode=mode)
    images = {}
    for texture_filter in ((0, 1) if exact_here else (0,)):
        with dvr_gl.Renderer() as r:
            r.programs._context_defines = {"TEXTURE_FILTER_EXACT": texture_filter}
            images[texture_filter] = r.render(scene, technique=technique, **options)
    assert images[0][..., 3].max() > 0.2
    if exact_here:
        # both are float32 trilinear interpolation of the same texels (position rounding
        # a few 1e-7 of a texel, times neighbour jumps <= 1), through at most ~40 samples
        assert np.abs(images[0] - images[1]).max() <= 2e-5
    else:  # a GPU: the fetch path is what every program gets
        with dvr_gl.Renderer() as r:
            assert r.programs.context_defines == {"TEXTURE_FILTER_EXACT": 0}
            assert np.abs(r.render(scene, technique=technique, **options) - images[0]).max() == 0.0


def linear_filter_probe():
    from dvr_gl.gl.context import shared_context
    from dvr_gl.gl.capabilities import linear_filter_is_exact
    return linear_filter_is_exact(shared_context()[0])
