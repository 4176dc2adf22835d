"""Lazy volumes: blocks read from zarr (v2, v3), OME-Zarr, HDF5, dask and memmaps equal the
array's slices; the per-brick min/max summary equals a brute-force one, halo included, and
is read from the cache folder the second time; the byte-bounded brick cache; the errors."""

import warnings

import numpy as np
import pytest

from dvr_gl import formats
from dvr_gl.model.lazy_volume import (LazyVolume, VolumeReadError, brick_block, brick_grid, brick_summary,
                                      summary_path)
from dvr_gl.util.memory import BrickCache, BudgetError, parse_bytes

zarr = pytest.importorskip("zarr")
h5py = pytest.importorskip("h5py")
da = pytest.importorskip("dask.array")

SHAPE = (19, 23, 29)          # (nz, ny, nx): no axis a multiple of the chunks or bricks
CHUNKS = (8, 8, 8)
BLOCKS = [(0, 19, 0, 23, 0, 29), (3, 11, 5, 6, 7, 28), (18, 19, 22, 23, 0, 1), (7, 16, 0, 23, 9, 17)]


@pytest.fixture(scope="module")
def samples():
    rng = np.random.default_rng(28)
    return rng.integers(0, 4000, SHAPE).astype(np.uint16)


def _zarr(tmp_path, data, fmt):
    path = tmp_path / f"v{fmt}.zarr"
    group = zarr.open_group(str(path), mode="w", zarr_format=fmt)
    group.create_array("scan/raw", shape=data.shape, chunks=CHUNKS, dtype=data.dtype)[:] = data
    group.create_array("other", shape=(4, 4), dtype="f4")
    return path


def _ome_by_hand(tmp_path, data):
    """An OME-Zarr 0.4 image (zarr v2) with a channel axis of one and two levels, written
    to the spec without ome-zarr's writer: level s1 takes every other sample in y and x."""
    path = tmp_path / "hand.ome.zarr"
    group = zarr.open_group(str(path), mode="w", zarr_format=2)
    group.create_array("s0", shape=(1,) + data.shape, chunks=(1,) + CHUNKS, dtype=data.dtype)[:] = data[None]
    half = data[:, ::2, ::2]
    group.create_array("s1", shape=(1,) + half.shape, chunks=(1,) + CHUNKS, dtype=data.dtype)[:] = half[None]
    axes = [{"name": "c", "type": "channel"}] + [{"name": n, "type": "space", "unit": "micrometer"} for n in "zyx"]
    datasets = [{"path": "s0", "coordinateTransformations": [{"type": "scale", "scale": [1, 3.0, 0.5, 0.25]},
                                                               {"type": "translation", "translation": [0, 10, 20, 30]}]},
                {"path": "s1", "coordinateTransformations": [{"type": "scale", "scale": [1, 3.0, 1.0, 0.5]},
                                                               {"type": "translation", "translation": [0, 10, 20.25, 30.125]}]}]
    group.attrs["multiscales"] = [{"version": "0.4", "axes": axes, "datasets": datasets,
                                   "coordinateTransformations": [{"type": "scale", "scale": [1, 2, 2, 2]}]}]
    return path


def _sources(tmp_path, data):
    """(name, LazyVolume) for every kind of array-like."""
    out = [("zarr v2", formats.open_volume(f"{_zarr(tmp_path, data, 2)}:/scan/raw")),
           ("zarr v3", formats.open_volume(_zarr(tmp_path, data, 3), key="scan/raw")),
           ("ome-zarr by hand", formats.open_volume(_ome_by_hand(tmp_path, data)))]
    with warnings.catch_warnings():        # the writer's own deprecation notice, on import
        warnings.simplefilter("ignore", DeprecationWarning)
        from ome_zarr.writer import write_image
    written = tmp_path / "written.ome.zarr"
    write_image(data, zarr.open_group(str(written), mode="w"), axes="zyx", scale_factors=(2,))
    out.append(("ome-zarr writer", formats.open_volume(written)))
    h5 = tmp_path / "scan.h5"
    with h5py.File(h5, "w") as f:
        f.create_dataset("entry/data", data=data, chunks=CHUNKS)
        f.create_dataset("entry/flat", data=np.zeros(5))
    out.append(("hdf5", formats.open_volume(f"{h5}:/entry/data")))
    npy = tmp_path / "scan.npy"
    np.save(npy, data)
    out.append(("npy memmap", formats.open_volume(npy)))
    out.append(("dask", LazyVolume(da.from_array(data, chunks=CHUNKS))))
    out.append(("ndarray", LazyVolume(data)))
    return out


