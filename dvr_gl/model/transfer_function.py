"""Transfer functions: piecewise-linear colour and opacity over the data value (1-D),
and over value and gradient magnitude (2-D)."""

from __future__ import annotations

import numpy as np

from .checks import _finite_number, interval


def _control_points(name, points, width):
    try:
        arr = np.array(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a list of {width}-tuples of numbers, got {points!r}") from None
    if arr.ndim != 2 or arr.shape[1] != width or arr.shape[0] < 1:
        raise ValueError(f"{name} must be a non-empty list of {width}-tuples, got {points!r}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {points!r}")
    pos = arr[:, 0]
    if np.any(np.diff(pos) <= 0):
        i = int(np.argmax(np.diff(pos) <= 0))
        raise ValueError(f"{name} positions must be strictly increasing, got {pos[i].item()!r} then {pos[i + 1].item()!r}")
    vals = arr[:, 1:]
    if np.any(vals < 0) or np.any(vals > 1):
        bad = vals[(vals < 0) | (vals > 1)][0].item()
        raise ValueError(f"{name} values must lie in [0, 1], got {bad!r}")
    arr.setflags(write=False)
    return arr


class TransferFunction:
    """Piecewise-linear colour and opacity over data values (not normalised).

    ``opacity`` is the opacity of a slab ``unit_distance`` thick (world units). Both
    functions are linear between their control points and clamped to their end values.
    """

    def __init__(self, color, opacity, unit_distance=1.0):
        self.color_points = _control_points("color", color, 4)
        self.opacity_points = _control_points("opacity", opacity, 2)
        self.unit_distance = _finite_number("unit_distance", unit_distance, positive=True)

    def color(self, s):
        """c(s), shape s.shape + (3,), float64."""
        s = np.asarray(s, dtype=np.float64)
        p = self.color_points
        return np.stack([np.interp(s, p[:, 0], p[:, k]) for k in (1, 2, 3)], axis=-1)

    def opacity(self, s):
        """alpha(s), float64."""
        s = np.asarray(s, dtype=np.float64)
        return np.interp(s, self.opacity_points[:, 0], self.opacity_points[:, 1])

    def extinction(self, s):
        """tau(s) = -ln(1 - alpha(s)) / unit_distance; inf where alpha = 1."""
        a = self.opacity(s)
        with np.errstate(divide="ignore"):
            return -np.log1p(-a) / self.unit_distance

    @property
    def knots(self):
        """All control-point positions, sorted and unique."""
        return np.unique(np.concatenate([self.color_points[:, 0], self.opacity_points[:, 0]]))

    def key(self):
        return (self.color_points.tobytes(), self.opacity_points.tobytes(), self.unit_distance)

    def to_dict(self):
        return {"color": self.color_points.tolist(), "opacity": self.opacity_points.tolist(),
                "unit_distance": self.unit_distance}

    def __repr__(self):
        return (f"TransferFunction({len(self.color_points)} colour points, "
                f"{len(self.opacity_points)} opacity points, unit_distance={self.unit_distance})")


class TransferFunction2D:
    """Colour and opacity over (data value, gradient magnitude): a 2D transfer function
    (Kniss et al. 2001), given as a table.

    ``table`` is (n_gradient, n_value, 4) RGBA in [0, 1]: row i holds gradient magnitude
    ``gradient_range[0] + i * dg``, column j value ``value_range[0] + j * dv``, spaced
    evenly over the two ranges. The function is the table's bilinear interpolant, clamped
    to its edges outside the ranges; opacity, as in ``TransferFunction``, is that of a slab
    ``unit_distance`` thick. The gradient magnitude is the contract's ``|grad f|`` (data units
    per world unit). ``dvr_gl.model.transfer2d`` builds tables from widgets (rectangles and
    triangles) and from Levoy's (1988) iso-contour and region-boundary opacities.

    A scene given one classifies every composite sample with it; ``envelope`` is the 1D
    function of the largest opacity over the gradient range at each value, which tells
    where nothing can be visible (empty-space skipping, the exact integrator's busy test).
    """

    def __init__(self, table, value_range, gradient_range, unit_distance=1.0):
        try:
            arr = np.array(table, dtype=np.float64)
        except (TypeError, ValueError):
            raise TypeError(f"table must be an array of numbers, got {type(table).__name__}") from None
        if arr.ndim != 3 or arr.shape[2] != 4 or arr.shape[0] < 2 or arr.shape[1] < 2:
            raise ValueError(f"table must have shape (n_gradient >= 2, n_value >= 2, 4) RGBA, got {arr.shape}")
        if not np.all(np.isfinite(arr)) or np.any(arr < 0) or np.any(arr > 1):
            bad = arr[~(np.isfinite(arr) & (arr >= 0) & (arr <= 1))][0].item()
            raise ValueError(f"table entries must lie in [0, 1], got {bad!r}")
        ranges = [interval("value_range", value_range), interval("gradient_range", gradient_range)]
        if ranges[1][0] < 0:
            raise ValueError(f"gradient_range must start at 0 or above (a magnitude), got {gradient_range!r}")
        arr.setflags(write=False)
        self.table = arr
        self.value_range, self.gradient_range = ranges
        self.unit_distance = _finite_number("unit_distance", unit_distance, positive=True)
        self.envelope = self._envelope()

    @property
    def values(self):
        """The table's column positions (data values)."""
        return np.linspace(*self.value_range, self.table.shape[1])

    @property
    def gradients(self):
        """The table's row positions (gradient magnitudes)."""
        return np.linspace(*self.gradient_range, self.table.shape[0])

    def _envelope(self):
        alpha = self.table[:, :, 3]
        top = np.argmax(alpha, axis=0)
        cols = np.arange(alpha.shape[1])
        peak = np.minimum(alpha[top, cols], np.nextafter(1.0, 0.0))    # never opaque: it only bounds
        v = self.values
        color = np.column_stack([v, self.table[top, cols, :3]])
        return TransferFunction(color, np.column_stack([v, peak]), self.unit_distance)

    def _weights(self, s, g):
        """Bilinear cells and weights of (value, gradient magnitude) points."""
        out = []
        for x, (lo, hi), n in ((s, self.value_range, self.table.shape[1]), (g, self.gradient_range, self.table.shape[0])):
            u = np.clip((np.asarray(x, np.float64) - lo) * ((n - 1) / (hi - lo)), 0.0, n - 1)
            i0 = np.minimum(np.floor(u).astype(np.int64), n - 2)
            out += [i0, u - i0]
        return out

    def lookup(self, s, g):
        """(rgba, transparency 1 - alpha) at values s and gradient magnitudes g (GLSL
        ``lookupTF2D``): the table's bilinear interpolant, float64."""
        j, fx, i, fy = self._weights(s, g)
        t = self.table
        fx, fy = fx[..., None], fy[..., None]
        rgba = ((t[i, j] * (1 - fx) + t[i, j + 1] * fx) * (1 - fy)
                + (t[i + 1, j] * (1 - fx) + t[i + 1, j + 1] * fx) * fy)
        return rgba, 1.0 - rgba[..., 3]

    def texture_rows(self):
        """(2 n_gradient, n_value, 4) float32 for the shader: the table, then 1 - alpha in
        the red channel of as many rows (precise near opacity 1)."""
        n_g, n_v, _ = self.table.shape
        out = np.zeros((2 * n_g, n_v, 4), np.float32)
        out[:n_g] = self.table
        out[n_g:, :, 0] = 1.0 - self.table[:, :, 3]
        return out

    def key(self):
        return ("2d", self.table.tobytes(), self.value_range, self.gradient_range, self.unit_distance)

    def __repr__(self):
        n_g, n_v, _ = self.table.shape
        return (f"TransferFunction2D({n_v} values in {self.value_range}, {n_g} gradient magnitudes in "
                f"{self.gradient_range}, unit_distance={self.unit_distance})")
