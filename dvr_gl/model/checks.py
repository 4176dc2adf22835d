"""Argument checks shared by the scene model: each raises TypeError or ValueError with
a message that names the parameter and the value."""

from __future__ import annotations

import math
from numbers import Real

import numpy as np


def _vector3(name, value, *, positive=False):
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be three numbers, got {value!r}") from None
    if arr.shape != (3,):
        raise ValueError(f"{name} must have 3 components (x, y, z), got {value!r}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if positive and not np.all(arr > 0):
        raise ValueError(f"{name} must be positive on every axis, got {value!r}")
    arr.setflags(write=False)
    return arr


def interval(name, value):
    """(low, high) from two finite numbers with low < high, or an error naming ``name``."""
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be two numbers (low, high), got {value!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
        raise ValueError(f"{name} must be two finite numbers with low < high, got {value!r}")
    return lo, hi


def _finite_number(name, value, *, positive=False):
    if isinstance(value, bool) or not isinstance(value, Real):
        raise TypeError(f"{name} must be a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if positive and value <= 0:
        raise ValueError(f"{name} must be positive, got {value!r}")
    return value


def _array(name, value, dtype):
    try:
        return np.array(value, dtype=dtype, order="C")
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be an array of numbers, got {type(value).__name__}") from None
