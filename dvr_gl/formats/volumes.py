"""Loading volumes.

:func:`load_volume` reads a structured scalar volume into a :class:`dvr_gl.Volume`:

- ``.npy`` -- a 3-D array (nz, ny, nx); spacing 1 unless given.
- ``.npz`` -- an array ``data`` (nz, ny, nx) and optionally ``spacing`` and ``origin``
  (x, y, z), the layout of the bundled data sets.
- ``.nrrd`` / ``.nhdr`` -- NRRD through pynrrd, attached or detached, including the
  multi-file forms of ``data file:`` that pynrrd does not read itself
  (``<format> <min> <max> <step> [<subdim>]`` and ``LIST [<subdim>]``). Spacing comes from
  ``space directions`` (the length of each axis vector) or ``spacings``, the origin from
  ``space origin``. The volume is axis-aligned: a direction matrix that is not a positive
  diagonal is not applied (a warning says so), as in VTK's image data without a direction.
- ``.mhd`` / ``.mha`` -- MetaImage (header plus raw, zlib or local data). The orientation
  comes from ``TransformMatrix`` (direction cosines in ITK's LPS patient axes) where it is
  not the identity, else from ``AnatomicalOrientation`` (written in ITK's "from" letters:
  ``RAI`` is the identity in LPS, read as ``LPS``); ``Modality`` (``MET_MOD_CT``, ...)
  becomes the volume's ``modality`` (``CT``, ...).
- ``.nii`` / ``.nii.gz`` -- NIfTI-1/2 through nibabel (``pip install "dvr-gl[io]"``; a
  missing nibabel is an error that says so). The samples as the file's x, y, z index axes
  (scaled by its slope and intercept), spacing from the voxel sizes, origin from the
  affine; like NRRD the volume is axis-aligned, and an affine that is not a positive
  diagonal is not applied (a warning says so).
- ``.raw``, ``.raw.gz``, ``.bin``, ``.dat`` and names without an extension -- raw samples,
  x fastest, which need ``shape`` (nz, ny, nx), ``dtype`` (a NumPy name such as ``int16``
  or ``>u2`` for big endian) and ``spacing``; a name ending in ``.gz`` is gunzipped
  first. A name in the Open SciVis convention, ``name_XxYxZ_dtype.raw`` (such as
  ``neghip_66x66x66_uint8.raw``), gives the shape and dtype itself, and spacing 1.
- a DICOM series -- a folder, or one ``.dcm`` file of it -- through pydicom
  (``pip install "dvr-gl[io]"``): see :func:`_load_dicom_series`; CT comes out in HU and
  the volume's ``orientation`` is the patient's.
- ``.tif`` / ``.tiff`` -- a multi-page TIFF stack through tifffile, one page per slice.
- ``.vti`` (VTK XML image data), legacy ``.vtk`` with ``DATASET STRUCTURED_POINTS`` and
  ``.slc`` -- through VTK's own readers (``pip install "dvr-gl[io]"``): the point
  scalars (or the first point array), spacing and origin from the file.
- any other extension is an error listing the formats above.

The volume's ``orientation`` (where the index axes point anatomically, e.g. ``RAS``) comes
from NIfTI, NRRD, MetaImage and DICOM; ``orientation``, when given, replaces or supplies it
(files such as a NRRD in ``3D-left-handed`` space or a MetaImage without orientation fields
have none). ``modality`` comes from DICOM's Modality, MetaImage's ``Modality`` and a NRRD
``modality:=`` key/value pair.

``spacing`` and ``origin``, when given, replace what the file says. ``shape`` and
``dtype`` describe raw files; for self-describing files they are checks. Samples are
returned in native byte order; types the Volume does not hold are widened without loss
(int8 -> int16, float16 -> float32, bool -> uint8, 32/64-bit integers -> float32 or
float64 when every value is exactly representable), anything else is an error.

Every error is an :class:`InputError` (a ``ValueError``) whose ``field`` names what was
wrong (``path``, ``shape``, ``dtype``, ``spacing``, a header field, ...) and whose message
shows the offending value; a missing file raises :class:`MissingFileError`, which is also
a ``FileNotFoundError``.
"""

