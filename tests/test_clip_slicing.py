"""Clip planes and crop boxes in 2D and 3D texture slicing: GL against the NumPy twin (the
bounds of tests/test_slicing.py), the gap pass for rays whose kept part holds no slice,
and the error against the clipped exact image on the CT head.

Each slice fragment's segment is cut to its ray's kept interval (``clipRange`` of the box
range; the twins get it from ``box_rays``), and a slice whose point the clip cuts away is
no slice for that ray: its neighbours' segments run to the kept interval's ends instead.
slice2d decides the cut along its stack axis once per slice in the plan (crop faces across
the axis, planes parallel to the slices), so a face on a slice plane keeps or cuts that
slice for every pixel: the crop boxes below put their faces on sample planes on purpose."""

import numpy as np
import pytest

import dvr_gl
from dvr_gl import metrics, reference
from dvr_gl.reference.common import box_rays
from dvr_gl.techniques import get_technique, slice2d, slice3d

from test_clip import _head_scenes, constant_scene
from test_raycast import TF, VOLUME, cameras
from test_slicing import H, W, preintegrated_tolerance, slice_tolerance


def clips(volume):
    """Clips of the test volume: an oblique plane through its middle; that plane and one
    parallel to the z slices through a sample plane; a crop box whose faces lie on sample
    planes."""
    lo, hi = volume.bounds
    centre = (lo + hi) / 2
    sp = volume.spacing
    on_sample_plane = lo + np.array([4.0, 3.0, 5.0]) * sp
    return {
        "plane": dict(clip_planes=[(centre, (0.6, -0.3, 0.5))]),
        "planes": dict(clip_planes=[(centre, (0.6, -0.3, 0.5)), (on_sample_plane, (0.0, 0.0, 1.0))]),
        "crop": dict(crop_box=(lo + np.array([9, 2, 3]) * sp, lo + np.array([19, 15, 12]) * sp)),
    }


VARIANTS = [("slice2d", {}), ("slice2d", {"interpolate": 2}), ("slice2d", {"preintegrate": True}),
            ("slice3d", {"step": 0.7}), ("slice3d", {"step": 0.7, "proxy": "vertex"}),
            ("slice3d", {"step": 0.7, "shells": True}), ("slice3d", {"step": 0.7, "preintegrate": True}),
            ("slice3d", {"step": 0.7, "shells": True, "preintegrate": True})]


def tolerance(plan):
    """test_slicing's bound for the plan: per slice, or per pre-integrated segment."""
    return slice_tolerance(plan) if plan.preint is None else preintegrated_tolerance(plan, 2 * plan.count)


@pytest.mark.parametrize("technique,opts", VARIANTS, ids=lambda v: str(v))
@pytest.mark.parametrize("camera", ["perspective", "ortho", "eye_inside"])
@pytest.mark.parametrize("clip", ["plane", "planes", "crop"])
def test_clipped_gl_matches_twin(renderer, technique, opts, camera, clip):
    scene = dvr_gl.Scene(VOLUME, TF, cameras(VOLUME)[camera], width=W, height=H, **clips(VOLUME)[clip])
    gl = renderer.render(scene, technique=technique, **opts)
    twin = reference.render(scene, technique=technique, **opts)
    plan = get_technique(technique).make_plan(scene, **opts)
    assert twin[..., 3].max() > 0.05, "the scene must show something"
    assert metrics.max_abs_error(gl, twin) <= tolerance(plan)
    unclipped = renderer.render(scene.replace(clip_planes=(), crop_box=None), technique=technique, **opts)
    assert metrics.max_abs_error(gl, unclipped) > 0.05          # the clip changes the picture


def test_slice2d_plan_keeps_the_slices_between_the_crop_faces():
    scene = dvr_gl.Scene(VOLUME, TF, cameras(VOLUME)["perspective"], width=W, height=H, **clips(VOLUME)["crop"])
    for k in (0, 2):
        plan = slice2d.make_plan(scene, interpolate=k)
        assert plan.axis == 2
        # crop z from sample plane 3 to 12, both faces on slices: kept, as every slice between
        assert plan.kept_slices == (3 * (k + 1), 12 * (k + 1))
        assert sorted(plan.order) == list(range(3 * (k + 1), 12 * (k + 1) + 1))
    planes = slice2d.make_plan(scene.replace(crop_box=None, **clips(VOLUME)["planes"]))
    assert planes.kept_slices == (5, 15)         # z >= sample plane 5; the oblique plane is per point
    unclipped = slice2d.make_plan(scene.replace(crop_box=None))
    assert unclipped.kept_slices is None and len(unclipped.order) == unclipped.count


