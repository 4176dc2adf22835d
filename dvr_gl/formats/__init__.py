"""Loading volumes and saving images.

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

:func:`load_mesh` reads an unstructured mesh into a :class:`dvr_gl.TetMesh`
(conventions section 2):

- ``.npz`` with arrays ``points`` (N, 3) and ``tets`` (M, 4) -- the layout of the shared
  mesh data sets -- and one (N,) array per point scalar (others, such as an (N, 3)
  vector, may be there too).
- ``.vtu``, legacy ``.vtk`` (``DATASET UNSTRUCTURED_GRID``) and every other format meshio
  reads (``.msh``, ``.xdmf``, ``.inp``, ``.mesh``, ``.vol``, ...). Tetrahedra are kept;
  hexahedra, wedges and pyramids are split into tetrahedra conformingly
  (:mod:`dvr_gl.model.cell_split`); vertices, lines and surface cells are ignored when the
  file has 3-D cells; any other 3-D cell (quadratic, polyhedral) is an error naming it.

The field is a point array chosen by name (``scalars``; default: the first array with
one component and more than three distinct values, so that blanking flags such as
IBlank are passed over; the first one-component array if all are flags). Points no cell uses are kept. :func:`is_mesh_file` says whether a path
is a mesh rather than a volume; :func:`point_arrays` lists a mesh file's point arrays.

:func:`save_png` writes a premultiplied float RGBA image (conventions section 7)
atomically; :func:`parse_size`, :func:`parse_triplet` and :func:`parse_orientation` parse
command-line values.
"""

from __future__ import annotations

import contextlib
import gzip
import math
import io
import os
import re
import secrets
import warnings
import zlib

import numpy as np

from ..model.scene import MAX_IMAGE_SIDE, TetMesh, Volume
from ..util.files import atomic_write

__all__ = ["InputError", "MissingFileError", "load_volume", "load_mesh", "is_mesh_file", "point_arrays",
           "save_png", "to_png_array", "parse_size", "parse_triplet", "parse_orientation", "RAW_DTYPES"]

#: dtypes accepted for raw files (any byte order); the Volume holds uint8, uint16, int16,
#: float32 and float64, the others are widened as the module docstring says.
RAW_DTYPES = ("uint8", "int8", "uint16", "int16", "uint32", "int32", "uint64", "int64",
              "float16", "float32", "float64")

_VOLUME_DTYPES = (np.uint8, np.uint16, np.int16, np.float32, np.float64)


class InputError(ValueError):
    """Bad input: ``field`` names what was wrong, ``detail`` says how (with the value)."""

    def __init__(self, field, detail):
        self.field = field
        self.detail = detail
        super().__init__(f"{field}: {detail}")


class MissingFileError(InputError, FileNotFoundError):
    """A file that should exist does not."""


# ----------------------------------------------------------------------------- parsing

def _triplet(value, name, kind=float, positive=False):
    """Three numbers from "a,b,c" or a sequence, checked; ``kind`` int or float."""
    what = "integers" if kind is int else "numbers"
    example = "64,64,93" if kind is int else "1,2,3"
    if isinstance(value, str):
        parts = [p.strip() for p in value.split(",")]
        if len(parts) != 3 or not all(parts):
            raise InputError(name, f"expected three comma-separated {what} like {example}, got {value!r}")
        try:
            nums = tuple(kind(p) for p in parts)
        except ValueError:
            raise InputError(name, f"expected three comma-separated {what} like {example}, got {value!r}") from None
    else:
        try:
            items = list(value)
        except TypeError:
            raise InputError(name, f"expected three {what}, got {value!r}") from None
        if len(items) != 3:
            raise InputError(name, f"expected three {what}, got {value!r}")
        nums = []
        for v in items:
            if kind is int:
                if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)):
                    raise InputError(name, f"expected three integers, got {value!r}")
                nums.append(int(v))
            else:
                try:
                    nums.append(float(v))
                except (TypeError, ValueError):
                    raise InputError(name, f"expected three numbers, got {value!r}") from None
        nums = tuple(nums)
    if kind is float and not all(math.isfinite(v) for v in nums):
        raise InputError(name, f"must be finite, got {value!r}")
    if positive and not all(v > 0 for v in nums):
        raise InputError(name, f"must be positive on every axis, got {value!r}")
    return nums


def parse_triplet(text, name="value", kind=float, positive=False):
    """``"1,2,3"`` -> ``(1.0, 2.0, 3.0)`` (``kind=int`` for integers); errors name ``name``."""
    return _triplet(text, name, kind=kind, positive=positive)


def parse_orientation(codes, name="orientation"):
    """``"ras"`` -> ``"RAS"``: three letters naming where the x, y and z index axes point,
    one each of R/L, A/P and S/I (nibabel's axis codes); errors name ``name``."""
    from ..model.scene import _orientation
    try:
        return _orientation(codes.strip() if isinstance(codes, str) else codes)
    except ValueError:
        raise InputError(name, f"expected three letters, one each of R/L, A/P and S/I, naming where the x, y "
                               f"and z axes point (such as RAS or LPI), got {codes!r}") from None


_AXIS_VECTORS = {"R": (1, 0, 0), "L": (-1, 0, 0), "A": (0, 1, 0), "P": (0, -1, 0), "S": (0, 0, 1), "I": (0, 0, -1)}


def right_handed(data, orientation):
    """``(data, orientation)`` drawn without a mirror image.

    The renderer places index axes x, y, z along world x, y, z, a right-handed frame.
    Where the anatomical directions of the index axes form a left-handed frame (``LPI``,
    ``RAI``, ``LAS`` -- the radiological storage of many NIfTI files -- ...), no view
    of that placement shows the patient the right way round: left and right come out
    swapped. Such data is returned with its x axis reversed and its letter swapped
    (``LPI`` -> ``RPI``), as nibabel's ``as_closest_canonical`` reorients; the box and
    spacing stay. Right-handed or unknown orientations are returned as they are."""
    if orientation is None:
        return data, orientation
    if np.linalg.det(np.array([_AXIS_VECTORS[c] for c in orientation], float)) > 0:
        return data, orientation
    return np.ascontiguousarray(np.asarray(data)[:, :, ::-1]), _OPPOSITE[orientation[0]] + orientation[1:]


def parse_size(text, name="size"):
    """``"640x480"`` -> ``(640, 480)`` (width, height); ``"512"`` means 512x512."""
    s = str(text).strip().lower().replace("\u00d7", "x")
    m = re.fullmatch(r"(\d+)\s*(?:x\s*(\d+))?", s)
    if not m:
        raise InputError(name, f"expected WIDTHxHEIGHT in pixels like 512x512, got {text!r}")
    w = int(m.group(1))
    h = int(m.group(2)) if m.group(2) is not None else w
    for v in (w, h):
        if not 1 <= v <= MAX_IMAGE_SIDE:
            raise InputError(name, f"width and height must be between 1 and {MAX_IMAGE_SIDE} pixels, got {text!r}")
    return w, h


