"""The ray caster: GL against its NumPy reference, closed forms, hard cases, options."""

import math

import numpy as np
import pytest

import dvr_gl
from conftest import rounds_to_nearest
from dvr_gl import metrics, reference
from dvr_gl.techniques import raycast

U32 = 2.0 ** -24
MODES = ["composite", "mip", "minip", "average", "isosurface"]


def blobs(shape=(16, 20, 24), spacing=(1.0, 0.8, 1.3), origin=(5.0, -2.0, 1.0), dtype=np.float32):
    """A smooth field: two Gaussian blobs, values 0..100."""
    nz, ny, nx = shape
    z, y, x = np.meshgrid(np.linspace(0, 1, nz), np.linspace(0, 1, ny), np.linspace(0, 1, nx), indexing="ij")
    f = 100 * np.exp(-((x - 0.4) ** 2 + (y - 0.5) ** 2 + (z - 0.5) ** 2) / 0.05)
    f += 60 * np.exp(-((x - 0.75) ** 2 + (y - 0.3) ** 2 + (z - 0.6) ** 2) / 0.02)
    return dvr_gl.Volume(f.astype(dtype), spacing=spacing, origin=origin)


TF = dvr_gl.TransferFunction(color=[(0, 0.1, 0.2, 0.9), (40, 0.9, 0.6, 0.1), (100, 1, 1, 1)],
                             opacity=[(5, 0.0), (30, 0.25), (60, 0.05), (90, 0.9)], unit_distance=1.0)
VOLUME = blobs()
# minimum projection sees the low values, which TF leaves transparent
TF_LOW = dvr_gl.TransferFunction(color=TF.color_points, opacity=[(0, 0.6), (50, 0.2), (100, 0.0)])


def cameras(volume):
    lo, hi = volume.bounds
    centre = (lo + hi) / 2
    return {
        "perspective": dvr_gl.default_camera(volume, azimuth=35, elevation=25),
        "ortho": dvr_gl.default_camera(volume, azimuth=-20, elevation=10, ortho=True),
        "eye_inside": dvr_gl.Camera(centre + [3.0, 1.0, 2.0], centre - [4.0, 0.0, 1.0], fov=70),
        "eye_on_face_plane": dvr_gl.Camera([lo[0], centre[1], hi[2] + 10], [lo[0] + 5, centre[1], lo[2]], fov=50),
        "axis_aligned": dvr_gl.Camera(centre + [0, 0, 60], centre, fov=30),
        "diagonal_45": dvr_gl.Camera(centre + np.array([40.0, 0, 40.0]), centre, fov=30),
    }


def derived_tolerance(plan):
    """Bound on |GL - reference| per channel, from the float32 arithmetic of the shader.

    Per sample, the value differs by the texture unit's position rounding (the texel
    position n * tc carries ~4u * n of absolute error; times the largest difference
    between neighbouring samples) plus the trilinear arithmetic (~16u * max |s|). The
    table index carries 2u * (its range in entries); classification turns a value error
    into a colour/opacity error of at most the table's steepest slope (the LUT's or the
    step table's). Opacity correction
    and compositing add ~64u relative per segment (tested in test_shaders). Errors add at
    most linearly over the segments of the longest ray (transmittance weights <= 1).
    """
    v = plan.scene.volume
    vals = v.values()
    jump = max(float(np.abs(np.diff(vals, axis=a)).max()) for a in range(3))
    value_err = 4 * U32 * float(v.dims.max()) * jump + 16 * U32 * float(np.abs(vals).max())
    table = plan.lut.table.astype(np.float64)
    if plan.step_rows is not None:      # full segments interpolate the step table: its slope too
        table = np.concatenate([table, plan.step_rows.astype(np.float64)], axis=1)
    slope = float(np.abs(np.diff(table, axis=0)).max()) * plan.lut.scale  # per data unit
    index_err = 2 * U32 * plan.lut.size
    per_sample = slope * value_err + index_err * slope / plan.lut.scale + 64 * U32
    if plan.step_rows is not None:
        # a segment whose end falls within rounding of the ray's exit may be full in one
        # arithmetic and partial in the other: the two ways differ by step_table_error
        per_sample += 2 * plan.lut.step_table_error(plan.step / plan.scene.tf.unit_distance) / plan.max_segments
    if plan.scene.mode in ("mip", "minip", "average"):
        return per_sample * 4  # one classification of one (max / min / mean) value
    if plan.scene.mode == "isosurface":
        # shading of a bisected hit: position error <= the last bisection interval
        return 1e-3
    return per_sample * plan.max_segments


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("camera", ["perspective", "ortho", "eye_inside", "eye_on_face_plane",
                                    "axis_aligned", "diagonal_45"])
