"""Pre-integrated ray casting: empty-space skipping, and refinement where the transfer
function has detail (``raycast.make_plan(..., preintegrate=True, refine=k)``)."""

import numpy as np
import pytest

import dvr_gl
from dvr_gl import metrics, reference
from dvr_gl.reference.common import box_rays
from dvr_gl.model.field import trilinear
from dvr_gl.reference.raycast import _jitter_per_pixel
from dvr_gl.techniques import raycast

from test_raycast import TF, VOLUME, blobs, cameras
from test_slicing import SPIKE, preintegrated_tolerance

W, H = 40, 32


def _scene(tf=SPIKE, camera="perspective", volume=VOLUME, **kw):
    return dvr_gl.Scene(volume, tf, cameras(volume)[camera], width=W, height=H, **kw)


# -- skipping ------------------------------------------------------------------------------

@pytest.mark.parametrize("tf", [SPIKE, TF], ids=["spike", "smooth"])
@pytest.mark.parametrize("refine", [1, 4])
def test_preintegrated_skipping_changes_no_pixel(renderer, tf, refine):
    """A skipped segment lies in a brick whose range, widened by a table cell, has zero
    opacity: its table entry is exactly zero, so the image is identical bit for bit."""
    volume = blobs(shape=(32, 40, 48))
    scene = _scene(tf, volume=volume)
    opts = dict(step=0.7, preintegrate=True, refine=refine, ert_transmittance=0.0)
    plan = raycast.make_plan(scene, **opts)
    assert 0 < plan.bricks.sum() < plan.bricks.size        # some bricks are skipped
    on = renderer.render(scene, **opts)
    off = renderer.render(scene, skip_empty=False, **opts)
    assert on[..., 3].max() > 0.1
    np.testing.assert_array_equal(on, off)


def test_preintegrated_occupancy_counts_a_spike_between_table_nodes():
    """A spike narrower than a table cell, just beyond a brick's range, still marks the
    brick occupied (the table's bilinear nodes reach it)."""
    volume = dvr_gl.Volume(np.full((10, 10, 10), 10.0, np.float32))
    table = raycast.preintegration_table(_scene(volume=volume), 1.0, dvr_gl.util.cache.TableCache())
    cell = 1.0 / table.scale
    near = dvr_gl.TransferFunction(color=[(0, 1, 1, 1), (100, 1, 1, 1)],
                                   opacity=[(0, 0.0), (10 + 0.5 * cell, 0.0), (10 + 0.6 * cell, 0.5),
                                            (10 + 0.7 * cell, 0.0)])
    far = dvr_gl.TransferFunction(color=[(0, 1, 1, 1), (100, 1, 1, 1)],
                                  opacity=[(0, 0.0), (10 + 3 * cell, 0.0), (10 + 3.1 * cell, 0.5),
                                           (10 + 3.2 * cell, 0.0)])
    ranges = raycast.brick_value_ranges(volume)
    assert raycast.preint_occupancy(ranges, near, table).all()
    assert not raycast.preint_occupancy(ranges, far, table).any()


# -- the gradient bound and the TF's detail ------------------------------------------------

@pytest.mark.parametrize("block", [1, 2])
def test_gradient_bound_is_a_lipschitz_bound_of_the_trilinear_field(block):
    """For random pairs of points within one block and its 26 neighbours, the field
    changes by no more than the block's bound times their distance; and the bound is
    not loose by more than the cell rule's own factor (edges of a cell can differ)."""
    rng = np.random.default_rng(3)
    values = rng.normal(size=(9, 11, 13)).astype(np.float32) * 50
    volume = dvr_gl.Volume(values, spacing=(0.7, 1.3, 0.4))
    bounds = raycast.gradient_bounds(volume, 1, block)
    v = volume.values(np.float64)
    ratios = []
    for _ in range(3000):
        bz, by, bx = (rng.integers(0, n) for n in bounds.shape)
        centre = (np.array([bx, by, bz]) + 0.5) * block                      # in index space
        p, q = (np.clip(centre + rng.uniform(-block, block, 3), 0, np.array(v.shape[::-1]) - 1)
                for _ in range(2))
        dist = float(np.linalg.norm((p - q) * volume.spacing))
        if dist == 0:
            continue
        change = abs(float(trilinear(v, p[None])[0] - trilinear(v, q[None])[0]))
        ratios.append(change / (bounds[bz, by, bx] * dist))
    assert max(ratios) <= 1.0
    assert max(ratios) > 0.2


