"""Building 2D transfer functions (``dvr_gl.TransferFunction2D``): widgets placed over the
(value, gradient magnitude) plane as in Kniss, Kindlmann and Hansen (2001), Levoy's
(1988) iso-contour and region-boundary opacities, and JSON files of either.

Every constructor rasterises its function onto a table of ``resolution`` = (values,
gradient magnitudes) entries; the table's bilinear interpolant is then *the* transfer
function, the one the shaders, the NumPy references and the exact image all use.

Widgets combine as independent layers: the opacities as ``1 - prod(1 - alpha_i)``, the
colours weighted by opacity.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .transfer_function import TransferFunction2D
from .checks import interval
from .transfer import read_json_object

RESOLUTION = (256, 64)   # (values, gradient magnitudes)


def _rgb(name, value):
    try:
        rgb = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be three numbers (RGB), got {value!r}") from None
    if len(rgb) != 3 or not all(0 <= v <= 1 for v in rgb):
        raise ValueError(f"{name} must be three numbers in [0, 1] (RGB), got {value!r}")
    return rgb


def _unit(name, value):
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a number, got {value!r}")
    if not 0 <= value <= 1:
        raise ValueError(f"{name} must lie in [0, 1], got {value!r}")
    return float(value)


@dataclass(frozen=True)
class Rectangle:
    """Constant colour and opacity over ``value`` x ``gradient`` (both (low, high)); the
    opacity falls linearly to 0 over the outer ``ramp`` fraction of each side (0: a hard
    edge, which the table still spreads over one entry)."""
    value: tuple
    gradient: tuple
    color: tuple
    opacity: float
    ramp: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "value", interval("rectangle value", self.value))
        object.__setattr__(self, "gradient", interval("rectangle gradient", self.gradient))
        object.__setattr__(self, "color", _rgb("rectangle color", self.color))
        object.__setattr__(self, "opacity", _unit("rectangle opacity", self.opacity))
        ramp = _unit("rectangle ramp", self.ramp)
        if ramp > 0.5:
            raise ValueError(f"rectangle ramp must be at most 0.5 (half of each side), got {ramp!r}")
        object.__setattr__(self, "ramp", ramp)

    def opacity_at(self, s, g):
        out = np.full(np.broadcast(s, g).shape, self.opacity)
        for x, (lo, hi) in ((s, self.value), (g, self.gradient)):
            inside = (x >= lo) & (x <= hi)
            if self.ramp > 0:
                edge = self.ramp * (hi - lo)
                out = out * np.clip(np.minimum(x - lo, hi - x) / edge, 0, 1)
            out = np.where(inside, out, 0.0)
        return out


@dataclass(frozen=True)
class Triangle:
    """Levoy's iso-contour opacity, Kniss's triangle widget: at gradient magnitude g, the
    opacity falls linearly from ``opacity`` at ``value`` to 0 at ``value +- thickness * g``.
    Since ``|f - value| / g`` is about the distance to the iso-surface, this draws the surface
    ``value`` about ``thickness`` world units thick wherever it is, however steep the field.
    Only gradient magnitudes in ``gradient`` (low, high; None: all) count."""
    value: float
    thickness: float
    color: tuple
    opacity: float
    gradient: tuple | None = None

    def __post_init__(self):
        for name in ("value", "thickness"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not math.isfinite(v):
                raise TypeError(f"triangle {name} must be a finite number, got {v!r}")
        if self.thickness <= 0:
            raise ValueError(f"triangle thickness must be positive (world units), got {self.thickness!r}")
        object.__setattr__(self, "color", _rgb("triangle color", self.color))
        object.__setattr__(self, "opacity", _unit("triangle opacity", self.opacity))
        if self.gradient is not None:
            object.__setattr__(self, "gradient", interval("triangle gradient", self.gradient))

    def opacity_at(self, s, g):
        s, g = np.broadcast_arrays(np.asarray(s, np.float64), np.asarray(g, np.float64))
        half = self.thickness * g
        with np.errstate(divide="ignore", invalid="ignore"):
            out = self.opacity * np.clip(1 - np.abs(s - self.value) / half, 0, 1)
        # where the field is flat, only the value itself is on the surface
        out = np.where(half > 0, out, np.where(s == self.value, self.opacity, 0.0))
        if self.gradient is not None:
            out = np.where((g >= self.gradient[0]) & (g <= self.gradient[1]), out, 0.0)
        return out


WIDGETS = {"rectangle": Rectangle, "triangle": Triangle}


def _grid(value_range, gradient_range, resolution):
    try:
        n_v, n_g = (int(n) for n in resolution)
    except (TypeError, ValueError):
        raise TypeError(f"resolution must be two integers (values, gradient magnitudes), got {resolution!r}") from None
    if n_v < 2 or n_g < 2 or n_v * n_g > 4096 * 4096:
        raise ValueError(f"resolution must be at least 2 x 2 and at most 4096 x 4096 entries, got {resolution!r}")
    v = np.linspace(*interval("value_range", value_range), n_v)
    g = np.linspace(*interval("gradient_range", gradient_range), n_g)
    return np.meshgrid(v, g)       # (n_g, n_v) each


def from_widgets(widgets, value_range, gradient_range, resolution=RESOLUTION, unit_distance=1.0):
    """A TransferFunction2D from Rectangle and Triangle widgets: each widget's opacity
    and colour evaluated at the table's entries, combined as independent layers."""
    widgets = list(widgets)
    if not widgets:
        raise ValueError("widgets must hold at least one Rectangle or Triangle, got none")
    for w in widgets:
        if not isinstance(w, (Rectangle, Triangle)):
            raise TypeError(f"widgets must be dvr_gl.model.transfer2d.Rectangle or Triangle, got {type(w).__name__}")
    S, G = _grid(value_range, gradient_range, resolution)
    clear = np.ones(S.shape)
    weighted = np.zeros(S.shape + (3,))
    total = np.zeros(S.shape)
    for w in widgets:
        a = w.opacity_at(S, G)
        clear *= 1 - a
        weighted += a[..., None] * np.asarray(w.color)
        total += a
    color = weighted / np.where(total > 0, total, 1.0)[..., None]
    table = np.concatenate([color, (1 - clear)[..., None]], axis=-1)
    return TransferFunction2D(table, value_range, gradient_range, unit_distance)


