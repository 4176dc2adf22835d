"""Pre-integrated classification: a 2-D table of ray segments (NumPy twin of
``shaders/common/preintegration.glsl``).

A ray segment ``length`` world units long along which the scalar goes linearly from
``s_front`` (the end nearest the eye) to ``s_back`` has, under the emission-absorption
model of the contract (conventions, sections 3 and 4), the exact result

    D = mean of tau(s) over s between s_front and s_back      (tau(s_front) if equal)
    A = 1 - exp(-length * D)
    C = integral_0^1 c(s(x)) tau(s(x)) length exp(-length integral_0^x tau(s(y)) dy) dx

with ``tau = -ln(1 - alpha) / unit_distance`` and ``s(x) = s_front + x (s_back - s_front)``.
The table holds, at every pair of nodes ``s_i = lo + i (hi - lo) / (size - 1)``, the mean
extinction ``D`` and the colour per unit opacity ``K = C / A`` of a segment of the nominal
length ``L0`` given to :func:`build_table`. A fragment interpolates (K, D) bilinearly.

The length correction
---------------------
``D`` does not depend on the length, so ``A(L) = 1 - exp(-L D)`` is exact for every length.
The colour does: a longer segment hides more of its far part behind its near part. The
table keeps ``K(L0)`` and, made once per TF for every length, ``K0``: the colour per unit
opacity as the length goes to 0 (the extinction-weighted mean colour). A segment of length
``L`` takes ``K = K0 + (K(L0) - K0) w`` with ``w = g(L D) / g(L0 D)``, ``g(x) = 1/x - 1/(e^x -
1) - 1/2`` (:func:`length_weight`): exact when the extinction is constant over the segment
and the colour linear along it, for any length. Measured by :func:`length_correction_error`
(largest absolute colour error, premultiplied, any channel, over all pairs of nodes of a
256-node table on [0, 1]; before the correction, ``K(L0)`` at every length, in brackets):

    L / L0                               0.1             0.5             0.9             1.5             2
    smooth ramp,  L0 = unit distance   5.9e-6 (3.2e-3) 7.0e-5 (7.4e-3) 3.9e-5 (2.2e-3) 4.4e-4 (1.5e-2) 1.3e-3 (3.3e-2)
    narrow spike, L0 = unit distance   7.5e-5 (8.4e-3) 7.5e-4 (1.8e-2) 3.6e-4 (5.0e-3) 3.4e-3 (3.0e-2) 9.1e-3 (6.3e-2)
    smooth ramp,  L0 = unit / 4        9.5e-8 (2.1e-4) 1.3e-6 (5.5e-4) 7.8e-7 (1.9e-4) 1.0e-5 (1.5e-3) 3.5e-5 (3.7e-3)
    narrow spike, L0 = unit / 4        1.3e-6 (5.5e-4) 1.6e-5 (1.4e-3) 9.6e-6 (4.8e-4) 1.2e-4 (3.6e-3) 3.8e-4 (8.8e-3)

The ramp is grey 0 -> 1 with opacity 0 -> 0.8 over the range; the spike is 0.005 wide
(1/200 of the range), opacity 0 -> 0.95 -> 0, red before its peak and blue after it.
Opaque entries (a segment reaching opacity 1) keep ``K(L0)``: their colour is exact at the
nominal length only.

The table's values
------------------
The nodes span the values with opacity (:func:`opacity_support`): where the TF is
transparent below or above some knot, nodes there would only ever read zero. A segment
reaching beyond such a cut end is empty there; its part within goes from the edge to its
other end (the field is linear along it) over its share of the length, which the length
correction takes (``PreintegrationTable.segment``, GLSL ``preintegratedSegmentIn``). At
an end that is not cut (the TF has opacity there: it is the data's extreme or a knot),
a value rounded beyond it reads the end's entry. A
spike 1 % of the data range wide thus gets all the nodes instead of 5 of 512. A TF that
reaches opacity 1 keeps nodes over the whole data range (its opaque entries do not follow
the correction).

The convention for alpha = 1 (contract, section 3: tau = inf, the ray ends there): a
segment whose closed value interval contains a value with alpha = 1, at a single point or
over a plateau, is opaque: ``A = 1`` and ``D`` is infinite (stored as ``OPAQUE_SENTINEL``);
its colour is that of the emission in front of the first such value plus the remaining
transmittance times the colour there, as in ``reference.exact``.

Algorithm of :func:`build_table`
--------------------------------
The value axis is cut into *atoms*: between consecutive table nodes, transfer-function
knots, and, where alpha nears 1 inside a piece, points at which ``1 - alpha`` halves (so
that ``-ln(1 - alpha)`` is smooth on every atom at the scale of the atom). On an atom
alpha and colour are linear, and its optical depth has a closed form (the mean of
``-ln b`` over an interval of a linear ``b``, evaluated without cancellation). A segment
from node i to node j = i + n crosses n cells at the rate ``k = L0 / (u n h)`` optical
depth per unit of the integral of ``-ln(1 - alpha)``, so every cell contributes the same
(colour, opacity) to every segment of the same n and direction. For each n (and each
direction) the cell's exact (C, A) comes from its atoms: ``C = c(start) A + c'
integral (T(s) - T(end)) ds`` (integration by parts, c' constant on an atom), the integral
by 8-point Gauss-Legendre on sub-intervals carrying at most 3 units of optical depth
(parts more than 50 units deep from both ends of an atom are dropped: e^-50 ~ 2e-22);
then all windows of n cells are composited with the over operator by doubling (blocks of
1, 2, 4, ... cells), which is O(size log size) per n and O(size^2 log size) in all. An
atom's colour is ``c(start) A`` plus a term of the order of A (``T(s) - T(end)`` is
computed as ``T(s) (-expm1(...))``, never as a difference of two numbers near 1), and
compositing adds non-negative terms, so ``K = C / A`` keeps its accuracy where the opacity
is tiny. ``D`` at the nodes is the sum of the closed-form cell integrals over the window
(positive terms: no cancellation).

Accuracy and cost
-----------------
Against :func:`exact_segment` (nested adaptive quadrature, no shared code), the float64
values at the nodes (``table64``) agree to about 1e-14 in colour and opacity, and K to
1e-14 where A > 1e-6 (tests: smooth ramp, narrow spike with a colour jump, alpha = 1
plateau and point, alpha within 1e-12 of 1, alpha = 0 regions, both directions, constant
segments, lengths of 0.5 and 20 unit distances; a 256-knot random function agrees to
1e-13). The float32 table adds its rounding (relative 6e-8). Between the nodes the
bilinear interpolation of (K, D) is the table's main error: on random segments of length
L0 = u, about 1e-6 for the ramp above and 1e-2 for the spike when it is 2.5 cells wide
(its share of 512 nodes spread over the whole range; 2e-3 with 1024 nodes): the reason the
nodes now span only the values with opacity, where the spike has them all.

Build time on two cores (NumPy, single thread): 0.15-0.3 s for 512 nodes, 0.05-0.1 s for
256, 0.55-0.9 s for 1024, for transfer functions of 2 to 256 knots (once more, per TF, for
the zero-length colour); it grows with
``L0 / unit_distance`` only where alpha is close to 1 (0.2-0.4 s at 512 with L0 = 50 u).
"""

