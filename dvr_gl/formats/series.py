"""Loading volumes over time into a :class:`dvr_gl.model.series.VolumeSeries`.

:func:`load_series` takes

- a list of volume files, or a glob pattern such as ``"steps/t_*.nrrd"``: one step per
  file, each read by :func:`dvr_gl.formats.load_volume` (any format it reads). A pattern's
  matches are sorted naturally, numbers by value (``t_2`` before ``t_10``); a list is
  taken in the order given. Every file must give the same grid (a file that differs is
  an :class:`InputError` naming it and the step);
- one 4-D array file, the time axis placed by its format's convention:

  - ``.npy`` -- (nt, nz, ny, nx): **time first**, the slowest axis, as NumPy stores a
    stack of the 3-D (nz, ny, nx) arrays a ``.npy`` volume holds; ``.npz`` likewise
    (an array ``data``, optional ``spacing`` and ``origin``);
  - ``.nrrd`` / ``.nhdr`` -- the axis whose ``kinds`` entry is not a spatial kind
    (``time``, ``list``, ...) or whose ``space directions`` entry is ``none``; where the
    header says neither, the **slowest (last listed) axis**, where NRRD keeps whole
    volumes one after another. Spacing, origin and orientation come from the three
    spatial axes as for a 3-D NRRD;
  - ``.nii`` / ``.nii.gz`` -- NIfTI's fourth dimension, **time last** in the file's
    (x, y, z, t) order (nibabel needed); spacing, origin and orientation as for a 3-D
    NIfTI.

:func:`is_series_file` tells whether a file holds a 4-D array, :func:`series_paths` lists
a pattern's files, :func:`natural_key` is the sort. Errors are :class:`InputError` with
the field that was wrong, as for single volumes.
"""

from __future__ import annotations

import glob
import os
import re

import numpy as np

from ..model.series import StepMismatchError, VolumeSeries
from ..model.volume import Volume
from .anatomy import _Assumed, right_handed
from .errors import InputError, MissingFileError, _existing_file, _named_errors
from .nifti import read_nifti
from .nrrd import _nrrd_geometry, _nrrd_lines, _nrrd_orientation
from .numpy_files import _load_npy, _load_npz
from .parsing import _triplet, parse_orientation
from .volumes import _volume_dtype, load_volume

#: the file types that may hold a 4-D array (time and three spatial axes)
SERIES_EXTENSIONS = (".npy", ".npz", ".nrrd", ".nhdr", ".nii", ".nii.gz")

_SPATIAL_KINDS = ("domain", "space")


def natural_key(text):
    """Sort key that orders runs of digits by value: ``t2`` before ``t10``."""
    return [(0, int(part), part) if part.isdigit() else (1, 0, part)
            for part in re.split(r"(\d+)", os.fspath(text)) if part]


def is_pattern(text):
    """Whether ``text`` is a glob pattern (it has ``*``, ``?`` or ``[``)."""
    return isinstance(text, str) and glob.has_magic(text)


def series_paths(source):
    """The files of a series: a glob pattern's matches, sorted naturally (an error when
    nothing matches), or a list's entries as given."""
    if isinstance(source, (str, os.PathLike)):
        pattern = os.fspath(source)
        if not is_pattern(pattern):
            return [pattern]
        paths = sorted((p for p in glob.glob(pattern) if not os.path.isdir(p)), key=natural_key)
        if not paths:
            raise MissingFileError("path", f"no file matches the pattern {pattern!r}")
        return paths
    try:
        paths = [os.fspath(p) for p in source]
    except TypeError:
        raise InputError("path", f"expected a list of file names or a glob pattern, got {source!r}") from None
    if not paths:
        raise InputError("path", "the list of files is empty: a series needs at least one step")
    return paths


