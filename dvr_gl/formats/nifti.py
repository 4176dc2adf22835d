"""NIfTI-1/2 (``.nii`` / ``.nii.gz``) through nibabel, an optional dependency."""

from __future__ import annotations

import math
import warnings

import numpy as np

from .errors import InputError, _named_errors


def read_nifti(path, what="volume"):
    """(image data as nibabel holds it, x fastest; spacing; origin; orientation codes) of
    a NIfTI file: the header read once for volumes and for series (``what`` names which,
    in the warning about an affine that is not axis-aligned)."""
    try:
        import nibabel
    except ImportError:
        raise InputError("path", f"{path!r} is NIfTI, which needs nibabel: pip install \"dvr-gl[io]\" "
                                 "(or pip install nibabel)") from None
    image = nibabel.load(path)
    data = np.asanyarray(image.dataobj)
    zooms = tuple(float(v) for v in image.header.get_zooms()[:3])
    if not all(v > 0 and math.isfinite(v) for v in zooms):
        raise InputError("pixdim", f"{path!r} has voxel sizes {zooms}; they must be positive")
    affine = np.asarray(image.affine, np.float64)
    linear = affine[:3, :3]
    if not np.allclose(linear, np.diag(np.diag(linear))) or (np.diag(linear) <= 0).any():
        warnings.warn(f"{path}: the affine's axes are not x, y, z with positive steps; the {what} is shown "
                      "axis-aligned in index order, without that orientation", stacklevel=4)
    origin = tuple(float(v) for v in affine[:3, 3])
    orientation = "".join(nibabel.aff2axcodes(affine))   # where the index axes point
    return data, zooms, origin, orientation


@_named_errors
def _load_nifti(path):
    """(data (nz, ny, nx), spacing, origin, orientation) of a NIfTI file, through nibabel."""
    data, zooms, origin, orientation = read_nifti(path)
    if data.ndim == 4 and data.shape[3] == 1:
        data = data[..., 0]
    if data.ndim != 3:
        raise InputError("path", f"{path!r} holds a {data.ndim}-D image of shape {data.shape}; a volume is 3-D")
    return np.ascontiguousarray(np.transpose(data, (2, 1, 0))), zooms, origin, orientation