def test_blocks_equal_the_arrays_slices(tmp_path, samples):
    for name, volume in _sources(tmp_path, samples):
        assert volume.shape == SHAPE and volume.dtype == np.uint16, name
        for z0, z1, y0, y1, x0, x1 in BLOCKS:
            block = volume.read(z0, z1, y0, y1, x0, x1)
            assert type(block) is np.ndarray and block.dtype == np.uint16, name
            np.testing.assert_array_equal(block, samples[z0:z1, y0:y1, x0:x1], err_msg=name)
        assert volume.digest() is not None, name


def test_store_geometry_and_levels(tmp_path, samples):
    volume = formats.open_volume(_ome_by_hand(tmp_path, samples))
    # the level's scale and translation, then the image's scale of 2 (x, y, z order)
    np.testing.assert_allclose(volume.spacing, [0.5, 1.0, 6.0])
    np.testing.assert_allclose(volume.origin, [60, 40, 20])
    assert [lv.key for lv in volume.levels] == ["/s0", "/s1"]
    assert volume.levels[1].shape == (19, 12, 15)
    np.testing.assert_allclose(volume.levels[1].spacing, [1.0, 2.0, 6.0])
    coarse = formats.stores.open_level(volume, 1)
    np.testing.assert_array_equal(coarse.read(0, 19, 0, 12, 0, 15), samples[:, ::2, ::2])
    np.testing.assert_allclose(coarse.origin, [60.25, 40.5, 20])
    assert volume.chunks == CHUNKS
    np.testing.assert_allclose(volume.bounds[1], volume.origin + (np.array(SHAPE[::-1]) - 1) * volume.spacing)


def _brute_force(data, brick, halo):
    grid = brick_grid(data.shape, brick)
    lo, hi = np.empty(grid), np.empty(grid)
    for index in np.ndindex(*grid):
        z0, z1, y0, y1, x0, x1 = brick_block(data.shape, brick, index, halo)
        lo[index], hi[index] = data[z0:z1, y0:y1, x0:x1].min(), data[z0:z1, y0:y1, x0:x1].max()
    return lo, hi


@pytest.mark.parametrize("brick, halo", [(8, 2), (5, 1), ((4, 9, 6), 2), (16, 0)])
def test_summary_equals_brute_force_with_halo(tmp_path, samples, brick, halo):
    volume = formats.open_volume(_zarr(tmp_path, samples, 3), key="scan/raw")
    summary = brick_summary(volume, brick, halo, cache=False, progress=False, block_bytes=3000)
    lo, hi = _brute_force(samples, brick, halo)
    np.testing.assert_array_equal(summary.lo, lo)
    np.testing.assert_array_equal(summary.hi, hi)
    assert summary.data_range == (samples.min(), samples.max())


def test_summary_sees_a_lone_peak_in_the_halo_only():
    data = np.zeros((17, 17, 17), np.float32)
    data[9, 4, 4] = 5.0              # in brick (1, 0, 0)'s cells; brick (0, 0, 0) reads it as halo
    data[3, 3, 3] = np.nan           # not a value
    data[3, 3, 4] = np.inf
    summary = brick_summary(LazyVolume(data), 8, 1, cache=False, progress=False)
    assert summary.hi[0, 0, 0] == 5.0 and summary.hi[1, 0, 0] == 5.0
    assert summary.hi[0, 1, 0] == 0.0 and summary.lo[0, 0, 0] == 0.0
    assert brick_summary(LazyVolume(data), 8, 0, cache=False, progress=False).hi[0, 0, 0] == 0.0


class CountingArray:
    """An array-like that counts the samples read through it."""

    def __init__(self, data):
        self.data, self.shape, self.dtype, self.chunks = data, data.shape, data.dtype, CHUNKS
        self.samples_read = 0

    def __getitem__(self, key):
        block = self.data[key]
        self.samples_read += block.size
        return block


def test_summary_is_made_once_and_kept_in_the_cache_folder(tmp_path, samples, monkeypatch, capsys):
    monkeypatch.setenv("DVR_GL_CACHE", str(tmp_path / "cache"))
    array = CountingArray(samples)
    volume = LazyVolume(array, identity="counting test array")
    first = brick_summary(volume, 8, 2)
    assert array.samples_read == samples.size       # every sample once, no overlap between reads
    assert "brick summary" in capsys.readouterr().err   # the progress bar
    path = summary_path(volume, 8, 2)
    assert path.startswith(str(tmp_path / "cache" / "summaries"))
    again = brick_summary(LazyVolume(array, identity="counting test array"), 8, 2)
    assert array.samples_read == samples.size       # read from the cache folder, not the array
    np.testing.assert_array_equal(again.lo, first.lo)
    np.testing.assert_array_equal(again.hi, first.hi)
    brick_summary(volume, 8, 1, progress=False)     # another halo is another summary
    assert array.samples_read == 2 * samples.size
    assert volume.data_range == (samples.min(), samples.max())