def _parse_dtype(dtype, name="dtype"):
    try:
        dt = np.dtype(dtype)
    except TypeError:
        dt = None
    if dt is None or dt.fields is not None or dt.subdtype is not None or dt.newbyteorder("=").name not in RAW_DTYPES:
        raise InputError(name, f"unsupported {dtype!r}; use one of {', '.join(RAW_DTYPES)} "
                               "(prefix < or > for little or big endian)")
    return dt


# ----------------------------------------------------------------------------- loading

def _existing_file(path, kind):
    """``path`` as a string, if it names an existing file (``kind``: for the message)."""
    try:
        path = os.fspath(path)
    except TypeError:
        raise InputError("path", f"expected a file name, got {path!r}") from None
    if not os.path.exists(path):
        raise MissingFileError("path", f"no such file {path!r}")
    if os.path.isdir(path):
        raise InputError("path", f"{path!r} is a directory, not a {kind} file")
    return path


def _named_errors(read):
    """A file reader whose failures on a damaged file (a cut-off array, a broken zip or
    gzip stream, a header that asks for more than there is) are InputErrors naming the
    path, not the parsing library's own exceptions. Only the reading is guarded: the
    Volume and TetMesh built from what was read name their own fields."""
    import functools

    @functools.wraps(read)
    def guarded(path, *args, **kwargs):
        try:
            return read(path, *args, **kwargs)
        except InputError:
            raise
        except Exception as e:   # EOFError, zipfile.BadZipFile, zlib.error, MemoryError, ...
            raise InputError("path", f"{os.fspath(path)!r} could not be read (damaged or cut short?): "
                                     f"{type(e).__name__}: {e}") from e
    return guarded


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
_RAW_EXTENSIONS = (".raw", ".raw.gz", ".bin", ".dat", ".gz")
_RAW_NAME = re.compile(r"_(\d+)x(\d+)x(\d+)_(uint8|int8|uint16|int16|uint32|int32|float32|float64)"
                       r"\.raw(\.gz)?$", re.IGNORECASE)


def raw_name_layout(path):
    """((nz, ny, nx), dtype) from a name in the Open SciVis convention
    ``name_XxYxZ_dtype.raw[.gz]`` (little-endian samples, x fastest), or None."""
    m = _RAW_NAME.search(os.path.basename(os.fspath(path)))
    if m is None:
        return None
    x, y, z = (int(v) for v in m.groups()[:3])
    return (z, y, x), np.dtype(m.group(4).lower()).newbyteorder("<")


def _is_raw_name(path):
    name = os.path.basename(path).lower()
    stem, ext = os.path.splitext(name)
    return name.endswith(_RAW_EXTENSIONS) or ext == "" or ext[1:].isdigit()


@_named_errors
def _load_vtk_image(path):
    """(data (nz, ny, nx), spacing, origin) of VTK image data -- XML ``.vti``, legacy
    ``.vtk`` structured points, ``.slc`` -- through VTK's own readers."""
    lower = path.lower()
    if lower.endswith(".vtk") and _vtk_dataset(path) not in ("STRUCTURED_POINTS", None):
        raise InputError("path", f"{path!r} is a legacy VTK {_vtk_dataset(path)}; load_volume reads "
                                 "STRUCTURED_POINTS (load_mesh reads UNSTRUCTURED_GRID)")
    try:
        from vtkmodules.util.numpy_support import vtk_to_numpy
        from vtkmodules.vtkIOImage import vtkSLCReader
        from vtkmodules.vtkIOLegacy import vtkStructuredPointsReader
        from vtkmodules.vtkIOXML import vtkXMLImageDataReader
    except ImportError:
        raise InputError("path", f"{path!r} is VTK image data, which needs VTK: pip install \"dvr-gl[io]\" "
                                 "(or pip install vtk)") from None
    reader = (vtkXMLImageDataReader() if lower.endswith(".vti") else vtkSLCReader() if lower.endswith(".slc")
              else vtkStructuredPointsReader())
    reader.SetFileName(path)
    reader.Update()
    image = reader.GetOutput()
    points = image.GetPointData() if image is not None else None
    scalars = points.GetScalars() if points is not None else None
    if scalars is None and points is not None and points.GetNumberOfArrays():
        scalars = points.GetArray(0)
    if scalars is None or image.GetNumberOfPoints() == 0:
        raise InputError("path", f"{path!r}: VTK read no image with point scalars from it")
    if scalars.GetNumberOfComponents() != 1:
        raise InputError("path", f"{path!r}: the scalars {scalars.GetName()!r} have "
                                 f"{scalars.GetNumberOfComponents()} components; a volume has one")
    nx, ny, nz = image.GetDimensions()
    data = vtk_to_numpy(scalars).reshape(nz, ny, nx).copy()
    return data, tuple(float(v) for v in image.GetSpacing()), tuple(float(v) for v in image.GetOrigin())


@_named_errors
def _load_nifti(path):
    """(data (nz, ny, nx), spacing, origin, orientation) of a NIfTI file, through nibabel."""
    try:
        import nibabel
    except ImportError:
        raise InputError("path", f"{path!r} is NIfTI, which needs nibabel: pip install \"dvr-gl[io]\" "
                                 "(or pip install nibabel)") from None
    image = nibabel.load(path)
    data = np.asanyarray(image.dataobj)
    if data.ndim == 4 and data.shape[3] == 1:
        data = data[..., 0]
    if data.ndim != 3:
        raise InputError("path", f"{path!r} holds a {data.ndim}-D image of shape {data.shape}; a volume is 3-D")
    zooms = tuple(float(v) for v in image.header.get_zooms()[:3])
    if not all(v > 0 and math.isfinite(v) for v in zooms):
        raise InputError("pixdim", f"{path!r} has voxel sizes {zooms}; they must be positive")
    affine = np.asarray(image.affine, np.float64)
    linear = affine[:3, :3]
    if not np.allclose(linear, np.diag(np.diag(linear))) or (np.diag(linear) <= 0).any():
        warnings.warn(f"{path}: the affine's axes are not x, y, z with positive steps; the volume is shown "
                      "axis-aligned in index order, without that orientation", stacklevel=3)
    origin = tuple(float(v) for v in affine[:3, 3])
    orientation = "".join(nibabel.aff2axcodes(affine))   # where the index axes point
    return np.ascontiguousarray(np.transpose(data, (2, 1, 0))), zooms, origin, orientation


def _optional(module, what):
    """Import an optional reader, or an InputError saying what to install."""
    import importlib
    try:
        return importlib.import_module(module)
    except ImportError:
        raise InputError("path", f"{what} needs {module}: pip install \"dvr-gl[io]\" (or pip install "
                                 f"{module})") from None


def _is_dicom_path(path):
    """A folder (a DICOM series) or a ``.dcm`` file."""
    try:
        path = os.fspath(path)
    except TypeError:
        return False
    return os.path.isdir(path) or path.lower().endswith(".dcm")


# DICOM's patient axes: +x towards the patient's left, +y posterior, +z superior (LPS).
_LPS = "LPS"