def test_gl_matches_reference(renderer, mode, camera):
    scene = dvr_gl.Scene(VOLUME, TF_LOW if mode == "minip" else TF, cameras(VOLUME)[camera], width=40,
                         height=32, mode=mode, iso_value=45.0 if mode == "isosurface" else None)
    opts = dict(step=0.7, ert_transmittance=0.0)
    gl = renderer.render(scene, **opts)
    ref = reference.render(scene, **opts)
    assert gl.shape == (32, 40, 4) and gl.dtype == np.float32
    assert ref[..., 3].max() > 0.05, "the scene must show something"
    if mode == "isosurface":
        # a pixel whose ray grazes the surface may find the crossing in one arithmetic and
        # not the other; require agreement on all but a few such pixels
        differ = np.abs(gl - ref).max(axis=-1) > derived_tolerance(raycast.make_plan(scene, **opts))
        assert differ.sum() <= 2
        return
    tol = derived_tolerance(raycast.make_plan(scene, **opts))
    assert metrics.max_abs_error(gl, ref) <= tol


def test_jittered_starts_follow_the_same_table(renderer):
    scene = dvr_gl.Scene(VOLUME, TF, cameras(VOLUME)["perspective"], width=40, height=32)
    opts = dict(step=1.1, ert_transmittance=0.0)
    plain = renderer.render(scene, **opts)
    jittered = renderer.render(scene, jitter_seed=7, **opts)
    ref = reference.render(scene, jitter_seed=7, **opts)
    assert metrics.max_abs_error(jittered, plain) > 1e-3  # jitter does move samples
    assert metrics.max_abs_error(jittered, ref) <= derived_tolerance(raycast.make_plan(scene, **opts))


@pytest.mark.parametrize("ert", [0.0, 1e-3, 0.05])
def test_empty_space_skipping_changes_no_pixel(renderer, ert):
    # with early termination too: the loop reads four full segments per iteration but
    # decides the end after each (deciding it once per group moved it with the groups'
    # starts, which skipping shifts: 0.04 off at ert 0.05)
    volume = blobs(shape=(32, 40, 48))
    tf = dvr_gl.TransferFunction(color=TF.color_points, opacity=[(30, 0.0), (60, 0.3), (100, 0.9)])
    scene = dvr_gl.Scene(volume, tf, cameras(volume)["perspective"], width=48, height=40)
    plan = raycast.make_plan(scene, step=0.5, skip_empty=True)
    assert 0 < plan.occupancy.sum() < plan.occupancy.size  # some bricks are skipped
    on = renderer.render(scene, step=0.5, skip_empty=True, ert_transmittance=ert)
    off = renderer.render(scene, step=0.5, skip_empty=False, ert_transmittance=ert)
    assert on[..., 3].max() > 0.1
    np.testing.assert_array_equal(on, off)


def _occupied_range_scene(camera_name, ortho_box=False):
    # one small blob off centre: most rays meet no occupied brick, the rest meet few
    volume = blobs(shape=(40, 48, 56))
    tf = dvr_gl.TransferFunction(color=TF.color_points, opacity=[(75, 0.0), (90, 0.6), (100, 0.9)])
    return dvr_gl.Scene(volume, tf, cameras(volume)[camera_name], width=48, height=40)