from __future__ import annotations

import os

import numpy as np

from ..model.volume import Volume
from .anatomy import _Assumed, right_handed
from .dicom import _is_dicom_path, _load_dicom_series
from .errors import InputError, _existing_file
from .metaimage import _load_metaimage
from .nifti import _load_nifti
from .nrrd import _load_nrrd
from .numpy_files import _load_npy, _load_npz
from .parsing import RAW_DTYPES, _parse_dtype, _triplet, parse_orientation
from .raw import _is_raw_name, _load_raw, raw_name_layout
from .tiff import _load_tiff
from .vtk_image import _load_vtk_image


_VOLUME_DTYPES = (np.uint8, np.uint16, np.int16, np.float32, np.float64)


def load_volume(path, shape=None, dtype=None, spacing=None, origin=None, mask_nonfinite=False,
                orientation=None) -> Volume:
    """Read a volume file (see the module docstring for formats); returns a Volume.
    ``orientation`` (three letters such as ``"RAS"``, see :func:`parse_orientation`)
    replaces the file's anatomical orientation, or supplies one where it has none."""
    if orientation is not None:
        orientation = parse_orientation(orientation)
    if _is_dicom_path(path):
        data, file_spacing, file_origin, file_orientation, modality = _load_dicom_series(os.fspath(path))
        if shape is not None and tuple(data.shape) != _triplet(shape, "shape", kind=int, positive=True):
            raise InputError("shape", f"{os.fspath(path)!r} holds shape {tuple(data.shape)} (nz, ny, nx), "
                                      f"not the {shape} given")
        data, orientation = right_handed(data, orientation or file_orientation)
        return Volume(_volume_dtype(data, os.fspath(path)),
                      spacing=file_spacing if spacing is None else _triplet(spacing, "spacing", positive=True),
                      origin=file_origin if origin is None else _triplet(origin, "origin"),
                      mask_nonfinite=mask_nonfinite, orientation=orientation, modality=modality)
    path = _existing_file(path, "volume")
    if spacing is not None:
        spacing = _triplet(spacing, "spacing", positive=True)
    if origin is not None:
        origin = _triplet(origin, "origin")
    if shape is not None:
        shape = _triplet(shape, "shape", kind=int, positive=True)
    if dtype is not None:
        dtype = _parse_dtype(dtype)

    lower = path.lower()
    file_orientation = modality = None   # anatomical orientation and modality, where the file says
    if lower.endswith((".npy", ".npz", ".nrrd", ".nhdr", ".mhd", ".mha")):
        if lower.endswith(".npy"):
            data, file_spacing, file_origin = _load_npy(path), None, None
        elif lower.endswith(".npz"):
            data, file_spacing, file_origin = _load_npz(path)
        elif lower.endswith((".nrrd", ".nhdr")):
            data, file_spacing, file_origin, file_orientation, modality = _load_nrrd(path)
        else:
            data, file_spacing, file_origin, file_orientation, modality = _load_metaimage(path)
        if data.ndim != 3:
            raise InputError("path", f"{path!r} holds a {data.ndim}-D array of shape {data.shape}; "
                                      "a volume is 3-D (nz, ny, nx)")
        if shape is not None and tuple(data.shape) != shape:
            raise InputError("shape", f"{path!r} holds shape {tuple(data.shape)} (nz, ny, nx), "
                                      f"not the {shape} given")
        if dtype is not None and data.dtype.newbyteorder("=") != dtype.newbyteorder("="):
            raise InputError("dtype", f"{path!r} holds {data.dtype.name}, not the {dtype.name} given")
        spacing = spacing if spacing is not None else (file_spacing or (1.0, 1.0, 1.0))
        origin = origin if origin is not None else (file_origin or (0.0, 0.0, 0.0))
    elif lower.endswith((".nii", ".nii.gz")):
        data, file_spacing, file_origin, file_orientation = _load_nifti(path)
        if shape is not None and tuple(data.shape) != shape:
            raise InputError("shape", f"{path!r} holds shape {tuple(data.shape)} (nz, ny, nx), "
                                      f"not the {shape} given")
        spacing = spacing if spacing is not None else file_spacing
        origin = origin if origin is not None else file_origin
    elif lower.endswith((".tif", ".tiff")):
        data, file_spacing = _load_tiff(path)
        if shape is not None and tuple(data.shape) != shape:
            raise InputError("shape", f"{path!r} holds shape {tuple(data.shape)} (nz, ny, nx), "
                                      f"not the {shape} given")
        spacing = spacing if spacing is not None else file_spacing
        origin = origin if origin is not None else (0.0, 0.0, 0.0)
    elif lower.endswith((".vti", ".slc", ".vtk")):
        data, file_spacing, file_origin = _load_vtk_image(path)
        spacing = spacing if spacing is not None else file_spacing
        origin = origin if origin is not None else file_origin
    elif not _is_raw_name(path):
        raise InputError("path", f"{path!r}: {os.path.splitext(path)[1]!r} is not a volume format dvr_gl reads; "
                                 f"it reads {SUPPORTED_VOLUMES}")
    else:
        named = raw_name_layout(path)
        if named is not None:     # name_XxYxZ_dtype.raw: the name carries shape and dtype
            shape = shape if shape is not None else named[0]
            dtype = dtype if dtype is not None else named[1]
            spacing = spacing if spacing is not None else (1.0, 1.0, 1.0)
        missing = [n for n, v in (("shape", shape), ("dtype", dtype), ("spacing", spacing)) if v is None]
        if missing:
            raise InputError(missing[0], f"a raw file such as {path!r} needs shape (nz,ny,nx), dtype and "
                                         f"spacing (sx,sy,sz); missing: {', '.join(missing)}")
        data = _load_raw(path, shape, dtype)
        origin = origin if origin is not None else (0.0, 0.0, 0.0)
    assumed = orientation is None and isinstance(file_orientation, _Assumed)
    data, orientation = right_handed(_volume_dtype(data, path), orientation or file_orientation)
    return Volume(data, spacing=spacing, origin=origin, mask_nonfinite=mask_nonfinite,
                  orientation=orientation, modality=modality, orientation_assumed=assumed)


