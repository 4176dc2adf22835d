"""Error targets (``Renderer.render(..., tolerance=E)``): the chosen step's image is within
E of the exact image on scenes of different kinds, no more than twice as fine as the best
step of a fixed ladder that meets E (frame time goes as 1 / step), the pilot is reused,
and bad requests are refused."""

import numpy as np
import pytest

import dvr_gl
from dvr_gl import data as bundled
from dvr_gl import metrics, reference
from dvr_gl.rendering import tolerance
from dvr_gl.data.phantoms import marschner_lobb, marschner_lobb_tf
from dvr_gl.rendering.tolerance import MAX_STEP, SAFETY, ErrorModel, error_model, measure

from test_shading import RAMP, TF, cameras

LADDER = [2.0 / 2 ** k for k in range(8)]     # 2 .. 1/64 voxel


def scenes():
    ml = marschner_lobb(41)
    head = bundled.ct_head()
    return {
        "marschner_lobb": dvr_gl.Scene(ml, marschner_lobb_tf(), dvr_gl.default_camera(ml, azimuth=30, elevation=20),
                                       48, 48),
        "ct_head": dvr_gl.Scene(head, bundled.ct_head_tf(), dvr_gl.default_camera(head, azimuth=30, elevation=15),
                                48, 40),
        "ramp_lit": dvr_gl.Scene(RAMP, TF, cameras(RAMP)["perspective"], 40, 32, shading=True),
    }


@pytest.mark.parametrize("name", ["marschner_lobb", "ct_head", "ramp_lit"])
@pytest.mark.parametrize("tolerance", [1e-2, 1e-3])
def test_the_chosen_step_meets_the_tolerance_and_is_not_needlessly_fine(renderer, name, tolerance):
    scene = scenes()[name]
    exact = reference.exact(scene)
    image = renderer.render(scene, tolerance=tolerance)
    choice = renderer.last_choice
    assert metrics.rmse(image, exact) <= tolerance, (choice, metrics.rmse(image, exact))
    voxel = scene.volume.min_spacing
    meets = [k for k in LADDER if metrics.rmse(renderer.render(scene, step=k * voxel), exact) <= tolerance]
    assert meets, "some step of the ladder meets the tolerance"
    assert choice.step_voxels >= 0.5 * max(meets), (choice, max(meets))


def test_the_pilot_is_reused_and_the_choice_is_readable(renderer, monkeypatch):
    import dvr_gl.rendering.tolerance as tol
    scene = scenes()["marschner_lobb"]
    # one way of sampling throughout: the fastest way is a timing call (a GPU took
    # pre-integration at 2e-3), and each way keeps its own pilot and model
    renderer.render(scene, tolerance=2e-3, preintegrate=False)
    first = renderer.last_choice
    renderer.render(scene, tolerance=2e-3, preintegrate=False)
    assert renderer.last_choice == first        # the same model and choice
    assert first.tolerance == 2e-3 and first.predicted_rmse <= SAFETY * 2e-3 * (1 + 1e-12)
    assert first.step == pytest.approx(first.step_voxels * scene.volume.min_spacing)
    assert max(first.pilot_size) <= 64 and 1.0 <= first.order <= 3.0

    def no_new_pilot(*args):
        raise AssertionError("the pilot was measured again")

    monkeypatch.setattr(tol, "measure", no_new_pilot)
    renderer.render(scene, tolerance=2e-4, preintegrate=False)
    finer = renderer.last_choice
    assert finer.step < first.step and finer.pilot_seconds >= first.pilot_seconds


def test_an_empty_image_takes_the_largest_step(renderer):
    volume = dvr_gl.Volume(np.zeros((8, 8, 8), np.float32))
    tf = dvr_gl.TransferFunction([(0, 1, 1, 1), (1, 1, 1, 1)], [(0, 0.0), (1, 0.5)])
    renderer.render(dvr_gl.Scene(volume, tf, dvr_gl.default_camera(volume), 16, 16), tolerance=1e-3)
    assert renderer.last_choice.step_voxels == MAX_STEP


def test_error_model_reads_the_order_off_the_differences():
    p, err = error_model(4e-3, 1e-3)          # second order: each halving quarters the difference
    assert p == pytest.approx(2.0) and err == pytest.approx(1e-3 / 3)
    assert error_model(1e-3, 2e-3)[0] == 1.0  # not converging yet: the safe, first order
    assert error_model(1e-3, 0.0) == (2.0, 0.0)