@pytest.mark.parametrize("camera", ["perspective", "ortho", "axis_aligned", "diagonal_45"])
def test_occupied_range_brackets_every_occupied_sample(renderer, camera):
    """The pass's (entry, exit) per pixel holds every point of the ray that the ray
    caster would place in an occupied brick (marched finely in float64, bricks found as
    the shader finds them), and leaves rays far from them empty."""
    from dvr_gl.gl.context import current
    from dvr_gl.reference.common import box_rays
    scene = _occupied_range_scene(camera)
    plan = raycast.make_plan(scene, step=0.5)
    occ = plan.occupancy
    assert 0 < occ.sum() < 0.2 * occ.size
    with current(renderer.ctx):
        tex = raycast.occupied_range(renderer, plan)
        rng = np.frombuffer(tex.read(), np.float32).reshape(scene.height, scene.width, 2)[::-1].reshape(-1, 2)
    enter, leave = rng[:, 0].astype(np.float64), -rng[:, 1].astype(np.float64)
    o, d, t0, t1 = box_rays(scene)
    brick = raycast.BRICK * np.asarray(scene.volume.spacing)
    shape = np.array(occ.shape[::-1])
    hit = np.zeros(len(o), bool)
    near = np.zeros(len(o), bool)
    for i in np.flatnonzero(t1 > t0):
        t = np.arange(t0[i], t1[i], 0.02)
        p = o[i] + t[:, None] * d[i]
        b = np.clip(np.floor(p / brick).astype(int), 0, shape - 1)
        inside = occ[b[:, 2], b[:, 1], b[:, 0]]
        if inside.any():
            hit[i] = True
            assert enter[i] <= t[inside].min() and leave[i] >= t[inside].max(), i
        # a ray at least a brick away from every occupied brick: its range is empty
        grown = np.clip(np.floor(p / brick + 0.5).astype(int), 0, shape - 1)
        near[i] = inside.any() or occ[grown[:, 2], grown[:, 1], grown[:, 0]].any()
    assert 0 < hit.sum() < len(o)
    far = ~near & (t1 > t0)
    assert far.sum() > 0.3 * (t1 > t0).sum()   # the scene leaves many rays far from the blob
    wide = np.zeros_like(far)
    for i in np.flatnonzero(far):
        wide[i] = leave[i] < enter[i]
    assert wide[far].mean() > 0.9


def test_occupied_range_pass_runs_only_where_it_can_shorten_a_ray(renderer):
    from dvr_gl.gl.context import current
    scene = _occupied_range_scene("perspective")
    with current(renderer.ctx):
        assert raycast.occupied_range(renderer, raycast.make_plan(scene, step=0.5)) is not None
        # every brick occupied: the range would be the box's own
        full = scene.replace(tf=dvr_gl.TransferFunction(color=TF.color_points, opacity=[(0, 0.1), (100, 0.5)]))
        assert raycast.make_plan(full, step=0.5).occupancy.all()
        assert raycast.occupied_range(renderer, raycast.make_plan(full, step=0.5)) is None
        # the eye inside the box, or skipping off
        inside = _occupied_range_scene("eye_inside")
        assert raycast.occupied_range(renderer, raycast.make_plan(inside, step=0.5)) is None
        assert raycast.occupied_range(renderer, raycast.make_plan(scene, step=0.5, skip_empty=False)) is None


@pytest.mark.parametrize("camera", ["perspective", "ortho", "eye_inside", "diagonal_45"])
@pytest.mark.parametrize("opts", [dict(step=0.7), dict(step=0.7, jitter_seed=3), dict(step=1.1, preintegrate=True),
                                  dict(step=1.3, preintegrate=True, refine=4, jitter_seed=3)],
                         ids=["plain", "jitter", "preint", "refine"])
def test_occupied_range_changes_no_pixel(renderer, camera, opts):
    scene = _occupied_range_scene(camera)
    on = renderer.render(scene, ert_transmittance=0.0, **opts)
    off = renderer.render(scene, ert_transmittance=0.0, skip_empty=False, **opts)
    assert on[..., 3].max() > 0.1
    np.testing.assert_array_equal(on, off)


def test_empty_space_skipping_identical_on_a_real_ct(renderer):
    from dvr_gl import data
    head = data.ct_head()
    tf = data.ct_head_tf()
    scene = dvr_gl.Scene(head, tf, dvr_gl.default_camera(head, azimuth=30, elevation=15), width=64, height=64)
    on = renderer.render(scene, skip_empty=True)
    off = renderer.render(scene, skip_empty=False)
    assert on[..., 3].max() > 0.3
    np.testing.assert_array_equal(on, off)


