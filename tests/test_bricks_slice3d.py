"""Bricked 3-D texture slicing (``techniques/slice3d_bricks.py``) against the single texture.

Why the images agree: the planes, each fragment's segment and its midpoint sample are
computed alike in every pass, and a brick's pass keeps the fragments whose sample lies in
the cells it owns, so each (pixel, plane) fragment is drawn by exactly one brick; the gap
pass's chords by the brick owning their midpoint. Bricks are drawn back to front in an
order valid for every ray, planes far to near within each, and GL blends a pixel's
fragments in drawing order: every pixel blends the same fragments in the same order with
the same arithmetic. The one difference is the texture coordinate. Interpolated from texel
fetches (``TEXTURE_FILTER_EXACT`` 0, as on GPUs), a brick's texel coordinate is the whole
texture's less a whole number, exact in float32, and the images are equal bit for bit.
Through llvmpipe's texture unit the normalised coordinates round differently; each image
then lies within its own filter's rounding of the common fetched image, so per pixel
``|bricked - single| <= |bricked - bricked_fetched| + |single - single_fetched|``
(triangle inequality): that is the bound tested, and it must stay at float rounding
(below 1e-5; a sample lost or drawn twice moves a pixel by 1e-3 or more).
"""

import numpy as np
import pytest

import dvr_gl
from dvr_gl.reference.common import box_rays
from dvr_gl.techniques import slice3d, slice3d_bricks
from test_bricks import _scene, _volume


def assert_within_filter_rounding(renderer, fetch_renderer, scene, brick, **options):
    single, single_fetched = renderer.render(scene, "slice3d", **options), fetch_renderer.render(scene, "slice3d", **options)
    bricked = renderer.render(scene, "slice3d", brick_size=brick, **options)
    bricked_fetched = fetch_renderer.render(scene, "slice3d", brick_size=brick, **options)
    assert single[..., 3].max() > 0.5, "the scene must show something"
    np.testing.assert_array_equal(bricked_fetched, single_fetched)
    bound = np.abs(bricked - bricked_fetched) + np.abs(single - single_fetched)
    assert np.all(np.abs(bricked - single) <= bound)
    assert bound.max() < 1e-5, "the filters' own difference should be float rounding"


@pytest.mark.parametrize("name", ["head", "chest"])
@pytest.mark.parametrize("brick,extra", [(32, ()), (64, ()), (32, ("lit",)), (64, ("lit",))])
def test_bricked_slicing_is_the_single_texture_image(renderer, fetch_renderer, name, brick, extra):
    """The CT head and the chest CT in their own integer types, forced bricks of 32 and
    64, lit and unlit, perspective."""
    volume, tf = _volume(name)
    assert_within_filter_rounding(renderer, fetch_renderer, _scene(volume, tf, "oblique", extra), brick)


@pytest.mark.parametrize("view,options", [("ortho_oblique", {"proxy": "vertex"}), ("oblique", {"shells": True}),
                                          ("axis", {"target": "rgba8"}), ("oblique", {"step": 1.3})])
def test_proxies_shells_targets_and_steps(fetch_renderer, view, options):
    """Every way of drawing the planes, a low-precision target (blended in the same
    order, so rounded alike) and a step longer than a cell (a larger halo): small bricks
    of 16, fetched, bit for bit."""
    volume, tf = _volume("head")
    scene = _scene(volume, tf, view, ("lit",))
    np.testing.assert_array_equal(fetch_renderer.render(scene, "slice3d", brick_size=16, **options),
                                  fetch_renderer.render(scene, "slice3d", **options))


def gap_pixels(scene, plan):
    """How many pixels the gap pass draws (the NumPy twin's test, reference.slice3d)."""
    o, d, t0, t1 = box_rays(scene)
    per_t = d @ scene.camera.forward
    gap = (t1 > t0) & ((t1 - t0) * per_t <= 2 * plan.step)
    k_far = np.ceil((plan.far_depth - np.where(gap, t1, 0) * per_t) / plan.step).astype(np.int64)
    for shift in range(-1, 3):
        k = k_far + shift
        t = (plan.far_depth - k * plan.step) / per_t
        gap &= ~((k >= 0) & (k < plan.count) & (t > 0) & (t >= t0) & (t <= t1))
    return int(gap.sum())