from __future__ import annotations

import bisect
import math
import warnings
from numbers import Integral, Real

import numpy as np

from .transfer_function import TransferFunction

# 512 nodes: a cell is 1/511 of the value range, fine enough that the bilinear error of a
# narrow feature is confined to a couple of cells, and the table (4 MiB of RGBA32F) builds
# in 0.15-0.3 s here; 1024 takes three to four times as long (and 16 MiB) for half the
# cell size, which matters only for features narrower than a few cells.
TABLE_SIZE = 512
OPAQUE_SENTINEL = 1e30        # D of a segment that meets alpha = 1 (float32 holds it)

_GL_X, _GL_W = np.polynomial.legendre.leggauss(8)
_OD_PER_PART = 3.0            # optical depth carried by one Gauss-Legendre sub-interval
_OD_NEGLIGIBLE = 50.0         # beyond this depth a transmittance (e^-50) is negligible
_GRADE_STEPS = 60             # halvings of 1 - alpha towards a knot where alpha = 1


# --------------------------------------------------------------------------- validation
def _positive_length(name, value):
    if isinstance(value, bool) or not isinstance(value, Real):
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    v = float(value)
    if not math.isfinite(v) or v <= 0:
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return v


def _table_size(size):
    if isinstance(size, bool) or not isinstance(size, Integral) or size < 2:
        raise ValueError(f"size must be an integer >= 2, got {size!r}")
    return int(size)


def _value_range(value_range):
    try:
        a, b = (float(v) for v in value_range)
    except (TypeError, ValueError):
        raise ValueError(f"value_range must be two numbers (low, high), got {value_range!r}") from None
    if not (math.isfinite(a) and math.isfinite(b)):
        raise ValueError(f"value_range must be finite, got {value_range!r}")
    if a > b:
        raise ValueError(f"value_range must be (low, high) with low <= high, got {value_range!r}")
    return a, b


def _check_tf(tf):
    if not isinstance(tf, TransferFunction):
        raise TypeError(f"tf must be a dvr_gl.TransferFunction, got {type(tf).__name__}")


# ------------------------------------------------------------- closed-form optical depth
def _excess_mean(e):
    """mean of -ln(y) over y in [1 - e, 1], for e in [0, 1]: 1 + (1 - e) ln(1 - e) / e.

    Its series is sum_k e^k / (k (k + 1)); it is used below e = 0.1 (16 terms leave a
    relative error below 1e-17), where the closed form would cancel."""
    e = np.clip(np.asarray(e, dtype=np.float64), 0.0, 1.0)
    out = np.empty_like(e)
    small = e < 0.1
    es = e[small]
    acc = np.zeros_like(es)
    for k in range(16, 0, -1):
        acc = es * (1.0 / (k * (k + 1)) + acc)
    out[small] = acc
    eb = e[~small]
    with np.errstate(divide="ignore", invalid="ignore"):
        big = 1.0 + (1.0 - eb) * np.log1p(-eb) / eb
    out[~small] = np.where(eb >= 1.0, 1.0, big)
    return out


