"""Bricked ray casting (``techniques/bricks.py``) against the single texture.

Why the images agree: a brick's pass takes exactly the segments whose midpoint lies in the
cells it owns, passes run in an order every ray meets them in, and each continues the
ray's sums from the float32 image of the passes before, so every ray composites the same
pieces in the same order with the same arithmetic. The one difference is the texture
coordinate. Interpolated from texel fetches in the shader (``TEXTURE_FILTER_EXACT`` 0, as
on GPUs; integer data is always bricked that way), a brick's texel coordinate is the
whole texture's less a whole number, exact in float32, so floor, fraction and the values
fetched are the same: the images are equal bit for bit. That needs the shaders' arithmetic
evaluated as written in both: a GPU compiler fuses ``p / spacing - o`` into one FMA (and
the rest as it pleases) unless told not to, so the ray's positions, the texel coordinates,
the sums and the extreme are ``precise`` (shaders/common/precise.glsl; measured on an
NVIDIA GPU: bit for bit with it, up to 3e-6 apart without). Through the texture unit (float
data on llvmpipe), the normalised coordinate ``(x - o + 0.5) / m`` rounds differently from
``(x + 0.5) / n``; with the fetched images equal, the triangle inequality bounds each
pixel's difference by the two paths' own differences from their fetched images: the
rounding of texture coordinates and nothing else (a missed or doubled sample is 1e-3 or
more; these are about 1e-6).
"""

import functools
import os

import numpy as np
import pytest

import dvr_gl
from dvr_gl import data
from dvr_gl.techniques import bricks, raycast

SHARED_DATA = os.environ.get("DVR_GL_DATA") or os.path.join(
    os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "shared", "data")
CHEST = os.path.join(SHARED_DATA, "vtkjs_lidc2_ct", "LIDC2_256x256x133_uint8.raw.gz")
SIZE = 48


@functools.lru_cache(maxsize=None)
def _volume(name, dtype=None):
    if name == "head":
        volume, tf = data.ct_head(), data.ct_head_tf()
    else:
        if not os.path.exists(CHEST):
            pytest.skip(f"shared data not found: {CHEST}")
        from dvr_gl.frontends import inputs
        volume, _ = inputs.load_input(CHEST)
        tf = inputs.PRESETS["ct_bone_8bit"](volume)
    if dtype is not None:
        volume = dvr_gl.Volume(volume.data.astype(dtype), spacing=volume.spacing, origin=volume.origin)
    return volume, tf


def _scene(volume, tf, view, extra=()):
    lo, hi = volume.bounds
    centre = (lo + hi) / 2
    size = float((hi - lo).max())
    if view == "oblique":      # perspective
        camera = dvr_gl.default_camera(volume, azimuth=35, elevation=25)
    elif view == "ortho_oblique":
        camera = dvr_gl.default_camera(volume, azimuth=-20, elevation=10, ortho=True)
    else:                      # orthographic along -y: rays run along brick faces
        camera = dvr_gl.Camera(centre + [0.0, -3 * size, 0.0], centre, up=(0, 0, 1), ortho_height=1.2 * size)
    options = {}
    if "lit" in extra:
        options["shading"] = True
    if "clipped" in extra:
        options["clip_planes"] = [(centre, (1.0, 0.3, 0.2))]
    return dvr_gl.Scene(volume, tf, camera, width=SIZE, height=SIZE, **options)


@pytest.mark.parametrize("name", ["head", "chest"])
@pytest.mark.parametrize("view,extra,brick", [("oblique", (), 16), ("axis", (), 32),
                                              ("oblique", ("lit", "clipped"), 32), ("axis", ("lit",), 16)])
def test_fetched_bricks_equal_the_single_texture_bit_for_bit(fetch_renderer, name, view, extra, brick):
    volume, tf = _volume(name)
    scene = _scene(volume, tf, view, extra)
    single = fetch_renderer.render(scene)
    bricked = fetch_renderer.render(scene, brick_size=brick)
    assert single[..., 3].max() > 0.5, "the scene must show something"
    np.testing.assert_array_equal(bricked, single)


@pytest.mark.parametrize("name", ["head", "chest"])
@pytest.mark.parametrize("view,extra,dtype", [("oblique", ("lit",), np.float32), ("axis", ("clipped",), np.float32),
                                              ("oblique", ("lit",), None)])
def test_filtered_bricks_differ_by_texture_coordinate_rounding(renderer, fetch_renderer, name, view, extra, dtype):
    """Float data and, where the texture unit's filter is exact, the data's own 8- and
    16-bit integers (as 16-bit normalised texels, whose conversion back is float
    rounding too)."""
    volume, tf = _volume(name, dtype)
    scene = _scene(volume, tf, view, extra)
    single, single_fetched = renderer.render(scene), fetch_renderer.render(scene)
    bricked, bricked_fetched = renderer.render(scene, brick_size=16), fetch_renderer.render(scene, brick_size=16)
    np.testing.assert_array_equal(bricked_fetched, single_fetched)
    bound = np.abs(bricked - bricked_fetched) + np.abs(single - single_fetched)
    assert np.all(np.abs(bricked - single) <= bound)
    assert bound.max() < 1e-5, "the filters' own difference should be float rounding"