def test_early_ray_termination_drops_at_most_its_threshold(renderer):
    tf = dvr_gl.TransferFunction(color=TF.color_points, opacity=[(0, 0.3), (100, 0.95)])
    scene = dvr_gl.Scene(VOLUME, tf, cameras(VOLUME)["perspective"], width=40, height=32)
    full = renderer.render(scene, ert_transmittance=0.0)
    for ert in (1e-3, 0.05):
        early = renderer.render(scene, ert_transmittance=ert)
        assert metrics.max_abs_error(early, full) <= ert + 1e-6
        ref = reference.render(scene, ert_transmittance=ert)
        # GL and reference stop at the same sample except where T crosses the threshold
        # within rounding; then they differ by less than the threshold
        assert metrics.max_abs_error(early, ref) <= ert + 1e-5
    assert metrics.max_abs_error(renderer.render(scene, ert_transmittance=0.05), full) > 1e-4


def constant_volume(value, shape=(4, 5, 6), spacing=(1.0, 1.0, 1.0), dtype=np.float32):
    return dvr_gl.Volume(np.full(shape, value, dtype), spacing=spacing)


@pytest.mark.parametrize("alpha", [0.0, 1e-6, 0.1, 0.5, 0.99, 1 - 1e-6])
@pytest.mark.parametrize("unit", [1.0, 1e-3, 50.0])
def test_constant_box_closed_form(renderer, alpha, unit):
    vol = constant_volume(10.0, shape=(9, 5, 6), spacing=(1.0, 1.0, 0.75))  # 6 deep along z
    tf = dvr_gl.TransferFunction(color=[(0, 0.2, 0.6, 1.0)], opacity=[(0, alpha)], unit_distance=unit)
    lo, hi = vol.bounds
    centre = (lo + hi) / 2
    cam = dvr_gl.Camera(centre + [0, 0, 20], centre, ortho_height=2.0)
    scene = dvr_gl.Scene(vol, tf, cam, width=8, height=8)
    gl = renderer.render(scene, step=0.7, ert_transmittance=0.0)  # 6 / 0.7: a shorter last step
    L = vol.extent[2]
    A = -math.expm1(L / unit * math.log1p(-alpha)) if alpha < 1 else 1.0
    # ~9 segments, each ~64u relative (correctOpacity) plus compositing
    np.testing.assert_allclose(gl[..., 3], A, rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(gl[..., :3], np.broadcast_to(A * np.array([0.2, 0.6, 1.0]), (8, 8, 3)),
                               rtol=1e-5, atol=1e-7)


def test_opaque_box_gives_alpha_exactly_one(renderer):
    vol = constant_volume(3.0)
    tf = dvr_gl.TransferFunction(color=[(0, 1, 1, 1)], opacity=[(0, 1.0)], unit_distance=1e-4)
    scene = dvr_gl.Scene(vol, tf, dvr_gl.default_camera(vol, azimuth=20, elevation=30, zoom=2.5), width=16, height=16)
    img = renderer.render(scene)
    inside = img[..., 3] > 0
    assert inside.sum() > 100
    assert np.all(img[..., 3][inside] == 1.0)
    assert np.all(img[..., :3][inside] == 1.0)


def test_two_sample_thick_volume(renderer):
    data = np.stack([np.linspace(0, 100, 30 * 20).reshape(20, 30)] * 2).astype(np.float32)
    vol = dvr_gl.Volume(data, spacing=(1, 1, 0.5))
    for camera in (dvr_gl.default_camera(vol, azimuth=10, elevation=10),
                   # edge-on: rays along the thin slab
                   dvr_gl.Camera(vol.extent / 2 + [40, 0, 0], vol.extent / 2, ortho_height=1.0)):
        scene = dvr_gl.Scene(vol, TF, camera, width=32, height=24)
        gl = renderer.render(scene, ert_transmittance=0.0)
        ref = reference.render(scene, ert_transmittance=0.0)
        assert ref[..., 3].max() > 0.01
        assert metrics.max_abs_error(gl, ref) <= derived_tolerance(raycast.make_plan(scene))


def test_nan_cells_are_outside_the_domain(renderer):
    data = VOLUME.data.copy()
    data[4:9, 5:12, 6:14] = np.nan
    masked = dvr_gl.Volume(data, spacing=VOLUME.spacing, origin=VOLUME.origin, mask_nonfinite=True)
    for mode in ("composite", "mip", "average"):
        scene = dvr_gl.Scene(masked, TF, cameras(VOLUME)["perspective"], width=40, height=32, mode=mode)
        gl = renderer.render(scene, ert_transmittance=0.0)
        ref = reference.render(scene, ert_transmittance=0.0)
        assert np.all(np.isfinite(gl))
        assert metrics.max_abs_error(gl, ref) <= derived_tolerance(raycast.make_plan(scene, ert_transmittance=0.0))
        unmasked = renderer.render(dvr_gl.Scene(VOLUME, TF, scene.camera, width=40, height=32, mode=mode))
        assert metrics.max_abs_error(gl, unmasked) > 0.01  # the hole shows


def test_all_nan_without_masking_is_an_error():
    data = VOLUME.data.copy()
    data[0, 0, 0] = np.inf
    with pytest.raises(ValueError, match="non-finite"):
        dvr_gl.Volume(data)


@pytest.mark.parametrize("value", [7.0, 45.0])
def test_constant_field_under_isosurface_shading(renderer, value):
    vol = constant_volume(value)
    scene = dvr_gl.Scene(vol, TF, dvr_gl.default_camera(vol, azimuth=30, elevation=20), width=16, height=16,
                         mode="isosurface", iso_value=45.0)
    img = renderer.render(scene)
    assert np.all(np.isfinite(img))
    # a constant field never changes status along a ray (equal to iso included): no surface
    assert np.all(img == 0)


def test_isosurface_of_a_step_with_a_flat_side_is_shaded_not_nan(renderer):
    data = np.zeros((6, 6, 6), np.float32)
    data[:, :, 3:] = 10.0
    vol = dvr_gl.Volume(data)
    scene = dvr_gl.Scene(vol, TF, dvr_gl.default_camera(vol, azimuth=60, elevation=10), width=24, height=24,
                         mode="isosurface", iso_value=5.0)
    gl = renderer.render(scene)
    ref = reference.render(scene)
    assert np.all(np.isfinite(gl)) and (gl[..., 3] == 1).sum() > 20
    assert (np.abs(gl - ref).max(axis=-1) > 1e-3).sum() <= 2


# rgba8 rounds to nearest on llvmpipe: half a step of 1/255 (GL allows either neighbour,
# a whole step, elsewhere; see conftest.rounds_to_nearest). llvmpipe converts float to half
# by truncation (measured: errors up to 1.84 * 2**-11 relative), so half floats get a
# whole ulp, 2**-10 relative, not the half ulp of round-to-nearest.
@pytest.mark.parametrize("target,bound", [("rgba8", 0.5 / 255), ("rgba16f", 2.0 ** -10)])
def test_low_precision_targets_error_is_their_rounding(renderer, target, bound):
    if target == "rgba8" and not rounds_to_nearest(renderer):
        bound = 1.0 / 255
    scene = dvr_gl.Scene(VOLUME, TF, cameras(VOLUME)["perspective"], width=40, height=32)
    full = renderer.render(scene, ert_transmittance=0.0)
    low = renderer.render(scene, target=target, ert_transmittance=0.0)
    err = np.abs(low.astype(np.float64) - full)
    assert err.max() > 0  # the target does round
    # one final write per pixel: the rounding of that write only (relative for half floats)
    limit = bound if target == "rgba8" else bound * np.maximum(np.abs(full), 2.0 ** -14)
    assert np.all(err <= limit + 1e-7)
    ref = reference.render(scene, target=target, ert_transmittance=0.0)
    assert metrics.max_abs_error(low, ref) <= bound + 1e-6


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.int16, np.float64])
def test_integer_and_double_data_map_back_to_data_units(renderer, dtype):
    rng = np.random.default_rng(3)
    values = rng.integers(0, 100, (6, 7, 8))
    tf = dvr_gl.TransferFunction(color=[(0, 0, 0, 0), (100, 1, 1, 1)], opacity=[(0, 0), (100, 0.8)])
    as32 = dvr_gl.Volume(values.astype(np.float32))
    other = dvr_gl.Volume(values.astype(dtype))
    cam = dvr_gl.default_camera(as32, azimuth=20, elevation=20)
    a = renderer.render(dvr_gl.Scene(as32, tf, cam, width=16, height=16))
    b = renderer.render(dvr_gl.Scene(other, tf, cam, width=16, height=16))
    np.testing.assert_array_equal(a, b)


