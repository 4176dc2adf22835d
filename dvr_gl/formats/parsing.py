"""The values users give, checked and parsed: three numbers (``"1,2,3"``), an image size
(``"640x480"``), an anatomical orientation (``"RAS"``) and a sample type (``"int16"``);
errors are :class:`~dvr_gl.formats.errors.InputError` naming the value."""

from __future__ import annotations

import math
import re

import numpy as np

from ..model.scene import MAX_IMAGE_SIDE
from .errors import InputError


#: dtypes accepted for raw files (any byte order); the Volume holds uint8, uint16, int16,
#: float32 and float64, the others are widened as :mod:`dvr_gl.formats.volumes` says.
RAW_DTYPES = ("uint8", "int8", "uint16", "int16", "uint32", "int32", "uint64", "int64",
              "float16", "float32", "float64")


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
    from ..model.volume import _orientation
    try:
        return _orientation(codes.strip() if isinstance(codes, str) else codes)
    except ValueError:
        raise InputError(name, f"expected three letters, one each of R/L, A/P and S/I, naming where the x, y "
                               f"and z axes point (such as RAS or LPI), got {codes!r}") from None


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