def test_detail_intervals_hold_every_bend_with_opacity():
    tf = dvr_gl.TransferFunction(color=[(0, 1, 1, 1), (100, 1, 1, 1)],
                                 opacity=[(0, 0.0), (10, 0.0), (20, 0.5), (30, 0.0), (60, 0.0), (70, 0.2),
                                          (100, 0.2)])
    knots = raycast.detail_knots(tf)
    np.testing.assert_array_equal(knots, [10, 20, 30, 60, 70, 100])     # 0 has no opacity beside it
    many = dvr_gl.TransferFunction(color=[(0, 1, 1, 1), (100, 1, 1, 1)],
                                   opacity=[(float(x), 0.1 + 0.1 * (i % 2)) for i, x in enumerate(range(0, 101, 5))])
    intervals = raycast.detail_intervals(many)
    assert len(intervals) == raycast.MAX_DETAIL
    assert raycast.touches_detail(intervals, many.knots, many.knots).all()
    assert np.all(intervals[1:, 0] > intervals[:-1, 1])


# -- refinement ----------------------------------------------------------------------------

def nonzero_lookups(plan, margin):
    """A bound, over the image's rays, on the table lookups that can be non-zero: a
    segment whose values, widened by the field's reach over it (its block's gradient
    bound times half its length, as the shader reads it) and by ``margin`` (float32
    value rounding),
    miss the table's values on a side where the table is cut, reads exactly zero (its
    share of the length is 0) in GL and in the reference alike; any other segment counts
    every cut it may be refined into."""
    scene, table = plan.scene, plan.preint
    values = np.nan_to_num(scene.volume.values(np.float64))
    o, d, t0, t1 = box_rays(scene)
    jitter = _jitter_per_pixel(plan, scene.height, scene.width).reshape(-1)
    lo = table.lo if table.cut[0] else -np.inf
    hi = table.hi if table.cut[1] else np.inf
    count = np.zeros(len(o))
    for k in range(-1, plan.max_segments):
        a = np.maximum(t0 + (jitter + k) * plan.step, t0)
        b = np.minimum(t0 + (jitter + k + 1) * plan.step, t1)
        if not (a < t1).any():
            break
        live = b > a
        sa, sb = (trilinear(values, (o + t[:, None] * d) / scene.volume.spacing) for t in (a, b))
        g = plan.reach[raycast.block_of(scene.volume, o + (0.5 * (a + b))[:, None] * d, plan.reach.shape,
                                        plan.reach_block)].astype(np.float64)
        pad = 0.5 * g * (b - a) + margin
        touches = (np.maximum(sa, sb) + pad >= lo) & (np.minimum(sa, sb) - pad <= hi)
        count += np.where(live & touches, raycast.refine_cuts(plan), 0)
    return int(count.max())


def refined_tolerance(plan):
    """The pre-integrated bound per lookup (test_slicing) times the lookups that can be
    non-zero on the worst ray."""
    vals = plan.scene.volume.values()
    margin = 16 * 2.0 ** -24 * float(np.nanmax(np.abs(vals))) * 8
    return preintegrated_tolerance(plan, 1) * nonzero_lookups(plan, margin)


@pytest.mark.parametrize("camera", ["perspective", "ortho", "eye_inside"])
@pytest.mark.parametrize("tf", [SPIKE, TF], ids=["spike", "smooth"])
@pytest.mark.parametrize("shading", [False, True])
def test_refined_gl_matches_reference(renderer, camera, tf, shading):
    """The reference takes the same decisions and cuts in float64. The bound is the
    pre-integrated one per lookup (test_slicing) times the lookups that can be non-zero
    on the worst ray (``nonzero_lookups``). A refinement decided differently in float32
    changes the segment by what refining changes it, which is the linear model's error at
    a knot the field just reaches: within that bound on these scenes."""
    scene = _scene(tf, camera, shading=shading)
    opts = dict(step=1.1, preintegrate=True, refine=4, ert_transmittance=0.0)
    plan = raycast.make_plan(scene, **opts)
    gl = renderer.render(scene, **opts)
    ref = reference.render(scene, technique="raycast", **opts)
    assert ref[..., 3].max() > 0.05
    assert metrics.max_abs_error(gl, ref) <= refined_tolerance(plan)