class _Pieces:
    """The transfer function cut at every knot (and at ``lo``, ``hi``): on each piece,
    colour and opacity are linear. Opacity at a point is evaluated from the piece end
    with the smaller alpha and transparency ``b = 1 - alpha`` from the end with the
    smaller ``b``, so both keep their relative precision (a sum of two non-negative
    terms)."""

    def __init__(self, tf, lo, hi):
        x = np.unique(np.concatenate([tf.knots, [lo, hi]]))
        x = x[(x >= lo) & (x <= hi)]
        if x.size < 2:
            x = np.array([lo, hi])
        self.x = x
        self.u = tf.unit_distance
        a = tf.opacity(x)
        c = tf.color(x)
        self.al, self.ar = a[:-1], a[1:]
        w = np.diff(x)
        self.slope = np.abs(self.ar - self.al) / w                 # |d alpha / ds|
        self.left_low = self.al <= self.ar                          # alpha grows to the right
        self.s_low = np.where(self.left_low, x[:-1], x[1:])         # end with the smaller alpha
        self.s_high = np.where(self.left_low, x[1:], x[:-1])
        self.a_low = np.minimum(self.al, self.ar)
        self.b_small = 1.0 - np.maximum(self.al, self.ar)           # exact for alpha >= 0.5
        self.cslope = np.diff(c, axis=0) / w[:, None]
        self.plateau = (self.al >= 1.0) & (self.ar >= 1.0)
        # cumulative integral of -ln(1 - alpha) over whole pieces; a plateau of alpha = 1
        # counts 0 here (segments that meet it are opaque by the knot count below)
        with np.errstate(invalid="ignore"):
            full = w * self.mean_neglog(np.arange(w.size), x[:-1], x[1:])
        self.cum = np.concatenate([[0.0], np.cumsum(np.where(self.plateau, 0.0, full))])
        opaque_knot = tf.opacity(x) >= 1.0
        self.opaque_count = np.concatenate([[0], np.cumsum(opaque_knot)])

    def piece(self, s):
        return np.clip(np.searchsorted(self.x, s, side="right") - 1, 0, self.x.size - 2)

    def alpha(self, j, s):
        return self.a_low[j] + self.slope[j] * np.abs(s - self.s_low[j])

    def transparency(self, j, s):
        return self.b_small[j] + self.slope[j] * np.abs(s - self.s_high[j])

    def mean_neglog(self, j, q1, q2):
        """Mean of -ln(1 - alpha(s)) over [q1, q2] (q1 <= q2, both in piece j), closed
        form: with b = 1 - alpha linear, b_max the larger end value and e = (b_max -
        b_min) / b_max, the mean is -ln(b_max) + _excess_mean(e). inf on a plateau of
        alpha = 1."""
        q1, q2 = np.broadcast_arrays(np.asarray(q1, np.float64), np.asarray(q2, np.float64))
        near_low = np.where(self.left_low[j], q1, q2)   # the end with the smaller alpha
        a_min = self.alpha(j, near_low)
        b_max = self.transparency(j, near_low)
        with np.errstate(divide="ignore", invalid="ignore"):
            e = self.slope[j] * (q2 - q1) / b_max
            base = np.where(a_min < 0.5, -np.log1p(-np.minimum(a_min, 0.5)), -np.log(b_max))
        out = base + _excess_mean(np.where(b_max > 0, e, 0.0))
        return np.where(b_max > 0, out, np.inf)


def mean_extinction(tf, s_front, s_back):
    """D(s_front, s_back): the mean of tau over the values between the two (either
    order), in closed form; tau(s_front) where they are equal; inf where the closed
    interval meets alpha = 1. Arrays broadcast; float64."""
    _check_tf(tf)
    sf, sb = np.broadcast_arrays(np.asarray(s_front, np.float64), np.asarray(s_back, np.float64))
    if not (np.all(np.isfinite(sf)) and np.all(np.isfinite(sb))):
        raise ValueError("s_front and s_back must be finite")
    q1, q2 = np.minimum(sf, sb), np.maximum(sf, sb)
    lo = min(float(q1.min(initial=0.0)), float(tf.knots[0])) - 1.0
    hi = max(float(q2.max(initial=0.0)), float(tf.knots[-1])) + 1.0
    P = _Pieces(tf, lo, hi)
    j1, j2 = P.piece(q1), P.piece(q2)
    with np.errstate(invalid="ignore", divide="ignore"):
        same = P.mean_neglog(j1, q1, np.where(j1 == j2, q2, q1))
        xa, xb = P.x[j1 + 1], P.x[j2]
        head = (xa - q1) * P.mean_neglog(j1, q1, np.minimum(xa, q2))
        tail = (q2 - xb) * P.mean_neglog(j2, np.maximum(xb, q1), q2)
        middle = P.cum[j2] - P.cum[np.minimum(j1 + 1, j2)]
        split = (head + middle + tail) / (q2 - q1)
        D = np.where(j1 == j2, same, split)
    # the contract's alpha = 1 rule: any such value on the closed interval is opaque
    knots_inside = P.opaque_count[j2 + 1] - P.opaque_count[j1 + 1]
    ends = (P.transparency(j1, q1) <= 0) | (P.transparency(j2, q2) <= 0)
    D = np.where((knots_inside > 0) | ends, np.inf, D)
    return D / P.u


