"""A volume read lazily, block by block, from an array larger than memory: a zarr array
(v2 or v3), an HDF5 dataset, a dask array, a NumPy memmap or a plain array.

:class:`LazyVolume` has the geometry of a :class:`dvr_gl.Volume` (shape, spacing, origin,
bounds ...) without holding the samples; :meth:`LazyVolume.read` returns one block.

Bricks: a brick of ``brick`` cells a side owns the cells ``[i*brick, (i+1)*brick)`` of
each axis (the last one fewer), so bricks tile the grid's cells without overlap; it
reads the samples of its cells, ``[i*brick, (i+1)*brick]``, plus ``halo`` samples on
every side (clipped to the grid) for interpolation and gradients.
:func:`brick_block` gives that block, :func:`brick_grid` the number of bricks, and
:meth:`LazyVolume.read_brick` reads it.

:func:`brick_summary` gives every brick's min and max over exactly the samples
:func:`brick_block` names, halo included, reading the array once, block by block, with a
progress bar; the result is kept in the cache folder (``$DVR_GL_CACHE/summaries``, else
``~/.cache/dvr_gl/summaries``) under the volume's :meth:`~LazyVolume.digest`, the brick
size and the halo, and read from there the next time.
"""

from __future__ import annotations

import hashlib
import io
import math
import os

import numpy as np

from ..util.memory import cache_folder
from .checks import _vector3
from .volume import SUPPORTED_DTYPES, GridGeometry, _modality, _orientation

SUMMARY_VERSION = 1          # part of the summary's file name: a new layout is a new file
DEFAULT_BRICK = 64           # cells a side, for data_range when no summary was asked for
DEFAULT_HALO = 2             # samples: trilinear interpolation needs 1, central gradients 2
READ_BLOCK_BYTES = 64 * 2 ** 20   # the summary reads blocks of about this size


class VolumeReadError(OSError):
    """Reading a block of a lazy volume failed; ``block`` is (z0, z1, y0, y1, x0, x1)."""

    def __init__(self, source, block, error):
        self.block = tuple(block)
        super().__init__(f"reading samples z {block[0]}:{block[1]}, y {block[2]}:{block[3]}, "
                         f"x {block[4]}:{block[5]} of {source} failed: {type(error).__name__}: {error}")


