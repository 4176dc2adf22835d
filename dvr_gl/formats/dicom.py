"""DICOM series (a folder, or one ``.dcm`` file of it) through pydicom, an optional
dependency: CT in HU, the orientation the patient's."""

from __future__ import annotations

import os
import warnings

import numpy as np

from .anatomy import _direction_codes, _modality_code
from .errors import InputError, MissingFileError, _named_errors, _optional


def _is_dicom_path(path):
    """A folder (a DICOM series) or a ``.dcm`` file."""
    try:
        path = os.fspath(path)
    except TypeError:
        return False
    return os.path.isdir(path) or path.lower().endswith(".dcm")


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
