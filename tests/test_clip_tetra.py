"""Clip planes and crop boxes on meshes: the exact image's mesh path, projected tetrahedra
("tetra") and its NumPy twin.

The kept region (the clip planes' half-spaces and the crop box) is convex, so each pixel
ray keeps one interval of itself; a cell's segment on the ray is cut to that interval,
its values at the cut ends interpolated (the field is linear in a cell), and a segment
with nothing left adds nothing.

Closed forms. A unit cube of six tets with the linear field ``s = z + 0.2 x``, cut by an
axis plane or a crop box, keeps an axis-aligned box: each ray's kept interval is its
chord through that box (``ray_box``, computed here on its own), along which s is linear
in t. The image is the contract's integral over that interval, taken here by a 1-D
quadrature (classical Runge-Kutta on optical depth and colour, 1000 steps: the TF's knots
lie outside the field's range, so the integrands are smooth and the rule's error, O(h^4),
is about 1e-13: doubling the steps moves the result by that). mip, minip and average of
a field linear in z seen along z are the values at the kept ends and halfway.

Tolerances. GL against its twin and against closed forms: ``GL_TOL`` of
tests/test_tetra.py, derived there from the float32 arithmetic of the cell planes,
rays and distances (relative errors of a few 1e-7 of the distance from the eye in a
chord end); a clipped end is one more float32 plane crossing (``clipRange``), with the
same relative error, so the derivation holds as it is. The twin against the closed form:
its segment integral is within 2e-8 of float64 quadrature (test_tetra.py). The exact
image against the closed form: 1e-9 (it is measured within 1e-11 of fine integration).
"""

import os

import numpy as np
import pytest

import dvr_gl
from dvr_gl import Camera, Scene, TetMesh, TransferFunction, metrics, reference
from dvr_gl.data import delaunay_ball, synthetic_tf
from dvr_gl.model.field import ray_box
from dvr_gl.techniques import tetra

from test_tetra import CUBE, GL_TOL, SIX, TF, blocks_mesh, closed_form_boxes

# ---------------------------------------------------------------- a linear cube, closed form
RAMP_TF = TransferFunction([(-0.5, 0.9, 0.2, 0.1), (1.5, 0.1, 0.6, 0.9)], [(-0.5, 0.05), (1.5, 0.85)],
                           unit_distance=0.4)


def ramp(points):
    return points[:, 2] + 0.2 * points[:, 0]


RAMP_CUBE = TetMesh(CUBE, SIX, ramp(CUBE))
ALONG_Z = Camera((0.5, 0.5, 3.0), (0.5, 0.5, 0.5), ortho_height=1.6)
OBLIQUE = Camera((2.3, -1.4, 2.6), (0.5, 0.5, 0.5), fov=35)
# the clips of the cube, and the box each keeps of it
CUBE_CLIPS = {
    "plane z >= 0.4": (dict(clip_planes=[((0.3, 0.2, 0.4), (0.0, 0.0, 2.0))]), ((0, 0, 0.4), (1, 1, 1))),
    "plane x <= 0.65": (dict(clip_planes=[((0.65, 0.5, 0.5), (-1.0, 0.0, 0.0))]), ((0, 0, 0), (0.65, 1, 1))),
    "crop box": (dict(crop_box=((-1.0, 0.2, 0.25), (0.7, 3.0, 0.8))), ((0, 0.2, 0.25), (0.7, 1, 0.8))),
    "plane and crop box": (dict(clip_planes=[((0.5, 0.6, 0.5), (0.0, -1.0, 0.0))],
                                crop_box=((0.1, -1.0, -1.0), (2.0, 2.0, 0.9))), ((0.1, 0, 0), (1, 0.6, 0.9))),
}


def quadrature(scene, box, tf=RAMP_TF, field=ramp, steps=1000):
    """The contract's composite integral over each ray's chord through ``box``, by
    classical Runge-Kutta on (optical depth, colour); premultiplied (H, W, 4)."""
    o, d = scene.camera.rays(scene.width, scene.height)
    o, d = o.reshape(-1, 3), d.reshape(-1, 3)
    t0, t1 = ray_box(o, d, np.asarray(box[0], float), np.asarray(box[1], float))
    length = np.maximum(t1 - t0, 0.0)
    t0, t1 = np.where(length > 0, t0, 0.0), np.where(length > 0, t1, 0.0)     # missed: no length
    s0 = field(o + t0[:, None] * d)
    rate = (field(o + t1[:, None] * d) - s0) / np.where(length > 0, length, 1.0)   # s linear in t

    def deriv(t, state):
        s = s0 + rate * t
        tau = -np.log1p(-tf.opacity(s)) / tf.unit_distance
        T = np.exp(-state[:, 0])
        return np.concatenate([tau[:, None], tf.color(s) * (tau * T)[:, None]], axis=1)

    h = length / steps
    state = np.zeros((len(o), 4))
    t = np.zeros(len(o))
    for _ in range(steps):
        k1 = deriv(t, state)
        k2 = deriv(t + h / 2, state + h[:, None] / 2 * k1)
        k3 = deriv(t + h / 2, state + h[:, None] / 2 * k2)
        k4 = deriv(t + h, state + h[:, None] * k3)
        state = state + h[:, None] / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        t = t + h
    A = -np.expm1(-state[:, 0])
    return np.concatenate([state[:, 1:], A[:, None]], axis=1).reshape(scene.height, scene.width, 4)


