"""Clip planes and crop boxes: the part of the data a scene shows.

A clip plane ``(point, normal)`` keeps the closed half-space its normal points to,
``normal . (x - point) >= 0``; a crop box ``(lower, upper)`` keeps the closed axis-aligned
box between its corners. Both are in world units. The kept region is their intersection
with the data's domain, a convex set, so each ray meets it in one interval: the image
contract is integrated over that interval only (``clip_interval``, the NumPy twin of
``clipRange`` in shaders/common/clip.glsl).
"""

from __future__ import annotations

import numpy as np

MAX_CLIP_PLANES = 6


def _show(v):
    return "(" + ", ".join(f"{float(x):g}" for x in v) + ")"


def _vector(name, value):
    try:
        v = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be three numbers (x, y, z), got {value!r}") from None
    if v.shape != (3,):
        raise ValueError(f"{name} must be three numbers (x, y, z), got {value!r}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return v


def check_clip_planes(planes):
    """``[(point, normal), ...]`` -> a tuple of (point, normal) float64 pairs, as given
    (normalised where they are used, so that checking a checked plane again leaves it
    bit for bit as it was)."""
    if planes is None:
        return ()
    try:
        planes = list(planes)
    except TypeError:
        raise TypeError(f"clip_planes must be a sequence of (point, normal) pairs, got {planes!r}") from None
    if len(planes) > MAX_CLIP_PLANES:
        raise ValueError(f"clip_planes takes at most {MAX_CLIP_PLANES} planes, got {len(planes)}")
    out = []
    for i, plane in enumerate(planes):
        try:
            point, normal = plane
        except (TypeError, ValueError):
            raise TypeError(f"clip_planes[{i}] must be a (point, normal) pair, got {plane!r}") from None
        point = _vector(f"clip_planes[{i}] point", point)
        normal = _vector(f"clip_planes[{i}] normal", normal)
        length = float(np.linalg.norm(normal))
        if not length > 0:
            raise ValueError(f"clip_planes[{i}] normal must be non-zero, got {_show(normal)}")
        point.setflags(write=False)
        normal.setflags(write=False)
        out.append((point, normal))
    return tuple(out)


def check_crop_box(box, bounds):
    """``(lower, upper)`` -> a (lower, upper) float64 pair, or None; the box must be
    non-empty and meet the data's ``bounds``."""
    if box is None:
        return None
    try:
        lower, upper = box
    except (TypeError, ValueError):
        raise TypeError(f"crop_box must be a (lower, upper) pair of corners, got {box!r}") from None
    lower = _vector("crop_box lower corner", lower)
    upper = _vector("crop_box upper corner", upper)
    if not np.all(lower < upper):
        raise ValueError(f"crop_box's lower corner must be below its upper corner on every axis, "
                         f"got {_show(lower)} and {_show(upper)}")
    lo, hi = bounds
    if np.any(upper < lo) or np.any(lower > hi):
        raise ValueError(f"crop_box {_show(lower)} to {_show(upper)} lies outside the data "
                         f"({_show(lo)} to {_show(hi)})")
    lower.setflags(write=False)
    upper.setflags(write=False)
    return lower, upper


def clip_interval(origins, dirs, t0, t1, planes=(), crop_box=None):
    """The part [t0, t1] of each ray ``origins + t dirs`` (n, 3) that the planes and the
    crop box keep (GLSL ``clipRange``). ``planes`` are (unit normal, offset) pairs keeping
    ``normal . x >= offset``, and ``crop_box`` a (lower, upper) pair, in the coordinates
    of the rays. A ray the region misses gets t1 <= t0."""
    t0 = np.array(t0, np.float64)
    t1 = np.array(t1, np.float64)
    if crop_box is not None:
        from ..model.field import ray_box
        c0, c1 = ray_box(origins, dirs, crop_box[0], crop_box[1])
        t0 = np.maximum(t0, c0)
        t1 = np.minimum(t1, c1)
    for normal, offset in planes:
        along = dirs @ normal
        height = origins @ normal - offset            # >= 0: the origin is kept
        with np.errstate(divide="ignore", invalid="ignore"):
            cut = -height / along
        t0 = np.where(along > 0, np.maximum(t0, cut), t0)
        t1 = np.where(along < 0, np.minimum(t1, cut), t1)
        t1 = np.where((along == 0) & (height < 0), -np.inf, t1)
    return t0, t1


def inside_clip(points, planes=(), crop_box=None, margin=0.0):
    """(n,) bool: which ``points`` (n, 3) lie within ``margin`` (one, or one per point) of
    the kept region: at most ``margin`` outside every plane's kept side and inside the
    crop box grown by ``margin``, boundaries included (GLSL ``insideClip``); with margin 0,
    which points are kept. The coordinates as in ``clip_interval``. A sphere of radius
    ``margin`` about a point that fails meets no kept point."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    margin = np.broadcast_to(np.asarray(margin, np.float64), (len(p),))
    inside = np.ones(len(p), bool)
    if crop_box is not None:
        inside &= np.all((p >= crop_box[0] - margin[:, None]) & (p <= crop_box[1] + margin[:, None]), axis=1)
    for normal, offset in planes:
        inside &= p @ np.asarray(normal, np.float64) >= offset - margin
    return inside


def plane_offsets(planes, origin=(0.0, 0.0, 0.0)):
    """(unit normal, offset) pairs of ``planes`` ((point, normal) pairs) in coordinates
    relative to ``origin``."""
    origin = np.asarray(origin, np.float64)
    units = [normal / np.linalg.norm(normal) for _, normal in planes]
    return tuple((unit, float(unit @ (point - origin))) for (point, _), unit in zip(planes, units))