def test_16_bit_data_keeps_its_precision(renderer):
    # values 1000 and 1001 differ by 1/65535 of the range: an 8-bit texture would merge them
    data = np.full((4, 4, 4), 1000, np.uint16)
    data[:, :, 2:] = 1001
    vol = dvr_gl.Volume(data)
    tf = dvr_gl.TransferFunction(color=[(1000, 1, 0, 0), (1001, 0, 1, 0)], opacity=[(1000, 0.5)])
    scene = dvr_gl.Scene(vol, tf, dvr_gl.Camera((1.5, 1.5, 20), (1.5, 1.5, 0), ortho_height=3.0),
                         width=12, height=12, mode="mip")
    img = renderer.render(scene)
    left, right = img[6, 1], img[6, 10]
    assert left[0] > 0.49 and left[1] < 0.01 and right[1] > 0.49 and right[0] < 0.01


def test_backends_give_the_same_image(egl_renderer, osmesa_renderer):
    scene = dvr_gl.Scene(VOLUME, TF, cameras(VOLUME)["perspective"], width=40, height=32)
    a = egl_renderer.render(scene)
    b = osmesa_renderer.render(scene)
    assert a[..., 3].max() > 0.1
    assert metrics.max_abs_error(a, b) <= 1e-6


def test_unlit_composite_scene_builds_only_what_it_uses():
    scene = dvr_gl.Scene(VOLUME, TF, cameras(VOLUME)["perspective"], width=16, height=16)
    with dvr_gl.Renderer() as r:
        r.render(scene, skip_empty=False)
        kinds = sorted(k for k, _ in r.created)
        assert kinds == ["step_tf", "target", "tf", "volume"]  # no gradient, jitter, mask or brick texture
        (vs, fs), = r.programs.sources.values()
        prog = next(iter(r.programs._programs.values()))
        # the compiled program has no lighting or jitter inputs: that code is not built
        assert not {"u_phong", "u_gradient_epsilon", "t_jitter", "t_occupancy", "t_cell_valid"} & set(prog)
        assert "#define MODE_COMPOSITE 1" in fs
        r.render(scene, skip_empty=True, jitter_seed=1)
        # skipping adds the brick occupancy (every brick is occupied here: no range pass)
        assert sorted(k for k, _ in r.created) == ["jitter", "occupancy", "step_tf", "target", "tf", "volume"]
        r.render(scene, skip_empty=True, jitter_seed=1)  # a second frame makes nothing new
        assert len(r.created) == 6
        iso = scene.replace(mode="isosurface", iso_value=40.0)
        r.render(iso)
        iso_prog = [p for (v, f, d), p in r.programs._programs.items() if ("MODE_ISOSURFACE", 1) in d][0]
        assert {"u_phong", "u_gradient_epsilon"} <= set(iso_prog)


