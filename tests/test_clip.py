"""Clip planes and crop boxes: the scene's checks, the exact image against a closed form,
and the ray caster against its NumPy twin and against the clipped exact image.

The closed form: a constant volume (value s, TF opacity a per unit distance u, colour c)
seen orthographically along -z. A ray at (x, y) crosses the kept region over a length L
that this file computes on its own, from the plane's equation solved for z: the image is
``A = 1 - (1 - a)^(L/u)``, ``C = c A`` (premultiplied)."""

import numpy as np
import pytest

import dvr_gl
from dvr_gl import metrics, reference
from dvr_gl.data import ct_head, ct_head_tf
from dvr_gl.model.clipping import MAX_CLIP_PLANES, clip_interval

BOX = (20, 12, 16)        # (nz, ny, nx) samples, spacing 1: the box is 15 x 11 x 19
ALPHA, UNIT, COLOR = 0.2, 2.0, (0.9, 0.5, 0.25)


def constant_scene(size=24, **clip):
    vol = dvr_gl.Volume(np.full(BOX, 7.0, np.float32))
    tf = dvr_gl.TransferFunction(color=[(0.0, *COLOR), (10.0, *COLOR)], opacity=[(0.0, ALPHA), (10.0, ALPHA)],
                                 unit_distance=UNIT)
    lo, hi = vol.bounds
    centre = (lo + hi) / 2
    eye = centre + [0.0, 0.0, 100.0]
    cam = dvr_gl.Camera(eye, centre, up=(0, 1, 0), ortho_height=float(hi[1] - lo[1]) * 1.2)
    return dvr_gl.Scene(vol, tf, cam, size, size, **clip)


def pixel_xy(scene):
    """World (x, y) of every pixel's ray (orthographic, along -z)."""
    origins, _ = scene.camera.rays(scene.width, scene.height)
    return origins[..., 0], origins[..., 1]