def _axis_code(vector, space=_LPS):
    """The anatomical letter a direction points to in a patient space (``space``: the
    letters its +x, +y, +z point to; DICOM's LPS by default): its largest component, with
    its sign."""
    axis = int(np.argmax(np.abs(vector)))
    return space[axis] if vector[axis] > 0 else _OPPOSITE[space[axis]]


def _direction_codes(vectors, space=_LPS):
    """Where the index axes point (e.g. "RAS"), one letter per axis vector (rows of
    ``vectors``, in ``space``); None unless the three name one each of R/L, A/P, S/I (an
    axis halfway between two directions names none)."""
    d = np.asarray(vectors, dtype=np.float64)
    if d.shape != (3, 3) or not np.all(np.isfinite(d)) or np.any(np.abs(d).max(axis=1) <= 0):
        return None
    codes = "".join(_axis_code(v, space) for v in d)
    pairs = {pair for c in codes for pair in ("RL", "AP", "SI") if c in pair}
    return codes if len(pairs) == 3 else None


def _modality_code(value):
    """A modality as the Volume holds it ("CT", "MR", ...), or None for an empty, unknown
    or malformed one."""
    from ..model.scene import _modality
    text = str(value or "").strip().upper()
    try:
        return _modality(text) if text else None
    except ValueError:
        return None


@_named_errors
def _load_dicom_series(path):
    """(data (nz, ny, nx), spacing, origin, orientation, modality) of a DICOM series, through
    pydicom: every file of ``path`` (a folder; or the folder of a ``.dcm`` file, keeping
    that file's series) of one SeriesInstanceUID, sorted along the slice normal by
    ImagePositionPatient, with RescaleSlope and RescaleIntercept applied (CT in HU).
    Columns run along the first ImageOrientationPatient vector (x), rows along the second
    (y), slices along their cross product (z); spacing from PixelSpacing and the slice
    positions; orientation from those vectors in DICOM's LPS patient axes; modality from
    the Modality tag."""
    if not os.path.exists(path):
        raise MissingFileError("path", f"no such file or folder {path!r}")
    pydicom = _optional("pydicom", f"the DICOM series {path!r}")
    folder = path if os.path.isdir(path) else (os.path.dirname(path) or ".")
    want = None if os.path.isdir(path) else pydicom.dcmread(path, stop_before_pixels=True).get("SeriesInstanceUID")
    slices, other_series = [], set()
    for name in sorted(os.listdir(folder)):
        full = os.path.join(folder, name)
        if not os.path.isfile(full):
            continue
        try:
            ds = pydicom.dcmread(full, stop_before_pixels=True)
        except pydicom.errors.InvalidDicomError:
            continue                                  # not DICOM: a README, a DICOMDIR's siblings
        if "ImagePositionPatient" not in ds or "Rows" not in ds:
            continue
        uid = ds.get("SeriesInstanceUID")
        want = uid if want is None else want
        if uid != want:
            other_series.add(uid)
            continue
        slices.append((full, ds))
    if len(slices) < 2:
        where = "is a folder; read as a DICOM series, it holds" if os.path.isdir(path) else "is in a series of"
        raise InputError("path", f"{path!r} {where} {len(slices)} image slices (a DICOM series needs at least 2)")
    if other_series:
        warnings.warn(f"{path}: {len(other_series)} other series in the folder are left out; reading "
                      f"SeriesInstanceUID {want}", stacklevel=4)
    iop = np.array(slices[0][1].ImageOrientationPatient, np.float64)
    for full, ds in slices:
        if not np.allclose(np.array(ds.ImageOrientationPatient, np.float64), iop, atol=1e-4):
            raise InputError("ImageOrientationPatient", f"{full!r}: the slices of one series must share "
                                                        f"their orientation, got {list(ds.ImageOrientationPatient)}")
    row, col = iop[:3], iop[3:]
    normal = np.cross(row, col)
    where = np.array([np.array(ds.ImagePositionPatient, np.float64) @ normal for _, ds in slices])
    order = np.argsort(where, kind="stable")
    gaps = np.diff(where[order])
    if np.any(gaps <= 0):
        raise InputError("ImagePositionPatient", f"{path!r}: two slices share a position along the normal")
    dz = float(np.median(gaps))
    if np.any(np.abs(gaps - dz) > 0.01 * dz):
        warnings.warn(f"{path}: slice distances vary from {gaps.min():g} to {gaps.max():g}; using their "
                      f"median {dz:g}", stacklevel=4)
    first = slices[order[0]][1]
    dy, dx = (float(v) for v in first.PixelSpacing)   # between rows, between columns
    planes = []
    for k in order:
        ds = pydicom.dcmread(slices[k][0])
        try:
            pixels = ds.pixel_array
        except Exception as e:            # a compressed transfer syntax without its handler
            raise InputError("path", f"{slices[k][0]!r}: cannot decode its pixels ({e})") from None
        slope, intercept = float(ds.get("RescaleSlope", 1)), float(ds.get("RescaleIntercept", 0))
        planes.append(pixels * slope + intercept if (slope, intercept) != (1.0, 0.0) else pixels)
    data = np.stack(planes)
    if data.dtype.kind == "f" and np.all(data == np.round(data)) and -32768 <= data.min() and data.max() <= 32767:
        data = data.astype(np.int16)      # integer HU: keep them exact and small
    orientation = _direction_codes([row, col, normal])
    origin = tuple(float(v) for v in first.ImagePositionPatient)
    return np.ascontiguousarray(data), (dx, dy, dz), origin, orientation, _modality_code(first.get("Modality"))


@_named_errors
def _load_tiff(path):
    """(data (nz, ny, nx), spacing) of a multi-page TIFF stack, through tifffile: one page
    per slice; x and y spacing from the resolution tags (1 / pixels per unit) and z from
    ImageJ's ``spacing``, each 1 where the file says nothing."""
    tifffile = _optional("tifffile", f"the TIFF stack {path!r}")
    with tifffile.TiffFile(path) as tif:
        data = tif.asarray()
        page = tif.pages[0]
        spacing = [1.0, 1.0, 1.0]
        for axis, tag in ((0, "XResolution"), (1, "YResolution")):
            if tag in page.tags:
                num, den = page.tags[tag].value
                if num > 0 and den > 0 and not (num == 1 and den == 1):
                    spacing[axis] = den / num
        meta = tif.imagej_metadata or {}
        if float(meta.get("spacing", 0) or 0) > 0:
            spacing[2] = float(meta["spacing"])
    if data.ndim != 3:
        raise InputError("path", f"{path!r} holds an image of shape {data.shape}; a TIFF stack for a volume "
                                 "has one grey page per slice (pages, rows, columns)")
    return np.ascontiguousarray(data), tuple(spacing)


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


def _read_bytes(path, field="path"):
    try:
        if path.lower().endswith(".gz"):
            with gzip.open(path, "rb") as f:
                return f.read()
        with open(path, "rb") as f:
            return f.read()
    except FileNotFoundError:
        raise MissingFileError(field, f"no such file {path!r}") from None
    except (OSError, EOFError, zlib.error) as e:
        raise InputError(field, f"cannot read {path!r}: {e}") from None