@pytest.mark.parametrize("camera", ["along z", "oblique"])
@pytest.mark.parametrize("clip", sorted(CUBE_CLIPS))
def test_a_linear_cube_cut_to_a_box_is_the_quadrature_of_the_kept_box(renderer, clip, camera):
    kwargs, box = CUBE_CLIPS[clip]
    scene = Scene(RAMP_CUBE, RAMP_TF, ALONG_Z if camera == "along z" else OBLIQUE, 32, 32, **kwargs)
    want = quadrature(scene, box)
    assert want[..., 3].max() > 0.3 and (want[..., 3] == 0).any()
    # the whole cube differs: the cut is seen
    whole = quadrature(scene, ((0, 0, 0), (1, 1, 1)), steps=100)
    assert np.abs(whole - want).max() > 0.05
    assert np.abs(reference.exact(scene, cache=False) - want).max() < 1e-9
    assert np.abs(reference.render(scene, technique="tetra") - want).max() < 2e-8
    assert np.abs(renderer.render(scene, technique="tetra") - want).max() < GL_TOL


@pytest.mark.parametrize("mode", ["mip", "minip", "average"])
def test_reductions_see_only_the_kept_part(renderer, mode):
    """Seen along -z, a plane keeping z <= 0.6 leaves each ray the values from
    0.6 + 0.2x down to 0.2x: the largest, smallest and mean are those, classified."""
    scene = Scene(RAMP_CUBE, RAMP_TF, ALONG_Z, 16, 16, mode=mode, clip_planes=[((0.5, 0.5, 0.6), (0, 0, -1))])
    o, _ = scene.camera.rays(16, 16)
    x, y = o[..., 0], o[..., 1]
    inside = (x >= 0) & (x <= 1) & (y >= 0) & (y <= 1)
    s = 0.2 * x + {"mip": 0.6, "minip": 0.0, "average": 0.3}[mode]
    a = np.where(inside, RAMP_TF.opacity(s), 0.0)
    want = np.concatenate([RAMP_TF.color(s) * a[..., None], a[..., None]], axis=-1)
    assert np.abs(reference.exact(scene, cache=False) - want).max() < 1e-12
    assert np.abs(reference.render(scene, technique="tetra") - want).max() < 1e-12
    assert np.abs(renderer.render(scene, technique="tetra") - want).max() < 1e-6


def test_exact_isosurface_takes_its_side_where_the_kept_part_begins():
    """s = z + 0.2x seen along -z, iso value 0.7. Unclipped, every ray enters above 0.7
    and hits where s falls to it. Kept z <= 0.6, a ray with x < 0.5 enters below 0.7 and
    s only falls: no hit; with x > 0.5 it enters above and hits at z = 0.7 - 0.2x."""
    scene = Scene(RAMP_CUBE, RAMP_TF, ALONG_Z, 16, 16, mode="isosurface", iso_value=0.7)
    o, _ = scene.camera.rays(16, 16)
    x, y = o[..., 0], o[..., 1]
    inside = (x > 0) & (x < 1) & (y > 0) & (y < 1)
    whole = reference.exact(scene, cache=False)
    assert np.all(whole[..., 3][inside] == 1.0)
    cut = reference.exact(scene.replace(clip_planes=[((0.5, 0.5, 0.6), (0, 0, -1))]), cache=False)
    assert np.all(cut[..., 3][inside & (x < 0.5)] == 0.0)
    assert np.all(cut[..., 3][inside & (x > 0.5)] == 1.0)
    # the same hit, so the same shade, where the kept part still holds it
    np.testing.assert_array_equal(cut[inside & (x > 0.5)], whole[inside & (x > 0.5)])


