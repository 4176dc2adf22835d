"""A LazyVolume's bricks put together from the store's chunks, each read once through the
brick cache (``LazyVolume.read_chunked``, ``bricks.LazyBrickTextures``): the block equals
the array's slice; a frame reads only the chunks its drawn bricks meet, each once, and
the image equals the one whose cache holds whole bricks (a budget too small for chunks),
bit for bit: the same samples reach the same textures."""

import numpy as np
import pytest

import dvr_gl
from dvr_gl.model.lazy_volume import LazyVolume, brick_summary
from dvr_gl.techniques import bricks, raycast
from dvr_gl.util.memory import BrickCache

from test_lazy_render import _counting

zarr = pytest.importorskip("zarr")

SHAPE = (40, 48, 56)        # (nz, ny, nx)
CHUNK = 16
BRICK = 12                  # bricks and chunks out of step: a brick meets up to 3 chunks an axis
SIZE = 32


@pytest.fixture(autouse=True)
def cache_folder(tmp_path, monkeypatch):
    monkeypatch.setenv("DVR_GL_CACHE", str(tmp_path / "cache"))


@pytest.fixture
def store(tmp_path):
    """A blob in one corner of low noise, uint16, in chunks of 16."""
    nz, ny, nx = SHAPE
    z, y, x = np.mgrid[0:nz, 0:ny, 0:nx].astype(np.float64)
    blob = 3000 * np.exp(-((x - 12) ** 2 + (y - 12) ** 2 + (z - 10) ** 2) / 40.0)
    noise = np.random.default_rng(28).integers(0, 200, SHAPE)
    samples = (blob + noise).astype(np.uint16)
    array = zarr.create_array(str(tmp_path / "blob.zarr"), shape=SHAPE, chunks=(CHUNK,) * 3, dtype=np.uint16)
    array[...] = samples
    return samples, str(tmp_path / "blob.zarr")


def _open(path):
    return LazyVolume(zarr.open_array(path, mode="r"))


def test_a_block_from_chunks_is_the_slice(store):
    samples, path = store
    volume = _open(path)
    calls = _counting(volume)
    cache = BrickCache("1MB")
    for block in [(0, 40, 0, 48, 0, 56), (15, 17, 3, 33, 31, 49), (39, 40, 47, 48, 55, 56)]:
        z0, z1, y0, y1, x0, x1 = block
        np.testing.assert_array_equal(volume.read_chunked(*block, cache), samples[z0:z1, y0:y1, x0:x1])
    assert len(calls) == len(set(calls)) == 3 * 3 * 4      # every chunk once, whole
    assert all((c[0] % CHUNK, c[2] % CHUNK, c[4] % CHUNK) == (0, 0, 0) for c in calls)


def test_a_frame_reads_the_chunks_its_bricks_meet_once(store, renderer):
    _, path = store
    tf = dvr_gl.TransferFunction(color=[(0.0, 1.0, 0.8, 0.5), (3200.0, 1.0, 1.0, 1.0)],
                                 opacity=[(0.0, 0.0), (600.0, 0.0), (3200.0, 0.5)])
    images, reads = {}, {}
    for memory, by_chunks in (("4MB", True), ("64KB", False)):     # a chunk is 8 KiB: 64 KB holds < 8
        volume = _open(path)
        summary = brick_summary(volume, BRICK, progress=False)
        calls = _counting(volume)
        camera = dvr_gl.default_camera(volume, azimuth=30, elevation=20)
        scene = dvr_gl.Scene(volume, tf, camera, width=SIZE, height=SIZE)
        images[by_chunks] = renderer.render(scene, brick_size=BRICK, memory=memory)
        textures = bricks.lazy_textures(renderer, volume, raycast.make_plan(scene, memory=memory).lazy.memory,
                                        bricks.filter_is_exact(renderer))
        assert textures.by_chunks is by_chunks
        plan = raycast.make_plan(scene, brick_size=BRICK)
        occupied = bricks.brick_occupancy((summary.lo.ravel(), summary.hi.ravel()), plan.lut)
        drawn = [p.samples for p, o in zip(bricks.partition(SHAPE, BRICK, 1), occupied) if o]
        assert 0 < len(drawn) < 0.2 * occupied.size and textures.bricks_read == len(drawn)
        reads[by_chunks] = list(calls)
        if by_chunks:
            met = {(z, y, x) for s in drawn
                   for z in range(s[0][0] // CHUNK, (s[0][1] - 1) // CHUNK + 1)
                   for y in range(s[1][0] // CHUNK, (s[1][1] - 1) // CHUNK + 1)
                   for x in range(s[2][0] // CHUNK, (s[2][1] - 1) // CHUNK + 1)}
            assert sorted(c[0::2] for c in calls) == sorted(tuple(i * CHUNK for i in m) for m in met)
            assert len(met) < 0.5 * 3 * 3 * 4            # of 36 chunks: the far ones, all noise, are not read
        else:
            assert sorted(calls) == sorted(tuple(v for pair in s for v in pair) for s in drawn)
    assert images[True][..., 3].max() > 0.2
    np.testing.assert_array_equal(images[True], images[False])
