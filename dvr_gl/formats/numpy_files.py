"""NumPy files: ``.npy`` (a 3-D array) and ``.npz`` (an array ``data`` with optional
``spacing`` and ``origin``, the layout of the bundled data sets)."""

from __future__ import annotations

import zlib

import numpy as np

from .errors import InputError, _named_errors
from .parsing import _triplet


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


def _npz_keys(path):
    try:
        with np.load(path, allow_pickle=False) as npz:
            return list(npz.files)
    except (ValueError, OSError, zlib.error):
        return []