@_named_errors
def _load_raw(path, shape, dtype):
    raw = _read_bytes(path)
    need = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
    if len(raw) != need:
        what = "gunzipped " if path.lower().endswith(".gz") else ""
        hint = ""
        if len(raw) > need:
            hint = f" ({len(raw) - need} bytes too many: a header? this reader expects bare samples)"
        raise InputError("shape", f"{what}file {path!r} holds {len(raw)} bytes, but shape {shape} (nz,ny,nx) "
                                  f"of {dtype.name} needs {need}{hint}")
    return np.frombuffer(raw, dtype=dtype).reshape(shape)


@_named_errors
def _load_npy(path):
    try:
        return np.load(path, allow_pickle=False)
    except ValueError as e:
        raise InputError("path", f"{path!r} is not a plain .npy array: {e}") from None
    except OSError as e:
        raise InputError("path", f"cannot read {path!r}: {e}") from None


@_named_errors
def _load_npz(path):
    try:
        with np.load(path, allow_pickle=False) as npz:
            if "data" not in npz.files:
                raise InputError("data", f"{path!r} has no array named 'data' (it has {sorted(npz.files)})")
            data = npz["data"]
            spacing = origin = None
            if "spacing" in npz.files:
                spacing = _triplet(npz["spacing"].tolist(), "spacing", positive=True)
            if "origin" in npz.files:
                origin = _triplet(npz["origin"].tolist(), "origin")
    except InputError:
        raise
    except (ValueError, OSError, zlib.error) as e:
        raise InputError("path", f"cannot read {path!r} as .npz: {e}") from None
    return data, spacing, origin


# -- NRRD ----------------------------------------------------------------------------

_FORMAT_RE = re.compile(r"%[-+ 0#]*\d*d")


def _nrrd_lines(path):
    """The header lines (magic included) up to the blank line that ends it (or EOF)."""
    lines = []
    with open(path, "rb") as f:
        for raw in f:
            line = raw.decode("latin-1").rstrip("\r\n")
            if not line.strip():
                break
            lines.append(line)
            if len(lines) > 100000:
                raise InputError("path", f"{path!r}: NRRD header has no end")
    if not lines or not lines[0].startswith("NRRD"):
        raise InputError("path", f"{path!r} is not a NRRD file (it does not start with 'NRRD')")
    return lines


@_named_errors
def _load_nrrd(path):
    import nrrd

    lines = _nrrd_lines(path)
    file_list = None
    for i, line in enumerate(lines):
        key, _, value = line.partition(":")
        if line.startswith("#") or value.startswith("="):
            continue
        if key.strip().lower() in ("data file", "datafile") and value.strip().split()[:1] == ["LIST"]:
            file_list = [ln.strip() for ln in lines[i + 1:] if ln.strip()]
            lines = lines[:i + 1]
            break
    try:
        header = nrrd.read_header(lines)
    except (nrrd.NRRDError, ValueError, KeyError) as e:
        raise InputError("path", f"{path!r}: bad NRRD header: {e}") from None
    for field in ("dimension", "type", "encoding", "sizes"):
        if field not in header:
            raise InputError(field, f"{path!r}: the NRRD header lacks the required field {field!r}")
    dim = int(header["dimension"])
    sizes = [int(s) for s in np.atleast_1d(header["sizes"])]
    if len(sizes) != dim:
        raise InputError("sizes", f"{path!r}: dimension is {dim} but sizes has {len(sizes)} values: {sizes}")
    if dim != 3:
        raise InputError("dimension", f"{path!r} is {dim}-D (sizes {sizes}); a volume is 3-D")
    known = getattr(getattr(nrrd, "reader", None), "_TYPEMAP_NRRD2NUMPY", None)
    if header["type"] == "block" or (known is not None and header["type"] not in known):
        raise InputError("type", f"{path!r}: unsupported NRRD type {header['type']!r}")
    if header["encoding"] not in ("raw", "ascii", "text", "txt", "gzip", "gz", "bzip2", "bz2"):
        raise InputError("encoding", f"{path!r}: unsupported NRRD encoding {header['encoding']!r} "
                                     "(raw, ascii, gzip and bzip2 are)")
    if np.dtype(known[header["type"]] if known else "u1").itemsize > 1 and \
            header["encoding"] not in ("ascii", "text", "txt") and header.get("endian") not in ("little", "big"):
        raise InputError("endian", f"{path!r}: multi-byte {header['type']!r} needs 'endian: little' or "
                                   f"'endian: big', got {header.get('endian')!r}")

    spec_key = "data file" if "data file" in header else ("datafile" if "datafile" in header else None)
    spec = header.get(spec_key) if spec_key else None
    try:
        if file_list is not None:
            parts = spec.split()
            subdim = _subdim(parts[1:], dim, path, spec)
            data = _read_nrrd_pieces(header, file_list, subdim, sizes, path)
        elif spec is not None and _is_format_spec(spec):
            parts = spec.split()
            fmt, (lo, hi, step) = parts[0], _ints(parts[1:4], path, spec)
            subdim = _subdim(parts[4:], dim, path, spec)
            if step == 0:
                raise InputError("data file", f"{path!r}: file number step must not be 0 in {spec!r}")
            if (hi - lo) * step < 0:
                raise InputError("data file", f"{path!r}: file number max {hi} is not reached from min {lo} "
                                              f"by step {step} in {spec!r}")
            try:
                names = [fmt % i for i in range(lo, hi + (1 if step > 0 else -1), step)]
            except (TypeError, ValueError) as e:
                raise InputError("data file", f"{path!r}: bad file name format {fmt!r}: {e}") from None
            data = _read_nrrd_pieces(header, names, subdim, sizes, path)
        elif spec is not None:  # one detached data file
            data = _read_nrrd_pieces(header, [spec], dim, sizes, path)
        else:  # attached: the data follows the header
            data, _ = nrrd.read(path, index_order="C")
    except nrrd.NRRDError as e:
        raise _nrrd_error(e, "sizes", f"{path!r}", f"sizes {sizes} need") from None
    except (OSError, EOFError, zlib.error) as e:
        if isinstance(e, InputError):
            raise
        raise InputError("path", f"cannot read the data of {path!r}: {e}") from None
    except ValueError as e:  # numpy reshape / frombuffer on a short or long file
        if isinstance(e, InputError):
            raise
        raise InputError("sizes", f"{path!r}: the data does not match sizes {sizes} "
                                  f"of {header['type']}: {e}") from None
    spacing, origin = _nrrd_geometry(header, path)
    modality = next((v for k, v in header.items() if str(k).strip().lower() == "modality"), None)
    return data, spacing, origin, _nrrd_orientation(header), _modality_code(modality)


def _is_format_spec(spec):
    parts = spec.split()
    if len(parts) not in (4, 5) or not _FORMAT_RE.search(parts[0].replace("%%", "")):
        return False
    return all(re.fullmatch(r"[-+]?\d+", p) for p in parts[1:])


def _ints(parts, path, spec):
    try:
        return tuple(int(p) for p in parts)
    except ValueError:
        raise InputError("data file", f"{path!r}: expected integers in {spec!r}") from None