# ------------------------------------------------------------------------ the table
class PreintegrationTable:
    """Pre-integrated (K, D) at every pair of nodes; see the module docstring.

    ``table[i_front, i_back]`` is (K_r, K_g, K_b, D) as float32, D = ``OPAQUE_SENTINEL``
    for opaque segments; ``table64`` holds the same in float64 before rounding.
    Nodes: ``s_i = lo + i (hi - lo) / (size - 1)``; ``scale = (size - 1) / (hi - lo)``."""

    def __init__(self, lo, hi, size, length, table64, tf=None, colour0_64=None, cut=(False, False)):
        self.lo = float(lo)
        self.hi = float(hi)
        # (below lo, above hi): the table stops where the TF turns transparent for good on
        # that side (values beyond are empty); else values beyond take the end's value
        self.cut = (bool(cut[0]), bool(cut[1]))
        self.size = int(size)
        self.length = float(length)
        self.scale = (self.size - 1) / (self.hi - self.lo)
        self.tf = tf
        table64 = np.asarray(table64, np.float64)
        table64.setflags(write=False)
        self.table64 = table64
        table = table64.astype(np.float32)
        table.setflags(write=False)
        self.table = table
        # K as the length goes to 0 (the extinction-weighted mean colour), for the length
        # correction; without it, K(L0) at every length
        colour0_64 = table64[..., :3] if colour0_64 is None else np.asarray(colour0_64, np.float64)
        colour0_64.setflags(write=False)
        self.colour0_64 = colour0_64
        self.colour0 = colour0_64.astype(np.float32)
        self.colour0.setflags(write=False)
        self._widened = None     # the float32 tables as float64, for interpolation

    @property
    def nodes(self):
        return np.linspace(self.lo, self.hi, self.size)

    def _corner(self, s):
        u = np.clip((np.asarray(s, dtype=np.float64) - self.lo) * self.scale, 0.0, self.size - 1)
        i0 = np.minimum(np.floor(u).astype(np.int64), self.size - 2)
        return i0, u - i0

    def interpolate(self, s_front, s_back):
        """Bilinear (K, D) at the value pairs, float64 arithmetic on the float32 table:
        along the back index first, then the front one (the shader's order)."""
        return self._interpolate(s_front, s_back)[..., :4]

    def _interpolate(self, s_front, s_back):
        """Bilinear (K, D, K0) at the value pairs, (..., 7)."""
        f0, wf = self._corner(s_front)
        b0, wb = self._corner(s_back)
        f0, wf, b0, wb = np.broadcast_arrays(f0, wf, b0, wb)
        if self._widened is None:
            self._widened = np.concatenate([self.table, np.pad(self.colour0, ((0, 0), (0, 0), (0, 1)))],
                                           axis=-1).astype(np.float64)
        t = self._widened
        wb_, wf_ = wb[..., None], wf[..., None]
        row0 = t[f0, b0] * (1.0 - wb_) + t[f0, b0 + 1] * wb_
        row1 = t[f0 + 1, b0] * (1.0 - wb_) + t[f0 + 1, b0 + 1] * wb_
        return row0 * (1.0 - wf_) + row1 * wf_

    def inside_fraction(self, s_front, s_back):
        """The fraction of a segment (the field linear along it) within the table's values
        where the table is cut (GLSL: the same in node units; 1 where no end is beyond a
        cut side; an end beyond an uncut side counts as the end's value)."""
        last = self.size - 1
        uf = (np.asarray(s_front, np.float64) - self.lo) * self.scale
        ub = (np.asarray(s_back, np.float64) - self.lo) * self.scale
        if not self.cut[0]:
            uf, ub = np.maximum(uf, 0.0), np.maximum(ub, 0.0)
        if not self.cut[1]:
            uf, ub = np.minimum(uf, last), np.minimum(ub, last)
        cf, cb = np.clip(uf, 0, last), np.clip(ub, 0, last)
        with np.errstate(divide="ignore", invalid="ignore"):
            part = np.clip(np.abs(cb - cf) / np.abs(ub - uf), 0.0, 1.0)
        return np.where((cf != uf) | (cb != ub), np.nan_to_num(part), 1.0)

    def segment(self, s_front, s_back, length):
        """Premultiplied (C, A) of segments, (..., 4) float64: the twin of GLSL
        ``preintegratedSegment``. ``A = -expm1(-length D)`` (1 where length D > 88, as in
        the shader), ``C = K A``. The table holds every value with opacity (``build_table``):
        a segment reaching beyond it is empty there, so it counts with the length of its
        part within, the field being linear along it."""
        length = np.asarray(length, dtype=np.float64)
        bad = ~(np.isfinite(length) & (length >= 0))
        if bad.any():
            raise ValueError(f"length must be finite and >= 0, got {length[bad].ravel()[0]!r}")
        length = length * self.inside_fraction(s_front, s_back)
        both = self._interpolate(s_front, s_back)
        v, k0 = both[..., :4], both[..., 4:7]
        v, length = np.broadcast_arrays(v, length[..., None])
        k0 = np.broadcast_to(k0, v[..., :3].shape)
        od = length[..., 0] * v[..., 3]
        with np.errstate(over="ignore"):
            A = np.where(od > 88.0, 1.0, -np.expm1(-np.minimum(od, 88.0)))
        w = length_weight(v[..., 3] * length[..., 0], v[..., 3] * self.length)
        out = np.empty(v.shape, np.float64)
        out[..., :3] = (k0 + (v[..., :3] - k0) * w[..., None]) * A[..., None]
        out[..., 3] = A
        return out

    def texture_rows(self):
        """(2 size, size, 4) float32 rows of an RGBA32F texture: (K, D) at
        ``ivec2(i_back, i_front)``, then the zero-length colour (K0, 0) at
        ``ivec2(i_back, size + i_front)``."""
        zero = np.zeros(self.table.shape, np.float32)
        zero[..., :3] = self.colour0
        return np.concatenate([self.table, zero])

    def texture_bytes(self):
        """Bytes of ``texture_rows``: a (size, 2 size) RGBA32F texture, x (width) the back
        index, y (height) the front index."""
        return np.ascontiguousarray(self.texture_rows()).tobytes()

    def uniforms(self):
        """The shader's uniforms for this table (the sampler ``t_preint`` aside)."""
        return {"u_pi_lo": self.lo, "u_pi_scale": self.scale, "u_pi_size": self.size, "u_pi_length": self.length,
                "u_pi_cut": tuple(float(c) for c in self.cut)}

    def __repr__(self):
        return (f"PreintegrationTable(size={self.size}, lo={self.lo}, hi={self.hi}, "
                f"length={self.length})")


