"""Ray casting a LazyVolume (``techniques/lazy_bricks.py``): a store read brick by brick.

A LazyVolume is drawn by the same bricked passes as an in-memory Volume with the same
brick size: the same partition, texel formats, visibility order and shader. Only two
things differ: which bricks are skipped (from the store's summary, whose ranges include
a halo of 2 samples, not from ``bricks.value_ranges`` with 1) and the in-shader skipping
inside bricks (off for a LazyVolume). A skipped or extra brick is one whose every sample
has zero opacity, and composing a transparent sample leaves a ray's sums exactly as they
were, so the images are equal bit for bit: on the fetch path (as tests/test_bricks.py
takes it) and through the texture unit alike, since both volumes go through the same one.
"""

import numpy as np
import pytest

import dvr_gl
from dvr_gl import data
from dvr_gl.model.lazy_volume import LazyVolume, brick_summary
from dvr_gl.techniques import bricks, raycast
from dvr_gl.techniques.lazy_bricks import LazyVolumeTechniqueError
from dvr_gl.util.memory import BudgetError

SIZE = 40
BRICK = 16


@pytest.fixture(autouse=True)
def cache_folder(tmp_path, monkeypatch):
    """Summaries go to a folder of the test's own."""
    monkeypatch.setenv("DVR_GL_CACHE", str(tmp_path / "cache"))


def _store(tmp_path):
    """The CT head's samples as a zarr store (chunks of 32), opened lazily."""
    zarr = pytest.importorskip("zarr")
    head = data.ct_head()
    array = zarr.create_array(str(tmp_path / "head.zarr"), shape=head.shape, chunks=(32, 32, 32),
                              dtype=head.data.dtype)
    array[...] = head.data
    lazy = LazyVolume(zarr.open_array(str(tmp_path / "head.zarr"), mode="r"), spacing=head.spacing,
                      origin=head.origin)
    return head, lazy


def _counting(volume):
    """Count the volume's reads (the summary's and the bricks')."""
    calls = []
    read = volume.read

    def counted(*block):
        calls.append(block)
        return read(*block)
    volume.read = counted
    return calls


def _bone_tf():
    """Opaque only above 3000 (the densest bone): most of the head's bricks are empty."""
    return dvr_gl.TransferFunction(color=[(0.0, 1.0, 1.0, 0.9), (4000.0, 1.0, 1.0, 1.0)],
                                   opacity=[(0.0, 0.0), (3000.0, 0.0), (3500.0, 0.6), (4000.0, 0.8)])


def _scene(volume, tf, **options):
    camera = dvr_gl.default_camera(volume, azimuth=35, elevation=25)
    return dvr_gl.Scene(volume, tf, camera, width=SIZE, height=SIZE, **options)


@pytest.mark.parametrize("lit", [False, True])
def test_a_store_renders_as_the_volume_in_memory(tmp_path, renderer, fetch_renderer, lit):
    head, lazy = _store(tmp_path)
    tf = data.ct_head_tf()
    for r in (fetch_renderer, renderer):
        expected = r.render(_scene(head, tf, shading=lit), brick_size=BRICK)
        image = r.render(_scene(lazy, tf, shading=lit), brick_size=BRICK)
        assert expected[..., 3].max() > 0.5        # something to compare
        np.testing.assert_array_equal(image, expected)


def test_brick_size_comes_from_the_summary(tmp_path, fetch_renderer):
    head, lazy = _store(tmp_path)
    brick_summary(lazy, 32, progress=False)
    tf = data.ct_head_tf()
    plan = raycast.make_plan(_scene(lazy, tf))
    assert plan.brick_size == 32
    np.testing.assert_array_equal(fetch_renderer.render(_scene(lazy, tf)),
                                  fetch_renderer.render(_scene(head, tf), brick_size=32))