@pytest.mark.parametrize("camera,shading", [("perspective", False), ("ortho", False), ("perspective", True)])
def test_refinement_converges_at_second_order_and_beats_uniform_steps(renderer, camera, shading):
    """Cut at cell faces, a refined segment's parts each see one smooth cubic, so the
    straight line between their ends errs at second order in their length; uniform
    pre-integrated steps straddle the faces, where the field's slope jumps. So refining a
    one-voxel step k times beats a uniform step of 1/k voxel (6x to 10x here for k = 2,
    4, 8; asserted 3x), and the error keeps falling as the parts halve: by 2.8x to 3.8x
    each time here (4x at second order; asserted 2.5x). The parts are shorter than the
    fine table's nominal length where a face cuts them, which the length correction
    takes: without it, and with the table's nodes spread over the whole data range, the
    error stalled near 5e-4 from k = 4 on. Lit, each part is lit at its own midpoint (lit
    whole, the lighting's first-order error in the step stalled it too)."""
    scene = _scene(SPIKE, camera, shading=shading)
    exact = reference.exact(scene)
    parts = (2, 4, 8)
    errors = [metrics.rmse(renderer.render(scene, step=1.0, preintegrate=True, refine=k), exact) for k in parts]
    assert all(coarse > 2.5 * fine for coarse, fine in zip(errors, errors[1:])), errors
    for k, refined in zip(parts, errors):
        uniform = metrics.rmse(renderer.render(scene, step=1.0 / k, preintegrate=True), exact)
        assert refined * 3 < uniform, (k, refined, uniform)


def test_refinement_only_where_the_tf_has_detail(renderer):
    """A TF whose bends all lie far beyond the values any segment can reach refines
    nothing: the image is
    that of plain pre-integration, bit for bit."""
    lo, hi = VOLUME.data_range
    tf = dvr_gl.TransferFunction(color=[(lo - 1000, 0.2, 0.3, 0.9), (hi + 1000, 1.0, 0.8, 0.2)],
                                 opacity=[(lo - 1000, 0.05), (hi + 1000, 0.6)])
    scene = _scene(tf)
    assert raycast.detail_knots(tf).min() < lo and raycast.detail_knots(tf).max() > hi
    plain = renderer.render(scene, step=0.9, preintegrate=True)
    refined = renderer.render(scene, step=0.9, preintegrate=True, refine=8)
    assert plain[..., 3].max() > 0.1
    np.testing.assert_array_equal(plain, refined)


def test_refinement_at_long_steps_bounds_the_field_over_more_blocks(renderer):
    """Half a 5.9-voxel segment reaches 3 cells from its midpoint's: the gradient bound
    is taken over those (a radius of 3), and GL still matches the reference."""
    scene = _scene(SPIKE)
    opts = dict(step=5.9 * VOLUME.min_spacing, preintegrate=True, refine=8, ert_transmittance=0.0)
    plan = raycast.make_plan(scene, **opts)
    assert plan.reach_block == 1
    np.testing.assert_array_equal(plan.reach, raycast.gradient_bounds(VOLUME, 3, 1))
    assert plan.reach.sum() > raycast.gradient_bounds(VOLUME, 1, 1).sum()
    gl = renderer.render(scene, **opts)
    ref = reference.render(scene, technique="raycast", **opts)
    assert ref[..., 3].max() > 0.05
    assert metrics.max_abs_error(gl, ref) <= refined_tolerance(plan)


def test_refine_option_errors():
    scene = _scene()
    with pytest.raises(ValueError, match="refine splits pre-integrated segments; give preintegrate=True"):
        raycast.make_plan(scene, refine=4)
    with pytest.raises(TypeError, match="refine must be an integer"):
        raycast.make_plan(scene, preintegrate=True, refine=2.5)
    with pytest.raises(ValueError, match="refine must be from 1 to 64, got 0"):
        raycast.make_plan(scene, preintegrate=True, refine=0)
    with pytest.raises(ValueError, match="refine splits"):
        reference.render(scene, technique="raycast", refine=4)