def test_digest_follows_the_store(tmp_path, samples):
    path = _zarr(tmp_path, samples, 2)
    first = formats.open_volume(path, key="scan/raw").digest()
    assert formats.open_volume(path, key="scan/raw").digest() == first
    import os
    chunk = next(p for p in (path / "scan" / "raw").rglob("*") if p.is_file() and not p.name.startswith("."))
    later = max(p.stat().st_mtime_ns for p in path.rglob("*")) + 10 ** 9
    os.utime(chunk, ns=(later, later))        # a chunk rewritten (same size, a second later)
    assert formats.open_volume(path, key="scan/raw").digest() != first
    npy = tmp_path / "a.npy"
    np.save(npy, samples)
    mm = np.load(npy, mmap_mode="r")
    assert LazyVolume(mm[:5]).digest() != LazyVolume(mm[5:10]).digest()
    assert LazyVolume(samples).digest() == LazyVolume(samples.copy()).digest()
    assert LazyVolume(CountingArray(samples)).digest() is None


def test_lazily_generated_dask_volume_is_summarised_block_by_block():
    def ramp(block, block_info=None):
        (z0, _), (y0, _), (x0, _) = block_info[None]["array-location"]
        z, y, x = np.ogrid[:block.shape[0], :block.shape[1], :block.shape[2]]
        return ((z0 + z) + (y0 + y) + (x0 + x)).astype(np.uint8) % 200
    shape = (40, 48, 56)
    volume = LazyVolume(da.map_blocks(ramp, da.zeros(shape, dtype=np.uint8, chunks=16), dtype=np.uint8))
    summary = brick_summary(volume, 16, 2, cache=False, progress=False, block_bytes=16 ** 3)
    z, y, x = np.ogrid[:40, :48, :56]
    lo, hi = _brute_force(((z + y + x) % 200).astype(np.uint8), 16, 2)
    np.testing.assert_array_equal(summary.lo, lo)
    np.testing.assert_array_equal(summary.hi, hi)


def test_brick_cache_is_bounded_in_bytes():
    volume = LazyVolume(np.zeros((9, 9, 9), np.uint8))
    cache = BrickCache("3KiB")
    loads = []

    def loader(i):
        return lambda: loads.append(i) or np.full(1000, i, np.uint8)
    for i in (0, 1, 2, 0, 3):                  # 3 fit; 3 pushes out the least recently used, 1
        assert cache.get(volume, (i, 0, 0), loader(i))[0] == i
    assert loads == [0, 1, 2, 3] and cache.nbytes == 3000 and len(cache) == 3
    assert (volume, (1, 0, 0)) not in cache and (volume, (0, 0, 0)) in cache
    with pytest.raises(BudgetError, match=r"memory budget 3 KiB \(3072 bytes\) is smaller than one brick.*4000 bytes"):
        cache.get(volume, (4, 0, 0), lambda: np.zeros(4000, np.uint8))
    with pytest.raises(BudgetError, match="2048 bytes.*4096 bytes"):
        BrickCache(2048).require(4096)


@pytest.mark.parametrize("text, nbytes", [("2GB", 2 * 10 ** 9), ("512MiB", 512 * 2 ** 20), ("1.5G", 3 * 2 ** 29),
                                          ("4096", 4096), (" 64 kb ", 64000), (100, 100)])
def test_sizes(text, nbytes):
    assert parse_bytes(text) == nbytes


@pytest.mark.parametrize("text", ["2 parsecs", "", "-1GB", "0", "GB", True, 1.5])
def test_bad_sizes_name_the_value(text):
    with pytest.raises(ValueError, match="memory must be"):
        parse_bytes(text)