@pytest.mark.parametrize("mode", ["mip", "minip", "average"])
def test_projection_modes_carry_their_state_across_bricks(renderer, fetch_renderer, mode):
    """The extreme (or the sums of the average) goes from brick to brick in the running
    image and is classified once at the end, as the single pass does."""
    volume, tf = _volume("head")
    for view in ("oblique", "ortho_oblique"):     # (along an axis, minip sees the air around the head)
        scene = _scene(volume, tf, view).replace(mode=mode)
        single = fetch_renderer.render(scene)
        assert single[..., 3].max() > 0.01, "the scene must show something"
        np.testing.assert_array_equal(fetch_renderer.render(scene, brick_size=16), single)
    filtered = _scene(*_volume("head", np.float32), "oblique").replace(mode=mode)
    assert np.abs(renderer.render(filtered, brick_size=16) - renderer.render(filtered)).max() < 1e-5


def test_one_brick_larger_than_the_volume_is_the_single_texture(renderer):
    volume, tf = _volume("head", np.float32)
    scene = _scene(volume, tf, "oblique", ("lit",))
    np.testing.assert_array_equal(renderer.render(scene, brick_size=1000), renderer.render(scene))


def test_tiles_eye_inside_jitter_and_low_precision_targets(fetch_renderer):
    """The running image is float32 whatever the target (converted once at the end), a
    tile's pixels are read where they are written, and an eye inside the volume draws
    every brick over the whole image."""
    volume, tf = _volume("head")
    scene = _scene(volume, tf, "oblique")
    for options in ({"target": "rgba8"}, {"target": "rgba16f"}, {"jitter_seed": 2}):
        np.testing.assert_array_equal(fetch_renderer.render(scene, brick_size=16, **options),
                              fetch_renderer.render(scene, **options))
    lo, hi = volume.bounds
    centre = (lo + hi) / 2
    inside = scene.replace(camera=dvr_gl.Camera(centre + [3.0, 1.0, 2.0], centre - [4.0, 0.0, 1.0], fov=70))
    np.testing.assert_array_equal(fetch_renderer.render(inside, brick_size=16), fetch_renderer.render(inside))
    tiled = dvr_gl.Renderer(max_tile=20)
    tiled.programs.context_defines["TEXTURE_FILTER_EXACT"] = 0
    try:
        np.testing.assert_array_equal(tiled.render(scene, brick_size=16), fetch_renderer.render(scene))
    finally:
        tiled.release()


def test_early_ray_termination_carries_across_bricks(fetch_renderer):
    """The threshold is tested on the ray's sums so far, brick after brick: the default
    termination leaves the same pixels as one pass."""
    volume, tf = _volume("head")
    scene = _scene(volume, tf, "oblique")
    for ert in (0.0, 0.05):
        single = fetch_renderer.render(scene, ert_transmittance=ert)
        np.testing.assert_array_equal(fetch_renderer.render(scene, brick_size=16, ert_transmittance=ert), single)


def test_empty_bricks_are_never_made(renderer):
    volume, tf = _volume("chest")
    scene = _scene(volume, tf, "oblique")
    parts = bricks.partition(volume.shape, 32, bricks.halo_for(scene))
    plan = raycast.make_plan(scene, brick_size=32)
    occupied = bricks.brick_occupancy(bricks.value_ranges(volume, parts), plan.lut)
    assert 0 < occupied.sum() < len(parts)
    skipped = renderer.render(scene, brick_size=32)
    made = bricks.brick_textures(renderer, volume).textures
    assert set(made) == {p.samples for p, o in zip(parts, occupied) if o}
    np.testing.assert_array_equal(renderer.render(scene, brick_size=32, skip_empty=False), skipped)


def test_bricks_come_by_themselves_past_the_texture_limit(renderer, monkeypatch):
    volume, tf = _volume("head")                     # 93 samples along z
    scene = _scene(volume, tf, "oblique")
    monkeypatch.setattr(bricks, "max_3d_texture_size", lambda ctx: 64)
    before = len(renderer.resources.created)
    auto = renderer.render(scene)
    assert ("brick_textures", ("Volume",)) in renderer.resources.created[before:]
    np.testing.assert_array_equal(auto, renderer.render(scene, brick_size=64 - 1 - 2 * bricks.halo_for(scene)))
    monkeypatch.undo()
    assert np.abs(auto - renderer.render(scene)).max() < 1e-5


def test_the_context_reports_its_3d_texture_limit(renderer):
    from dvr_gl.gl.capabilities import max_3d_texture_size
    assert max_3d_texture_size(renderer.ctx) >= 256