SUPPORTED_VOLUMES = (".npy, .npz, .nrrd/.nhdr, .mhd/.mha, .nii/.nii.gz (with nibabel), a DICOM series (a folder, or "
                     "one .dcm of it; with pydicom), a TIFF stack (.tif/.tiff; with tifffile), .vti, .slc and "
                     "structured-points .vtk (with VTK), and raw samples "
                     "(.raw, .raw.gz, .bin, .dat, or no extension; with shape, dtype and spacing unless the "
                     "name is name_XxYxZ_dtype.raw); meshes: .vtu, legacy .vtk and what meshio reads")


def _volume_dtype(data, path):
    """Native byte order and a dtype the Volume holds, widened without loss."""
    dt = data.dtype
    if dt.fields is not None or dt.kind not in "biuf":
        raise InputError("dtype", f"unsupported {dt!s} in {path!r}; volumes hold numbers "
                                  f"({', '.join(RAW_DTYPES)})")
    native = dt.newbyteorder("=")
    if native.type in _VOLUME_DTYPES:
        return data.astype(native, copy=False)
    if dt.kind == "b":
        return data.astype(np.uint8)
    if native == np.int8:
        return data.astype(np.int16)
    if native == np.float16:
        return data.astype(np.float32)
    if dt.kind in "iu":  # 32- and 64-bit integers: to the float that holds every value
        if data.size == 0:
            return data.astype(np.float32)
        lo, hi = int(data.min()), int(data.max())
        biggest = max(abs(lo), abs(hi))
        if biggest <= 2 ** 24:
            return data.astype(np.float32)
        if biggest <= 2 ** 53:
            return data.astype(np.float64)
        raise InputError("dtype", f"{dt.name} values in {path!r} reach {lo if abs(lo) > abs(hi) else hi}, "
                                  "beyond what float64 holds exactly (2**53)")
    raise InputError("dtype", f"unsupported {dt.name} in {path!r}; use one of {', '.join(RAW_DTYPES)}")