def test_bad_requests_are_refused(renderer):
    scene = scenes()["ramp_lit"]
    with pytest.raises(ValueError, match="give tolerance or step, not both"):
        renderer.render(scene, step=0.5, tolerance=1e-3)
    with pytest.raises(ValueError, match="tolerance chooses the ray caster's step"):
        renderer.render(scene, technique="slice3d", tolerance=1e-3)
    with pytest.raises(ValueError, match="tolerance must be a positive RMSE, got -1"):
        renderer.render(scene, tolerance=-1)
    with pytest.raises(TypeError, match="tolerance must be a number"):
        renderer.render(scene, tolerance=True)


def spike_scene():
    """The bundled CT head with an opacity spike 1 % of its value range wide, 48x40."""
    head = bundled.ct_head()
    lo, hi = head.data_range
    centre, width = lo + 0.55 * (hi - lo), 0.01 * (hi - lo)
    tf = dvr_gl.TransferFunction(color=[(lo, 0.9, 0.6, 0.4), (centre, 1.0, 0.95, 0.8), (hi, 0.6, 0.7, 1.0)],
                                 opacity=[(lo, 0.0), (centre - width / 2, 0.0), (centre, 0.9),
                                          (centre + width / 2, 0.0), (hi, 0.0)], unit_distance=head.min_spacing)
    return dvr_gl.Scene(head, tf, dvr_gl.default_camera(head, azimuth=30, elevation=15), 48, 40)


def test_a_narrow_tf_feature_is_pre_integrated(renderer):
    """An opacity spike 1 % of the range wide: plain steps would have to be very short,
    pre-integrated ones need not; the cheaper choice meets the tolerance."""
    scene = spike_scene()
    image = renderer.render(scene, tolerance=2e-2)
    choice = renderer.last_choice
    assert choice.preintegrate
    assert metrics.rmse(image, reference.exact(scene)) <= 2e-2
    renderer.render(scene, tolerance=2e-2, preintegrate=False)      # the caller's say is kept
    plain = renderer.last_choice
    assert not plain.preintegrate and plain.step_voxels * 2.5 < choice.step_voxels


def test_each_way_of_sampling_is_timed_and_the_fastest_taken(renderer):
    """On a narrow spike all four ways apply (plain, pre-integrated, refined, walked by
    crossings, the values with opacity being a narrow share of the data's); the one
    taken is the way ``fastest`` picked among the timed choices (its own rules are tested
    below), at no longer a step (the check on the request's view may shorten it), it
    carries its frame time, and it meets the tolerance on the image. The caller's say is
    kept, untimed."""
    scene = spike_scene()
    ways = tolerance.samplings(scene)
    assert [(w["preintegrate"], w["refine"], w.get("refine_walk", "even")) for w in ways] == [
        (False, 1, "even"), (True, 1, "even"), (True, tolerance.REFINE_PARTS, "even"),
        (True, tolerance.REFINE_PARTS, "crossings")]
    picked = []
    original = tolerance.fastest

    def spy(choices, frame_seconds):
        picked.append(original(choices, frame_seconds))
        return picked[-1]
    tolerance.fastest = spy
    try:
        image = renderer.render(scene, tolerance=5e-3)
    finally:
        tolerance.fastest = original
    choice = renderer.last_choice
    assert len(picked) == 1 and choice.frame_seconds == picked[0].frame_seconds is not None
    assert choice.sampling == picked[0].sampling and choice.step <= picked[0].step
    assert choice.checked_rmse <= tolerance.CHECK_TARGET * 5e-3
    assert metrics.rmse(image, reference.exact(scene)) <= 5e-3
    renderer.render(scene, tolerance=5e-3, preintegrate=True, refine=2)      # the caller's say is kept
    assert (renderer.last_choice.preintegrate, renderer.last_choice.refine) == (True, 2)
    assert renderer.last_choice.frame_seconds is None
    # no TF detail within reach of the data: no refined way
    lo, hi = scene.volume.data_range
    smooth = dvr_gl.TransferFunction(color=[(lo - 9 * (hi - lo), 1, 1, 1), (hi + 9 * (hi - lo), 1, 0, 0)],
                                     opacity=[(lo - 9 * (hi - lo), 0.0), (hi + 9 * (hi - lo), 0.5)])
    assert len(tolerance.samplings(scene.replace(tf=smooth))) == 2


