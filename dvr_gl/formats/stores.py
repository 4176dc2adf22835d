"""Stores opened without loading: zarr (format 2 and 3), OME-Zarr multiscale images, HDF5
datasets and ``.npy`` files as memmaps, each as a :class:`dvr_gl.model.lazy_volume.LazyVolume`.

A path may name an array inside its store after a colon, ``scan.zarr:/labels/0`` or
``scan.h5:/entry/data`` (or give ``key=``). Without a key a store's array is found when
there is one: the root array, the OME-Zarr image at the root, or the store's only 3-D
array; otherwise the error lists the arrays there are.

OME-Zarr (versions 0.1 to 0.5): the ``multiscales`` metadata lists the levels, finest
first, each with its ``scale`` and ``translation`` (after the image's own, where it has
them); the spatial axes are the last three (z, y, x), and leading axes (time, channel) must
have one entry. The finest level is returned, with every level in ``volume.levels``.
"""

from __future__ import annotations

import dataclasses
import os

import numpy as np

from ..model.lazy_volume import LazyVolume
from .errors import InputError, MissingFileError, _optional

STORE_SUFFIXES = (".zarr", ".ome.zarr", ".h5", ".hdf5", ".he5", ".hdf", ".npy")
_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
_LISTED = 20        # arrays named in an error, at most


@dataclasses.dataclass(frozen=True)
class Level:
    """One level of a multiscale image: its array's key, shape (nz, ny, nx), chunks,
    and spacing and origin (x, y, z) from the metadata."""
    key: str
    shape: tuple
    chunks: tuple | None
    spacing: tuple
    origin: tuple


def split_key(path, key=None):
    """``(path, key)`` from ``"store.zarr:/a/b"`` (a key after the first colon whose
    prefix exists), or ``(path, key)`` unchanged when the path exists as written."""
    path = os.fspath(path)
    if os.path.exists(path) or ":" not in path:
        return path, key
    for i, c in enumerate(path):
        if c == ":" and i > 1 and os.path.exists(path[:i]):
            inner = path[i + 1:]
            if key is not None and key != inner:
                raise InputError("key", f"two keys given: {inner!r} in the path and {key!r}")
            return path[:i], inner
    return path, key


def store_kind(path):
    """"zarr", "hdf5" or "npy" for a store these readers open (``path`` without key), else None."""
    if os.path.isdir(path):
        names = set(os.listdir(path))
        return "zarr" if names & {".zgroup", ".zarray", "zarr.json"} or path.rstrip("/").endswith(".zarr") else None
    if path.lower().endswith(".npy"):
        return "npy"
    try:
        with open(path, "rb") as f:
            head = f.read(8)
    except OSError:
        return None
    return "hdf5" if head == _HDF5_SIGNATURE else None


def is_store(path):
    """True when ``path`` (perhaps with ``:key``) names a zarr store, an HDF5 file or a
    ``.npy`` file (which opens as a memmap)."""
    try:
        path, _ = split_key(path)
    except InputError:
        return True
    return store_kind(path) is not None


def open_store(path, key=None, spacing=None, origin=None):
    """The store's array as a LazyVolume (``volume.levels``: the OME-Zarr levels, else
    one). ``spacing`` and ``origin`` (x, y, z) replace what the store says."""
    path, key = split_key(path, key)
    if not os.path.exists(path):
        raise MissingFileError("path", f"no such file or store {path!r}")
    kind = store_kind(path)
    if kind is None:
        raise InputError("path", f"{path!r} is not a zarr store, HDF5 file or .npy file")
    reader = {"zarr": _open_zarr, "hdf5": _open_hdf5, "npy": _open_npy}[kind]
    try:
        array, info = reader(path, key)
    except InputError:
        raise
    except Exception as e:
        raise InputError("path", f"{path!r} could not be read as {kind}: {type(e).__name__}: {e}") from e
    levels = info.get("levels")
    level0 = levels[0] if levels else None
    return _lazy(array, path, info["key"], spacing if spacing is not None else (level0.spacing if level0 else None),
                 origin if origin is not None else (level0.origin if level0 else None), info)


