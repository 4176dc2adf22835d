"""What files say about the patient: where the index axes point (three letters such as
``RAS``, one each of R/L, A/P and S/I), drawing such data without a mirror image, and the
modality (``CT``, ``MR``, ...) as the Volume holds it."""

from __future__ import annotations

import numpy as np


_AXIS_VECTORS = {"R": (1, 0, 0), "L": (-1, 0, 0), "A": (0, 1, 0), "P": (0, -1, 0), "S": (0, 0, 1), "I": (0, 0, -1)}
_OPPOSITE = {"R": "L", "L": "R", "A": "P", "P": "A", "S": "I", "I": "S"}

# DICOM's patient axes: +x towards the patient's left, +y posterior, +z superior (LPS).
_LPS = "LPS"


class _Assumed(str):
    """An orientation code that is a format's convention, not the file's statement."""


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
    from ..model.volume import _modality
    text = str(value or "").strip().upper()
    try:
        return _modality(text) if text else None
    except ValueError:
        return None
