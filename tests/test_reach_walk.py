"""Refined pre-integrated segments walked by reach (``refine_walk="reach"``): each part as
long as the field cannot reach the transfer function's detail from its front, short
parts (at least 1/refine of the segment, cut at cell faces) only where it can."""

import numpy as np
import pytest

import dvr_gl
from dvr_gl import metrics, reference
from dvr_gl.data.phantoms import marschner_lobb
from dvr_gl.techniques import raycast

from test_refine import _scene, refined_tolerance
from test_raycast import TF, VOLUME
from test_slicing import SPIKE


def ml_spike(n=21, width=0.02):
    """The Marschner-Lobb signal with an opacity spike ``width`` of its range wide at
    the middle of the range (detail everywhere the band can be)."""
    volume = marschner_lobb(n)
    lo, hi = volume.data_range
    c, w = 0.5 * (lo + hi), width * (hi - lo)
    tf = dvr_gl.TransferFunction(color=[(lo, 0.9, 0.6, 0.4), (c, 1.0, 0.95, 0.8), (hi, 0.6, 0.7, 1.0)],
                                 opacity=[(lo, 0.0), (c - w / 2, 0.0), (c, 0.9), (c + w / 2, 0.0), (hi, 0.0)],
                                 unit_distance=volume.min_spacing)
    return volume, tf


@pytest.mark.parametrize("camera,tf,shading", [("perspective", SPIKE, False), ("ortho", SPIKE, True),
                                               ("eye_inside", TF, False)],
                         ids=["spike", "spike-ortho-lit", "smooth-eye-inside"])
def test_reach_walk_gl_matches_reference(renderer, camera, tf, shading):
    """The reference takes the same pieces in float64. A refined segment has at most
    ``refine_cuts`` pieces (those that do not end on a face are at least 1/refine of it
    long), so test_refine's bound holds: the pre-integrated bound per lookup times the
    lookups that can be non-zero on the worst ray; a piece ended differently in float32
    changes the segment by the linear model's error there, within that bound."""
    scene = _scene(tf, camera, shading=shading)
    opts = dict(step=1.1, preintegrate=True, refine=4, refine_walk="reach", ert_transmittance=0.0)
    plan = raycast.make_plan(scene, **opts)
    assert plan.defines["REACH_WALK"] == 1
    gl = renderer.render(scene, **opts)
    ref = reference.render(scene, technique="raycast", **opts)
    assert ref[..., 3].max() > 0.05
    assert metrics.max_abs_error(gl, ref) <= refined_tolerance(plan)


def test_reach_walk_on_marschner_lobb_matches_reference(renderer):
    """Detail everywhere: most segments of the Marschner-Lobb spike are walked, at a
    2.5-voxel step with parts down to 1/8 of it."""
    volume, tf = ml_spike()
    scene = dvr_gl.Scene(volume, tf, dvr_gl.default_camera(volume, azimuth=30, elevation=20), 40, 32)
    opts = dict(step=2.5 * volume.min_spacing, preintegrate=True, refine=8, refine_walk="reach",
                ert_transmittance=0.0)
    plan = raycast.make_plan(scene, **opts)
    gl = renderer.render(scene, **opts)
    ref = reference.render(scene, technique="raycast", **opts)
    assert ref[..., 3].max() > 0.05
    assert metrics.max_abs_error(gl, ref) <= refined_tolerance(plan)


def test_reach_walk_error_shrinks_with_its_parts(renderer):
    """Against the exact image of the Marschner-Lobb spike, at a fixed 2-voxel step: the
    error falls as the shortest part (step / refine) halves (3.3x and 3.9x here; asserted
    1.8x), and stays within 1.25x of the even walk's with the same parts (1.04x to 1.12x
    here), which cuts every walked segment into its shortest parts."""
    volume, tf = ml_spike()
    scene = dvr_gl.Scene(volume, tf, dvr_gl.default_camera(volume, azimuth=30, elevation=20), 48, 40)
    exact = reference.exact(scene)
    step = 2.0 * volume.min_spacing
    parts = (4, 8, 16)
    errors = [metrics.rmse(renderer.render(scene, step=step, preintegrate=True, refine=k, refine_walk="reach"), exact)
              for k in parts]
    assert all(coarse > 1.8 * fine for coarse, fine in zip(errors, errors[1:])), errors
    even = [metrics.rmse(renderer.render(scene, step=step, preintegrate=True, refine=k), exact) for k in parts]
    assert all(r < 1.25 * e for r, e in zip(errors, even)), (errors, even)


def test_reach_walk_refines_nothing_where_detail_is_out_of_reach(renderer):
    """A TF whose bends lie beyond every value: no segment is walked, the image is plain
    pre-integration's bit for bit."""
    lo, hi = VOLUME.data_range
    tf = dvr_gl.TransferFunction(color=[(lo - 1000, 0.2, 0.3, 0.9), (hi + 1000, 1.0, 0.8, 0.2)],
                                 opacity=[(lo - 1000, 0.05), (hi + 1000, 0.6)])
    scene = _scene(tf)
    plain = renderer.render(scene, step=0.9, preintegrate=True)
    walked = renderer.render(scene, step=0.9, preintegrate=True, refine=8, refine_walk="reach")
    assert plain[..., 3].max() > 0.1
    np.testing.assert_array_equal(plain, walked)


def test_refine_walk_option_errors():
    scene = _scene(SPIKE)
    with pytest.raises(ValueError, match="refine_walk"):
        raycast.make_plan(scene, preintegrate=True, refine=4, refine_walk="uniform")


def test_tolerance_keeps_the_callers_walk(renderer):
    """``tolerance=`` with ``refine_walk="reach"`` chooses the step for that way, renders
    with it, and keeps the request on the Marschner-Lobb spike."""
    volume, tf = ml_spike()
    scene = dvr_gl.Scene(volume, tf, dvr_gl.default_camera(volume, azimuth=30, elevation=20), 48, 40)
    exact = reference.exact(scene)
    opts = dict(preintegrate=True, refine=8, refine_walk="reach")
    image = renderer.render(scene, tolerance=1e-2, **opts)
    choice = renderer.last_choice
    assert (choice.refine, choice.refine_walk) == (8, "reach")
    assert choice.sampling["refine_walk"] == "reach"
    np.testing.assert_array_equal(image, renderer.render(scene, step=choice.step, **opts))
    assert metrics.rmse(image, exact) <= 1e-2