def test_named_errors(tmp_path, samples):
    with pytest.raises(formats.MissingFileError, match="no such file or store.*nowhere.zarr"):
        formats.open_store(tmp_path / "nowhere.zarr")
    path = _zarr(tmp_path, samples, 3)
    with pytest.raises(formats.InputError, match=r"'scan/missing' is not in .*/scan/raw \(19, 23, 29\) uint16") as e:
        formats.open_volume(path, key="scan/missing")
    assert e.value.field == "key"
    with pytest.raises(formats.InputError, match="is a group; name one of its arrays.*/scan/raw"):
        formats.open_volume(f"{path}:/scan")
    assert formats.open_volume(path).source[1] == "/scan/raw"      # the store's only 3-D array
    with pytest.raises(formats.InputError, match="shape"):
        formats.open_volume(path, key="other")
    wide = zarr.open_group(str(tmp_path / "wide.zarr"), mode="w")
    wide.create_array("x", shape=(3, 3, 3), dtype="int64")
    with pytest.raises(formats.InputError, match="int64") as e:
        formats.open_volume(tmp_path / "wide.zarr")
    assert e.value.field == "dtype"
    h5 = tmp_path / "two.h5"
    with h5py.File(h5, "w") as f:
        f["a"], f["b"] = samples, samples
    with pytest.raises(formats.InputError, match="holds 2 3-D datasets.*/a .*/b"):
        formats.open_volume(h5)
    with pytest.raises(formats.InputError, match="'/c' is not in"):
        formats.open_volume(f"{h5}:/c")
    channels = zarr.open_group(str(tmp_path / "channels.zarr"), mode="w", zarr_format=2)
    channels.create_array("0", shape=(2, 4, 4, 4), dtype="u1")
    channels.attrs["multiscales"] = [{"version": "0.4", "axes": ["c", "z", "y", "x"], "datasets": [{"path": "0"}]}]
    with pytest.raises(formats.InputError, match="axis 'c' has 2 entries"):
        formats.open_volume(tmp_path / "channels.zarr")
    with pytest.raises(formats.InputError, match="3 is not a level of .* \\(it has 2\\)"):
        formats.stores.open_level(formats.open_volume(_ome_by_hand(tmp_path, samples)), 3)
    broken = tmp_path / "broken.zarr"
    broken.mkdir()
    (broken / "zarr.json").write_text("{ not json")
    with pytest.raises(formats.InputError, match="broken.zarr.*could not be read as zarr") as e:
        formats.open_volume(broken)
    assert e.value.field == "path"
    volume = LazyVolume(samples)
    with pytest.raises(ValueError, match="block x 0:30 is empty or outside the volume's 0:29"):
        volume.read(0, 1, 0, 1, 0, 30)
    with pytest.raises(ValueError, match=r"brick index \(3, 0, 0\) is outside the grid of \(3, 3, 4\)"):
        brick_block(SHAPE, 8, (3, 0, 0))

    class Failing(CountingArray):
        def __getitem__(self, key):
            raise OSError("chunk missing")
    with pytest.raises(VolumeReadError, match="samples z 0:2, y 0:2, x 0:2 of .*failed: OSError: chunk missing"):
        LazyVolume(Failing(samples)).read(0, 2, 0, 2, 0, 2)


def test_load_volume_is_unchanged_and_open_volume_loads_whole(tmp_path, samples):
    npy = tmp_path / "scan.npy"
    np.save(npy, samples)
    loaded = formats.load_volume(npy)
    assert type(loaded).__name__ == "Volume"
    whole = formats.open_volume(_zarr(tmp_path, samples, 2), key="/scan/raw", lazy=False, spacing=(1, 2, 3))
    assert type(whole).__name__ == "Volume"
    np.testing.assert_array_equal(whole.data, samples)
    np.testing.assert_allclose(whole.spacing, [1, 2, 3])
    assert isinstance(formats.open_volume(npy), LazyVolume)


def test_cli_info_describes_a_store_without_reading_it(tmp_path, samples, capsys):
    from dvr_gl.frontends.cli import main
    path = _ome_by_hand(tmp_path, samples)
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "shape      29x23x19 (x, y, z)" in out and "dtype      uint16" in out
    assert "chunks     8x8x8" in out and "OME-Zarr" in out
    assert f"bytes      {19 * 23 * 29 * 2 / 1024:.3g} KiB as uint16, {19 * 23 * 29 * 4 / 1024:.3g} KiB as float32" in out
    assert "level 1    /s1: 15x12x19" in out
    h5 = tmp_path / "scan.h5"
    with h5py.File(h5, "w") as f:
        f["x"], f["y"] = samples, samples
    assert main(["info", str(h5), "--key", "/y"]) == 0
    assert "HDF5" in capsys.readouterr().out
    assert main(["info", str(h5)]) == 2
    assert "holds 2 3-D datasets; name one with a key" in capsys.readouterr().err


def test_bricks_agree_with_the_bricked_ray_caster():
    """One convention: the blocks summarised here are the blocks the ray caster's bricks
    read (its partition of cells, with its halo)."""
    bricks = pytest.importorskip("dvr_gl.techniques.bricks")
    for shape in [(19, 23, 29), (2, 9, 17), (33, 33, 33)]:
        for size in (4, 8, 16):
            for halo in (0, 1, 2):
                parts = bricks.partition(shape, size, halo)
                assert len(parts) == np.prod(brick_grid(shape, size))
                for part in parts:
                    expected = tuple(v for pair in part.samples for v in pair)
                    assert brick_block(shape, size, part.index, halo) == expected