def test_fastest_takes_the_least_frame_time_and_leaves_out_dear_estimates():
    def c(step, pre=False, refine=1):
        return tolerance.Choice(tolerance=1e-2, step=step, step_voxels=step, predicted_rmse=1e-3, order=2.0,
                                pilot_size=(8, 8), pilot_seconds=0.0, preintegrate=pre, refine=refine)
    seen = []

    def seconds(choice):
        seen.append(choice.step_voxels)
        return {1.0: 3.0, 1.5: 1.0, 2.0: 2.0}[choice.step_voxels]
    best = tolerance.fastest([c(1.0), c(1.5, True), c(2.0, True, 4), c(1 / 64)], seconds)
    assert best.step_voxels == 1.5 and best.preintegrate and best.frame_seconds == 1.0
    assert 1 / 64 not in seen        # 64 plain steps per voxel: over 4x the cheapest estimate
    # a close call (within TIMING_MARGIN) stays with the estimate's cheapest: plain at 1 voxel
    close = tolerance.fastest([c(1.0), c(1.5, True)], lambda ch: {1.0: 1.0, 1.5: 0.9}[ch.step_voxels])
    assert close.step_voxels == 1.0 and not close.preintegrate and close.frame_seconds == 1.0
    # a refined way's estimate is a lower bound: its being low rules no other way out
    # (plain at 0.25 voxel, estimate 4, beside refined at 2 voxels, bound 0.8)
    seen.clear()
    best = tolerance.fastest([c(0.25), c(2.0, True, 4)], lambda ch: seen.append(ch.step_voxels) or
                             {0.25: 1.0, 2.0: 3.0}[ch.step_voxels])
    assert sorted(seen) == [0.25, 2.0] and best.step_voxels == 0.25 and not best.preintegrate


def test_the_model_measures_each_pilot_step_against_the_richardson_image():
    """Pilot images that converge as exact + c h^2 + d h^3: the order read off the finest
    pair is near 2, the Richardson image removes the h^2 term, and each pilot step's error
    is measured against it; predictions interpolate those errors, never fall as the step
    grows, and largest_step inverts predict."""
    exact = np.linspace(0.0, 1.0, 64).reshape(8, 8)
    shape = np.cos(np.arange(64)).reshape(8, 8)

    def render(scene, h):
        return exact + 1e-3 * h ** 2 * shape + 4e-4 * h ** 3 * shape

    scene = scenes()["marschner_lobb"]
    model = measure(lambda s, step: render(s, step / scene.volume.min_spacing), scene)
    assert 2.0 <= model.order <= 2.3
    truth = [np.sqrt(np.mean((render(None, k) - exact) ** 2)) for k in model.steps]
    for k, measured, true in zip(model.steps, model.errors, truth):
        assert model.predict(k) == pytest.approx(measured, rel=1e-12)
        assert measured == pytest.approx(true, rel=0.25)      # the Richardson image is near exact
    for e in (1e-5, 3e-4, 2e-3, 1e-2):
        assert model.predict(model.largest_step(e)) == pytest.approx(e, rel=1e-9)
    steps = np.geomspace(1 / 64, 2, 40)
    assert np.all(np.diff([model.predict(k) for k in steps]) >= 0)
    flat = ErrorModel(order=2.0, steps=(1.0, 0.5, 0.25, 0.125), errors=(0.0,) * 4, pilot_size=(8, 8),
                      pilot_seconds=0.0)
    assert flat.predict(1.0) == 0.0


def test_an_interpolated_step_is_checked_on_the_pilot():
    """The error between the pilot's octaves need not follow the curve through them: a
    pilot whose error jumps just above 1 voxel. The first step chosen (interpolated) is
    rendered, found over SAFETY * E, and the step returned is one whose measured error is
    within it; asking again renders nothing."""
    exact = np.zeros((8, 8))

    def error_at(k):
        return 1e-3 * k ** 2 if k <= 1.0 else 5e-3       # a jump past one voxel

    calls = []

    def render(scene, step):
        k = step / voxel
        calls.append(k)
        return exact + error_at(k)

    scene = scenes()["marschner_lobb"]
    voxel = scene.volume.min_spacing
    from dvr_gl.rendering.tolerance import verified
    model = measure(render, scene)
    assert model.predict(1.3) < SAFETY * 3e-3          # the curve alone would take ~1.3 voxel
    calls.clear()
    model, choice = verified(model, render, scene, 3e-3)
    assert calls and error_at(choice.step_voxels) <= SAFETY * 3e-3
    assert choice.step_voxels >= 1.0 - 1e-9             # and not finer than needed
    calls.clear()
    assert verified(model, render, scene, 3e-3)[1] == choice and not calls
