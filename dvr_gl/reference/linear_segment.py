"""The emission-absorption integral of a ray segment along which the field is linear
(NumPy twin of ``shaders/common/linear_segment.glsl``; float64 here, float32 there).

This is how a cell of a tetrahedral mesh is classified: the ray's segment through the
cell runs from ``s_front`` to ``s_back`` over ``length`` world units. The segment is cut
at every transfer-function knot between the two values, so that on each *piece* opacity
and colour are linear in the distance t. On a piece ``l`` long, with transparency
``w = 1 - alpha`` going linearly from ``w_a`` to ``w_b``:

- optical depth, closed form: with ``w`` going from ``w_a`` to ``w_a (1 + r)``, the optical
  depth to fraction f of the piece is ``l/u * f * (-ln w_a - H(r f))``, where
  ``H(x) = (1 + x) ln(1 + x) / x - 1`` is the mean of ``ln(1 + x g)`` over g in [0, 1] (its
  series below |x| = 0.1, where the closed form would cancel); ``-ln w_a`` comes from
  ``log1p(-alpha_a)`` while alpha <= 0.5;
- colour, by parts (colour linear in t, ``T`` the transmittance from the piece's start):
  ``C = c_a (1 - T_l) + (c_b - c_a) * mean_t [T(t) - T_l]``, the mean by Gauss-Legendre
  on ``ceil(OD)`` equal parts (at most ``MAX_PARTS``), with 2, 3 or 4 points where the
  piece is thin and its opacity nearly constant (``node_count``) and 8 otherwise; each
  node's ``T(t) - T_l`` is ``T(t) * -expm1(-(OD - OD(t)))``, never a difference of two
  numbers near 1. Parts more than ``DEEP`` units of optical depth in are skipped (their
  weight is below e^-30). Towards an end where alpha reaches 1 (tau's log singularity)
  the parts halve in length instead (``GRADED_PARTS``). The shader evaluates the 2-point
  case with short series (truncations below 1e-12 there).

Pieces are composited front to back. alpha = 1 at a point ends the segment there with
A = 1, the remaining transmittance taking that point's colour (the contract's rule, as
``reference.exact`` applies it).

Accuracy (float64, against ``preintegration.exact_segment``'s nested adaptive quadrature):
below 2e-8 over random segments crossing knots either way, lengths from 0.01 to 6 unit
distances; 1e-15 where alpha reaches 1 inside a segment (tests/test_tetra.py).
"""

from __future__ import annotations

import numpy as np

from ..model.transfer import SegmentKnots
from .exact_one import _segmented_exclusive_sum

MAX_PARTS = 16
GRADED_PARTS = 24
DEEP = 30.0
# Gauss-Legendre rules on [0, 1], by number of points
GAUSS = {n: ((np.polynomial.legendre.leggauss(n)[0] + 1) / 2, np.polynomial.legendre.leggauss(n)[1] / 2)
         for n in (2, 3, 4, 8)}


def mean_log1p(x):
    """H(x): the mean of ln(1 + x g) over g in [0, 1], for x >= -1; its series below
    |x| = 0.1 (where ``(1 + x) ln(1 + x) / x - 1`` would cancel)."""
    x = np.asarray(x, np.float64)
    acc = np.zeros_like(x)
    for k in range(8, 0, -1):           # Horner: x (1/2 - x (1/6 - x (1/12 - ...)))
        acc = x * (1.0 / (k * (k + 1)) - acc)
    with np.errstate(divide="ignore", invalid="ignore"):
        big = np.where(x <= -1.0, -1.0, (1.0 + x) * np.log1p(np.maximum(x, -1.0)) / x - 1.0)
    return np.where(np.abs(x) < 0.1, acc, big)


def mean_f_log1p(x):
    """G(x): the integral of g ln(1 + x g) over g in [0, 1], for x > -1 (the emission
    integral's colour slope); its series below |x| = 0.1, where the closed form
    ``ln(1 + x) / 2 - (x^2 / 2 - x + ln(1 + x)) / (2 x^2)`` would cancel."""
    x = np.asarray(x, np.float64)
    acc = np.zeros_like(x)
    for k in range(8, 0, -1):           # x/3 - x^2/8 + x^3/15 - ...: (-1)^(k+1) x^k / (k (k + 2))
        acc = x * (1.0 / (k * (k + 2)) - acc)
    with np.errstate(divide="ignore", invalid="ignore"):
        l1 = np.log1p(np.maximum(x, -1.0 + 1e-300))
        big = 0.5 * l1 - (0.5 * x * x - x + l1) / (2.0 * x * x)
    return np.where(np.abs(x) < 0.1, acc, big)


def optical_depth_to(f, nlw, r, l_over_u):
    """Optical depth from a piece's start to fraction f of it: with w = 1 - alpha going
    linearly from w_a to w_a (1 + r), ``l/u * f * (-ln w_a - H(r f))``."""
    return l_over_u * f * (nlw - mean_log1p(r * f))


