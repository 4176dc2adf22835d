"""The exact image of a scene whose volume is a LazyVolume (a store larger than memory),
reading only the samples its rays need, block by block.

The integrator is ``exact_one``'s, unchanged: its traversal cuts every ray at the grid
planes and reads the eight corners of each cell a piece lies in by their flat index into
the samples (``z * nx * ny + y * nx + x``). Here those samples are not in memory. For one
block of rays at a time:

1. Gather: the same traversal (``_Exact.march`` with the mode's window) is run with the
   corner reads recorded instead of made, every ray to its end (no early termination), so
   the recorded cells are those the integrator visits, or more. Their corners' flat
   indices, sorted and made unique, are what the block needs.
2. Read: the needed samples are grouped by the store's chunks (``LazyVolume.chunks``,
   else cubes of ``DEFAULT_BLOCK``); each chunk holding some is read once
   (``LazyVolume.read``) and only those samples kept, as float64.
3. Integrate: the integrator runs on the block of rays with its corner reads answered
   from the gathered samples (``_Gathered``: a lookup by sorted flat index).

Memory stays near one chunk plus the block's samples (a few bytes of index and value per
cell each ray crosses); the image is ``exact_one``'s for the same samples, bit for bit
where the arithmetic is the same (the corners are the same numbers; only where they come
from differs). Rows of the image go together in a block, so a block's rays cross a slab
of the volume and the chunks read per block overlap little.

What it takes: one volume, modes composite, mip, minip and average, unlit (lighting and
illustration terms read gradients over the whole volume), no 2-D transfer function, no
opaque geometry; clip planes and a crop box as ``exact_one``. A LazyVolume's samples are
taken as finite (a chunk read with a non-finite sample is an error naming it).
"""

from __future__ import annotations

import numpy as np

from ..model.clipping import clip_interval, plane_offsets
from ..model.lazy_volume import LazyVolume
from .common import ray_box
from .exact_one import _WINDOW, _Exact, _classify

__all__ = ["exact_lazy"]

DEFAULT_RAYS = 1024       # rays gathered and integrated at a time (bounds memory)
DEFAULT_BLOCK = 128       # samples a side of a read where the store has no chunks
MODES = ("composite", "mip", "minip", "average")


class _Gathered:
    """Samples by flat index: ``keys`` sorted unique int64, ``values`` float64 beside
    them; ``g[flat]`` looks each index up (all must be there)."""

    def __init__(self, keys, values):
        self.keys, self.values = keys, values

    def __getitem__(self, flat):
        at = np.searchsorted(self.keys, flat)
        if at.size and (at.max() >= self.keys.size or not np.array_equal(self.keys[at], flat)):
            raise LookupError("exact_lazy: a corner outside the gathered samples (a bug in the gather)")
        return self.values[at]