def test_gap_chords_clip_planes_geometry_and_an_eye_inside(fetch_renderer):
    """An opaque field up to the box's faces, so the gap pass's chords at the silhouette
    show (its chords are the bricks' owning their midpoints, the rest read from the
    halo); a clip plane; an opaque sphere ending the rays; the eye inside the volume."""
    from test_geometry import icosphere
    rng = np.random.default_rng(5)
    values = 0.5 + 0.4 * np.sin(np.linspace(0, 9, 40))[None, None, :] * rng.uniform(0.5, 1, (24, 30, 1))
    volume = dvr_gl.Volume(values.astype(np.float32), spacing=(1.0, 1.3, 0.8))
    tf = dvr_gl.TransferFunction(color=[(0.0, 0.2, 0.4, 0.9), (1.0, 1.0, 0.8, 0.3)], opacity=[(0.0, 0.05), (1.0, 0.3)])
    scene = dvr_gl.Scene(volume, tf, dvr_gl.default_camera(volume, azimuth=40, elevation=30), width=64, height=64)
    # (a step of 2.5 cells: a larger halo)
    for step, least in ((None, 10), (2.0, 50)):
        assert gap_pixels(scene, slice3d.make_plan(scene, step)) > least, "the gap pass must draw some pixels"
    lo, hi = volume.bounds
    centre = (lo + hi) / 2
    sphere = icosphere(centre + [4.0, 0.0, 2.0], 6.0)
    for variant, step, sizes in ((scene, None, (5, 8)), (scene, 2.0, (8,)),
                                 (scene.replace(clip_planes=[(centre, (1.0, 0.3, 0.2))]), None, (8,)),
                                 (scene.replace(geometry=[sphere]), None, (8,)),
                                 (scene.replace(camera=dvr_gl.Camera(centre + [3.0, 1.0, 2.0], centre - [4.0, 0.0, 1.0],
                                                                     fov=70)), None, (8,))):
        single = fetch_renderer.render(variant, "slice3d", step)
        assert single[..., 3].max() > 0.2
        for brick in sizes:
            np.testing.assert_array_equal(fetch_renderer.render(variant, "slice3d", step, brick_size=brick), single)


def test_a_volume_past_the_texture_limit_is_bricked_by_itself(fetch_renderer, monkeypatch):
    volume, tf = _volume("head")
    scene = _scene(volume, tf, "oblique")
    single = fetch_renderer.render(scene, "slice3d")
    monkeypatch.setattr(slice3d_bricks.bricks, "max_3d_texture_size", lambda ctx: 40)
    plan = slice3d.make_plan(scene)
    assert slice3d_bricks.brick_size_for(fetch_renderer, plan) == 40 - 1 - 2 * slice3d_bricks.slice_halo(
        scene, plan.step, False)
    np.testing.assert_array_equal(fetch_renderer.render(scene, "slice3d"), single)


def test_what_is_not_bricked_is_named(renderer):
    volume, tf = _volume("head")
    scene = _scene(volume, tf, "oblique", ("lit",))
    with pytest.raises(ValueError, match="preintegrate"):
        renderer.render(scene, "slice3d", brick_size=32, preintegrate=True)
    with pytest.raises(ValueError, match="gradients='texture'"):
        renderer.render(scene, "slice3d", brick_size=32, gradients="texture")
    with pytest.raises(ValueError, match="brick_size must be at least 1"):
        renderer.render(scene, "slice3d", brick_size=0)
    with pytest.raises(TypeError, match="brick_size"):
        renderer.render(scene, "slice3d", brick_size=2.5)
    values = volume.data.astype(np.float32)
    values[3, 4, 5] = np.nan
    nan_scene = scene.replace(volume=dvr_gl.Volume(values, spacing=volume.spacing, mask_nonfinite=True))
    with pytest.raises(ValueError, match="non-finite samples"):
        renderer.render(nan_scene, "slice3d", brick_size=32)


def test_empty_bricks_are_skipped():
    """The chest's air around the body: bricks whose every texel is transparent are never
    drawn (the fetched images above are equal with them left out)."""
    volume, tf = _volume("chest")
    scene = _scene(volume, tf, "oblique")
    plan = slice3d.make_plan(scene)
    halo = slice3d_bricks.slice_halo(scene, plan.step, False)
    parts = slice3d_bricks.bricks.partition(volume.shape, 32, halo)
    ranges = slice3d_bricks.texture_ranges(volume, parts)
    occupied = slice3d_bricks.bricks.brick_occupancy(ranges, plan.lut)
    assert 0 < occupied.sum() < len(parts)


def test_float_data_in_float_bricks(renderer, fetch_renderer):
    volume, tf = _volume("chest", np.float32)
    assert_within_filter_rounding(renderer, fetch_renderer, _scene(volume, tf, "ortho_oblique", ("clipped",)), 32)


def test_tiles(fetch_renderer):
    """Each tile is a window of the same camera: the same planes, bricks and order."""
    volume, tf = _volume("head")
    scene = _scene(volume, tf, "oblique")
    tiled = dvr_gl.Renderer(max_tile=20)
    tiled.programs.context_defines["TEXTURE_FILTER_EXACT"] = 0
    try:
        np.testing.assert_array_equal(tiled.render(scene, "slice3d", brick_size=16),
                                      fetch_renderer.render(scene, "slice3d"))
    finally:
        tiled.release()
