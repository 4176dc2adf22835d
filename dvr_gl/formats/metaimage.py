"""MetaImage (``.mhd`` / ``.mha``): a header plus raw, zlib or local data, with ITK's
orientation conventions and MetaIO's modality names."""

from __future__ import annotations

import math
import os
import warnings
import zlib

import numpy as np

from .anatomy import _LPS, _OPPOSITE, _Assumed, _direction_codes, _modality_code
from .errors import InputError, MissingFileError, _named_errors
from .parsing import _triplet
from .raw import _read_bytes


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