def node_count(od, r):
    """Gauss-Legendre points per part: fewer where the piece is thin and its opacity
    nearly constant (each choice keeps the rule's error below ~5e-8 of the colour,
    measured over random pieces), 8 otherwise."""
    small = np.abs(r)
    return np.where((od <= 0.01) & (small <= 0.01), 2,
                    np.where((od <= 0.1) & (small <= 0.1), 3,
                             np.where((od <= 0.3) & (small <= 0.3), 4, 8)))


def _pieces(knots, sf, sb):
    """Cut every segment at the knots strictly between its end values: per piece its
    segment, interval, start and end values (front to back)."""
    K = knots.s
    n = knots.count
    up = sb >= sf
    lo_v, hi_v = np.minimum(sf, sb), np.maximum(sf, sb)
    first = np.searchsorted(K, lo_v, side="right")     # knots strictly above lo
    last = np.searchsorted(K, hi_v, side="left")       # knots strictly below hi
    inner = np.maximum(last - first, 0)
    count = inner + 1
    seg = np.repeat(np.arange(sf.size), count)
    rank = np.arange(seg.size) - np.repeat(np.cumsum(count) - count, count)
    # boundaries in order of travel: value at rank r and r + 1
    m = inner[seg]
    kidx_up = first[seg] + rank                         # knot ending piece `rank` going up
    kidx_dn = last[seg] - 1 - rank                      # knot ending piece `rank` going down
    u = up[seg]
    end_k = np.where(u, kidx_up, kidx_dn)
    start_k = np.where(u, kidx_up - 1, kidx_dn + 1)
    a = np.where(rank == 0, sf[seg], K[np.clip(start_k, 0, n - 1)])
    b = np.where(rank == m, sb[seg], K[np.clip(end_k, 0, n - 1)])
    # interval holding the piece: going up, the last knot <= its start; down, < its start
    j = np.where(u, np.searchsorted(K, a, side="right") - 1, np.searchsorted(K, a, side="left") - 1)
    return seg, j, a, b


def linear_segment(knots: SegmentKnots, s_front, s_back, length, model="emission_absorption", weights=False,
                   cue=None):
    """Premultiplied (r, g, b, A) of segments (arrays broadcast) of the given lengths
    along which the field goes linearly from s_front to s_back, under the optical
    ``model`` (GLSL ``linearSegmentCued``): emission-absorption; absorption only, (0, A);
    emission only, (integral of c tau, 0). Float64, (n, 4). ``cue`` = (q_front, q_back)
    multiplies the colour by a factor going linearly between them along each segment (a
    depth cue; not with emission only). With ``weights``, also what a colour added along
    the segment is multiplied by: A (weighted by the cue), or for emission only the
    optical depth."""
    sf, sb, L = (np.asarray(v, np.float64).ravel() for v in np.broadcast_arrays(s_front, s_back, length))
    out = np.zeros((sf.size, 4))
    if model == "emission":
        out = _emission_segment(knots, sf, sb, L, out)
        depth = out[:, 3].copy()
        out[:, 3] = 0.0
        return (out, depth) if weights else out
    if model == "absorption":
        out, weight = linear_segment(knots, sf, sb, L, weights=True, cue=cue)
        out[:, :3] = 0.0
        return (out, weight) if weights else out
    qf, qb_seg = (np.ones(sf.size), np.ones(sf.size)) if cue is None else \
        (np.broadcast_to(np.asarray(q, np.float64).ravel(), sf.shape) for q in cue)
    seg, j, a, b = _pieces(knots, sf, sb)
    ds = np.abs(sb - sf)[seg]
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.where(ds > 0, np.abs(b - a) / ds, 1.0)
    lp = np.where(L[seg] > 0, L[seg] * frac, 0.0)
    ca, aa, wa = knots.at(j, a)
    cb, ab, wb = knots.at(j, b)
    # the cue at the piece's ends: linear along the segment, as the field is
    with np.errstate(divide="ignore", invalid="ignore"):
        qa = np.where(ds > 0, qf[seg] + (qb_seg[seg] - qf[seg]) * np.abs(a - sf[seg]) / ds, qf[seg])
        qb = np.where(ds > 0, qf[seg] + (qb_seg[seg] - qf[seg]) * np.abs(b - sf[seg]) / ds, qb_seg[seg])
    lu = lp * knots.inv_unit
    with np.errstate(divide="ignore", invalid="ignore"):
        nlw = np.where(aa <= 0.5, -np.log1p(-np.minimum(aa, 0.5)), -np.log(wa))
        r = np.where(wa > 0, (wb - wa) / wa, 0.0)
    od = np.where(lp > 0, optical_depth_to(1.0, nlw, r, lu), 0.0)
    od = np.where(wa > 0, od, 0.0)
    # colour, by parts with g = c q: g(0) (1 - T_l) + integral g'(f) (T(f) - T_l) df, from
    # mean[T(f) - T_l] and mean[f (T(f) - T_l)]
    Al = -np.expm1(-od)
    mean = np.zeros(seg.size)
    mean_f = np.zeros(seg.size)
    graded = wb <= 0
    parts = np.clip(np.ceil(od), 1, MAX_PARTS)
    nodes = np.where(graded, 8, node_count(od, r))
    for n in (2, 3, 4, 8):
        X, Wt = GAUSS[n]
        sel = np.flatnonzero((nodes == n) & (lp > 0) & (wa > 0))
        if sel.size == 0:
            continue
        g, pt = graded[sel], parts[sel]
        for p in range(max(MAX_PARTS, GRADED_PARTS)):
            f0, f1 = part_bounds(p, pt, g)
            act = np.where(g, p < GRADED_PARTS, p < pt)
            for x, wgt in zip(X, Wt):
                f = f0 + x * (f1 - f0)
                od_to = optical_depth_to(f, nlw[sel], r[sel], lu[sel])
                val = np.exp(-od_to) * -np.expm1(-np.maximum(od[sel] - od_to, 0.0))
                term = np.where(act & (od_to < DEEP), wgt * (f1 - f0) * val, 0.0)
                mean[sel] += term
                mean_f[sel] += f * term
            if not act.any():
                break
    dq = qb - qa
    dc = cb - ca
    C = (ca * (qa * Al)[:, None] + (dc * qa[:, None] + ca * dq[:, None]) * mean[:, None]
         + 2.0 * dc * (dq * mean_f)[:, None])
    Q = qa * Al + dq * mean                     # the opacity weighted by the cue
    # alpha = 1 at a piece's start or end ends the segment there
    opaque_start = wa <= 0
    opaque_end = wb <= 0
    C = np.where(opaque_start[:, None], ca * qa[:, None], C)
    Q = np.where(opaque_start, qa, Q)
    Al = np.where(opaque_start, 1.0, Al)
    T_end = np.where(opaque_end & ~opaque_start, np.exp(-od), 0.0)
    C = C + (T_end * qb)[:, None] * cb
    Q = Q + T_end * qb
    Al = np.where(opaque_end, 1.0, Al)
    # front-to-back over the pieces of each segment (pieces are ordered by segment)
    with np.errstate(divide="ignore"):
        logT = np.where(Al >= 1.0, -np.inf, np.log1p(-np.minimum(Al, 1.0)))
    T_before = np.exp(_segmented_exclusive_sum(logT, seg))
    for ch in range(3):
        out[:, ch] = np.bincount(seg, T_before * C[:, ch], sf.size)
    out[:, 3] = np.bincount(seg, T_before * Al, sf.size)
    return (out, np.bincount(seg, T_before * Q, sf.size)) if weights else out