# ------------------------------------------------------------------- non-convex, closed form
@pytest.mark.parametrize("sort", ["mpvo", "centroid"])
def test_non_convex_blocks_cut_to_boxes(renderer, sort):
    """tests/test_tetra.py's L of three cubes seen into its notch and two blocks one
    behind the other (constant field), cut by an axis plane or a crop box: the image is
    the constant field's over the kept boxes (closed form), and cells wholly cut away are
    not drawn."""
    into_notch = Camera((4.5, 3.5, 4.0), (1.0, 0.8, 0.5), fov=35)
    through_both = Camera((8.0, 2.0, 6.0), (1.5, 0.5, 1.2), fov=35)     # the near block hides part of the far
    L_cells, blobs = [(0, 0, 0), (1, 0, 0), (0, 1, 0)], [(0, 0, 0), (3, 0, 2)]
    cases = [
        (L_cells, into_notch, dict(clip_planes=[((1.5, 0, 0), (-1, 0, 0))]),
         [((0, 0, 0), (1, 1, 1)), ((1, 0, 0), (1.5, 1, 1)), ((0, 1, 0), (1, 2, 1))]),
        (L_cells, into_notch, dict(crop_box=((-1, 0.5, 0.25), (3, 3, 0.75))),
         [((0, 0.5, 0.25), (1, 1, 0.75)), ((1, 0.5, 0.25), (2, 1, 0.75)), ((0, 1, 0.25), (1, 2, 0.75))]),
        (blobs, through_both, dict(clip_planes=[((0, 0, 2.5), (0, 0, -1))]),
         [((0, 0, 0), (1, 1, 1)), ((3, 0, 2), (4, 1, 2.5))]),
        (blobs, through_both, dict(crop_box=((0.5, 0.2, -1), (3.5, 0.9, 2.6))),
         [((0.5, 0.2, 0), (1, 0.9, 1)), ((3, 0.2, 2), (3.5, 0.9, 2.6))]),
        (L_cells, into_notch, dict(clip_planes=[((1, 0, 0), (-1, 0, 0))]),       # in a shared face's plane
         [((0, 0, 0), (1, 1, 1)), ((0, 1, 0), (1, 2, 1))]),
        (L_cells, into_notch, dict(clip_planes=[((0.9, 0, 0), (-1, 0, 0))]),     # one cube wholly cut away
         [((0, 0, 0), (0.9, 1, 1)), ((0, 1, 0), (0.9, 2, 1))]),
    ]
    for cells, cam, clip, boxes in cases:
        mesh = blocks_mesh(cells)
        scene = Scene(mesh, TF, cam, 48, 48, **clip)
        img = renderer.render(scene, technique="tetra", sort=sort)
        want = closed_form_boxes(scene, boxes)
        assert want[..., 3].max() > 0.1
        assert np.abs(img - want).max() < GL_TOL
        assert np.abs(reference.render(scene, technique="tetra", sort=sort) - want).max() < 1e-7
        assert np.abs(reference.exact(scene, cache=False) - want).max() < 1e-9
    # the last plane keeps nothing of the cube at x = 1: its six cells are not drawn
    assert tetra.make_plan(scene, sort=sort).draw.size == mesh.n_tets - 6


# ------------------------------------------------------------------------ GL against its twin
def ball_scene(view, size=48, mode="composite", **clip):
    mesh = delaunay_ball()
    lo, hi = mesh.bounds
    centre = (lo + hi) / 2
    cameras = {
        "perspective": dvr_gl.default_camera(mesh, azimuth=30, elevation=20),
        "orthographic": dvr_gl.default_camera(mesh, azimuth=60, elevation=-10, ortho=True),
        "along an axis": Camera(centre + [0, 0, 150.0], centre, ortho_height=70.0),
        "45 degrees": Camera(centre + [100.0, 100.0, 0], centre, up=(0, 0, 1), fov=30),
        "eye inside": Camera(centre + [8.0, -5.0, 3.0], centre + [-10.0, 10.0, 0.0], fov=70),
    }
    return Scene(mesh, synthetic_tf(), cameras[view], size, size, mode=mode, **clip)


def ball_clips():
    lo, hi = delaunay_ball().bounds
    centre = (lo + hi) / 2
    return {
        "plane": dict(clip_planes=[(centre, (1.0, 0.3, 0.2))]),
        "crop box": dict(crop_box=(lo + 0.2 * (hi - lo), lo + 0.7 * (hi - lo))),
        "two planes and a crop box": dict(clip_planes=[(centre, (0.0, -1.0, 0.3)),
                                                       (lo + 0.3 * (hi - lo), (0.2, 0.1, 1.0))],
                                          crop_box=(lo + 0.1 * (hi - lo), lo + 0.8 * (hi - lo))),
    }


@pytest.mark.parametrize("clip", ["plane", "crop box", "two planes and a crop box"])
@pytest.mark.parametrize("view", ["perspective", "orthographic", "along an axis", "45 degrees", "eye inside"])
def test_gl_clips_as_its_twin_does(renderer, view, clip):
    scene = ball_scene(view, **ball_clips()[clip])
    gl = renderer.render(scene, technique="tetra")
    twin = reference.render(scene, technique="tetra")
    assert gl[..., 3].max() > 0.2
    assert metrics.max_abs_error(gl, twin) < GL_TOL
    whole = renderer.render(scene.replace(clip_planes=(), crop_box=None), technique="tetra")
    assert metrics.max_abs_error(gl, whole) > 0.05            # the clip changes the picture