@pytest.mark.parametrize("ortho", [False, True])
def test_visibility_order_is_the_order_of_every_ray(ortho):
    """Rays from eyes outside, inside and on brick faces: the bricks owning a ray's
    midpoints (float32 positions against the float32 owned boxes, as the shader decides)
    come in the order's order."""
    rng = np.random.default_rng(4)
    volume = dvr_gl.Volume(np.zeros((20, 30, 25), np.float32), spacing=(0.8, 1.0, 1.5))
    parts = bricks.partition(volume.shape, 7, 1)
    extent = volume.extent
    eyes = [extent * [0.5, 0.4, 0.3], [7 * 0.8, 7.0, 14 * 1.5], extent * [1.6, -0.5, 2.0], [-9.0, 10.0, 4.5]]
    for eye in eyes:
        forward = rng.normal(size=3)
        order = bricks.visibility_order(parts, volume, np.asarray(eye), forward, ortho)
        rank = {p.index: i for i, p in enumerate(order)}
        boxes = [bricks.brick_uniforms(volume, p) for p in order]
        lo = np.array([b["u_own_lo"] for b in boxes], np.float32)
        hi = np.array([b["u_own_hi"] for b in boxes], np.float32)
        for _ in range(40):
            if ortho:
                dirs = np.broadcast_to(forward / np.linalg.norm(forward), (1, 3))
                origin = (np.asarray(eye) + rng.normal(size=3) * 10).astype(np.float32)
            else:
                dirs = rng.normal(size=(1, 3))
                dirs /= np.linalg.norm(dirs)
                origin = np.asarray(eye, np.float32)
            t = np.arange(0, 200, 0.37, dtype=np.float32)
            p = origin + t[:, None] * dirs.astype(np.float32)
            inside = np.all((p >= 0) & (p <= extent.astype(np.float32)), axis=1)
            owner = [int(np.flatnonzero(np.all((q >= lo) & (q < hi), axis=1))[0]) for q in p[inside]]
            ranks = [rank[order[i].index] for i in owner]
            assert ranks == sorted(ranks)


def test_bad_brick_sizes_are_named_errors():
    volume, tf = _volume("head")
    scene = _scene(volume, tf, "oblique")
    for bad in (0, -3):
        with pytest.raises(ValueError, match=f"brick_size must be at least 1 cell, got {bad}"):
            raycast.make_plan(scene, brick_size=bad)
    for bad in (2.5, True, "8"):
        with pytest.raises(TypeError, match="brick_size must be a whole number"):
            raycast.make_plan(scene, brick_size=bad)
    with pytest.raises(ValueError, match="does not yet take mode 'isosurface'"):
        raycast.make_plan(dvr_gl.Scene(volume, tf, scene.camera, width=8, height=8, mode="isosurface",
                                       iso_value=1000.0), brick_size=8)
    with pytest.raises(ValueError, match="does not yet take preintegrate=True"):
        raycast.make_plan(scene, brick_size=8, preintegrate=True)
    from dvr_gl.model.layers import channel_layers
    layers = channel_layers(np.stack([volume.data, volume.data]).astype(np.float32), spacing=tuple(volume.spacing))
    layered = dvr_gl.Scene.from_layers(layers, camera=scene.camera, width=8, height=8)
    with pytest.raises(ValueError, match=r"does not yet take several volumes \(Scene.layers\)"):
        raycast.make_plan(layered, brick_size=8)
    raycast.make_plan(layered)       # (no bricks asked for: planned by raycast_layers as before)


def test_memory_per_sample_follows_the_data():
    types = (np.uint8, np.int8, np.uint16, np.int16, np.float32, np.float64)
    assert [bricks.texel_format(t, filter_exact=False)[2] for t in types] == [1, 1, 2, 2, 4, 4]
    assert [bricks.texel_format(t, filter_exact=True)[2] for t in types] == [2, 2, 2, 2, 4, 4]


def test_bricks_read_a_source_through_its_read_method():
    calls = []

    class Source:
        shape = (5, 6, 7)

        def read(self, *bounds):
            calls.append(bounds)
            (z0, z1, y0, y1, x0, x1) = bounds
            return np.zeros((z1 - z0, y1 - y0, x1 - x0), np.uint16)

    block = bricks.read_block(Source(), 1, 3, 0, 6, 2, 7)
    assert block.shape == (2, 6, 5) and block.dtype == np.uint16 and calls == [(1, 3, 0, 6, 2, 7)]


def test_cli_takes_brick_size():
    from dvr_gl.frontends import cli
    parser = cli.build_parser()
    args = parser.parse_args(["render", "scan.npy", "--out", "x.png", "--brick-size", "32"])
    assert cli.technique_options(args) == {"technique": "raycast", "brick_size": 32}
    with pytest.raises(SystemExit):
        parser.parse_args(["render", "scan.npy", "--out", "x.png", "--brick-size", "0"])