def _over(front, back):
    """The over operator on stacked (C_r, C_g, C_b, A) rows."""
    return front + (1.0 - front[:, 3:4]) * back


def _windows(cells, n, forward):
    """Composite of every run of n consecutive cells, front to back: forward runs go up
    the value axis (cell i first), backward ones down (cell i + n - 1 first). Row i of
    the result is the run that starts at cell i. Doubling: blocks of 2^p cells."""
    count = cells.shape[0] - n + 1
    blocks = [cells]
    width = 1
    while 2 * width <= n:
        b = blocks[-1]
        blocks.append(_over(b[:-width], b[width:]) if forward else _over(b[width:], b[:-width]))
        width *= 2
    result = None
    offset = 0 if forward else n
    for p in range(len(blocks) - 1, -1, -1):
        if not n & (1 << p):
            continue
        if not forward:
            offset -= 1 << p
        blk = blocks[p][offset:offset + count]
        result = blk if result is None else _over(result, blk)
        if forward:
            offset += 1 << p
    return result


def _atoms(P, nodes):
    """Breakpoints: nodes, knots, and points where 1 - alpha halves towards a small end."""
    pts = [nodes, P.x]
    j = np.flatnonzero((P.b_small < 0.5 * (1.0 - P.a_low)) & ~P.plateau)
    if j.size:
        b_big = 1.0 - P.a_low[j]
        m = np.arange(1, _GRADE_STEPS + 1)
        b_at = b_big[:, None] * 0.5 ** m[None, :]                      # (pieces, steps)
        keep = b_at > P.b_small[j][:, None]
        dist = (b_at - P.b_small[j][:, None]) / P.slope[j][:, None]
        sign = np.where(P.left_low[j], -1.0, 1.0)[:, None]             # from the high end
        g = P.s_high[j][:, None] + sign * dist
        pts.append(g[keep])
    x = np.unique(np.concatenate(pts))
    return x[(x >= nodes[0]) & (x <= nodes[-1])]


def _mean_offset(x):
    """g(x) = 1/x - 1/(e^x - 1) - 1/2: the mean position in [0, 1] under the density
    e^(-x t), less 1/2 (series below x = 0.5; -1/2 for x = inf)."""
    x = np.asarray(x, np.float64)
    small = x < 0.5
    xs = np.where(small, x, 0.0)
    series = -xs / 12 * (1 - xs * xs / 60 * (1 - xs * xs / 42))
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        xb = np.where(small, 1.0, x)
        direct = 1 / xb - 1 / np.expm1(xb) - 0.5
    return np.where(small, series, np.where(np.isinf(x), -0.5, direct))


def length_weight(depth, nominal_depth):
    """The weight w of the length correction ``K(L) = K0 + (K(L0) - K0) w`` for a segment of
    optical depth ``depth`` whose table entry was made at ``nominal_depth``:
    ``g(depth) / g(nominal_depth)``, exact when the extinction is constant over the
    segment and the colour linear along it (1 where the nominal depth is 0)."""
    depth, nominal_depth = np.broadcast_arrays(np.asarray(depth, np.float64), np.asarray(nominal_depth, np.float64))
    gn = _mean_offset(nominal_depth)
    with np.errstate(divide="ignore", invalid="ignore"):
        w = _mean_offset(depth) / np.where(gn != 0, gn, 1.0)
    return np.where(gn != 0, w, 1.0)


def opacity_support(tf, lo, hi):
    """The smallest [a, b] within [lo, hi] outside which ``tf``'s opacity is zero ([lo,
    hi] itself when the TF has no opacity at all, or reaches opacity 1: an opaque
    segment's colour depends on its length in a way the length correction does not
    follow, and a segment cut short at the table's edge would need it)."""
    knots = tf.knots
    alpha = tf.opacity(knots)
    seen = alpha > 0
    if not seen.any() or alpha.max() >= 1.0:
        return lo, hi
    first = int(np.argmax(seen))
    last = knots.size - 1 - int(np.argmax(seen[::-1]))
    a = lo if first == 0 else max(lo, float(knots[first - 1]))
    b = hi if last == knots.size - 1 else min(hi, float(knots[last + 1]))
    return (a, b) if a < b else (lo, hi)


ZERO_LENGTH = 1e-6     # the zero-length colour's table is made at this fraction of the length