def _thin_crop_scenes(technique, opts, volume, spacing_z):
    """A crop box across the whole volume in x and y but thinner along z than the distance
    between slices, placed between two slices: no ray's kept part holds a slice. Views
    along -z, perspective and orthographic."""
    lo, hi = volume.bounds
    centre = (lo + hi) / 2
    scenes = {}
    for name, extra in (("perspective", dict(fov=40)), ("ortho", dict(ortho_height=float(hi[1] - lo[1]) * 1.2))):
        cam = dvr_gl.Camera(centre + [0.7, 0.4, 60.0], centre + [0.7, 0.4, 0.0], up=(0, 1, 0), **extra)
        base = dvr_gl.Scene(volume, TF if volume is VOLUME else constant_scene().tf, cam, W, H)
        if technique == "slice2d":             # between sample planes 6 and 7
            z0, z1 = 6.3 * spacing_z, 6.7 * spacing_z
        else:                                  # between two view planes (depth = eye z - z)
            plan = slice3d.make_plan(base, **opts)
            depth = plan.depths()[plan.count // 2]
            eye_z = cam.eye[2] - lo[2]
            z0, z1 = eye_z - depth + 0.25 * plan.step, eye_z - depth + 0.75 * plan.step
        crop = (lo + [-1.0, -1.0, z0], np.array([hi[0] + 1.0, hi[1] + 1.0, lo[2] + z1]))
        scenes[name] = base.replace(crop_box=crop)
    return scenes


def _no_slice_in_any_kept_part(scene, plan):
    if isinstance(plan, slice2d.Slice2DPlan):
        return plan.order.size == 0           # the plan keeps no slice at all
    o, d, t0, t1 = box_rays(scene)
    t = plan.depths()[:, None] / (d @ scene.camera.forward)[None, :]
    return not np.any((t >= t0) & (t <= t1) & (t1 > t0))


THIN_VARIANTS = [("slice2d", {}), ("slice2d", {"preintegrate": True}),
                 ("slice3d", {"step": 0.7}), ("slice3d", {"step": 0.7, "preintegrate": True})]


@pytest.mark.parametrize("technique,opts", THIN_VARIANTS, ids=lambda v: str(v))
@pytest.mark.parametrize("camera", ["perspective", "ortho"])
def test_a_kept_part_without_a_slice_goes_through_the_gap_pass(renderer, technique, opts, camera):
    """On the blobs, GL against the twin; on a constant volume, against the exact image,
    which the gap pass's midpoint pieces (or pre-integrated ones) integrate exactly: both
    within test_slicing's bound."""
    scene = _thin_crop_scenes(technique, opts, VOLUME, VOLUME.spacing[2])[camera]
    plan = get_technique(technique).make_plan(scene, **opts)
    assert _no_slice_in_any_kept_part(scene, plan)
    gl = renderer.render(scene, technique=technique, **opts)
    twin = reference.render(scene, technique=technique, **opts)
    assert twin[..., 3].max() > 0.3
    assert metrics.max_abs_error(gl, twin) <= tolerance(plan)

    constant = constant_scene().volume
    scene = _thin_crop_scenes(technique, opts, constant, 1.0)[camera]
    plan = get_technique(technique).make_plan(scene, **opts)
    assert _no_slice_in_any_kept_part(scene, plan)
    gl = renderer.render(scene, technique=technique, **opts)
    exact = reference.exact(scene, cache=False)
    assert exact[..., 3].max() > 0.03
    assert metrics.max_abs_error(gl, exact) <= tolerance(plan)


@pytest.mark.parametrize("technique,opts", [("slice2d", {}), ("slice3d", {"step": 0.7}),
                                            ("slice3d", {"step": 0.7, "shells": True})], ids=lambda v: str(v))
def test_clips_that_keep_nothing_give_an_empty_image(renderer, technique, opts):
    lo, hi = VOLUME.bounds
    centre = (lo + hi) / 2
    scene = dvr_gl.Scene(VOLUME, TF, cameras(VOLUME)["perspective"], width=W, height=H,
                         clip_planes=[(centre + 0.5, (1, 0, 0)), (centre - 0.5, (-1, 0, 0))])
    assert not renderer.render(scene, technique=technique, **opts).any()
    assert not reference.render(scene, technique=technique, **opts).any()


HEAD_VARIANTS = [("slice2d", {}), ("slice2d", {"preintegrate": True}), ("slice3d", {"step": 1.5}),
                 ("slice3d", {"step": 1.5, "shells": True}), ("slice3d", {"step": 1.5, "preintegrate": True})]


@pytest.mark.parametrize("technique,opts", HEAD_VARIANTS, ids=lambda v: str(v))
@pytest.mark.parametrize("name", ["plane", "two planes", "crop box"])
def test_head_error_against_clipped_exact_stays_within_the_unclipped_error(renderer, technique, opts, name):
    scene = _head_scenes(48)[name]
    unclipped = scene.replace(clip_planes=(), crop_box=None)
    gl = renderer.render(scene, technique=technique, **opts)
    plan = get_technique(technique).make_plan(scene, **opts)
    assert gl[..., 3].max() > 0.2
    assert metrics.max_abs_error(gl, reference.render(scene, technique=technique, **opts)) <= tolerance(plan)
    err = metrics.rmse(gl, reference.exact(scene))
    err_unclipped = metrics.rmse(renderer.render(unclipped, technique=technique, **opts), reference.exact(unclipped))
    assert err <= err_unclipped
    # against the unclipped exact image it is plainly wrong: the judge sees the clip
    assert metrics.rmse(gl, reference.exact(unclipped)) > 5 * err