def open_level(volume, index):
    """Level ``index`` (0 the finest) of a multiscale LazyVolume from :func:`open_store`."""
    levels = volume.levels
    if not 0 <= index < len(levels):
        raise InputError("level", f"{index} is not a level of {volume.describe()} (it has {len(levels)})")
    path, _ = volume.source
    level = levels[index]
    array = volume._level_arrays[index]
    return _lazy(array, path, level.key, level.spacing, level.origin,
                 {"levels": levels, "arrays": volume._level_arrays, "format": volume.store_format})


def _lazy(array, path, key, spacing, origin, info):
    try:
        volume = LazyVolume(array, spacing=(1.0, 1.0, 1.0) if spacing is None else spacing,
                            origin=(0.0, 0.0, 0.0) if origin is None else origin, source=(os.path.abspath(path), key))
    except TypeError as e:
        if "dtype" in str(e):
            raise InputError("dtype", f"{path}:{key or ''} holds {np.dtype(array.dtype)} samples; {e}") from None
        raise
    except ValueError as e:
        field = "spacing" if "spacing" in str(e) else "origin" if "origin" in str(e) else "shape"
        raise InputError(field, f"{path}:{key or ''}: {e}") from None
    volume.levels = tuple(info.get("levels") or (Level(key or "", volume.shape, volume.chunks,
                                                       tuple(volume.spacing.tolist()), tuple(volume.origin.tolist())),))
    volume.store_format = info["format"]
    volume._level_arrays = tuple(info.get("arrays") or (array,))
    return volume


# ----------------------------------------------------------------------------- zarr

def _open_zarr(path, key):
    zarr = _optional("zarr", "a zarr store")
    root = zarr.open(path, mode="r")
    node = root
    if key not in (None, "", "/"):
        try:
            node = root[key.strip("/")]
        except KeyError:
            raise InputError("key", f"{key!r} is not in {path!r}; it holds {_zarr_listing(root)}") from None
    if _is_array(node):
        return node, {"key": "/" + str(node.path).strip("/"), "format": f"zarr v{_zarr_format(node)}"}
    multiscales = _multiscales(node)
    if multiscales is not None:
        return _open_ome(path, node, multiscales)
    arrays = [a for _, a in node.members(max_depth=None) if _is_array(a) and len(a.shape) == 3]
    if key in (None, "", "/") and len(arrays) == 1:
        return arrays[0], {"key": "/" + arrays[0].path, "format": f"zarr v{_zarr_format(arrays[0])}"}
    where = f"{path}:{key}" if key else path
    raise InputError("key", f"{where!r} is a group; name one of its arrays with a key (STORE:/KEY or --key): "
                            f"{_zarr_listing(node)}")


def _is_array(node):
    return hasattr(node, "shape") and hasattr(node, "dtype")


def _zarr_format(array):
    meta = getattr(array, "metadata", None)
    return getattr(meta, "zarr_format", None) or "2"


def _zarr_listing(group):
    arrays = [f"/{a.path} {tuple(a.shape)} {a.dtype}" for _, a in group.members(max_depth=None) if _is_array(a)]
    if not arrays:
        return "no arrays"
    more = f" and {len(arrays) - _LISTED} more" if len(arrays) > _LISTED else ""
    return ", ".join(sorted(arrays)[:_LISTED]) + more


def _multiscales(group):
    attrs = dict(group.attrs)
    found = attrs.get("multiscales") or (attrs.get("ome") or {}).get("multiscales")
    return found[0] if isinstance(found, list) and found else None