def test_reference_and_gl_reject_bad_options(renderer):
    scene = dvr_gl.Scene(VOLUME, TF, cameras(VOLUME)["perspective"], width=8, height=8)
    for kwargs, exc, text in [
        (dict(step=0), ValueError, "step must be positive"),
        (dict(step=-1.0), ValueError, "step must be positive"),
        (dict(step=float("nan")), ValueError, "step must be positive and finite, got nan"),
        (dict(step="1"), TypeError, "step must be a number"),
        (dict(step=1e-9), ValueError, "absurdly small"),
        (dict(target="rgb10"), ValueError, "target must be one of"),
        (dict(jitter_seed=1.5), TypeError, "jitter_seed must be None or an integer, got 1.5"),
        (dict(ert_transmittance=1.0), ValueError, "ert_transmittance must be in \\[0, 1\\), got 1.0"),
        (dict(skip_empty="yes"), TypeError, "skip_empty must be True or False"),
        (dict(colour="red"), TypeError, "colour"),
    ]:
        with pytest.raises(exc, match=text):
            renderer.render(scene, **kwargs)
        with pytest.raises(exc, match=text):
            reference.render(scene, **kwargs)
    with pytest.raises(ValueError, match="technique must be one of raycast, slice2d, slice3d, tetra, particles, splat, got 'splatz'"):
        renderer.render(scene, technique="splatz")