def build_table(tf, value_range, length, size=TABLE_SIZE, zero=None) -> PreintegrationTable:
    """The pre-integration table of ``tf`` for segments of nominal ``length`` (world
    units), over the values with opacity (``opacity_support``) within ``min(value_range[0],
    first knot)`` to ``max(value_range[1], last knot)``: its nodes spend no resolution
    on values that are transparent anyway (a spike 1 % of the data range wide gets all
    of them), and a segment reaching beyond them is empty there
    (``PreintegrationTable.segment``); see the module docstring for the method and its
    accuracy."""
    _check_tf(tf)
    lo, hi = _value_range(value_range)
    L = _positive_length("length", length)
    N = _table_size(size)
    lo = min(lo, float(tf.knots[0]))
    hi = max(hi, float(tf.knots[-1]))
    full = (lo, hi)
    lo, hi = opacity_support(tf, lo, hi)
    cut = (lo > full[0], hi < full[1])
    if hi <= lo:  # one value only: any width will do, the function is constant near it
        lo, hi = lo - 0.5, lo + 0.5
    nodes = np.linspace(lo, hi, N)
    h = (hi - lo) / (N - 1)
    u = tf.unit_distance
    P = _Pieces(tf, lo, hi)

    # -- atoms: pieces of cells on which alpha, colour are linear and -ln(1-alpha) smooth
    x = _atoms(P, nodes)
    x0, x1 = x[:-1], x[1:]
    na = x0.size
    mid = 0.5 * (x0 + x1)
    jp = P.piece(mid)
    cell = np.clip(np.searchsorted(nodes, mid, side="right") - 1, 0, N - 2)
    with np.errstate(invalid="ignore"):
        dF = (x1 - x0) * P.mean_neglog(jp, x0, x1)       # integral of -ln(1 - alpha)
    b0, b1 = P.transparency(jp, x0), P.transparency(jp, x1)
    op_start = (b0 <= 0) | P.plateau[jp]
    op_end = (b1 <= 0) | P.plateau[jp]
    op_any = op_start | op_end
    dF = np.where(op_any, np.inf, dF)
    c0, c1 = tf.color(x0), tf.color(x1)
    cs = P.cslope[jp]
    busy = (dF > 0) & ~P.plateau[jp]                      # atoms that need quadrature

    # within-cell exclusive depth in front of each atom (forward) and behind it (backward)
    cell_first = np.searchsorted(cell, np.arange(N - 1), side="left")
    cell_last = np.searchsorted(cell, np.arange(N - 1), side="right") - 1
    rank_f = np.arange(na) - cell_first[cell]
    rank_b = cell_last[cell] - np.arange(na)
    pex_f = np.zeros(na)
    pex_b = np.zeros(na)
    for r in range(1, int(rank_f.max()) + 1):
        i = np.flatnonzero(rank_f == r)
        pex_f[i] = pex_f[i - 1] + dF[i - 1]
    for r in range(1, int(rank_b.max()) + 1):
        i = np.flatnonzero(rank_b == r)
        pex_b[i] = pex_b[i + 1] + dF[i + 1]
    dF_cell = pex_f[cell_last] + dF[cell_last]
    cell_opaque = ~np.isfinite(dF_cell)

    # -- quadrature nodes per level p (segments of n in [2^p, 2^(p+1)) cells)
    b_min = np.minimum(b0, b1)
    with np.errstate(divide="ignore"):
        tau_max = np.where(b_min > 0, -np.log(np.where(b_min > 0, b_min, 1.0)), 0.0)
    ai = np.flatnonzero(busy)
    levels = []
    p = 0
    while (1 << p) <= N - 1:
        k_hi = L / (u * (1 << p) * h)
        k_lo = L / (u * min((2 << p) - 1, N - 1) * h)
        M = np.ceil(k_hi * (x1[ai] - x0[ai]) * tau_max[ai] / _OD_PER_PART)
        M = np.where(b_min[ai] > 0, np.maximum(M, 1), 1).astype(np.int64)
        sub_atom = np.repeat(ai, M)
        first = np.repeat(np.cumsum(M) - M, M)
        t = np.arange(sub_atom.size) - first
        Ms = M.repeat(M)
        wa = x1[sub_atom] - x0[sub_atom]
        ja = jp[sub_atom]
        lo_s = x0[sub_atom] + wa * (t / Ms)
        hi_s = np.where(t + 1 == Ms, x1[sub_atom], x0[sub_atom] + wa * ((t + 1) / Ms))
        with np.errstate(invalid="ignore"):
            p_start = (lo_s - x0[sub_atom]) * P.mean_neglog(ja, x0[sub_atom], lo_s)
            r_end = (x1[sub_atom] - hi_s) * P.mean_neglog(ja, hi_s, x1[sub_atom])
        need_f = ~op_start[sub_atom] & (k_lo * p_start < _OD_NEGLIGIBLE)
        need_b = ~op_end[sub_atom] & (k_lo * r_end < _OD_NEGLIGIBLE)
        keep = need_f | need_b
        sub_atom, lo_s, hi_s, ja = sub_atom[keep], lo_s[keep], hi_s[keep], ja[keep]
        half = 0.5 * (hi_s - lo_s)
        sq = (0.5 * (lo_s + hi_s))[:, None] + half[:, None] * _GL_X[None, :]
        wq = (half[:, None] * _GL_W[None, :]).ravel()
        sq = sq.ravel()
        aq = np.repeat(sub_atom, _GL_X.size)
        ja = np.repeat(ja, _GL_X.size)
        with np.errstate(invalid="ignore", divide="ignore"):
            Pq = (sq - x0[aq]) * P.mean_neglog(ja, x0[aq], sq)
            Rq = (x1[aq] - sq) * P.mean_neglog(ja, sq, x1[aq])
        levels.append(dict(
            aq=aq, wq=wq, Pq=Pq, Rq=Rq,
            Rf=np.where(op_end[aq], np.inf, Rq),       # forward: the atom ends opaque
            Pb=np.where(op_start[aq], np.inf, Pq)))    # backward: ends at its start
        p += 1

    # -- all segments, one length n (cells) at a time
    K = np.zeros((N, N, 3))
    A = np.zeros((N, N))
    Dsum = np.zeros((N, N))
    cell_start = cell_first
    window_sum = None
    ar = np.arange(N)
    with np.errstate(over="ignore", invalid="ignore"):
        for n in range(1, N):
            q = levels[n.bit_length() - 1]
            k = L / (u * n * h)
            ef = q["wq"] * np.exp(-k * q["Pq"]) * -np.expm1(-k * q["Rf"])
            eb = q["wq"] * np.exp(-k * q["Rq"]) * -np.expm1(-k * q["Pb"])
            If = np.bincount(q["aq"], ef, minlength=na)
            Ib = np.bincount(q["aq"], eb, minlength=na)
            Aa = np.where(op_any, 1.0, -np.expm1(-k * dF))
            Cf = np.where(op_start[:, None], c0, c0 * Aa[:, None] + cs * If[:, None])
            Cb = np.where(op_end[:, None], c1, c1 * Aa[:, None] - cs * Ib[:, None])
            Ac = np.where(cell_opaque, 1.0, -np.expm1(-k * dF_cell))
            cf = np.empty((N - 1, 4))
            cb = np.empty((N - 1, 4))
            cf[:, :3] = np.add.reduceat(Cf * np.exp(-k * pex_f)[:, None], cell_start, axis=0)
            cb[:, :3] = np.add.reduceat(Cb * np.exp(-k * pex_b)[:, None], cell_start, axis=0)
            cf[:, 3] = Ac
            cb[:, 3] = Ac
            wf = _windows(cf, n, True)
            wb = _windows(cb, n, False)
            i = ar[:N - n]
            K[i, i + n] = wf[:, :3]
            A[i, i + n] = wf[:, 3]
            K[i + n, i] = wb[:, :3]
            A[i + n, i] = wb[:, 3]
            # D: windowed sums of cell integrals, built up one cell at a time
            window_sum = dF_cell.copy() if n == 1 else window_sum[:-1] + dF_cell[n - 1:]
            Dsum[i, i + n] = window_sum
            Dsum[i + n, i] = window_sum

    D = Dsum / (u * h * np.maximum(np.abs(ar[:, None] - ar[None, :]), 1))
    with np.errstate(invalid="ignore", divide="ignore"):
        K = K / A[..., None]
    with np.errstate(divide="ignore"):
        diag_tau = -np.log1p(-np.minimum(tf.opacity(nodes), 1.0)) / u
    D[ar, ar] = diag_tau
    K[ar, ar] = tf.color(nodes)
    A[ar, ar] = -np.expm1(-L * diag_tau)
    _fill_transparent(K, A, tf.color(nodes))
    table = np.empty((N, N, 4))
    table[..., :3] = K
    table[..., 3] = np.where(np.isfinite(D), D, OPAQUE_SENTINEL)
    if zero is False:               # this is the zero-length table itself
        return PreintegrationTable(lo, hi, N, L, table, tf, cut=cut)
    if zero is None:
        zero = build_table(tf, value_range, ZERO_LENGTH * L, size, zero=False)
    elif (zero.lo, zero.hi, zero.size) != (lo, hi, N):
        raise ValueError(f"zero must be a table of the same nodes ({lo}, {hi}, {N}), got "
                         f"({zero.lo}, {zero.hi}, {zero.size})")
    return PreintegrationTable(lo, hi, N, L, table, tf, colour0_64=zero.table64[..., :3], cut=cut)