def _subdim(parts, dim, path, spec):
    if not parts:
        return dim - 1
    if len(parts) != 1:
        raise InputError("data file", f"{path!r}: cannot parse {spec!r}")
    (subdim,) = _ints(parts, path, spec)
    if not 1 <= subdim <= dim:
        raise InputError("data file", f"{path!r}: data file dimension {subdim} is outside [1, {dim}] in {spec!r}")
    return subdim


def _read_nrrd_pieces(header, names, subdim, sizes, path):
    """Read a NRRD whose data is split over several files, each holding a ``subdim``-D
    piece (the fastest ``subdim`` axes; for ``subdim == dim``, equal slabs of the slowest
    axis), through pynrrd's per-file reader (encodings, skips and endianness)."""
    import nrrd

    dim = len(sizes)
    if not names:
        raise InputError("data file", f"{path!r}: the data file list is empty")
    if subdim < dim:
        piece = sizes[:subdim]
        count = int(np.prod(sizes[subdim:], dtype=np.int64))
        if count != len(names):
            raise InputError("data file", f"{path!r} names {len(names)} data files, but sizes {sizes} split into "
                                          f"{subdim}-D pieces need {count}")
    else:
        if sizes[-1] % len(names):
            raise InputError("data file", f"{path!r} names {len(names)} data files, which do not split the "
                                          f"{sizes[-1]} slices of the slowest axis evenly")
        piece = sizes[:-1] + [sizes[-1] // len(names)]
    base = os.path.dirname(path)
    chunks = []
    for name in names:
        target = name if os.path.isabs(name) else os.path.join(base, name)
        if not os.path.exists(target):
            raise MissingFileError("data file", f"{path!r} names the data file {name!r}, which does not exist "
                                                f"({target!r})")
        h = {k: v for k, v in header.items() if k not in ("data file", "datafile")}
        h["dimension"] = len(piece)
        h["sizes"] = np.array(piece)
        h["data file"] = os.path.abspath(target)
        try:
            chunk = nrrd.read_data(h, filename=path, index_order="C")
        except nrrd.NRRDError as e:
            need = "sizes {} need".format(sizes) if len(names) == 1 else \
                f"sizes {sizes} in {len(names)} files need per file"
            raise _nrrd_error(e, "data file", f"{path!r}: data file {name!r}", need) from None
        chunks.append(chunk.reshape(-1))
    return np.concatenate(chunks).reshape(tuple(sizes[::-1]))


def _nrrd_error(exc, field, where, need):
    """pynrrd's error as an InputError; its size mismatch ("...: 72-60=12") spelled out."""
    m = re.search(r"dimensions: (\d+)-(\d+)=", str(exc))
    if m:
        return InputError(field, f"{where} holds {m.group(2)} samples, but {need} {m.group(1)}")
    return InputError(field, f"{where}: {exc}")


_NRRD_SPACES = {"right-anterior-superior": "RAS", "ras": "RAS", "left-anterior-superior": "LAS", "las": "LAS",
                "left-posterior-superior": "LPS", "lps": "LPS"}
_OPPOSITE = {"R": "L", "L": "R", "A": "P", "P": "A", "S": "I", "I": "S"}


class _Assumed(str):
    """An orientation code that is a format's convention, not the file's statement."""


#: NRRD's non-anatomical 3-D spaces, read the way DICOM lays out a slice (columns towards
#: the patient's left, rows towards the back), the third axis then fixed by the space's
#: handedness: right-handed is LPS, left-handed LPI (VTK's CT head ``quarter.nhdr``, whose
#: slices run from the crown down, says ``3D-left-handed``)
_NRRD_CONVENTIONS = {"3d-right-handed": "LPS", "3d-right-handed-time": "LPS",
                     "3d-left-handed": "LPI", "3d-left-handed-time": "LPI"}


def _nrrd_orientation(header):
    """Where the index axes point anatomically (e.g. "RAS"), from an anatomical ``space``
    and the ``space directions`` (each axis named by its vector's largest component, with
    its sign). A ``3D-right-handed`` or ``3D-left-handed`` space gives the convention of
    ``_NRRD_CONVENTIONS``, marked as assumed; other spaces give None."""
    name = str(header.get("space", "")).lower()
    space = _NRRD_SPACES.get(name)
    if space is None and name in _NRRD_CONVENTIONS:
        directions = header.get("space directions")
        try:
            d = np.eye(3) if directions is None else np.array(directions, dtype=np.float64)
        except (TypeError, ValueError):
            return None
        codes = _direction_codes(d, _NRRD_CONVENTIONS[name])
        return None if codes is None else _Assumed(codes)
    if space is None:
        return None
    directions = header.get("space directions")
    try:
        d = np.eye(3) if directions is None else np.array(directions, dtype=np.float64)
    except (TypeError, ValueError):
        return None
    return _direction_codes(d, space)


def _nrrd_geometry(header, path):
    spacing = origin = None
    directions = header.get("space directions")
    if directions is not None:
        d = np.array(directions, dtype=np.float64)
        if d.ndim != 2 or d.shape[0] != 3 or not np.all(np.isfinite(d)):
            raise InputError("space directions", f"{path!r}: expected a vector per axis, got {directions!r}")
        lengths = np.linalg.norm(d, axis=1)
        if np.any(lengths <= 0):
            raise InputError("space directions", f"{path!r}: an axis vector has length 0 in {directions!r}")
        spacing = tuple(float(v) for v in lengths)
        if d.shape[1] != 3 or not np.allclose(d, np.diag(np.diagonal(d)), rtol=0, atol=1e-9 * lengths.max()) \
                or np.any(np.diagonal(d) < 0):
            warnings.warn(f"{path}: space directions {d.tolist()} are not a positive diagonal; the volume is "
                          "used axis-aligned in index order with spacing = the vector lengths "
                          f"{spacing}", stacklevel=4)
    elif "spacings" in header:
        s = np.array(header["spacings"], dtype=np.float64)
        if s.shape != (3,) or not np.all(np.isfinite(s)) or np.any(s <= 0):
            raise InputError("spacings", f"{path!r}: must be three positive numbers, got {header['spacings']!r}")
        spacing = tuple(float(v) for v in s)
    if "space origin" in header:
        o = np.array(header["space origin"], dtype=np.float64)
        if o.shape != (3,) or not np.all(np.isfinite(o)):
            raise InputError("space origin", f"{path!r}: must be three finite numbers, got {header['space origin']!r}")
        origin = tuple(float(v) for v in o)
    return spacing, origin


# -- MetaImage -------------------------------------------------------------------------

_MET_TYPES = {"MET_UCHAR": "u1", "MET_CHAR": "i1", "MET_USHORT": "u2", "MET_SHORT": "i2",
              "MET_UINT": "u4", "MET_INT": "i4", "MET_ULONG": "u4", "MET_LONG": "i4",
              "MET_ULONG_LONG": "u8", "MET_LONG_LONG": "i8", "MET_FLOAT": "f4", "MET_DOUBLE": "f8"}

#: MetaIO's modality names (MET_ImageModalityTypeName) as DICOM's codes; MET_MOD_UNKNOWN,
#: like any name MetaIO does not know (it reads those as unknown), gives none.
_MET_MODALITIES = {"MET_MOD_CT": "CT", "MET_MOD_MR": "MR", "MET_MOD_NM": "NM", "MET_MOD_US": "US",
                   "MET_MOD_OTHER": "OT", "MET_MOD_UNKNOWN": ""}


def _metaimage_matrix(fields):
    """The header's TransformMatrix (or its other names, Rotation and Orientation), or None."""
    return next((fields[k] for k in ("transformmatrix", "rotation", "orientation") if k in fields), None)


def _metaimage_orientation(fields, path):
    """Where the index axes point (dvr_gl's "to" letters, e.g. "LPS"), from a MetaImage
    header; None where it does not say.

    MetaIO keeps ITK's conventions. ITK's world is LPS (+x towards the patient's left, +y
    posterior, +z superior), and ``TransformMatrix`` holds the direction cosines row by
    row, row i the i-th index axis in that world (ITK's MetaImageIO writes
    ``GetDirection(i)`` into row i). ``AnatomicalOrientation`` uses ITK's older "from"
    letters: MetaImageIO writes an axis running from right to left as
    ``MET_ORIENTATION_RL``, whose letter (``MET_OrientationTypeName``) is "R", so the
    identity direction is written ``RAI`` (``itk::AnatomicalOrientation`` calls these its
    NegativeEnum codes); each letter is the opposite of where the axis points. "?" is
    MetaIO's unknown axis. A TransformMatrix other than the identity decides; an
    identity one (which ITK writes for every image, VTK for images without orientation)
    leaves it to AnatomicalOrientation. MetaIO reads ``Rotation`` and ``Orientation`` as
    other names of TransformMatrix; so does this. A header that says neither is read as
    ITK reads it, the identity in LPS, marked as assumed (``Volume.orientation_assumed``):
    the first view faces that way, presets do not take the volume for a scan."""
    matrix = _metaimage_matrix(fields)
    if matrix is not None:
        values = _float_list(matrix)
        if values is None or len(values) != 9 or not all(math.isfinite(v) for v in values):
            raise InputError("TransformMatrix", f"{path!r}: expected nine numbers (3x3 direction cosines), "
                                                f"got {matrix!r}")
        if values != [1, 0, 0, 0, 1, 0, 0, 0, 1]:
            codes = _direction_codes(np.reshape(values, (3, 3)), _LPS)
            if codes is not None or not fields.get("anatomicalorientation", "").strip():
                return codes      # an oblique matrix without letters names no direction
    letters = fields.get("anatomicalorientation", "").strip().upper()
    if not letters:
        # nothing said: ITK reads the image with the identity direction in its LPS world
        return _Assumed(_LPS)
    if len(letters) != 3 or not all(c in _OPPOSITE for c in letters):
        return None       # "???" or malformed: no orientation
    codes = "".join(_OPPOSITE[c] for c in letters)
    pairs = {pair for c in codes for pair in ("RL", "AP", "SI") if c in pair}
    return codes if len(pairs) == 3 else None


@_named_errors
def _load_metaimage(path):
    """(data (nz, ny, nx), spacing, origin, orientation, modality) of a MetaImage."""
    fields = {}
    header_len = 0
    with open(path, "rb") as f:
        for raw in f:
            header_len += len(raw)
            line = raw.decode("latin-1").strip()
            if not line or line.startswith("#"):
                continue
            key, sep, value = line.partition("=")
            if not sep:
                raise InputError("path", f"{path!r}: not a MetaImage header line: {line!r}")
            fields[key.strip().lower()] = value.strip()
            if key.strip().lower() == "elementdatafile":
                break  # the last header field; LOCAL data follows
            if len(fields) > 1000:
                raise InputError("path", f"{path!r}: MetaImage header has no ElementDataFile")

    def need(key):
        if key.lower() not in fields:
            raise InputError(key, f"{path!r}: the MetaImage header lacks {key}")
        return fields[key.lower()]

    ndims = need("NDims")
    if ndims.strip() != "3":
        raise InputError("NDims", f"{path!r} is {ndims}-D; a volume is 3-D")
    try:
        dims = [int(v) for v in need("DimSize").split()]
    except ValueError:
        raise InputError("DimSize", f"{path!r}: expected three integers, got {fields['dimsize']!r}") from None
    if len(dims) != 3 or min(dims) < 1:
        raise InputError("DimSize", f"{path!r}: expected three positive integers, got {fields['dimsize']!r}")
    channels = fields.get("elementnumberofchannels", "1").strip()
    if channels != "1":
        raise InputError("ElementNumberOfChannels", f"{path!r} has {channels} channels; a volume has 1")
    etype = need("ElementType").strip().upper()
    if etype not in _MET_TYPES:
        raise InputError("ElementType", f"{path!r}: unsupported {etype!r}; use one of {', '.join(_MET_TYPES)}")
    msb = fields.get("elementbyteordermsb", fields.get("binarydatabyteordermsb", "False")).strip().lower() == "true"
    dtype = np.dtype(_MET_TYPES[etype]).newbyteorder(">" if msb else "<")
    def floats(key, name, positive=False):
        try:
            values = [float(v) for v in fields[key].split()]
        except ValueError:
            raise InputError(name, f"{path!r}: expected three numbers, got {fields[key]!r}") from None
        return _triplet(values, name, positive=positive)

    spacing = origin = None
    for key, name in (("elementspacing", "ElementSpacing"), ("elementsize", "ElementSize")):
        if key in fields:
            spacing = floats(key, name, positive=True)
            break
    for key, name in (("offset", "Offset"), ("position", "Position"), ("origin", "Origin")):
        if key in fields:
            origin = floats(key, name)
            break
    orientation = _metaimage_orientation(fields, path)
    matrix = _metaimage_matrix(fields)
    if matrix is not None and _float_list(matrix) != [1, 0, 0, 0, 1, 0, 0, 0, 1]:
        warnings.warn(f"{path}: TransformMatrix {matrix} is not the identity; the volume is used "
                      "axis-aligned in index order" + (f" (orientation {orientation})" if orientation else ""),
                      stacklevel=4)
    modality = _modality_code(_MET_MODALITIES.get(fields.get("modality", "").strip().upper()))
    datafile = need("ElementDataFile")
    if datafile.upper() == "LOCAL":
        with open(path, "rb") as f:
            f.seek(header_len)
            raw = f.read()
    else:
        if datafile.split()[:1] == ["LIST"] or len(datafile.split()) > 1:
            raise InputError("ElementDataFile", f"{path!r}: multi-file MetaImage data {datafile!r} is not supported")
        target = datafile if os.path.isabs(datafile) else os.path.join(os.path.dirname(path), datafile)
        if not os.path.exists(target):
            raise MissingFileError("ElementDataFile", f"{path!r} names the data file {datafile!r}, which does not "
                                                      f"exist ({target!r})")
        raw = _read_bytes(target, "ElementDataFile")
    if fields.get("compresseddata", "false").strip().lower() == "true":
        try:
            raw = zlib.decompress(raw)
        except zlib.error as e:
            raise InputError("CompressedData", f"{path!r}: cannot inflate the data: {e}") from None
    need_bytes = int(np.prod(dims, dtype=np.int64)) * dtype.itemsize
    try:
        header_size = int(fields.get("headersize", "0"))
    except ValueError:
        raise InputError("HeaderSize", f"{path!r}: expected an integer, got {fields['headersize']!r}") from None
    if header_size == -1:
        raw = raw[len(raw) - need_bytes:] if len(raw) >= need_bytes else raw
    elif header_size > 0:
        raw = raw[header_size:]
    if len(raw) != need_bytes:
        raise InputError("DimSize", f"{path!r}: the data holds {len(raw)} bytes, but DimSize {dims} of "
                                    f"{etype} needs {need_bytes}")
    data = np.frombuffer(raw, dtype=dtype).reshape(dims[::-1])
    return data, spacing, origin, orientation, modality


def _float_list(text):
    try:
        return [float(v) for v in text.split()]
    except ValueError:
        return None


# ----------------------------------------------------------------------------- meshes

#: meshio's extensions that are also common names for raw volumes: a mesh only when the
#: command line gives no raw geometry (see dvr_gl.frontends.cli).
AMBIGUOUS_MESH_EXTENSIONS = (".dat", ".vol")

_SPLIT_CELLS = ("tetra", "pyramid", "wedge", "hexahedron")
_LOW_DIMENSIONAL_PREFIXES = ("vertex", "line", "triangle", "quad", "polygon")


def _mesh_path(path):
    return _existing_file(path, "mesh")


def _meshio_extensions():
    try:
        import meshio
    except ImportError:
        return ()
    return tuple(sorted(getattr(meshio, "extension_to_filetypes", {}), key=len, reverse=True))


def _vtk_dataset(path):
    """The DATASET keyword of a legacy .vtk file (its header is ASCII even when the data
    is binary), or None."""
    try:
        with open(path, "rb") as f:
            for _ in range(12):
                line = f.readline(1024)
                if not line:
                    break
                words = line.decode("latin-1").split()
                if len(words) >= 2 and words[0].upper() == "DATASET":
                    return words[1].upper()
    except OSError:
        return None
    return None


def _npz_keys(path):
    try:
        with np.load(path, allow_pickle=False) as npz:
            return list(npz.files)
    except (ValueError, OSError, zlib.error):
        return []


def is_mesh_file(path) -> bool:
    """Whether ``path`` names an unstructured mesh (for :func:`load_mesh`) rather than a
    volume (for :func:`load_volume`): ``.vtu``; ``.vtk`` whose DATASET is
    UNSTRUCTURED_GRID; ``.npz`` holding ``points`` and ``tets``; any other extension
    meshio reads (``.dat`` and ``.vol`` included, see ``AMBIGUOUS_MESH_EXTENSIONS``)."""
    path = os.fspath(path)
    lower = path.lower()
    if lower.endswith(".vtu"):
        return True
    if lower.endswith(".vtk"):
        return _vtk_dataset(path) == "UNSTRUCTURED_GRID"
    if lower.endswith(".npz"):
        return os.path.isfile(path) and {"points", "tets"} <= set(_npz_keys(path))
    if lower.endswith((".npy", ".nrrd", ".nhdr", ".mhd", ".mha", ".raw", ".raw.gz")):
        return False
    return any(lower.endswith(ext) for ext in _meshio_extensions())


class _MeshFile:
    """What a mesh file holds: points, tetrahedra and the point arrays by name."""

    def __init__(self, points, tets, arrays):
        self.points, self.tets, self.arrays = points, tets, arrays


_last_read = {}


@_named_errors
def _read_mesh_file(path):
    """The file's content, read once per (path, size, mtime): ``dvr-gl info`` asks for the
    mesh and its array names without reading a large file twice."""
    st = os.stat(path)
    key = (os.path.abspath(path), st.st_size, st.st_mtime_ns)
    if key not in _last_read:
        content = _read_npz_mesh(path) if path.lower().endswith(".npz") else _read_meshio(path)
        _last_read.clear()
        _last_read[key] = content
    return _last_read[key]


def _read_npz_mesh(path):
    try:
        with np.load(path, allow_pickle=False) as npz:
            missing = [k for k in ("points", "tets") if k not in npz.files]
            if missing:
                raise InputError("path", f"{path!r} is not a mesh: it lacks {missing} "
                                         f"(it has {sorted(npz.files)})")
            points, tets = npz["points"], npz["tets"]
            arrays = {k: npz[k] for k in npz.files if k not in ("points", "tets")}
    except InputError:
        raise
    except (ValueError, OSError, zlib.error) as e:
        raise InputError("path", f"cannot read {path!r} as .npz: {e}") from None
    if tets.dtype.kind not in "iu":
        raise InputError("tets", f"{path!r}: tets must be integer indices, got dtype {tets.dtype}")
    if tets.ndim != 2 or tets.shape[1] != 4:
        raise InputError("tets", f"{path!r}: tets must have shape (M, 4), got {tets.shape}")
    return _MeshFile(points, tets.astype(np.int64), arrays)


def _cell_dimension(cell_type):
    """3 for solid cells, less for vertices, lines and surface cells; None if unknown."""
    try:
        from meshio._mesh import topological_dimension
        if cell_type in topological_dimension:
            return topological_dimension[cell_type]
    except ImportError:
        pass
    if cell_type.startswith(_LOW_DIMENSIONAL_PREFIXES):
        return 2
    return None


def _read_meshio(path):
    try:
        import meshio
    except ImportError as e:
        raise InputError("path", f"reading {path!r} needs meshio (pip install meshio): {e}") from None
    m = _meshio_read(meshio, path)
    blocks, ignored = [], []
    for block in m.cells:
        dimension = _cell_dimension(block.type)
        if block.type in _SPLIT_CELLS:
            blocks.append((block.type, np.asarray(block.data)))
        elif dimension is not None and dimension < 3:
            ignored.append(block.type)
        else:
            raise InputError("cells", f"{path!r} has {len(block.data)} cells of type {block.type!r}, which "
                                      f"cannot be rendered; supported 3-D cells: {', '.join(_SPLIT_CELLS)}")
    if not blocks:
        kinds = ", ".join(sorted(set(ignored))) or "none"
        raise InputError("cells", f"{path!r} has no 3-D cells (cell types: {kinds}); a volume mesh needs "
                                  f"{', '.join(_SPLIT_CELLS)}")
    from ..model.cell_split import split_cells
    try:
        tets = split_cells(blocks)
    except (TypeError, ValueError) as e:
        raise InputError("cells", f"{path!r}: {e}") from None
    arrays = {name: np.asarray(a) for name, a in m.point_data.items()}
    return _MeshFile(np.asarray(m.points), tets, arrays)


def _meshio_read(meshio, path):
    """``meshio.read`` for each format the extension allows, with meshio's own printing
    kept off the terminal: on a malformed file it prints and calls ``sys.exit``."""
    lower = path.lower()
    formats = next((types for ext, types in sorted(getattr(meshio, "extension_to_filetypes", {}).items(),
                                                    key=lambda item: -len(item[0]))
                    if lower.endswith(ext)), [None])
    problems = []
    for file_format in formats:
        chatter = io.StringIO()
        try:
            with contextlib.redirect_stdout(chatter), contextlib.redirect_stderr(chatter):
                return meshio.read(path, file_format=file_format)
        except (Exception, SystemExit) as e:  # meshio's readers raise many types for a bad file
            said = " ".join(chatter.getvalue().split())
            problems.append(str(e).strip() if isinstance(e, Exception) and str(e).strip()
                            else said or type(e).__name__)
    kinds = " or ".join(f for f in formats if f) or "a mesh"
    raise InputError("path", f"cannot read {path!r} as {kinds}: {'; '.join(problems)}")


def _components(array):
    return 1 if array.ndim == 1 else int(np.prod(array.shape[1:]))


def point_arrays(path) -> dict:
    """A mesh file's point arrays: name -> number of components, in file order."""
    path = _mesh_path(path)
    return {name: _components(a) for name, a in _read_mesh_file(path).arrays.items()}


def _is_flag(values):
    """A point array of at most three distinct values (a blanking or ghost flag)."""
    return len(np.unique(np.asarray(values).ravel()[:100000])) <= 3


def load_mesh(path, scalars=None) -> TetMesh:
    """Read a mesh file (see the module docstring for formats) with the point array
    ``scalars`` (default: the first one-component point array that is not a flag of at
    most three values, such as IBlank) as the field."""
    path = _mesh_path(path)
    content = _read_mesh_file(path)
    arrays = content.arrays
    listing = ", ".join(f"{n} ({_components(a)} components)" if _components(a) != 1 else n
                        for n, a in arrays.items()) or "none"
    if scalars is None:
        candidates = [n for n, a in arrays.items() if _components(a) == 1]
        # a field, not a flag: blanking arrays (IBlank: -1, 0, 1) come first in some files
        name = next((n for n in candidates if not _is_flag(arrays[n])), candidates[0] if candidates else None)
        if name is None:
            raise InputError("scalars", f"{path!r} has no scalar point array to render "
                                        f"(point arrays: {listing})")
    else:
        name = str(scalars)
        if name not in arrays:
            raise InputError("scalars", f"{path!r} has no point array {name!r}; available: {listing}")
    values = arrays[name]
    if _components(values) != 1:
        raise InputError("scalars", f"point array {name!r} in {path!r} has {_components(values)} components; "
                                    "a scalar field has 1")
    if values.dtype.kind not in "biuf":
        raise InputError("scalars", f"point array {name!r} in {path!r} holds {values.dtype}, not numbers")
    points = np.asarray(content.points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise InputError("points", f"{path!r}: points must be (N, 3), got shape {points.shape}")
    try:
        mesh = TetMesh(points, content.tets, values.reshape(len(values)).astype(np.float64))
    except (TypeError, ValueError) as e:
        raise InputError("mesh", f"{path!r}: {e}") from None
    mesh.scalars_name = name     # which array the field is (dvr-gl info marks it)
    return mesh


# ----------------------------------------------------------------------------- images

def to_png_array(image, background=None):
    """The 8-bit array :func:`save_png` writes: (H, W, 4) un-premultiplied RGBA, or
    (H, W, 3) RGB composited over ``background``.

    ``image`` is (H, W, 4) float premultiplied RGBA (conventions section 7), clipped to
    [0, 1]. Without a background the colour is ``C / A`` (0 where the 8-bit alpha is 0);
    with ``background = (r, g, b)`` in [0, 1] the pixel is ``C + (1 - A) * B``. Rounded to
    the nearest of 256 levels.
    """
    if not isinstance(image, np.ndarray):
        raise InputError("image", f"expected a numpy array (H, W, 4), got {type(image).__name__}")
    if image.ndim != 3 or image.shape[2] != 4 or image.shape[0] < 1 or image.shape[1] < 1:
        raise InputError("image", f"expected shape (H, W, 4) premultiplied RGBA, got {image.shape}")
    if image.dtype.kind != "f":
        raise InputError("image", f"expected floats in [0, 1], got dtype {image.dtype}")
    bg = None
    if background is not None:
        bg = np.array(_triplet(background, "background"), dtype=np.float64)
        if np.any(bg < 0) or np.any(bg > 1):
            raise InputError("background", f"components must lie in [0, 1], got {tuple(bg.tolist())}")
    height, width = image.shape[:2]
    out = np.empty((height, width, 4 if bg is None else 3), np.uint8)
    rows = max(1, (1 << 22) // (width * 4))  # float64 work in blocks of ~32 MiB: posters fit in memory
    for start in range(0, height, rows):
        block = image[start:start + rows]
        if not np.isfinite(block).all():
            idx = tuple(int(i) for i in np.argwhere(~np.isfinite(block))[0])
            idx = (idx[0] + start,) + idx[1:]
            raise InputError("image", f"has non-finite values (first at (row, col, channel) {idx}: {image[idx]!r})")
        out[start:start + rows] = _png_block(np.clip(block.astype(np.float64), 0.0, 1.0), bg)
    return out


def _png_block(img, bg):
    colour, alpha = img[..., :3], img[..., 3:]
    if bg is None:
        alpha8 = np.rint(alpha * 255)
        with np.errstate(divide="ignore", invalid="ignore"):
            straight = np.where(alpha > 0, colour / alpha, 0.0)
        rgb8 = np.rint(np.clip(straight, 0.0, 1.0) * 255)
        rgb8[np.broadcast_to(alpha8 == 0, rgb8.shape)] = 0
        return np.concatenate([rgb8, alpha8], axis=-1)
    return np.rint(np.clip(colour + (1.0 - alpha) * bg, 0.0, 1.0) * 255)


def save_png(path, image, background=None):
    """Write ``image`` ((H, W, 4) float premultiplied RGBA, row 0 on top) to ``path``.

    Without ``background`` the PNG is un-premultiplied RGBA (colour 0 where alpha is 0);
    with ``background = (r, g, b)`` in [0, 1] it is RGB, ``C + (1 - A) * B``. 8 bits per
    channel, rounded (see :func:`to_png_array`). The write is atomic: the PNG is written to
    a temporary file in the same directory and renamed over ``path``, so ``path`` is
    either untouched or complete, and nothing is left behind on an error. Returns
    ``path``.
    """
    from PIL import Image

    try:
        path = os.fspath(path)
    except TypeError:
        raise InputError("path", f"expected a file name, got {path!r}") from None
    pixels = to_png_array(image, background)  # validate before touching the disk
    directory = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(directory):
        raise MissingFileError("path", f"the directory {directory!r} of {path!r} does not exist")
    if os.path.isdir(path):
        raise InputError("path", f"{path!r} is a directory")
    buffer = io.BytesIO()
    Image.fromarray(pixels).save(buffer, format="PNG")
    atomic_write(path, buffer.getvalue())
    return path
