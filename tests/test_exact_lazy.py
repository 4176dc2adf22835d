"""The exact image of a LazyVolume read only where its rays go (reference/exact_lazy.py)
equals ``reference.exact`` of the same samples in memory: the same integrator fed the
same corner values, so the two agree to rounding (1e-12 here; ``exact``'s own accuracy is
about 1e-11), for perspective and orthographic views, several ray blocks, chunks that do
not divide the shape, and a crop box. It reads only chunks its rays cross."""

import numpy as np
import pytest

import dvr_gl
from dvr_gl.model.lazy_volume import LazyVolume
from dvr_gl.reference.exact import exact
from dvr_gl.reference.exact_lazy import exact_lazy

da = pytest.importorskip("dask.array")

SHAPE = (21, 26, 30)          # (nz, ny, nx): no axis a multiple of the chunks
CHUNKS = (8, 8, 8)
SIZE = 20
AGREE = 1e-12


@pytest.fixture(scope="module")
def samples():
    """Two smooth blobs on low noise, uint8: structure, empty parts and fine detail."""
    nz, ny, nx = SHAPE
    z, y, x = np.mgrid[0:nz, 0:ny, 0:nx].astype(np.float64)
    blob = 200 * np.exp(-((x - 10) ** 2 + (y - 12) ** 2 + (z - 9) ** 2) / 30.0)
    shell = 160 * np.exp(-((np.sqrt((x - 20) ** 2 + (y - 15) ** 2 + (z - 12) ** 2) - 6.0) ** 2) / 3.0)
    noise = np.random.default_rng(28).integers(0, 30, SHAPE)
    return np.clip(blob + shell + noise, 0, 255).astype(np.uint8)


def _tf():
    return dvr_gl.TransferFunction(color=[(0.0, 0.2, 0.4, 1.0), (255.0, 1.0, 0.8, 0.3)],
                                   opacity=[(0.0, 0.0), (40.0, 0.0), (120.0, 0.3), (255.0, 0.9)])


def _pair(samples, camera_options, **scene_options):
    spacing, origin = (1.0, 0.8, 1.3), (2.0, -1.0, 0.5)
    volume = dvr_gl.Volume(samples, spacing=spacing, origin=origin)
    lazy = LazyVolume(da.from_array(samples, chunks=CHUNKS), spacing=spacing, origin=origin)
    camera = dvr_gl.default_camera(volume, **camera_options)
    make = lambda v: dvr_gl.Scene(v, _tf(), camera, width=SIZE, height=SIZE, **scene_options)   # noqa: E731
    return make(volume), make(lazy)


@pytest.mark.parametrize("camera_options, scene_options", [
    (dict(azimuth=35, elevation=25), dict(mode="composite")),
    (dict(azimuth=-60, elevation=-10, ortho=True), dict(mode="composite")),
    (dict(azimuth=10, elevation=70), dict(mode="mip")),
    (dict(azimuth=120, elevation=5), dict(mode="average")),
])
def test_the_lazy_exact_image_is_the_in_memory_one(samples, camera_options, scene_options):
    in_memory, lazy = _pair(samples, camera_options, **scene_options)
    want = exact(in_memory, cache=False)
    stats = {}
    got = exact_lazy(lazy, rays=97, progress=False, stats=stats)     # several blocks of rays
    assert want[..., 3].max() > 0.2                                 # something to see
    assert np.abs(got - want).max() <= AGREE
    assert stats["chunks_read"] > 0 and stats["samples_gathered"] > 0


def test_a_crop_box_cuts_both_alike(samples):
    in_memory, lazy = _pair(samples, dict(azimuth=35, elevation=25))
    lo, hi = in_memory.volume.bounds
    box = (lo, np.array([0.5 * (lo[0] + hi[0]), hi[1], hi[2]]))
    in_memory, lazy = in_memory.replace(crop_box=box), lazy.replace(crop_box=box)
    assert np.abs(exact_lazy(lazy, progress=False) - exact(in_memory, cache=False)).max() <= AGREE


def test_only_the_chunks_the_rays_cross_are_read(samples):
    """A narrow view of one corner reads few of the 4 x 4 x 4 chunks."""
    _, lazy = _pair(samples, dict(azimuth=0, elevation=0, ortho=True))
    lo, hi = lazy.volume.bounds
    camera = lazy.camera
    corner = lo + 0.1 * (hi - lo)
    narrow = dvr_gl.Camera(eye=corner + (camera.eye - camera.target), target=corner, up=camera.up,
                           ortho_height=0.1 * float(hi[1] - lo[1]))
    stats = {}
    exact_lazy(lazy.replace(camera=narrow), progress=False, stats=stats)
    assert 0 < stats["chunks_read"] <= 4 * 2         # one column of chunks along the view, or two


def test_what_it_does_not_take_is_named(samples):
    in_memory, lazy = _pair(samples, dict(azimuth=35, elevation=25))
    with pytest.raises(TypeError, match="LazyVolume"):
        exact_lazy(in_memory)
    with pytest.raises(ValueError, match="mode 'isosurface'"):
        exact_lazy(lazy.replace(mode="isosurface", iso_value=100.0))