def _fill_transparent(K, A, node_colors):
    """K = C / A means nothing where D = 0 (A = 0). Such entries only matter through the
    bilinear interpolation next to entries with D > 0, so they get the opacity-weighted
    mean of K over their 3 x 3 neighbours (the colour a sliver of their extinction would
    show), or the mean of the end colours when no neighbour is visible."""
    empty = ~(A > 0)
    np.fill_diagonal(empty, False)
    if not empty.any():
        return
    W = np.where(empty, 0.0, np.nan_to_num(A, nan=0.0))
    KW = np.where(empty[..., None], 0.0, np.nan_to_num(K, nan=0.0)) * W[..., None]
    Wp = np.pad(W, 1)
    KWp = np.pad(KW, ((1, 1), (1, 1), (0, 0)))
    n = W.shape[0]
    sw = sum(Wp[1 + di:1 + di + n, 1 + dj:1 + dj + n] for di in (-1, 0, 1) for dj in (-1, 0, 1))
    skw = sum(KWp[1 + di:1 + di + n, 1 + dj:1 + dj + n] for di in (-1, 0, 1) for dj in (-1, 0, 1))
    ends = 0.5 * (node_colors[:, None, :] + node_colors[None, :, :])
    with np.errstate(invalid="ignore", divide="ignore"):
        fill = np.where(sw[..., None] > 0, skw / sw[..., None], ends)
    K[empty] = fill[empty]