def is_series_file(path):
    """Whether ``path`` is a file holding a 4-D array (a series in one file). Only the
    header is read; a file that cannot be read is not one (load_volume will say why)."""
    try:
        path = os.fspath(path)
    except TypeError:
        return False
    lower = path.lower()
    if not lower.endswith(SERIES_EXTENSIONS) or not os.path.isfile(path):
        return False
    try:
        if lower.endswith(".npy"):
            return np.load(path, mmap_mode="r", allow_pickle=False).ndim == 4
        if lower.endswith(".npz"):
            with np.load(path, allow_pickle=False) as npz:
                if "data" not in npz.files:
                    return False
                return _npz_member_ndim(npz, "data") == 4
        if lower.endswith((".nrrd", ".nhdr")):
            for line in _nrrd_lines(path):
                key, _, value = line.partition(":")
                if key.strip().lower() == "dimension":
                    return int(value.strip()) == 4
            return False
        import nibabel
        shape = nibabel.load(path).shape
        return len(shape) == 4 and shape[3] > 1
    except Exception:
        return False


def _npz_member_ndim(npz, name):
    """ndim of an .npz member from its header, without reading the samples."""
    from numpy.lib import format as npformat
    with npz.zip.open(name + ".npy") as f:
        version = npformat.read_magic(f)
        reader = npformat.read_array_header_1_0 if version == (1, 0) else npformat.read_array_header_2_0
        return len(reader(f)[0])


def load_series(source, *, shape=None, dtype=None, spacing=None, origin=None, mask_nonfinite=False,
                orientation=None) -> VolumeSeries:
    """A :class:`~dvr_gl.model.series.VolumeSeries` from a list of volume files, a glob
    pattern or one 4-D array file (see the module docstring for the time axis of each
    format). ``spacing``, ``origin`` and ``orientation`` replace what the files say, as
    in :func:`dvr_gl.formats.load_volume`; ``shape`` and ``dtype`` are for raw files (and
    checks for the others), ``mask_nonfinite`` as for a Volume."""
    if isinstance(source, (str, os.PathLike)) and not is_pattern(os.fspath(source)):
        path = _existing_file(source, "volume")
        if not is_series_file(path):
            raise InputError("path", f"{path!r} holds no 4-D array; a series in one file is a 4-D .npy, .npz, "
                                     f".nrrd or .nii (a list of files or a glob pattern makes a series too)")
        if shape is not None or dtype is not None:
            raise InputError("shape" if shape is not None else "dtype",
                             f"is for raw files, not the 4-D array file {path!r}")
        return load_series_file(path, spacing=spacing, origin=origin, mask_nonfinite=mask_nonfinite,
                                orientation=orientation)
    paths = series_paths(source)
    volumes = [load_volume(p, shape=shape, dtype=dtype, spacing=spacing, origin=origin,
                           mask_nonfinite=mask_nonfinite, orientation=orientation) for p in paths]
    try:
        return VolumeSeries(volumes, names=paths)
    except StepMismatchError as e:
        raise InputError("path", f"{paths[e.step]!r} (step {e.step}) has {e.field} {e.value}, but "
                                 f"{paths[0]!r} (step 0) has {e.expected}: the files of a series share "
                                 "one grid") from None