def test_refined_jittered_and_masked_rays_match_the_reference(renderer):
    """Jittered starts (a short first segment, refined with its own length) and a volume
    with non-finite cells (segments whose midpoint is masked are skipped whole) take the
    same decisions in GL and in the reference."""
    values = VOLUME.values().copy()
    values[4:7, 5:9, 6:10] = np.nan
    masked = dvr_gl.Volume(values, spacing=VOLUME.spacing, origin=VOLUME.origin, mask_nonfinite=True)
    for volume, opts in ((VOLUME, dict(jitter_seed=3)), (masked, {})):
        scene = _scene(SPIKE, volume=volume)
        opts = dict(opts, step=1.1, preintegrate=True, refine=4, ert_transmittance=0.0)
        plan = raycast.make_plan(scene, **opts)
        gl = renderer.render(scene, **opts)
        ref = reference.render(scene, technique="raycast", **opts)
        assert ref[..., 3].max() > 0.05
        assert metrics.max_abs_error(gl, ref) <= refined_tolerance(plan)


def test_refined_rays_end_early_where_the_reference_does(renderer):
    """Early termination is decided at a segment's end, refined or not, as in the
    reference: rays through the dense TF end early, and a decision taken differently in
    float32 moves a pixel by at most the light left behind (the threshold)."""
    ert = 0.05
    scene = _scene(TF)
    opts = dict(step=1.1, preintegrate=True, refine=4, ert_transmittance=ert)
    plan = raycast.make_plan(scene, **opts)
    gl = renderer.render(scene, **opts)
    ref = reference.render(scene, technique="raycast", **opts)
    full = reference.render(scene, technique="raycast", **dict(opts, ert_transmittance=0.0))
    assert metrics.max_abs_error(full, ref) > 0.5 * ert      # some rays do end early
    assert metrics.max_abs_error(gl, ref) <= refined_tolerance(plan) + ert


def test_refinement_with_a_transparent_tf_draws_nothing(renderer):
    """A TF with no opacity has no detail to refine at: the shader gets one interval no
    value meets, and the image is empty."""
    tf = dvr_gl.TransferFunction(color=[(0, 1, 1, 1), (100, 1, 1, 1)], opacity=[(0, 0.0), (100, 0.0)])
    scene = _scene(tf)
    assert len(raycast.detail_intervals(tf)) == 0
    image = renderer.render(scene, step=1.1, preintegrate=True, refine=4)
    assert not image.any()


def test_large_volumes_bound_the_gradient_per_block_of_cells(renderer, monkeypatch):
    """Above MAX_REACH_BOUNDS cells the bounds cover blocks of 2 (then 4, ...) cells, so
    that their memory stays within the budget; the shader reads the plan's block, and GL
    still matches the reference."""
    cells = int(np.prod(np.array(VOLUME.shape) - 1))
    assert raycast.reach_block(VOLUME) == 1
    monkeypatch.setattr(raycast, "MAX_REACH_BOUNDS", cells // 2)
    assert raycast.reach_block(VOLUME) == 2
    monkeypatch.setattr(raycast, "MAX_REACH_BOUNDS", cells // 20)
    assert raycast.reach_block(VOLUME) == 4
    monkeypatch.setattr(raycast, "MAX_REACH_BOUNDS", cells // 2)
    scene = _scene(SPIKE)
    opts = dict(step=1.1, preintegrate=True, refine=4, ert_transmittance=0.0)
    plan = raycast.make_plan(scene, **opts)
    assert plan.reach_block == 2
    assert plan.reach.size <= cells // 2
    np.testing.assert_array_equal(plan.reach, raycast.gradient_bounds(VOLUME, 1, 2))
    gl = renderer.render(scene, **opts)
    ref = reference.render(scene, technique="raycast", **opts)
    assert ref[..., 3].max() > 0.05
    assert metrics.max_abs_error(gl, ref) <= refined_tolerance(plan)