def _emission_segment(knots, sf, sb, L, out):
    """Emission only: per piece, with c = c_a + (c_b - c_a) g and tau = (-ln w_a -
    ln(1 + r g)) / u over the piece's fraction g, the integral of c tau is
    ``l/u (-ln w_a (c_a + dc / 2) - c_a H(r) - dc G(r))`` (H ``mean_log1p``, G
    ``mean_f_log1p``); the pieces add, nothing absorbs. Opacity 1 is refused upstream.
    Returns the colours with the segments' optical depths in the alpha channel."""
    seg, j, a, b = _pieces(knots, sf, sb)
    ds = np.abs(sb - sf)[seg]
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.where(ds > 0, np.abs(b - a) / ds, 1.0)
    lu = np.where(L[seg] > 0, L[seg] * frac, 0.0) * knots.inv_unit
    ca, aa, wa = knots.at(j, a)
    cb, ab, wb = knots.at(j, b)
    with np.errstate(divide="ignore", invalid="ignore"):
        nlw = np.where(aa <= 0.5, -np.log1p(-np.minimum(aa, 0.5)), -np.log(wa))
        r = np.where(wa > 0, (wb - wa) / wa, 0.0)
    dc = cb - ca
    C = lu[:, None] * (nlw[:, None] * (ca + 0.5 * dc) - ca * mean_log1p(r)[:, None] - dc * mean_f_log1p(r)[:, None])
    C = np.where(((aa > 0) | (ab > 0))[:, None], C, 0.0)
    for ch in range(3):
        out[:, ch] = np.bincount(seg, C[:, ch], sf.size)
    od = np.where((lu > 0) & ((aa > 0) | (ab > 0)), optical_depth_to(1.0, nlw, r, lu), 0.0)
    out[:, 3] = np.bincount(seg, od, sf.size)
    return out


def part_bounds(p, parts, graded):
    """Fractions [f0, f1] of part p of a piece: ``parts`` equal parts, or, towards an end
    where alpha reaches 1 (tau's log singularity), parts halving in length."""
    f0 = np.where(graded, 1.0 - 0.5 ** p, p / parts)
    f1 = np.where(graded, np.where(p == GRADED_PARTS - 1, 1.0, 1.0 - 0.5 ** (p + 1)), (p + 1) / parts)
    return f0, f1