def _transform(transforms, ndim):
    """(scale, translation) over all axes from a list of coordinateTransformations."""
    scale, shift = np.ones(ndim), np.zeros(ndim)
    for t in transforms or ():
        if t.get("type") == "scale":
            values = np.asarray(t["scale"], dtype=float)
            scale, shift = scale * values, shift * values
        elif t.get("type") == "translation":
            shift = shift + np.asarray(t["translation"], dtype=float)
    return scale, shift


def _open_ome(path, group, meta):
    datasets = meta.get("datasets") or []
    if not datasets:
        raise InputError("key", f"{path!r}: the OME-Zarr multiscales metadata lists no datasets")
    axes = meta.get("axes") or ["t", "c", "z", "y", "x"]      # versions 0.1 and 0.2: always 5-D
    names = [a if isinstance(a, str) else a.get("name", "?") for a in axes]
    base = "/" + str(group.path).strip("/") if str(group.path).strip("/") else ""
    levels, arrays = [], []
    for d in datasets:
        try:
            array = group[d["path"]]
        except KeyError:
            raise InputError("key", f"{path!r}: the OME-Zarr level {d['path']!r} is missing; the store holds "
                                    f"{_zarr_listing(group)}") from None
        if len(array.shape) != len(names) or len(names) < 3:
            raise InputError("shape", f"{path}:{base}/{d['path']} has shape {tuple(array.shape)} but the metadata "
                                      f"names the axes {names}")
        lead = len(names) - 3
        for name, n in zip(names[:lead], array.shape[:lead]):
            if n != 1:
                raise InputError("shape", f"{path}:{base}/{d['path']}: axis {name!r} has {n} entries; only "
                                          f"one entry per non-spatial axis is read (select it into its own array)")
        scale, shift = _transform(d.get("coordinateTransformations"), len(names))
        outer_scale, outer_shift = _transform(meta.get("coordinateTransformations"), len(names))
        scale, shift = scale * outer_scale, shift * outer_scale + outer_shift
        chunks = tuple(int(c) for c in array.chunks[lead:]) if getattr(array, "chunks", None) else None
        levels.append(Level(f"{base}/{d['path']}", tuple(int(n) for n in array.shape[lead:]), chunks,
                            tuple(float(s) for s in scale[lead:][::-1]), tuple(float(t) for t in shift[lead:][::-1])))
        arrays.append(_Spatial(array, lead) if lead else array)
    return arrays[0], {"key": levels[0].key, "levels": levels, "arrays": arrays, "format": f"OME-Zarr (zarr v{_zarr_format(array)})"}


class _Spatial:
    """The last three axes of an array whose leading axes have one entry each."""

    def __init__(self, array, lead):
        self.array, self.lead = array, lead
        self.shape = tuple(array.shape[lead:])
        self.dtype = array.dtype
        self.chunks = tuple(array.chunks[lead:]) if getattr(array, "chunks", None) else None

    def __getitem__(self, key):
        return self.array[(0,) * self.lead + (key if isinstance(key, tuple) else (key,))]


# ----------------------------------------------------------------------------- HDF5, npy

def _open_hdf5(path, key):
    h5py = _optional("h5py", "an HDF5 file")
    f = h5py.File(path, "r")
    datasets = []
    f.visititems(lambda name, obj: datasets.append((name, obj)) if isinstance(obj, h5py.Dataset) else None)
    listing = ", ".join(f"/{n} {o.shape} {o.dtype}" for n, o in datasets[:_LISTED]) or "no datasets"
    if key in (None, "", "/"):
        three = [o for _, o in datasets if o.ndim == 3]
        if len(three) != 1:
            raise InputError("key", f"{path!r} holds {len(three)} 3-D datasets; name one with a key "
                                    f"(FILE:/GROUP/DATASET or --key): {listing}")
        node = three[0]
    else:
        node = f.get(key)
        if node is None:
            raise InputError("key", f"{key!r} is not in {path!r}; it holds {listing}")
        if not isinstance(node, h5py.Dataset):
            raise InputError("key", f"{key!r} in {path!r} is a group; name one of its datasets: {listing}")
    return node, {"key": node.name, "format": "HDF5"}