def test_empty_bricks_are_never_read(tmp_path, renderer):
    head, lazy = _store(tmp_path)
    summary = brick_summary(lazy, BRICK, progress=False)
    calls = _counting(lazy)
    scene = _scene(lazy, _bone_tf())
    plan = raycast.make_plan(scene, brick_size=BRICK)
    occupied = bricks.brick_occupancy((summary.lo.ravel(), summary.hi.ravel()), plan.lut)
    assert 0 < occupied.sum() < 0.5 * occupied.size          # most bricks empty
    image = renderer.render(scene, brick_size=BRICK)
    # the store's chunks (32 a side) are read, each once: those the drawn bricks meet
    parts = bricks.partition(lazy.shape, BRICK, bricks.halo_for(scene))
    drawn = [p.samples for p, o in zip(parts, occupied) if o]

    def chunks_met(samples):
        return {(z, y, x) for z in range(samples[0][0] // 32, (samples[0][1] - 1) // 32 + 1)
                for y in range(samples[1][0] // 32, (samples[1][1] - 1) // 32 + 1)
                for x in range(samples[2][0] // 32, (samples[2][1] - 1) // 32 + 1)}
    expected = set().union(*(chunks_met(s) for s in drawn))
    assert sorted(calls) == sorted({(z * 32, min(z * 32 + 32, lazy.shape[0]), y * 32, min(y * 32 + 32, lazy.shape[1]),
                                     x * 32, min(x * 32 + 32, lazy.shape[2])) for z, y, x in expected})
    np.testing.assert_array_equal(image, renderer.render(_scene(head, _bone_tf()), brick_size=BRICK))
    count = len(calls)
    renderer.render(scene, brick_size=BRICK)                  # again: every chunk from the cache
    assert len(calls) == count


def test_a_budget_below_one_brick_is_a_named_error(tmp_path, renderer):
    _, lazy = _store(tmp_path)
    scene = _scene(lazy, data.ct_head_tf())
    one_brick = (BRICK + 1 + 2) ** 3 * 2           # int16 samples, halo 1 each side
    with pytest.raises(BudgetError, match="memory budget .* smaller than one brick of 16 cells"):
        renderer.render(scene, brick_size=BRICK, memory=one_brick - 1)
    with pytest.raises(ValueError, match="memory must be a size"):
        renderer.render(scene, brick_size=BRICK, memory="lots")
    renderer.render(scene, brick_size=BRICK, memory=one_brick)    # one brick at a time fits


def test_a_small_budget_gives_the_same_image(tmp_path, renderer):
    head, lazy = _store(tmp_path)
    tf = data.ct_head_tf()
    full = renderer.render(_scene(lazy, tf), brick_size=BRICK)
    np.testing.assert_array_equal(renderer.render(_scene(lazy, tf), brick_size=BRICK, memory="64KiB"), full)


def test_other_techniques_name_the_ray_caster(tmp_path, renderer):
    head, lazy = _store(tmp_path)
    scene = _scene(lazy, data.ct_head_tf())
    for technique in ("slice3d", "slice2d", "particles", "splat"):
        with pytest.raises(LazyVolumeTechniqueError, match="only the ray caster"):
            renderer.render(scene, technique)
    with pytest.raises(ValueError, match="memory bounds the bricks read from a LazyVolume"):
        renderer.render(_scene(head, data.ct_head_tf()), memory="1GB")


def test_render_and_the_command_line_take_a_store(tmp_path, renderer):
    from dvr_gl.frontends import cli
    from dvr_gl.frontends.inputs import range_tf
    head, lazy = _store(tmp_path)
    path = str(tmp_path / "head.zarr")
    spacing = tuple(float(v) for v in head.spacing)        # (the store keeps none)
    by_path = dvr_gl.render(path, size=SIZE, spacing=spacing, memory="1MB", brick_size=BRICK)
    by_volume = dvr_gl.render(lazy, size=SIZE, brick_size=BRICK)
    np.testing.assert_array_equal(by_path, by_volume)
    tf = range_tf(lazy)                      # the default TF: a ramp over the summary's range
    assert tf.opacity_points[0][0] == pytest.approx(sum(head.data_range) / 2)
    assert by_volume[..., 3].max() > 0.1
    with pytest.raises(ValueError, match="only the ray caster"):
        dvr_gl.render(lazy, size=SIZE, technique="slice3d")
    out = tmp_path / "head.png"
    assert cli.main(["render", path, "-o", str(out), "--size", f"{SIZE}x{SIZE}", "--memory", "2MB"]) == 0
    assert out.stat().st_size > 0
    assert cli.main(["render", path, "-o", str(out), "--memory", "plenty"]) == 2