def levoy_isocontours(contours, value_range, gradient_range, resolution=RESOLUTION, unit_distance=1.0):
    """Levoy's (1988) iso-contour opacity for several surfaces: ``contours`` is a list of
    (value, thickness, color, opacity), one Triangle each."""
    return from_widgets([Triangle(*c) for c in contours], value_range, gradient_range, resolution, unit_distance)


def levoy_region_boundaries(materials, gradient_range, resolution=RESOLUTION, unit_distance=1.0):
    """Levoy's (1988) region-boundary opacity: ``materials`` is a list of (value, color,
    opacity) at increasing values. Between two neighbours colour and opacity blend
    linearly by value, and the opacity is scaled by the gradient magnitude over the top
    of ``gradient_range``, so that the boundaries between materials show and their
    homogeneous insides do not. Outside the first and last value nothing is visible."""
    rows = []
    for m in materials:
        try:
            value, color, opacity = m
        except (TypeError, ValueError):
            raise TypeError(f"materials must be (value, color, opacity) triples, got {m!r}") from None
        rows.append((float(value), _rgb("material color", color), _unit("material opacity", opacity)))
    if len(rows) < 2:
        raise ValueError(f"materials must hold at least two (value, color, opacity) triples, got {len(rows)}")
    values = np.array([r[0] for r in rows])
    if not np.all(np.isfinite(values)) or np.any(np.diff(values) <= 0):
        raise ValueError(f"material values must be finite and strictly increasing, got {values.tolist()}")
    g_lo, g_hi = interval("gradient_range", gradient_range)
    value_range = (values[0], values[-1])
    S, G = _grid(value_range, (g_lo, g_hi), resolution)
    alpha = np.interp(S, values, [r[2] for r in rows]) * (G / g_hi)
    color = np.stack([np.interp(S, values, [r[1][c] for r in rows]) for c in range(3)], axis=-1)
    table = np.concatenate([color, alpha[..., None]], axis=-1)
    return TransferFunction2D(table, value_range, (g_lo, g_hi), unit_distance)