def _open_npy(path, key):
    if key not in (None, "", "/"):
        raise InputError("key", f"a .npy file holds one array; no key {key!r} in {path!r}")
    return np.load(path, mmap_mode="r"), {"key": None, "format": ".npy (memmap)"}


# ----------------------------------------------------------------------------- describing

def describe_store(path, key=None):
    """Lines saying what a store holds, read from its metadata alone (no samples)."""
    from ..util.memory import format_bytes
    volume = open_store(path, key)
    nz, ny, nx = volume.shape
    voxels = nz * ny * nx
    chunks = "x".join(str(c) for c in volume.chunks[::-1]) + " (x, y, z)" if volume.chunks else "none (contiguous)"
    lines = [f"store      {volume.describe()}",
             f"format     {volume.store_format}",
             f"shape      {nx}x{ny}x{nz} (x, y, z)",
             f"dtype      {volume.dtype}",
             f"chunks     {chunks}",
             "spacing    " + ",".join(f"{v:g}" for v in volume.spacing),
             "origin     " + ",".join(f"{v:g}" for v in volume.origin),
             f"bytes      {format_bytes(voxels * volume.dtype.itemsize)} as {volume.dtype}, "
             f"{format_bytes(voxels * 4)} as float32"]
    if len(volume.levels) > 1:
        for i, level in enumerate(volume.levels):
            z, y, x = level.shape
            lines.append(f"level {i:<4} {level.key}: {x}x{y}x{z}, spacing "
                         + ",".join(f"{v:g}" for v in level.spacing) + ", origin "
                         + ",".join(f"{v:g}" for v in level.origin))
    return lines


# ----------------------------------------------------------------------------- either way

def open_volume(path, key=None, lazy=True, spacing=None, origin=None, **load_options):
    """A volume from any file :func:`dvr_gl.formats.load_volume` reads or any store here.

    ``lazy=True``: a LazyVolume; stores (zarr, OME-Zarr, HDF5, ``.npy``) stay on disk, other
    formats are loaded and wrapped. ``lazy=False``: a :class:`dvr_gl.Volume` with every
    sample in memory (a store read whole; other formats exactly as ``load_volume``).
    ``load_options`` go to ``load_volume`` (raw files' ``shape`` and ``dtype``, ...)."""
    from ..model.volume import Volume
    from .volumes import load_volume
    store_path, inner = split_key(path, key)
    kind = store_kind(store_path) if os.path.exists(store_path) else None
    if kind is None or (kind == "npy" and not lazy):
        if inner is not None:
            raise InputError("key", f"{store_path!r} is not a store with keys; got key {inner!r}")
        volume = load_volume(path, spacing=spacing, origin=origin, **load_options)
        if not lazy:
            return volume
        lazy_volume = LazyVolume(volume.data, spacing=volume.spacing, origin=volume.origin,
                                 orientation=volume.orientation, modality=volume.modality,
                                 source=(os.path.abspath(store_path), None))
        lazy_volume.store_format = "loaded whole"
        return lazy_volume
    volume = open_store(store_path, inner, spacing=spacing, origin=origin)
    if lazy:
        return volume
    nz, ny, nx = volume.shape
    return Volume(volume.read(0, nz, 0, ny, 0, nx), spacing=volume.spacing, origin=volume.origin,
                  **load_options)


# ----------------------------------------------------------------------------- pyramids

PYRAMID_SMALLEST = 32        # build_pyramid's default: halve until the largest side is at most this
PYRAMID_BLOCK_BYTES = 64 * 2 ** 20   # a level is made from slabs of the finer one of about this size