# -- error against the exact image ---------------------------------------------------------

def _smooth_scene(size=24):
    """A smooth field and a TF with only end control points, so the lookup table is exact
    (linear interpolation of a linear function) and only the marching error remains."""
    vol = blobs(shape=(12, 14, 16), spacing=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0))
    tf = dvr_gl.TransferFunction(color=[(0, 0.2, 0.4, 1.0), (100, 1.0, 0.9, 0.3)], opacity=[(0, 0.0), (100, 0.6)])
    return dvr_gl.Scene(vol, tf, dvr_gl.default_camera(vol, azimuth=25, elevation=15, zoom=1.3), size, size)


def test_error_against_exact_falls_at_second_order(renderer, tmp_path):
    scene = _smooth_scene()
    exact = reference.exact(scene, cache_dir=tmp_path)
    steps = np.array([1.0, 0.5, 0.25, 0.125, 0.0625])
    errors = np.array([metrics.rmse(renderer.render(scene, step=d, ert_transmittance=0.0), exact) for d in steps])
    # Midpoint samples with a true-length last step are second order. One halving's ratio
    # jitters (measured 5.7, 5.1, 2.5, 4.9) with where each ray's last step falls, so fit
    # the order over four halvings (measured 2.12).
    order = np.polyfit(np.log(steps), np.log(errors), 1)[0]
    assert 1.8 < order < 2.5, (errors, order)


def test_gl_error_at_quarter_voxel_is_that_of_an_ideal_float64_marcher(renderer, tmp_path):
    from dvr_gl import data
    head = data.ct_head()
    scene = dvr_gl.Scene(head, data.ct_head_tf(), dvr_gl.default_camera(head, elevation=90, zoom=1.3), 40, 40)
    step = 0.25 * head.min_spacing
    exact = reference.exact(scene, cache_dir=tmp_path)
    gl = metrics.rmse(renderer.render(scene, step=step), exact)
    ideal = metrics.rmse(reference.render(scene, step=step, lut_exact=True, ert_transmittance=0.0), exact)
    assert gl <= 1.5 * ideal, (gl, ideal)


@pytest.mark.parametrize("camera", ["perspective", "ortho", "eye_inside"])
@pytest.mark.parametrize("jitter_seed", [None, 3])
def test_step_table_is_the_per_sample_correction(renderer, camera, jitter_seed):
    """Full-length segments read the step table instead of correcting each sample: the
    image is the per-sample one up to the table's own difference (step_table_error per
    segment) and the float32 bounds of both; the references agree to that difference."""
    scene = dvr_gl.Scene(VOLUME, TF, cameras(VOLUME)[camera], width=40, height=32)
    opts = dict(step=0.7, ert_transmittance=0.0, jitter_seed=jitter_seed)
    table_plan = raycast.make_plan(scene, **opts)
    plain_plan = raycast.make_plan(scene, step_table=False, **opts)
    assert table_plan.step_rows is not None and plain_plan.step_rows is None
    assert "STEP_TABLE" not in plain_plan.defines
    difference = table_plan.max_segments * table_plan.lut.step_table_error(0.7 / TF.unit_distance)
    with_table, without = renderer.render(scene, **opts), renderer.render(scene, step_table=False, **opts)
    assert with_table[..., 3].max() > 0.1
    assert metrics.max_abs_error(with_table, without) <= (difference + derived_tolerance(table_plan)
                                                          + derived_tolerance(plain_plan))
    assert metrics.max_abs_error(reference.render(scene, **opts),
                                 reference.render(scene, step_table=False, **opts)) <= difference + 1e-12