class LazyVolume(GridGeometry):
    """A structured scalar volume whose samples stay where they are stored.

    Parameters
    ----------
    array_like : 3-D (nz, ny, nx), with ``shape``, ``dtype`` and NumPy slicing (zarr,
        h5py, dask, memmap, ndarray); dtype uint8, uint16, int16, float32 or float64.
    spacing, origin : (x, y, z) world units, as for a Volume.
    orientation, modality : as for a Volume.
    source : ``(path, key)`` of the file or store the array lives in (the format readers
        give it); names it in messages and in :meth:`digest`. Found by itself for zarr
        arrays, HDF5 datasets and memmaps.
    identity : a string that names the data for :meth:`digest` when nothing else can
        (an array-like of your own).
    """

    def __init__(self, array_like, spacing=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0), orientation=None,
                 modality=None, source=None, identity=None):
        shape = getattr(array_like, "shape", None)
        dtype = getattr(array_like, "dtype", None)
        if shape is None or dtype is None or not hasattr(array_like, "__getitem__"):
            raise TypeError(f"array_like must have shape, dtype and NumPy slicing (zarr, h5py, dask, memmap, "
                            f"ndarray), got {type(array_like).__name__}")
        dtype = np.dtype(dtype)
        if dtype.type not in SUPPORTED_DTYPES:
            names = ", ".join(np.dtype(t).name for t in SUPPORTED_DTYPES)
            raise TypeError(f"dtype must be one of {names}, got {dtype}")
        shape = tuple(int(n) for n in shape)
        if len(shape) != 3:
            raise ValueError(f"array_like must be 3-D (nz, ny, nx), got ndim={len(shape)} shape={shape}")
        if min(shape) < 2:
            raise ValueError(f"array_like needs at least 2 samples on every axis, got shape={shape}")
        self.array = array_like
        self.shape = shape
        self.dtype = dtype
        self.spacing = _vector3("spacing", spacing, positive=True)
        self.origin = _vector3("origin", origin)
        self.orientation = _orientation(orientation)
        self.orientation_assumed = False
        self.modality = _modality(modality)
        self.mask_nonfinite = False
        self.source = source if source is not None else _source_of(array_like)
        self.identity = identity
        self.chunks = _chunks_of(array_like)
        self.levels = ()              # a multiscale store's levels (dvr_gl.formats.stores.Level)
        self.store_format = None      # what the format readers opened ("zarr v3", "HDF5", ...)
        self._digest = None
        self._summary = None

    # -- geometry: dims, extent, bounds, min_spacing from GridGeometry ---------------
    @property
    def nbytes(self):
        """Bytes of all samples in their own dtype."""
        return int(np.prod(self.shape, dtype=np.int64)) * self.dtype.itemsize

    @property
    def data_range(self):
        """(min, max) of the finite samples, from the brick summary: the one made last
        for this volume, else the one at DEFAULT_BRICK (read from the cache folder, or
        made there: one pass over the whole array)."""
        if self._summary is None:
            brick_summary(self, DEFAULT_BRICK)
        return self._summary.data_range

    @property
    def has_nonfinite(self):
        """False: a lazily read volume is taken as finite without reading it all; the ray
        caster checks each brick it reads and names one with non-finite samples."""
        return False

    # -- samples ---------------------------------------------------------------------
    def read(self, z0, z1, y0, y1, x0, x1):
        """The samples ``[z0:z1, y0:y1, x0:x1]`` as a NumPy array in the array's dtype
        (a dask array computes just this block). A read that fails is a VolumeReadError
        naming the block."""
        block = tuple(int(v) for v in (z0, z1, y0, y1, x0, x1))
        for axis, n, lo, hi in zip("zyx", self.shape, block[0::2], block[1::2]):
            if not 0 <= lo < hi <= n:
                raise ValueError(f"block {axis} {lo}:{hi} is empty or outside the volume's 0:{n} samples")
        try:
            data = self.array[block[0]:block[1], block[2]:block[3], block[4]:block[5]]
            if hasattr(data, "compute"):        # dask: this block only
                data = data.compute()
            data = np.asarray(data)
        except Exception as e:
            raise VolumeReadError(self.describe(), block, e) from e
        expected = (block[1] - block[0], block[3] - block[2], block[5] - block[4])
        if data.shape != expected or data.dtype != self.dtype:
            raise VolumeReadError(self.describe(), block, ValueError(
                f"got shape {data.shape} dtype {data.dtype}, expected {expected} {self.dtype}"))
        return data

    def read_chunked(self, z0, z1, y0, y1, x0, x1, cache):
        """The samples ``[z0:z1, y0:y1, x0:x1]`` put together from the whole chunks they
        meet, each read once through ``cache`` (a ``util.memory.BrickCache``, keyed by
        the chunk's index (cz, cy, cx)). A brick's block with its halo meets up to 27
        chunks; read alone, each brick would read (and a dask array compute, a zarr
        store decode) all of them again for a few samples. Reads directly where the array
        has no chunks."""
        if self.chunks is None:
            return self.read(z0, z1, y0, y1, x0, x1)
        block = (z0, z1, y0, y1, x0, x1)
        out = np.empty((z1 - z0, y1 - y0, x1 - x0), self.dtype)
        size = self.chunks
        spans = [range(lo // c, (hi - 1) // c + 1) for lo, hi, c in zip(block[0::2], block[1::2], size)]
        for cz in spans[0]:
            for cy in spans[1]:
                for cx in spans[2]:
                    index = (cz, cy, cx)
                    first = [i * c for i, c in zip(index, size)]
                    last = [min(n, f + c) for f, c, n in zip(first, size, self.shape)]
                    chunk = cache.get(self, index, lambda: self.read(first[0], last[0], first[1], last[1],
                                                                   first[2], last[2]))
                    lo = [max(b, f) for b, f in zip(block[0::2], first)]
                    hi = [min(b, e) for b, e in zip(block[1::2], last)]
                    out[lo[0] - z0:hi[0] - z0, lo[1] - y0:hi[1] - y0, lo[2] - x0:hi[2] - x0] = \
                        chunk[lo[0] - first[0]:hi[0] - first[0], lo[1] - first[1]:hi[1] - first[1],
                              lo[2] - first[2]:hi[2] - first[2]]
        return out

    def read_brick(self, brick, index, halo=DEFAULT_HALO):
        """The samples of brick ``index`` (bz, by, bx) of ``brick`` cells a side, with
        ``halo`` samples around it: see :func:`brick_block`."""
        return self.read(*brick_block(self.shape, brick, index, halo))

    # -- identity --------------------------------------------------------------------
    def describe(self):
        """The source in words, for messages: ``'scan.zarr:/0'``, ``'dask array x'``."""
        if self.source is not None:
            path, key = self.source
            return f"{path}:{key}" if key else str(path)
        if self.identity is not None:
            return str(self.identity)
        return f"{type(self.array).__module__.split('.')[0]} array {self.shape} {self.dtype}"

    def digest(self):
        """A hex string that names these samples, without reading them all, or None.

        What it promises: two volumes with the same digest have the same shape, dtype and
        samples, as far as these checks see. A store or file on disk: its absolute path,
        the key inside it, shape, dtype, and the modification time and size of every file
        under the array (a chunk rewritten changes it; content rewritten with its times
        and sizes restored does not, and copies of one store elsewhere differ). A dask
        array: its name, which dask derives from the graph (same functions and arguments,
        same name). A plain in-memory array: a hash of its bytes. Other array-likes:
        ``identity`` if given, else None (nothing is cached on disk for them). Taken once
        per object, when first asked."""
        if self._digest is None:
            parts = _identity_parts(self)
            if parts is None:
                return None
            h = hashlib.sha256(repr((self.shape, self.dtype.str)).encode())
            for part in parts:
                h.update(part if isinstance(part, bytes) else repr(part).encode())
            self._digest = h.hexdigest()
        return self._digest

    def __repr__(self):
        return (f"LazyVolume(shape={self.shape}, dtype={self.dtype}, spacing={tuple(self.spacing.tolist())}, "
                f"origin={tuple(self.origin.tolist())}, source={self.describe()!r})")


# ----------------------------------------------------------------------------- bricks

def _brick3(brick):
    values = (brick,) * 3 if np.isscalar(brick) else tuple(brick)
    if len(values) != 3 or not all(isinstance(b, (int, np.integer)) and not isinstance(b, bool) and b >= 1
                                   for b in values):
        raise ValueError(f"brick must be a positive whole number of cells (or three: z, y, x), got {brick!r}")
    return tuple(int(b) for b in values)


def _halo(halo):
    if isinstance(halo, bool) or not isinstance(halo, (int, np.integer)) or halo < 0:
        raise ValueError(f"halo must be a whole number of samples >= 0, got {halo!r}")
    return int(halo)


def brick_grid(shape, brick):
    """How many bricks of ``brick`` cells a side cover a grid of ``shape`` samples: (bz, by, bx)."""
    return tuple(max(1, math.ceil((n - 1) / b)) for n, b in zip(shape, _brick3(brick)))


def brick_block(shape, brick, index, halo=DEFAULT_HALO):
    """(z0, z1, y0, y1, x0, x1): the samples brick ``index`` reads, its own cells' samples
    ``[i*brick, (i+1)*brick]`` and ``halo`` more on each side, clipped to the grid."""
    brick, halo = _brick3(brick), _halo(halo)
    grid = brick_grid(shape, brick)
    out = []
    for axis, n, b, i, nb in zip("zyx", shape, brick, index, grid):
        if not 0 <= int(i) < nb:
            raise ValueError(f"brick index {tuple(index)} is outside the grid of {grid} bricks (axis {axis})")
        out += [max(0, int(i) * b - halo), min(n, (int(i) + 1) * b + 1 + halo)]
    return tuple(out)


class BrickSummary:
    """Per brick (bz, by, bx): ``lo`` and ``hi`` (float64), the min and max of the finite
    samples the brick reads (halo included); NaN where it reads none. ``data_range`` is
    the whole volume's."""

    def __init__(self, brick, halo, shape, lo, hi):
        self.brick, self.halo, self.shape = tuple(brick), int(halo), tuple(shape)
        self.lo, self.hi = lo, hi
        for a in (lo, hi):
            a.setflags(write=False)
        with np.errstate(all="ignore"):
            finite = np.isfinite(lo)
        self.data_range = ((float(np.min(lo[finite])), float(np.max(hi[finite]))) if finite.any()
                           else (math.nan, math.nan))

    @property
    def grid(self):
        return self.lo.shape

    def __repr__(self):
        return f"BrickSummary(brick={self.brick}, halo={self.halo}, grid={self.grid}, range={self.data_range})"


def summary_path(volume, brick, halo=DEFAULT_HALO, cache_dir=None):
    """The file that keeps ``volume``'s summary, or None when it has no digest."""
    digest = volume.digest()
    if digest is None:
        return None
    bz, by, bx = _brick3(brick)
    folder = os.fspath(cache_dir) if cache_dir is not None else cache_folder("summaries")
    return os.path.join(folder, f"{digest}-b{bz}x{by}x{bx}-h{_halo(halo)}-v{SUMMARY_VERSION}.npz")


def brick_summary(volume, brick, halo=DEFAULT_HALO, cache=True, cache_dir=None, progress=True,
                  block_bytes=READ_BLOCK_BYTES):
    """The :class:`BrickSummary` of ``volume`` (a LazyVolume) for bricks of ``brick``
    cells a side reading ``halo`` samples around them.

    Made once: it is read from the cache folder when there (``cache``), else computed by
    reading the array in blocks of whole chunks of about ``block_bytes`` (so memory stays
    near one block, whatever the array's size), with a progress bar on stderr
    (``progress``), and written there."""
    brick, halo = _brick3(brick), _halo(halo)
    path = summary_path(volume, brick, halo, cache_dir) if cache else None
    summary = _load_summary(path, brick, halo, volume.shape) if path is not None else None
    if summary is None:
        summary = _compute_summary(volume, brick, halo, progress, block_bytes)
        if path is not None:
            _save_summary(path, summary)
    volume._summary = summary
    return summary


def _load_summary(path, brick, halo, shape):
    try:
        with np.load(path) as f:
            lo, hi, meta = f["lo"], f["hi"], tuple(int(v) for v in f["meta"])
    except (OSError, ValueError, KeyError):       # absent or unreadable: made again
        return None
    if meta != tuple(brick) + (halo,) + tuple(shape) or lo.shape != brick_grid(shape, brick) or hi.shape != lo.shape:
        return None
    return BrickSummary(brick, halo, shape, lo, hi)


def _save_summary(path, summary):
    from ..util.files import atomic_write
    os.makedirs(os.path.dirname(path), exist_ok=True)
    buffer = io.BytesIO()
    np.savez(buffer, lo=summary.lo, hi=summary.hi, meta=np.array(summary.brick + (summary.halo,) + summary.shape))
    atomic_write(path, buffer.getvalue())


def _segments(n, b, nb, halo):
    """Cut points of one axis: every brick's sample range [start, stop) is a run of
    whole segments. Returns (cuts, first, last): segment k is [cuts[k], cuts[k+1]);
    brick i covers segments first[i] .. last[i]-1."""
    starts = np.maximum(0, np.arange(nb) * b - halo)
    stops = np.minimum(n, (np.arange(nb) + 1) * b + 1 + halo)
    cuts = np.unique(np.concatenate([[0, n], starts, stops]))
    return cuts, np.searchsorted(cuts, starts), np.searchsorted(cuts, stops)


def _read_blocks(shape, chunks, itemsize, block_bytes):
    """Blocks of whole chunks (a chunk's multiple along x, then y, then z) of about
    ``block_bytes``, covering the grid: a list of (z0, z1, y0, y1, x0, x1)."""
    if chunks is None:                          # unchunked: slabs of whole z planes
        chunks = (1, shape[1], shape[2])
    size = [min(c, n) for c, n in zip(chunks, shape)]
    for axis in (2, 1, 0):
        while size[axis] < shape[axis]:
            grown = min(shape[axis], size[axis] * 2)
            if np.prod(size) * itemsize * grown / size[axis] > block_bytes:
                break
            size[axis] = grown
    ranges = [[(s, min(n, s + c)) for s in range(0, n, c)] for n, c in zip(shape, size)]
    return [(z0, z1, y0, y1, x0, x1) for z0, z1 in ranges[0] for y0, y1 in ranges[1] for x0, x1 in ranges[2]]


def _compute_summary(volume, brick, halo, progress, block_bytes):
    grid = brick_grid(volume.shape, brick)
    axes = [_segments(n, b, nb, halo) for n, b, nb in zip(volume.shape, brick, grid)]
    nseg = [len(cuts) - 1 for cuts, _, _ in axes]
    seg_lo = np.full(nseg, np.nan)      # per segment; fmin/fmax skip NaN, so NaN = nothing yet
    seg_hi = np.full(nseg, np.nan)
    blocks = _read_blocks(volume.shape, volume.chunks, volume.dtype.itemsize, block_bytes)
    bar = None
    if progress:
        from ..util.progress import Progress
        bar = Progress(len(blocks))
        bar.begin(f"brick summary of {volume.describe()}")
    try:
        for block in blocks:
            data = volume.read(*block)
            if data.dtype.kind == "f":      # non-finite samples are not values (inf included)
                data = np.where(np.isfinite(data), data, np.nan)
            lo, hi, where = data, data, [None] * 3
            for axis in (2, 1, 0):      # x first: along the contiguous axis, 30 times faster than z first
                cuts = axes[axis][0]
                a, b = block[2 * axis], block[2 * axis + 1]
                k0 = int(np.searchsorted(cuts, a, side="right")) - 1
                k1 = int(np.searchsorted(cuts, b, side="left"))
                local = np.maximum(cuts[k0:k1], a) - a
                lo = np.fmin.reduceat(lo, local, axis=axis)
                hi = np.fmax.reduceat(hi, local, axis=axis)
                where[axis] = slice(k0, k1)
            where = tuple(where)
            seg_lo[where] = np.fmin(seg_lo[where], lo)
            seg_hi[where] = np.fmax(seg_hi[where], hi)
            if bar is not None:
                bar.advance()
    finally:
        if bar is not None:
            bar.close()
    # segments to bricks, one axis at a time (bricks share their halo segments)
    with np.errstate(all="ignore"):
        for axis, (_, first, last) in enumerate(axes):
            seg_lo = np.stack([np.fmin.reduce(np.take(seg_lo, np.arange(f, l), axis=axis), axis=axis)
                               for f, l in zip(first, last)], axis=axis)
            seg_hi = np.stack([np.fmax.reduce(np.take(seg_hi, np.arange(f, l), axis=axis), axis=axis)
                               for f, l in zip(first, last)], axis=axis)
    return BrickSummary(brick, halo, volume.shape, seg_lo, seg_hi)


# ----------------------------------------------------------------------------- identity

def _source_of(array):
    """(path, key) of the file or store an array lives in, where it says so."""
    file = getattr(array, "file", None)
    if file is not None and hasattr(file, "filename") and hasattr(array, "name"):   # h5py
        return os.path.abspath(file.filename), array.name
    filename = getattr(array, "filename", None)
    if isinstance(array, np.memmap) and filename:
        return os.path.abspath(filename), None
    store = getattr(array, "store", None)
    root = None
    for attr in ("root", "path", "dir_path"):       # zarr 3 LocalStore, zarr 2 DirectoryStore
        value = getattr(store, attr, None) if store is not None else None
        if isinstance(value, (str, os.PathLike)) and os.path.exists(value):
            root = os.path.abspath(value)
            break
    if root is not None:
        return root, "/" + str(getattr(array, "path", "") or "").strip("/")
    return None


def _chunks_of(array):
    chunks = getattr(array, "chunksize", None)    # dask
    if chunks is None:
        chunks = getattr(array, "chunks", None)   # zarr, h5py (None: contiguous)
    try:
        chunks = tuple(int(c) for c in chunks)
    except (TypeError, ValueError):
        return None
    return chunks if len(chunks) == 3 else None


def _file_stamps(path, key):
    """(count, total size, newest mtime_ns) of the files under ``path`` (the key's part of
    a store folder, where it is one), or of the file."""
    if os.path.isfile(path):
        st = os.stat(path)
        return 1, st.st_size, st.st_mtime_ns
    top = os.path.join(path, *[p for p in (key or "").split("/") if p])
    count = size = newest = 0
    stack = [top if os.path.isdir(top) else path]
    while stack:
        with os.scandir(stack.pop()) as entries:
            for entry in entries:
                if entry.is_dir(follow_symlinks=False):
                    stack.append(entry.path)
                else:
                    st = entry.stat()
                    count, size, newest = count + 1, size + st.st_size, max(newest, st.st_mtime_ns)
    return count, size, newest


def _memmap_position(array):
    """Where a memmap's samples begin in its file, and its strides (slices of one file differ)."""
    mm = getattr(array, "_mmap", None)
    if mm is None:
        return None
    start = np.frombuffer(mm, np.uint8).ctypes.data
    return array.ctypes.data - start, array.strides


def _identity_parts(volume):
    array = volume.array
    if volume.identity is not None:
        return ("identity", str(volume.identity))
    if volume.source is not None:
        path, key = volume.source
        extra = _memmap_position(array) if isinstance(array, np.memmap) else None
        return ("store", os.path.abspath(path), key, _file_stamps(path, key), extra)
    name = getattr(array, "name", None)
    if hasattr(array, "dask") and isinstance(name, str):
        return ("dask", name)
    if type(array) is np.ndarray:
        return ("bytes", np.ascontiguousarray(array).tobytes())
    return None