def pyramid_path(path):
    """Where :func:`build_pyramid` writes by default: beside the store (or file), its
    name with ``.pyramid.ome.zarr`` for its extension (``scan.zarr`` ->
    ``scan.pyramid.ome.zarr``)."""
    path = os.fspath(path).rstrip("/")
    stem = os.path.basename(path)
    for suffix in (".ome.zarr",) + STORE_SUFFIXES + (".gz",):
        if stem.lower().endswith(suffix):
            stem = stem[:-len(suffix)]
    return os.path.join(os.path.dirname(path), stem + ".pyramid.ome.zarr")


def pyramid_shapes(shape, levels=None):
    """The shapes (nz, ny, nx) of a pyramid's levels from ``shape``: each level halves
    every axis (n // 2) that keeps at least 2 samples; ``levels`` levels in all (level 0
    included), or, when None, until the largest side is at most PYRAMID_SMALLEST."""
    if levels is not None and (isinstance(levels, bool) or not isinstance(levels, (int, np.integer)) or levels < 1):
        raise InputError("levels", f"must be a whole number of levels >= 1 (level 0 included), got {levels!r}")
    shapes = [tuple(int(n) for n in shape)]
    while len(shapes) < (levels if levels is not None else 64):
        finer = shapes[-1]
        if levels is None and max(finer) <= PYRAMID_SMALLEST:
            break
        coarser = tuple(n // 2 if n // 2 >= 2 else n for n in finer)
        if coarser == finer:
            raise InputError("levels", f"{levels} levels from shape {tuple(shape)} (z, y, x): level "
                                       f"{len(shapes) - 1} ({finer}) cannot be halved again")
        shapes.append(coarser)
    return shapes


def halve(block, factors):
    """The mean of ``block``'s (z, y, x) groups of ``factors`` (each 1 or 2) samples,
    in the block's dtype (integers rounded to nearest); a trailing odd sample is dropped."""
    nz, ny, nx = (n // f for n, f in zip(block.shape, factors))
    fz, fy, fx = factors
    # 8- and 16-bit sums of at most 8 samples are exact in float32 (and a power of 2 divides them)
    work = np.float32 if block.dtype.kind in "iu" and block.dtype.itemsize <= 2 else np.float64
    groups = np.asarray(block[:nz * fz, :ny * fy, :nx * fx], work).reshape(nz, fz, ny, fy, nx, fx)
    mean = groups.mean(axis=(1, 3, 5))
    if block.dtype.kind in "iu":
        info = np.iinfo(block.dtype)
        mean = np.clip(np.rint(mean), info.min, info.max)
    return mean.astype(block.dtype)


def build_pyramid(path, out=None, levels=None, key=None, spacing=None, origin=None, chunks=64, overwrite=False,
                  progress=True, block_bytes=PYRAMID_BLOCK_BYTES, **load_options):
    """Write an OME-Zarr multiscale image (metadata 0.4, zarr v2) of the store or volume
    file at ``path`` and return its path, read level by level, never whole.

    Level 0 is the samples as they are; level ``k+1`` is the mean of each 2x2x2 group of
    level ``k``'s samples (an axis that would keep fewer than 2 samples is not halved),
    placed at the group's centre: its ``scale`` is twice level ``k``'s and its
    ``translation`` half a level-``k`` spacing further, so the coarse samples sit where
    the means belong (a level's bounds are inside the finer level's). ``levels``: how many
    levels (level 0 included); default: until the largest side is at most
    PYRAMID_SMALLEST. ``out``: default :func:`pyramid_path` (beside the store). The store
    is written under a temporary name beside ``out`` and renamed when whole, so a store
    at ``out`` is always complete; an existing ``out`` is an error unless ``overwrite``.
    ``spacing``/``origin`` (x, y, z) replace the source's; ``chunks``: samples a side of
    every level's chunks. Progress on stderr (``progress``). A file that is not a store
    is read by :func:`dvr_gl.formats.load_volume` (with ``load_options``: a raw file's
    ``shape`` and ``dtype``)."""
    import shutil
    zarr = _optional("zarr", "a zarr store")
    source = open_volume(path, key=key, lazy=True, spacing=spacing, origin=origin, **load_options)
    out = os.fspath(out) if out is not None else pyramid_path(split_key(path, key)[0])
    if os.path.exists(out) and not overwrite:
        raise InputError("out", f"{out!r} exists; give overwrite=True (--overwrite) to replace it")
    if isinstance(chunks, bool) or not isinstance(chunks, (int, np.integer)) or chunks < 2:
        raise InputError("chunks", f"must be a whole number of samples >= 2, got {chunks!r}")
    shapes = pyramid_shapes(source.shape, levels)
    spacings, origins = [np.asarray(source.spacing, float)], [np.asarray(source.origin, float)]
    for finer, coarser in zip(shapes, shapes[1:]):
        factors = np.array([f // c for f, c in zip(finer, coarser)][::-1], float)     # x, y, z
        origins.append(origins[-1] + 0.5 * (factors - 1) * spacings[-1])
        spacings.append(spacings[-1] * factors)
    tmp = os.path.join(os.path.dirname(os.path.abspath(out)), f".{os.path.basename(out)}.{os.getpid()}.tmp")
    if os.path.exists(tmp):
        shutil.rmtree(tmp)
    bar = None
    try:
        group = zarr.open_group(tmp, mode="w", zarr_format=2)
        arrays = [group.create_array(str(k), shape=s, chunks=tuple(min(chunks, n) for n in s), dtype=source.dtype)
                  for k, s in enumerate(shapes)]
        slab = max(2, int(block_bytes // max(1, shapes[0][1] * shapes[0][2] * source.dtype.itemsize)) // 2 * 2)
        slabs = [list(range(0, s[0], slab)) for s in shapes[:-1]]
        if progress:
            from ..util.progress import Progress
            bar = Progress(sum(len(s) for s in slabs) + len(range(0, shapes[0][0], slab)))
            bar.begin(f"pyramid of {source.describe()}: level 0")
        nz, ny, nx = shapes[0]
        for z0 in range(0, nz, slab):          # level 0: copied
            arrays[0][z0:min(nz, z0 + slab)] = source.read(z0, min(nz, z0 + slab), 0, ny, 0, nx)
            if bar is not None:
                bar.advance()
        for k in range(1, len(shapes)):
            finer, coarser = shapes[k - 1], shapes[k]
            factors = tuple(f // c for f, c in zip(finer, coarser))
            if bar is not None:
                bar.begin(f"pyramid of {source.describe()}: level {k} {coarser[2]}x{coarser[1]}x{coarser[0]}")
            for z0 in slabs[k - 1]:
                z1 = min(finer[0], z0 + slab)
                c0, c1 = z0 // factors[0], min(coarser[0], z1 // factors[0])
                if c1 > c0:
                    arrays[k][c0:c1] = halve(arrays[k - 1][c0 * factors[0]:c1 * factors[0]], factors)
                if bar is not None:
                    bar.advance()
        axes = [{"name": a, "type": "space"} for a in "zyx"]
        datasets = [{"path": str(k), "coordinateTransformations": [
            {"type": "scale", "scale": [float(v) for v in spacings[k][::-1]]},
            {"type": "translation", "translation": [float(v) for v in origins[k][::-1]]}]}
            for k in range(len(shapes))]
        group.attrs["multiscales"] = [{"version": "0.4", "name": os.path.basename(source.describe()), "axes": axes,
                                       "datasets": datasets, "type": "mean of 2x2x2",
                                       "metadata": {"made_by": "dvr_gl.formats.stores.build_pyramid"}}]
        if os.path.exists(out):         # overwrite: the old store goes only once the new one is whole
            shutil.rmtree(out)
        os.rename(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    finally:
        if bar is not None:
            bar.close()
    return out