class _LazyExact(_Exact):
    """``exact_one``'s grid integrator over a LazyVolume: ``flat`` is the gathered
    samples of the current block of rays (``gather`` then ``load``)."""

    def __init__(self, scene):                  # _Exact's, without reading the samples
        vol = scene.volume
        self.scene = scene
        self.vol = vol
        nz, ny, nx = vol.shape
        self.nx, self.nxy = nx, nx * ny
        self.dims = vol.dims.astype(np.float64)
        self.origin = vol.origin
        self.spacing = vol.spacing
        self.valid = None
        self.flat = None
        self._recorded = None
        super(_Exact, self).__init__(scene.tf, scene.optical_model)

    def cubic(self, flat, u, hu, ends):
        if self._recorded is None:
            return super().cubic(flat, u, hu, ends)
        nx, nxy = self.nx, self.nxy
        corners = (flat[:, None] + np.array([0, 1, nx, nx + 1, nxy, nxy + 1, nxy + nx, nxy + nx + 1])).ravel()
        self._recorded.append(np.unique(corners))
        zero = np.zeros(len(flat))
        return np.zeros((len(flat), 4)), zero, zero

    def gather(self, o, d, t0, t1, window):
        """Sorted unique flat indices of every corner of every cell the rays cross."""
        self._recorded = []
        try:
            self.march(o, d, t0, t1, window, lambda a, P: np.zeros(len(a), bool))
            parts = self._recorded
        finally:
            self._recorded = None
        return np.unique(np.concatenate(parts)) if parts else np.zeros(0, np.int64)

    def load(self, keys, block, on_read=None):
        """Read the samples ``keys`` (sorted flat indices) chunk by chunk; they become
        ``flat``."""
        nz, ny, nx = self.vol.shape
        z, rest = np.divmod(keys, self.nxy)
        y, x = np.divmod(rest, nx)
        bz, by, bx = block
        gy, gx = -(-ny // by), -(-nx // bx)
        chunk = ((z // bz) * gy + y // by) * gx + x // bx
        order = np.argsort(chunk, kind="stable")
        chunk_sorted = chunk[order]
        starts = np.flatnonzero(np.r_[True, chunk_sorted[1:] != chunk_sorted[:-1]])
        stops = np.r_[starts[1:], chunk_sorted.size]
        values = np.empty(keys.size, np.float64)
        for s0, s1 in zip(starts, stops):
            c = int(chunk_sorted[s0])
            cz, rest_c = divmod(c, gy * gx)
            cy, cx = divmod(rest_c, gx)
            z0, y0, x0 = cz * bz, cy * by, cx * bx
            data = self.vol.read(z0, min(nz, z0 + bz), y0, min(ny, y0 + by), x0, min(nx, x0 + bx))
            if data.dtype.kind == "f" and not np.isfinite(data).all():
                raise ValueError(f"exact_lazy takes finite samples: samples z {z0}:{z0 + bz}, y {y0}:{y0 + by}, "
                                 f"x {x0}:{x0 + bx} of {self.vol.describe()} have some that are not")
            i = order[s0:s1]
            values[i] = data[z[i] - z0, y[i] - y0, x[i] - x0]
            if on_read is not None:
                on_read()
        self.flat = _Gathered(keys, values)


def _check(scene):
    if not isinstance(scene.volume, LazyVolume):
        raise TypeError(f"exact_lazy takes a scene whose volume is a LazyVolume, got {type(scene.volume).__name__}; "
                        f"a Volume in memory: dvr_gl.reference.exact")
    what = None
    if scene.layers:
        what = "several volumes (Scene.layers)"
    elif scene.mode not in MODES:
        what = f"mode {scene.mode!r} (it takes {', '.join(MODES)})"
    elif scene.optical_model == "sabella":
        what = "optical_model 'sabella'"
    elif scene.geometry:
        what = "opaque geometry (Scene.geometry)"
    elif getattr(scene, "tf_2d", None) is not None:
        what = "a 2-D transfer function"
    elif scene.reads_gradient:
        what = "lighting or terms that read gradients"
    if what is not None:
        raise ValueError(f"exact_lazy does not take {what}")


def exact_lazy(scene, rays=DEFAULT_RAYS, progress=True, stats=None):
    """The exact image of ``scene`` (its volume a LazyVolume): float64 (H, W, 4),
    premultiplied RGBA, row 0 on top, as ``dvr_gl.reference.exact`` gives for the same
    samples in memory. ``rays`` at a time are gathered, read and integrated (memory
    grows with it). ``stats``, a dict, receives ``chunks_read`` and ``samples_gathered``.
    Not cached (the caller keeps what it needs)."""
    _check(scene)
    ex = _LazyExact(scene)
    vol = scene.volume
    block = tuple(min(n, c) for n, c in zip(vol.shape, vol.chunks or (DEFAULT_BLOCK,) * 3))
    W, H = scene.width, scene.height
    origins, dirs = scene.camera.rays(W, H)
    o = origins.reshape(-1, 3)
    d = dirs.reshape(-1, 3)
    lo, hi = vol.bounds
    t0, t1 = ray_box(o, d, lo, hi)
    if scene.clips:
        t0, t1 = clip_interval(o, d, t0, t1, plane_offsets(scene.clip_planes), scene.crop_box)
    out = np.zeros((W * H, 4))
    hit = np.flatnonzero(t1 > t0)
    groups = [hit[i:i + max(1, int(rays))] for i in range(0, hit.size, max(1, int(rays)))]
    mode = scene.mode
    window = _WINDOW["composite" if mode == "composite" else "other"]
    counts = {"chunks_read": 0, "samples_gathered": 0}
    bar = None
    if progress and groups:
        from ..util.progress import Progress
        bar = Progress(len(groups))

    def counted():
        counts["chunks_read"] += 1

    with np.errstate(divide="ignore", invalid="ignore", over="ignore", under="ignore"):
        for k, r in enumerate(groups):
            args = (o[r], d[r], t0[r], t1[r])
            if bar is not None:
                bar.begin(f"exact image {W}x{H} of {vol.describe()}: rays {k + 1}/{len(groups)}, gather")
            keys = ex.gather(*args, window)
            counts["samples_gathered"] += int(keys.size)
            if bar is not None:
                bar.begin(f"exact image {W}x{H} of {vol.describe()}: rays {k + 1}/{len(groups)}, "
                          f"read {keys.size} samples")
            ex.load(keys, block, counted)
            if mode == "composite":
                out[r] = ex.composite(*args)
            elif mode in ("mip", "minip"):
                out[r] = _classify(scene.tf, ex.extreme(*args, 1.0 if mode == "mip" else -1.0))
            else:
                out[r] = _classify(scene.tf, ex.average(*args))
            ex.flat = None
            if bar is not None:
                bar.advance()
    if bar is not None:
        bar.close()
    if stats is not None:
        stats.update(counts)
    if not np.all(np.isfinite(out)):
        raise FloatingPointError("exact_lazy: non-finite pixel values (a bug in the integrator)")
    return out.reshape(H, W, 4)