def load_tf2d_json(path, value_range=None, gradient_range=None):
    """A TransferFunction2D from a JSON file::

        {"value_range": [lo, hi], "gradient_range": [0, gmax], "unit_distance": 1.0,
         "resolution": [256, 64],
         "widgets": [{"type": "rectangle", "value": [a, b], "gradient": [c, d],
                      "color": [r, g, b], "opacity": 0.5, "ramp": 0.1},
                     {"type": "triangle", "value": v, "thickness": 1.5,
                      "color": [r, g, b], "opacity": 0.8}]}

    or ``"table"`` (n_gradient rows of n_value RGBA entries) instead of ``"widgets"``.
    ``value_range`` and ``gradient_range`` given here are the defaults for a file
    without them (the data's range and largest gradient magnitude)."""
    spec = read_json_object(path)
    unknown = sorted(set(spec) - {"value_range", "gradient_range", "unit_distance", "resolution", "widgets", "table"})
    if unknown:
        raise ValueError(f"{path}: unknown key {unknown[0]!r} (keys: value_range, gradient_range, unit_distance, "
                         f"resolution, widgets, table)")
    vr = spec.get("value_range", value_range)
    gr = spec.get("gradient_range", gradient_range)
    for name, value in (("value_range", vr), ("gradient_range", gr)):
        if value is None:
            raise ValueError(f"{path}: {name} is missing")
    unit = spec.get("unit_distance", 1.0)
    if ("widgets" in spec) == ("table" in spec):
        raise ValueError(f"{path}: give exactly one of 'widgets' and 'table'")
    if "table" in spec:
        return TransferFunction2D(spec["table"], vr, gr, unit)
    widgets = []
    for i, w in enumerate(spec["widgets"]):
        if not isinstance(w, dict) or w.get("type") not in WIDGETS:
            raise ValueError(f"{path}: widgets[{i}] needs a 'type' of {', '.join(WIDGETS)}, got {w!r}")
        args = {k: v for k, v in w.items() if k != "type"}
        try:
            widgets.append(WIDGETS[w["type"]](**args))
        except TypeError as e:
            if "unexpected keyword" in str(e) or "missing" in str(e):
                raise ValueError(f"{path}: widgets[{i}]: {e}") from None
            raise
    return from_widgets(widgets, vr, gr, spec.get("resolution", RESOLUTION), unit)


def gradient_modulated(tf, gradient_range, floor=0.1, resolution=RESOLUTION):
    """Levoy's gradient-magnitude opacity modulation of a 1D function as a 2D one: the
    colour of ``tf`` and its opacity times ``floor + (1 - floor) g / g_hi`` at gradient
    magnitude g (``gradient_range`` = (g_lo, g_hi)), so homogeneous regions fade and
    boundaries between materials stay. ``tf`` is sampled at ``resolution[0]`` values over
    its control points' span (its knots fall between entries unless they are evenly
    spaced)."""
    floor = _unit("floor", floor)
    knots = tf.knots
    if len(knots) < 2:
        raise ValueError(f"tf needs control points at two values at least, got {knots.tolist()}")
    S, G = _grid((knots[0], knots[-1]), gradient_range, resolution)
    g_hi = interval("gradient_range", gradient_range)[1]
    alpha = tf.opacity(S) * (floor + (1 - floor) * G / g_hi)
    table = np.concatenate([tf.color(S), alpha[..., None]], axis=-1)
    return TransferFunction2D(table, (knots[0], knots[-1]), gradient_range, tf.unit_distance)