def load_series_file(path, spacing=None, origin=None, mask_nonfinite=False, orientation=None) -> VolumeSeries:
    """A series from one 4-D array file (``.npy``, ``.npz``, ``.nrrd``/``.nhdr``,
    ``.nii``/``.nii.gz``); the time axis by the format's convention (module docstring)."""
    path = _existing_file(path, "volume")
    if orientation is not None:
        orientation = parse_orientation(orientation)
    if spacing is not None:
        spacing = _triplet(spacing, "spacing", positive=True)
    if origin is not None:
        origin = _triplet(origin, "origin")
    lower = path.lower()
    file_spacing = file_origin = file_orientation = modality = None
    if lower.endswith(".npy"):
        data = _load_npy(path)
    elif lower.endswith(".npz"):
        data, file_spacing, file_origin = _load_npz(path)
    elif lower.endswith((".nrrd", ".nhdr")):
        data, file_spacing, file_origin, file_orientation, modality = _load_nrrd_4d(path)
    elif lower.endswith((".nii", ".nii.gz")):
        data, file_spacing, file_origin, file_orientation = _load_nifti_4d(path)
    else:
        raise InputError("path", f"{path!r}: a series in one file is a 4-D {', '.join(SERIES_EXTENSIONS)}")
    if data.ndim != 4:
        raise InputError("path", f"{path!r} holds a {data.ndim}-D array of shape {data.shape}; a series in one "
                                 "file is 4-D (nt, nz, ny, nx)")
    if data.shape[0] < 1:
        raise InputError("path", f"{path!r} holds no time step (shape {data.shape})")
    assumed = orientation is None and isinstance(file_orientation, _Assumed)
    data = _volume_dtype(data, path)          # widened once, so that every step has one type
    steps = [right_handed(step, orientation or file_orientation) for step in data]   # (samples, code)
    spacing = spacing if spacing is not None else (file_spacing or (1.0, 1.0, 1.0))
    origin = origin if origin is not None else (file_origin or (0.0, 0.0, 0.0))
    volumes = [Volume(s, spacing=spacing, origin=origin, mask_nonfinite=mask_nonfinite, orientation=code,
                      modality=modality, orientation_assumed=assumed) for s, code in steps]
    return VolumeSeries(volumes, names=[f"{os.path.basename(path)}[{t}]" for t in range(len(volumes))])


def _time_axis(header, path):
    """The NRRD axis (in the header's order, fastest first) that is time: the one
    non-spatial kind or ``none`` direction, else the slowest axis."""
    flagged = set()
    kinds = header.get("kinds")
    if kinds is not None:
        flagged |= {i for i, k in enumerate(kinds) if str(k).lower() not in _SPATIAL_KINDS + ("none", "???")}
    directions = header.get("space directions")
    if directions is not None:
        d = np.array(directions, dtype=np.float64)
        if d.ndim == 2 and d.shape[0] == 4:
            flagged |= {i for i in range(4) if not np.all(np.isfinite(d[i]))}
    if len(flagged) > 1:
        raise InputError("kinds", f"{path!r}: axes {sorted(flagged)} are all non-spatial (kinds {kinds}); "
                                  "a series has one time axis and three spatial ones")
    return flagged.pop() if flagged else 3


@_named_errors
def _load_nrrd_4d(path):
    """(data (nt, nz, ny, nx), spacing, origin, orientation, modality) of a 4-D NRRD."""
    import nrrd
    from .anatomy import _modality_code
    try:
        data, header = nrrd.read(path, index_order="C")
    except nrrd.NRRDError as e:
        raise InputError("path", f"{path!r}: {e}") from None
    if data.ndim != 4:
        raise InputError("dimension", f"{path!r} is {data.ndim}-D (sizes {list(data.shape[::-1])}); a series "
                                      "in one file is 4-D")
    t = _time_axis(header, path)
    data = np.moveaxis(data, 3 - t, 0)          # C order reverses the header's axes
    spatial = dict(header)
    if header.get("space directions") is not None:
        d = np.array(header["space directions"], dtype=np.float64)
        spatial["space directions"] = np.delete(d, t, axis=0)
    if "spacings" in header:
        spatial["spacings"] = np.delete(np.array(header["spacings"], dtype=np.float64), t)
    spacing, origin = _nrrd_geometry(spatial, path)
    modality = next((v for k, v in header.items() if str(k).strip().lower() == "modality"), None)
    return np.ascontiguousarray(data), spacing, origin, _nrrd_orientation(spatial), _modality_code(modality)


@_named_errors
def _load_nifti_4d(path):
    """(data (nt, nz, ny, nx), spacing, origin, orientation) of a 4-D NIfTI: its fourth
    dimension is time."""
    data, zooms, origin, orientation = read_nifti(path, what="series")
    if data.ndim != 4:
        raise InputError("path", f"{path!r} holds a {data.ndim}-D image of shape {data.shape}; a series in one "
                                 "file is 4-D (x, y, z, t)")
    return np.ascontiguousarray(np.transpose(data, (3, 2, 1, 0))), zooms, origin, orientation
