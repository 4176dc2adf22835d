"""Transfer-function tables and presets.

The GL path classifies through a lookup table (LUT): the piecewise-linear transfer
function sampled at ``LUT_SIZE`` evenly spaced data values between its first and last
control point, and interpolated linearly between entries *in the shader's own arithmetic*
(two ``texelFetch`` and a ``mix``, not the texture unit's filter, whose weight precision
is the rasteriser's business). The NumPy twin is :func:`lookup`. The LUT differs from the
exact function only inside the LUT cells that contain an interior control point; its
error is reported by :func:`lut_max_error`.
"""

from __future__ import annotations

import json
import os

import numpy as np

from .scene import TetMesh, TransferFunction

LUT_SIZE = 4096


class LookupTable:
    """RGBA (colour, opacity) samples of a transfer function, float32, with the mapping
    from data values to table index: ``u = (s - lo) * scale``, clamped to [0, n-1].

    ``transparency`` holds ``1 - alpha`` per entry, computed in float64 before rounding:
    near alpha = 1 it keeps the relative precision that a float32 alpha has lost, and
    interpolating it linearly is the same as interpolating alpha."""

    def __init__(self, tf: TransferFunction, size: int = LUT_SIZE):
        knots = tf.knots
        lo, hi = float(knots[0]), float(knots[-1])
        if hi <= lo:  # a single control point: the function is constant
            lo, hi = lo - 0.5, lo + 0.5
        s = np.linspace(lo, hi, size)
        table = np.empty((size, 4), dtype=np.float64)
        table[:, :3] = tf.color(s)
        table[:, 3] = tf.opacity(s)
        self.lo = lo
        self.hi = hi
        self.size = size
        self.scale = (size - 1) / (hi - lo)
        self.table = table.astype(np.float32)
        self.transparency = (1.0 - table[:, 3]).astype(np.float32)

    def _interpolate(self, rows, s):
        """Twin of GLSL ``lookupTFRow``: linear between entries, float64 arithmetic."""
        u = np.clip((np.asarray(s, dtype=np.float64) - self.lo) * self.scale, 0.0, self.size - 1)
        i0 = np.minimum(np.floor(u).astype(np.int64), self.size - 2)
        f = (u - i0).reshape(u.shape + (1,) * (rows.ndim - 1))
        t = rows.astype(np.float64)
        return t[i0] * (1 - f) + t[i0 + 1] * f

    def lookup(self, s):
        """RGBA at data values ``s`` (float64 arithmetic on the float32 table)."""
        return self._interpolate(self.table, s)

    def lookup_transparency(self, s):
        """1 - alpha at data values ``s``, from the transparency row."""
        return self._interpolate(self.transparency, s)

    def texture_rows(self):
        """(2, n, 4) float32: row 0 RGBA, row 1 transparency in its first channel."""
        rows = np.zeros((2, self.size, 4), np.float32)
        rows[0] = self.table
        rows[1, :, 0] = self.transparency
        return rows

    def max_opacity_between(self, smin, smax):
        """Largest LUT opacity over each value interval [smin, smax] (arrays): the
        interpolated end points and every table entry strictly inside."""
        a = self.table[:, 3].astype(np.float64)
        ends = np.maximum(self.lookup(smin)[..., 3], self.lookup(smax)[..., 3])
        u0 = np.clip((np.asarray(smin, np.float64) - self.lo) * self.scale, 0, self.size - 1)
        u1 = np.clip((np.asarray(smax, np.float64) - self.lo) * self.scale, 0, self.size - 1)
        i0 = np.ceil(u0).astype(np.int64)
        i1 = np.floor(u1).astype(np.int64)
        # running maximum over table ranges via a sparse table would be faster; the
        # number of bricks is small, so a prefix over sorted entries is enough here.
        out = ends.copy()
        flat_i0, flat_i1, flat_out = i0.ravel(), i1.ravel(), out.ravel()
        for k in np.nonzero(flat_i1 >= flat_i0)[0]:
            flat_out[k] = max(flat_out[k], a[flat_i0[k]:flat_i1[k] + 1].max())
        return flat_out.reshape(out.shape)


def lut_max_error(tf: TransferFunction, size: int = LUT_SIZE, samples: int = 200001):
    """Largest absolute difference between the LUT and the exact transfer function."""
    lut = LookupTable(tf, size)
    s = np.linspace(lut.lo, lut.hi, samples)
    exact = np.concatenate([tf.color(s), tf.opacity(s)[:, None]], axis=1)
    return float(np.abs(lut.lookup(s) - exact).max())


def auto_preset(volume, unit_distance=None) -> TransferFunction:
    """Greyscale ramp whose opacity rises from 0 to 0.5 over the data's 1st to 99th
    percentile; unit distance one voxel (the smallest spacing) unless given. For a
    TetMesh the percentiles are over its point scalars and the unit distance is one
    cell (``mesh.cell_size``, the median edge length)."""
    if isinstance(volume, TetMesh):
        values = volume.scalars
        default_unit = volume.cell_size
    else:
        values = volume.data[np.isfinite(volume.data)] if volume.has_nonfinite else volume.data
        default_unit = volume.min_spacing
    lo, hi = (float(v) for v in np.percentile(values, [1, 99]))
    if hi <= lo:
        lo, hi = volume.data_range
        if hi <= lo:
            hi = lo + 1.0
    return TransferFunction(color=[(lo, 0.0, 0.0, 0.0), (hi, 1.0, 1.0, 1.0)],
                            opacity=[(lo, 0.0), (hi, 0.5)],
                            unit_distance=unit_distance or default_unit)


def load_tf_json(path) -> TransferFunction:
    """Read ``{"color": [[s, r, g, b], ...], "opacity": [[s, a], ...], "unit_distance": u}``."""
    with open(path) as f:
        try:
            spec = json.load(f)
        except json.JSONDecodeError as e:
            raise ValueError(f"transfer function file {os.fspath(path)!r} is not valid JSON: {e}") from None
    if not isinstance(spec, dict):
        raise ValueError(f"transfer function file {os.fspath(path)!r} must hold a JSON object, got {type(spec).__name__}")
    missing = {"color", "opacity"} - spec.keys()
    if missing:
        raise ValueError(f"transfer function file {os.fspath(path)!r} lacks {sorted(missing)}")
    unknown = spec.keys() - {"color", "opacity", "unit_distance"}
    if unknown:
        raise ValueError(f"transfer function file {os.fspath(path)!r} has unknown keys {sorted(unknown)}")
    return TransferFunction(spec["color"], spec["opacity"], spec.get("unit_distance", 1.0))


def save_tf_json(path, tf: TransferFunction):
    """Write ``tf`` as the JSON :func:`load_tf_json` reads (and ``dvr-gl render --tf
    FILE``), one control point per line. Numbers are written with Python's shortest
    round-tripping ``repr``, so loading the file gives back exactly the same function.
    The write is atomic (:func:`dvr_gl.io.atomic_write`). Returns ``path``."""
    from .io import atomic_write

    if not isinstance(tf, TransferFunction):
        raise TypeError(f"tf must be a dvr_gl.TransferFunction, got {type(tf).__name__}")
    spec = tf.to_dict()

    def rows(points):
        return ",\n".join("    " + json.dumps([float(v) for v in row]) for row in points)

    text = ("{\n"
            f'  "color": [\n{rows(spec["color"])}\n  ],\n'
            f'  "opacity": [\n{rows(spec["opacity"])}\n  ],\n'
            f'  "unit_distance": {json.dumps(float(spec["unit_distance"]))}\n'
            "}\n")
    atomic_write(os.fspath(path), text.encode("utf-8"))
    return path