# --------------------------------------------------------------------------- the oracle
def exact_segment(tf, s_front, s_back, length) -> np.ndarray:
    """(C_r, C_g, C_b, A) of one segment, float64, by adaptive quadrature of the
    definition (scipy.integrate.quad, split at the knots; the optical depth inside the
    colour integrand is itself a quadrature). Shares no code with the table. A value
    with alpha = 1 on the closed segment ends the ray there (contract, section 3)."""
    from scipy import integrate

    _check_tf(tf)
    L = _positive_length("length", length)
    sf, sb = float(s_front), float(s_back)
    if not (math.isfinite(sf) and math.isfinite(sb)):
        raise ValueError(f"s_front and s_back must be finite, got {s_front!r}, {s_back!r}")
    u = tf.unit_distance
    op = tf.opacity_points
    cp = tf.color_points
    alpha_max = math.nextafter(1.0, 0.0)

    def alpha(s):
        return float(np.interp(s, op[:, 0], op[:, 1]))

    def color(s, ch):
        return float(np.interp(s, cp[:, 0], cp[:, 1 + ch]))

    def tau(s):  # inside an integration interval alpha < 1 except by rounding
        return -math.log1p(-min(alpha(s), alpha_max)) / u

    if sf == sb:
        a = alpha(sf)
        A = 1.0 if a >= 1.0 else -math.expm1(L * math.log1p(-a) / u)
        return np.array([color(sf, 0) * A, color(sf, 1) * A, color(sf, 2) * A, A])

    delta = sb - sf
    lo_s, hi_s = min(sf, sb), max(sf, sb)
    knots = [float(k) for k in tf.knots if lo_s < k < hi_s]
    stops = [(k - sf) / delta for k in knots if alpha(k) >= 1.0]
    if alpha(sf) >= 1.0:
        stops.append(0.0)
    if alpha(sb) >= 1.0:
        stops.append(1.0)
    x_stop = min(stops) if stops else None
    end = 1.0 if x_stop is None else x_stop
    # Break at the knots, and where alpha nears 1 at the end of an interval between
    # knots, at points 2^-m of its width from that end: tau's (near-)logarithmic
    # singularity is then resolved by the partition rather than by quad's extrapolation.
    edges = [lo_s] + knots + [hi_s]
    breaks = set()
    for ka, kb in zip(edges[:-1], edges[1:]):
        breaks.update(((ka - sf) / delta, (kb - sf) / delta))
        slope = abs(alpha(kb) - alpha(ka)) / (kb - ka)
        for kend, sign in ((ka, 1.0), (kb, -1.0)):
            reach = (1.0 - alpha(kend)) / slope if slope > 0 else math.inf  # to alpha = 1
            breaks.update((kend + sign * (kb - ka) * 0.5 ** m - sf) / delta
                          for m in range(1, 31) if (kb - ka) * 0.5 ** m > reach)
    breaks = sorted(x for x in breaks if 0.0 < x < end)
    breaks = [0.0] + breaks + [end]

    def g(x):
        return L * tau(sf + x * delta)

    opts = dict(epsabs=1e-15, epsrel=1e-13, limit=200)
    C = np.zeros(3)
    od = 0.0
    # On the last sliver before a value with alpha = 1 (1e-9 of the interval and less)
    # the data values no longer resolve the logarithm, and quad warns about roundoff
    # while reporting errors near 1e-15: those warnings are not news.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", integrate.IntegrationWarning)
        for xa, xb in zip(breaks[:-1], breaks[1:]):
            if xb <= xa:
                continue
            od_b = od + integrate.quad(g, xa, xb, **opts)[0]
            # optical depth at the colour integrand's points, integrated from the nearest
            # point already known (so each inner quadrature is short and smooth)
            known_x, known_d = [xa, xb], [od, od_b]
            memo = {}

            def depth(x, known_x=known_x, known_d=known_d, memo=memo):
                if x not in memo:
                    i = bisect.bisect_left(known_x, x)
                    if i == 0 or i == len(known_x):
                        j = min(i, len(known_x) - 1)
                    else:
                        j = i - 1 if x - known_x[i - 1] <= known_x[i] - x else i
                    d = known_d[j] + integrate.quad(g, known_x[j], x, **opts)[0]
                    memo[x] = d
                    known_x.insert(i, x)
                    known_d.insert(i, d)
                return memo[x]

            for ch in range(3):
                def emission(x, ch=ch):
                    return color(sf + x * delta, ch) * g(x) * math.exp(-depth(x))
                C[ch] += integrate.quad(emission, xa, xb, **opts)[0]
            od = od_b
    if x_stop is not None:
        T = math.exp(-od)
        s_stop = sf + x_stop * delta
        C += T * np.array([color(s_stop, ch) for ch in range(3)])
        A = 1.0
    else:
        A = -math.expm1(-od)
    return np.array([C[0], C[1], C[2], A])


# ---------------------------------------------------------------- the length correction
def length_correction_error(tf, value_range, length, ratios, size=TABLE_SIZE, corrected=True) -> dict:
    """Largest absolute colour error (premultiplied, any channel) of the colour at ``L =
    ratio * L0`` against the exact one, over all pairs of table nodes: the length
    correction ``K0 + (K(L0) - K0) w`` (``corrected=False``: ``K(L0)``) times ``A(L)``. The
    exact colour at L comes from a table built for L (exact at the nodes to ~1e-12,
    checked against :func:`exact_segment` by the tests); opaque entries are left out
    (their colour is exact only at L0). Returns {ratio: error}."""
    base = build_table(tf, value_range, length, size)
    D = base.table64[..., 3]
    finite = D < OPAQUE_SENTINEL
    out = {}
    for r in ratios:
        r = _positive_length("ratio", r)
        Lr = r * base.length
        ref = build_table(tf, value_range, Lr, size, zero=False)
        with np.errstate(over="ignore"):
            Ar = -np.expm1(-Lr * D)
        K = base.table64[..., :3]
        if corrected:
            K0 = base.colour0_64
            K = K0 + (K - K0) * length_weight(Lr * D, base.length * D)[..., None]
        err = np.abs((K - ref.table64[..., :3]) * Ar[..., None])
        out[r] = float(err[finite].max())
    return out