@pytest.mark.parametrize("mode", ["mip", "minip", "average"])
def test_gl_reductions_clip_as_the_twin_does(renderer, mode):
    scene = ball_scene("perspective", mode=mode, **ball_clips()["plane"])
    gl = renderer.render(scene, technique="tetra")
    assert metrics.max_abs_error(gl, reference.render(scene, technique="tetra")) < GL_TOL
    assert metrics.max_abs_error(gl, reference.exact(scene, cache=False)) < GL_TOL


def test_lit_and_depth_cued_cells_clip_as_the_twin_does(renderer):
    for extra in (dict(shading=True), dict(illustration="depth_cue")):
        scene = ball_scene("perspective", **ball_clips()["plane"], **extra)
        gl = renderer.render(scene, technique="tetra")
        assert gl[..., 3].max() > 0.2
        assert metrics.max_abs_error(gl, reference.render(scene, technique="tetra")) < GL_TOL


def test_culled_cells_change_no_pixel(renderer, monkeypatch):
    """Leaving out the cells the clip keeps nothing of (once per clip) changes no pixel:
    every fragment of theirs would be discarded, and the rest of the order is still
    back to front."""
    scene = ball_scene("perspective", **ball_clips()["two planes and a crop box"])
    plan = tetra.make_plan(scene)
    assert 0 < plan.draw.size < tetra.make_plan(scene.replace(clip_planes=(), crop_box=None)).draw.size
    culled = renderer.render(scene, technique="tetra")
    calls = []
    monkeypatch.setattr(tetra, "cells_kept", lambda scene, cells: calls.append(1) or np.ones(len(cells), bool))
    fresh = dvr_gl.Renderer()
    try:
        everything = fresh.render(scene, technique="tetra")
        fresh.render(scene, technique="tetra")
        fresh.render(ball_scene("perspective", size=40, **ball_clips()["two planes and a crop box"]),
                     technique="tetra")
    finally:
        fresh.release()
    assert len(calls) == 1                                    # found once per mesh and clip
    assert np.abs(culled - everything).max() < 1e-6


# ------------------------------------------------------------- error against the clipped exact
def _shared_bluntfin():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    data = os.environ.get("DVR_GL_DATA") or os.path.join(os.path.dirname(root), "shared", "data")
    path = os.path.join(data, "nasa_bluntfin", "bluntfin_tets.npz")
    if not os.path.exists(path):
        pytest.skip("the shared data folder is not beside the checkout (or at $DVR_GL_DATA)")
    from dvr_gl.formats import load_mesh
    from dvr_gl.model.transfer import auto_preset
    mesh = load_mesh(path)
    lo, hi = mesh.bounds
    centre = (lo + hi) / 2
    base = Scene(mesh, auto_preset(mesh), dvr_gl.default_camera(mesh, azimuth=30, elevation=20), 48, 48)
    return base, {"plane": dict(clip_planes=[(centre, (1.0, 0.3, 0.2))]),
                  "crop box": dict(crop_box=(lo + 0.2 * (hi - lo), lo + 0.7 * (hi - lo)))}


@pytest.mark.parametrize("data", ["delaunay ball", "blunt fin"])
def test_error_against_the_clipped_exact_stays_within_the_unclipped_error(renderer, data):
    """The ball (scattered points, Delaunay) and NASA's blunt fin (a curvilinear CFD grid
    split into tets: non-convex around the fin, with zero-volume cells), cut by an
    oblique plane through the middle and by a crop box, composite and mip."""
    if data == "blunt fin":
        base, clips = _shared_bluntfin()
        scenes = [(base, clip) for clip in clips.values()]
    else:
        clips = ball_clips()
        scenes = [(ball_scene("perspective", mode=mode), clips[name])
                  for mode in ("composite", "mip") for name in ("plane", "crop box")]
    for base, clip in scenes:
        scene = base.replace(**clip)
        exact = reference.exact(scene)
        gl = renderer.render(scene, technique="tetra")
        err = metrics.rmse(gl, exact)
        err_unclipped = metrics.rmse(renderer.render(base, technique="tetra"), reference.exact(base))
        assert err <= err_unclipped, (clip, err, err_unclipped)
        assert metrics.max_abs_error(gl, exact) < GL_TOL
        # against the unclipped exact image it is plainly wrong: the judge sees the clip
        assert metrics.rmse(gl, reference.exact(base)) > 100 * err
