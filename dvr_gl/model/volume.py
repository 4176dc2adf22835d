"""The structured grid: samples, spacing, origin, orientation, and the mask of cells
with non-finite corners."""

from __future__ import annotations

import hashlib

import numpy as np

from .checks import _vector3


SUPPORTED_DTYPES = (np.uint8, np.uint16, np.int16, np.float32, np.float64)


class GridGeometry:
    """Where a grid's samples lie, from its ``shape`` (nz, ny, nx), ``spacing`` and
    ``origin`` (x, y, z): shared by a Volume and a LazyVolume."""

    @property
    def dims(self):
        """Sample counts in x, y, z order."""
        nz, ny, nx = self.shape
        return np.array([nx, ny, nz])

    @property
    def extent(self):
        """World size of the domain box, x, y, z."""
        return (self.dims - 1) * self.spacing

    @property
    def bounds(self):
        """(lower corner, upper corner) of the domain box in world units."""
        return self.origin, self.origin + self.extent

    @property
    def min_spacing(self):
        return float(self.spacing.min())


class Volume(GridGeometry):
    """A structured scalar volume.

    Parameters
    ----------
    data : ndarray (nz, ny, nx) of uint8, uint16, int16, float32 or float64
    spacing, origin : (x, y, z) world units
    mask_nonfinite : if True, NaN/inf samples are allowed and every grid cell with a
        non-finite corner is removed from the domain (no emission, no absorption);
        otherwise non-finite samples are an error.
    orientation : None, or three letters naming where the x, y and z index axes point
        anatomically ("RAS": x towards the patient's right, ...); the first view faces the
        subject and transfer-function presets take it as a scan's.
    modality : None, or the imaging modality as DICOM names it ("CT", "MR", ...), from
        the file's metadata; presets use it (an 8-bit "CT" gets the windowed CT preset).
    orientation_assumed : True where ``orientation`` is the file format's convention
        rather than the file's statement (a MetaImage without orientation fields is in
        ITK's LPS frame; see ``dvr_gl.formats``): the first view uses it, presets do not take
        the volume for a scan because of it.
    """

    def __init__(self, data, spacing=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0), mask_nonfinite=False,
                 orientation=None, modality=None, orientation_assumed=False):
        if not isinstance(data, np.ndarray):
            raise TypeError(f"data must be a numpy array, got {type(data).__name__}")
        if data.dtype.type not in SUPPORTED_DTYPES:
            names = ", ".join(np.dtype(t).name for t in SUPPORTED_DTYPES)
            raise TypeError(f"data dtype must be one of {names}, got {data.dtype}")
        if data.ndim != 3:
            raise ValueError(f"data must be 3-D (nz, ny, nx), got ndim={data.ndim} shape={data.shape}")
        if min(data.shape) < 2:
            raise ValueError(f"data needs at least 2 samples on every axis, got shape={data.shape}")
        self.spacing = _vector3("spacing", spacing, positive=True)
        self.origin = _vector3("origin", origin)
        self.mask_nonfinite = bool(mask_nonfinite)
        self.orientation = _orientation(orientation)
        self.orientation_assumed = bool(orientation_assumed) and self.orientation is not None
        self.modality = _modality(modality)

        data = np.array(data, copy=True, order="C")
        data.setflags(write=False)
        self.data = data
        finite = np.isfinite(data) if data.dtype.kind == "f" else None
        if finite is not None and not finite.all():
            if not self.mask_nonfinite:
                bad = tuple(int(i) for i in np.argwhere(~finite)[0])
                raise ValueError(
                    f"data has non-finite values (first at index {bad}: {data[bad].item()!r}); "
                    "pass mask_nonfinite=True to treat them as outside the domain")
            if not finite.any():
                raise ValueError("data has no finite value at all")
            self.has_nonfinite = True
        else:
            self.has_nonfinite = False
            finite = None
        valid = data[finite] if finite is not None else data
        self.data_range = (float(valid.min()), float(valid.max()))

        if self.has_nonfinite:
            # A cell (the cube between 8 neighbouring samples) is inside the domain only if
            # all its corners are finite; the texture holds 0 where the data is not finite.
            f = finite
            c = (f[:-1, :-1, :-1] & f[:-1, :-1, 1:] & f[:-1, 1:, :-1] & f[:-1, 1:, 1:]
                 & f[1:, :-1, :-1] & f[1:, :-1, 1:] & f[1:, 1:, :-1] & f[1:, 1:, 1:])
            c.setflags(write=False)
            self.cell_valid = c
        else:
            self.cell_valid = None
        self._digest = None

    # -- geometry ---------------------------------------------------------------
    @property
    def shape(self):
        """(nz, ny, nx)"""
        return self.data.shape

    def values(self, dtype=np.float64):
        """The samples as floats, non-finite ones replaced by 0 (they are masked)."""
        v = self.data.astype(dtype)
        if self.has_nonfinite:
            v[~np.isfinite(v)] = 0
        return v

    def digest(self):
        """A content hash (data, spacing, origin, masking) for caches on disk."""
        if self._digest is None:
            h = hashlib.sha256()
            h.update(str((self.data.dtype.str, self.data.shape)).encode())
            h.update(self.data.tobytes())
            h.update(self.spacing.tobytes() + self.origin.tobytes())
            h.update(b"mask" if self.mask_nonfinite else b"")
            self._digest = h.hexdigest()
        return self._digest

    def __repr__(self):
        return (f"Volume(shape={self.shape}, dtype={self.data.dtype}, spacing={tuple(self.spacing.tolist())}, "
                f"origin={tuple(self.origin.tolist())}, range={self.data_range})")


def _orientation(codes):
    """None, or three letters naming where the x, y and z axes point: one of R/L, one of
    A/P, one of S/I (as nibabel's ``aff2axcodes``)."""
    if codes is None:
        return None
    try:
        text = codes.upper() if isinstance(codes, str) else "".join(codes).upper()
    except TypeError:
        text = ""
    pair_of = {c: i for i, pair in enumerate(("RL", "AP", "SI")) for c in pair}
    if len(text) != 3 or sorted(pair_of.get(c, -1) for c in text) != [0, 1, 2]:
        raise ValueError(f"orientation must be three letters, one each of R/L, A/P and S/I (as 'RAS'), "
                         f"got {codes!r}")
    return text


def _modality(value):
    """None, or a modality code as DICOM writes it: up to 16 capitals, digits, spaces or
    underscores ("CT", "MR", "PT"), given in either case."""
    if value is None:
        return None
    text = value.strip().upper() if isinstance(value, str) else None
    if not text or len(text) > 16 or not all(c.isascii() and (c.isalnum() or c in " _") for c in text):
        raise ValueError(f"modality must be a code such as 'CT' or 'MR' (up to 16 letters, digits, spaces or "
                         f"underscores), got {value!r}")
    return text
