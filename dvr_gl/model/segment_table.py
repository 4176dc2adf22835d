"""Table-integrated segments: an approximate, cheap integral of a segment along which the
field is linear (``tetra`` with ``sort="walk", segments="table"``; its GLSL is
``tableSegment`` in shaders/tetra/walk.frag, its NumPy twin :func:`table_segment`).

Once per transfer function, two rows of ``ENTRIES`` entries over the TF's knots:

- row 0, cumulative: the integral from the first knot to s of the extinction
  tau(s) = -ln(1 - alpha(s)) (per unit distance) and of c(s) tau(s), by the trapezoid
  rule on ``SUBSTEPS`` steps per entry, in float64, stored as float32;
- row 1, the point values (c(s), tau(s)) at each entry.

A segment ``length`` long with the field going linearly from s_front to s_back then has
optical depth ``length / unit * mean tau`` over [s_front, s_back] (the difference of
the cumulative row over s_back - s_front; the point value at the middle where the two lie
within one entry, below which the difference of float32 sums loses its digits), and
colour the tau-weighted mean colour times its opacity 1 - exp(-depth). The exact integral
(``reference.linear_segment``) also weighs each colour by what lies in front of it inside
the segment; this one does not, so its error grows with the segment's optical depth and
the change of colour along it: it is measured per scene by the mesh pilot
(``rendering.mesh_tolerance``), never assumed. Beyond the knots the TF is constant and
so is tau: the cumulative row goes on linearly. Opacity 1 is taken as ``1 - MIN_TRANSPARENCY``.
"""

from __future__ import annotations

import numpy as np

ENTRIES = 4096
SUBSTEPS = 16
MIN_TRANSPARENCY = 1e-7


class SegmentTable:
    """The two rows (float32, (2, ENTRIES, 4)) and the map from value to entry,
    ``u = (s - lo) * scale``; ``unit``: the TF's unit distance."""

    def __init__(self, tf, entries=ENTRIES):
        knots = np.asarray(tf.knots, np.float64)
        lo, hi = float(knots[0]), float(knots[-1])
        if hi <= lo:
            lo, hi = lo - 0.5, lo + 0.5
        n = int(entries)
        fine = np.linspace(lo, hi, (n - 1) * SUBSTEPS + 1)
        tau = -np.log(np.maximum(1.0 - tf.opacity(fine), MIN_TRANSPARENCY))
        emitted = tf.color(fine) * tau[:, None]
        h = (hi - lo) / ((n - 1) * SUBSTEPS)
        integrand = np.concatenate([emitted, tau[:, None]], axis=1)
        steps = 0.5 * h * (integrand[1:] + integrand[:-1])
        cumulative = np.concatenate([np.zeros((1, 4)), np.cumsum(steps, axis=0)])[::SUBSTEPS]
        rows = np.empty((2, n, 4), np.float64)
        rows[0] = cumulative
        rows[1, :, :3] = tf.color(fine[::SUBSTEPS])
        rows[1, :, 3] = tau[::SUBSTEPS]
        self.rows = rows.astype(np.float32)
        self.lo, self.hi, self.size = lo, hi, n
        self.scale = (n - 1) / (hi - lo)
        self.inv_unit = 1.0 / tf.unit_distance

    def texture_rows(self):
        return self.rows

    def _row_at(self, row, s):
        """Row ``row`` linear between entries at ``s`` (clamped), float64 on the float32 table."""
        u = np.clip((s - self.lo) * self.scale, 0.0, self.size - 1)
        i0 = np.minimum(np.floor(u).astype(np.int64), self.size - 2)
        f = (u - i0)[:, None]
        t = self.rows[row].astype(np.float64)
        return t[i0] * (1.0 - f) + t[i0 + 1] * f

    def cumulative(self, s):
        """Row 0 at ``s``, continued linearly beyond the ends by the end's point value."""
        s = np.asarray(s, np.float64)
        inside = self._row_at(0, s)
        clamped = np.clip(s, self.lo, self.hi)
        end = self.rows[1, np.where(s < self.lo, 0, self.size - 1)].astype(np.float64)
        return inside + (s - clamped)[:, None] * np.concatenate([end[:, :3] * end[:, 3:], end[:, 3:]], axis=1)


def table_segment(table, s_front, s_back, length):
    """(N, 4) float64 premultiplied RGBA of segments (NumPy twin of walk.frag's
    ``tableSegment``): the tau-weighted mean colour times 1 - exp(-depth)."""
    s_front = np.asarray(s_front, np.float64)
    s_back = np.asarray(s_back, np.float64)
    ds = s_back - s_front
    wide = np.abs(ds) * table.scale >= 1.0
    safe = np.where(wide, ds, 1.0)
    mean = (table.cumulative(s_back) - table.cumulative(s_front)) / safe[:, None]
    point = table._row_at(1, 0.5 * (s_front + s_back))
    tau = np.where(wide, mean[:, 3], point[:, 3])
    with np.errstate(invalid="ignore", divide="ignore"):
        color = np.where(wide[:, None], mean[:, :3] / np.where(mean[:, 3:] > 0, mean[:, 3:], 1.0), point[:, :3])
    depth = np.maximum(tau, 0.0) * np.asarray(length, np.float64) * table.inv_unit
    alpha = -np.expm1(-depth)
    return np.concatenate([color * alpha[:, None], alpha[:, None]], axis=1)