def test_exact_matches_the_closed_form_of_a_box_cut_by_an_oblique_plane():
    point, normal = (7.0, 5.0, 9.0), (0.5, -0.3, 0.8)
    scene = constant_scene(clip_planes=[(point, normal)])
    x, y = pixel_xy(scene)
    (x0, y0, z0), (x1, y1, z1) = scene.volume.bounds
    # kept: n . (p - point) >= 0, i.e. z >= z_cut (normal's z > 0)
    n = np.asarray(normal) / np.linalg.norm(normal)
    z_cut = point[2] - (n[0] * (x - point[0]) + n[1] * (y - point[1])) / n[2]
    inside = (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
    length = np.where(inside, np.clip(z1 - np.maximum(z_cut, z0), 0.0, None), 0.0)
    alpha = 1 - (1 - ALPHA) ** (length / UNIT)
    expected = np.concatenate([np.asarray(COLOR) * alpha[..., None], alpha[..., None]], axis=-1)
    image = reference.exact(scene, cache=False)
    assert 0 < length.max() and (length == 0).any() and (length < z1 - z0).any()   # cut, whole and empty rays
    np.testing.assert_allclose(image, expected, rtol=0, atol=1e-9)


def test_exact_matches_the_closed_form_of_a_crop_box():
    lower, upper = (3.0, -5.0, 4.5), (11.5, 7.0, 30.0)
    scene = constant_scene(crop_box=(lower, upper))
    x, y = pixel_xy(scene)
    (x0, y0, z0), (x1, y1, z1) = scene.volume.bounds
    inside = (x >= max(x0, lower[0])) & (x <= min(x1, upper[0])) & (y >= max(y0, lower[1])) & (y <= min(y1, upper[1]))
    length = np.where(inside, min(z1, upper[2]) - max(z0, lower[2]), 0.0)
    alpha = 1 - (1 - ALPHA) ** (length / UNIT)
    expected = np.concatenate([np.asarray(COLOR) * alpha[..., None], alpha[..., None]], axis=-1)
    np.testing.assert_allclose(reference.exact(scene, cache=False), expected, rtol=0, atol=1e-9)


def test_two_planes_that_keep_nothing_give_an_empty_image():
    # x >= 8 and x <= 7
    scene = constant_scene(clip_planes=[((8.0, 5.0, 9.0), (1, 0, 0)), ((7.0, 5.0, 9.0), (-1, 0, 0))])
    assert np.all(reference.exact(scene, cache=False) == 0)


def test_clip_interval_on_parallel_rays_and_planes():
    o = np.array([[0.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    d = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    plane = ((np.array([0.0, 1.0, 0.0]), -0.5),)      # keeps y >= -0.5: the first ray, not the second
    t0, t1 = clip_interval(o, d, [0.0, 0.0], [5.0, 5.0], plane)
    assert t0[0] == 0 and t1[0] == 5 and t1[1] <= t0[1]
    t0, t1 = clip_interval(o, d, [0.0, 0.0], [5.0, 5.0], ((np.array([1.0, 0.0, 0.0]), 2.0),))
    np.testing.assert_array_equal(t0, [2.0, 2.0])


@pytest.mark.parametrize("kwargs, message", [
    (dict(clip_planes=[((0, 0, 0), (0, 0, 0))]), "clip_planes\\[0\\] normal must be non-zero"),
    (dict(clip_planes=[((0, 0, 0), (1, 0, 0))] * (MAX_CLIP_PLANES + 1)), "at most 6"),
    (dict(clip_planes=[((0, 0, np.nan), (1, 0, 0))]), "clip_planes\\[0\\] point must be finite"),
    (dict(clip_planes=[(0, 0, 1)]), "clip_planes\\[0\\] must be a \\(point, normal\\) pair"),
    (dict(crop_box=((5, 5, 5), (5, 6, 6))), "lower corner must be below"),
    (dict(crop_box=((100, 100, 100), (200, 200, 200))), "lies outside the data"),
    (dict(crop_box=(0, 1)), "crop_box lower corner must be three numbers"),
])
def test_bad_clips_are_named_errors(kwargs, message):
    with pytest.raises((ValueError, TypeError), match=message):
        constant_scene(**kwargs)


def test_clip_is_part_of_the_scene():
    plain = constant_scene()
    clipped = constant_scene(clip_planes=[((7, 5, 9), (0, 0, 1))])
    assert plain.digest() != clipped.digest()
    assert clipped.replace(width=32).digest() == clipped.replace(width=32, clip_planes=clipped.clip_planes).digest()
    assert clipped.replace(width=32).clips and not clipped.replace(clip_planes=()).clips
    assert plain.digest() == constant_scene(clip_planes=()).digest()     # earlier caches stay valid


def _head_scenes(size):
    head = ct_head()
    lo, hi = head.bounds
    centre = (lo + hi) / 2
    cam = dvr_gl.default_camera(head, azimuth=30, elevation=20)
    tf = ct_head_tf()
    return {
        "plane": dvr_gl.Scene(head, tf, cam, size, size, clip_planes=[(centre, (1.0, 0.3, 0.2))]),
        "two planes": dvr_gl.Scene(head, tf, cam, size, size,
                                   clip_planes=[(centre, (0.0, -1.0, 0.3)), (lo + 0.3 * (hi - lo), (0.2, 0.1, 1.0))]),
        "crop box": dvr_gl.Scene(head, tf, cam, size, size, crop_box=(lo + 0.2 * (hi - lo), lo + 0.7 * (hi - lo))),
        "plane, mip": dvr_gl.Scene(head, tf, cam, size, size, mode="mip", clip_planes=[(centre, (1.0, 0.3, 0.2))]),
        "crop, isosurface": dvr_gl.Scene(head, tf, cam, size, size, mode="isosurface", iso_value=1300.0,
                                         crop_box=(lo + 0.1 * (hi - lo), lo + 0.6 * (hi - lo))),
    }


@pytest.mark.parametrize("name", list(_head_scenes(8)))
def test_raycast_clips_as_its_twin_does(renderer, name):
    """Same bound as the unclipped ray caster's twin test (tests/test_raycast.py): the
    float32 sample positions and the 8-bit-free float target; the clipped interval's ends
    round like the box's."""
    scene = _head_scenes(48)[name]
    gl = renderer.render(scene)
    twin = reference.render(scene)
    assert gl[..., 3].max() > 0.2
    assert metrics.max_abs_error(gl, twin) < 2e-3
    unclipped = renderer.render(scene.replace(clip_planes=(), crop_box=None))
    assert metrics.max_abs_error(gl, unclipped) > 0.05          # the clip changes the picture


@pytest.mark.parametrize("name", ["plane", "two planes", "crop box"])
def test_raycast_error_against_clipped_exact_stays_within_the_unclipped_error(renderer, name):
    scene = _head_scenes(48)[name]
    unclipped = scene.replace(clip_planes=(), crop_box=None)
    err = metrics.rmse(renderer.render(scene, step=1.5), reference.exact(scene))
    err_unclipped = metrics.rmse(renderer.render(unclipped, step=1.5), reference.exact(unclipped))
    assert err <= err_unclipped
    # and against the unclipped exact image it is plainly wrong: the judge sees the clip
    assert metrics.rmse(renderer.render(scene, step=1.5), reference.exact(unclipped)) > 5 * err


def test_every_technique_clips_and_one_that_does_not_would_say_so(renderer, monkeypatch):
    from dvr_gl import techniques
    from dvr_gl.techniques import common
    assert set(common.CLIPPING_TECHNIQUES) == set(techniques.names())
    monkeypatch.setattr(common, "CLIPPING_TECHNIQUES", ("raycast",))
    with pytest.raises(ValueError, match="slice3d does not clip yet"):
        renderer.render(_head_scenes(16)["plane"], technique="slice3d")


def test_render_and_the_command_line_take_clips(renderer, tmp_path, capsys):
    from PIL import Image

    from dvr_gl.frontends import cli
    head = ct_head()
    centre = (head.bounds[0] + head.bounds[1]) / 2
    plane = (tuple(centre), (1.0, 0.3, 0.2))
    whole = dvr_gl.render("builtin:ct_head", size=32)
    cut = dvr_gl.render("builtin:ct_head", size=32, clip_planes=[plane])
    assert metrics.max_abs_error(whole, cut) > 0.05
    arg = ",".join(f"{v:g}" for v in (*plane[0], *plane[1]))
    assert cli.main(["render", "builtin:ct_head", "--size", "32x32", "--clip", arg,
                     "--out", str(tmp_path / "cut.png")]) == 0
    assert cli.main(["render", "builtin:ct_head", "--size", "32x32", "--out", str(tmp_path / "whole.png")]) == 0
    a = np.asarray(Image.open(tmp_path / "cut.png"), np.float64)
    b = np.asarray(Image.open(tmp_path / "whole.png"), np.float64)
    assert np.abs(a - b).max() > 20
    assert cli.main(["render", "builtin:ct_head", "--crop", "0,0,0,100,100,200", "--size", "32x32",
                     "--out", str(tmp_path / "crop.png")]) == 0


@pytest.mark.parametrize("args, option, message", [
    (["--clip", "1,2,3,0,0,0"], "--clip", "normal must be non-zero"),
    (["--crop", "500,500,500,600,600,600"], "--crop", "lies outside the data"),
    (["--crop", "5,5,5,1,6,6"], "--crop", "lower corner must be below"),
])
def test_the_command_line_names_a_bad_clip(tmp_path, capsys, args, option, message):
    from dvr_gl.frontends import cli
    out = tmp_path / "x.png"
    assert cli.main(["render", "builtin:ct_head", "--size", "16x16", *args, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{option}: " in err and message in err
    assert not out.exists()


def test_tolerance_keeps_its_promise_on_a_clipped_scene(renderer):
    # the pilot measures the clipped scene (Scene.replace keeps the clip)
    scene = _head_scenes(48)["plane"]
    image = renderer.render(scene, tolerance=2e-3)
    assert metrics.rmse(image, reference.exact(scene)) <= 2e-3
