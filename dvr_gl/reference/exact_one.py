"""The exact image of a scene of one volume or one mesh (the contract,
``shared/design/conventions.md``, sections 3-7), in float64. ``dvr_gl.reference.exact``
is the entry point (and its cache); scenes of several volumes are ``exact_layers``.

Method. Every ray (from ``Camera.rays``, clipped to the domain box by ``ray_box``) is cut
where it crosses a grid plane ``x = ox + i*sx`` (likewise y, z), so each piece lies in one
cell. There the trilinear field along the ray is a cubic in t: its four coefficients are the
multilinear interpolant expanded about the piece's midpoint (a finite Taylor series, so
exact up to rounding); the values at piece ends are computed as ``common.trilinear`` does,
so they are exact at samples. mip/minip take the extremes of the cubics (ends and roots of
the derivative); average integrates them in closed form; isosurface finds the first sign
change of ``cubic - v`` by isolating roots between critical points and polishing them with
Newton steps safeguarded by bisection.

Composite: each piece is cut again where the cubic crosses a control point of the transfer
function, so that on every sub-piece colour and opacity are linear in s and the integrands
are analytic, except for tau's log singularity where alpha reaches 1 (the ray ends there).
Sub-pieces are integrated by adaptive Gauss-Kronrod 7/15: the transmittance at the nodes of
a part comes from integrating the degree-14 interpolant of tau (a spectral integration
matrix); a part is halved until G7 and K15 agree on optical depth and colour, and
sum(w tau T) agrees with 1 - exp(-OD) (which catches a transmittance falling too fast for
the nodes), to ``_TOL`` times a rigorous upper bound of the transmittance in front of it.
This grades the parts into large optical depths and towards alpha -> 1. A ray stops once
its transmittance is below ``_T_STOP``.

Accuracy: the error per pixel is about the sum of the accepted estimates, far below 1e-8:
measured 1e-15 against closed forms and scipy quad on linear ramps (also with alpha = 1 and
1 - 1e-9), about 1e-11 against a tight ODE solve on random data with 256-point transfer
functions, 1e-12 on a CT scan. mip/minip/average/isosurface are exact up to rounding.

Meshes (``TetMesh``): ``mesh_rays`` gives every ray's segment through every tet (float64
Cyrus-Beck against face planes shared bitwise by neighbouring tets, so no cracks), image
row block by row block; per ray the segments are sorted by t and overlapping coverage (a
ray lying in a face shared by two tets) is counted once. Each segment is a piece on which
the field is linear in t and goes through the same integrator as a grid's cubic piece
(``_Classified``: knot cuts, adaptive Gauss-Kronrod, the same tolerances); gaps between
segments (a non-convex domain) add nothing. mip/minip take the segment ends, average
integrates the linear pieces over the union's length, isosurface solves the first
crossing on a linear piece with the grid's rules for entry side and gaps, and shades with
the hit tet's own (constant) gradient, threshold ``1e-6 * (data range) / cell_size``.
Clip planes and a crop box cut each segment to its ray's kept interval (the values at a
cut end interpolated linearly, empty segments dropped) before any mode sees it.
Measured against a Richardson-extrapolated fine integration on single tets and split
cubes: below 1e-11; against the tetra reference's closed-form segment integral on the
blunt fin: 1.5e-11.

Opaque geometry (``Scene.geometry``): every ray's first surface hit (``exact_geometry``,
float64 Möller-Trumbore) ends its interval, ``t1 = min(t1, t_hit)`` (after the clip,
which cuts the data only), for grids and meshes alike; every mode then runs on the
shortened ray, and the surface's lit colour goes behind the pixel it made:
``C + (1 - A) * colour``, A = 1 (for emission-absorption ``1 - A`` is ``T(t_hit)``).

Choices where the contract is silent: alpha = 1 at any point of the ray (its last point
too) ends the ray there; the remaining transmittance goes to that point's colour and
A = 1 exactly. Masked volumes: a cell with a non-finite corner is outside the domain for
every mode (no emission or absorption, no length in the average, no extreme value). For
isosurface the entry side (``f >= v`` or not) is taken at the first point of the first
valid cell on the ray and is never re-taken: the hit is the first point of the valid domain
where the field is strictly on the other side of v (so a touch is not a hit), and
re-entering valid cells on the other side after a masked gap is a hit at the re-entry
point. Gradients for shading read ``Volume.values()`` (non-finite samples as 0, like the
texture) clamped to the domain box.
"""

from __future__ import annotations

import numpy as np

from ..model.clipping import clip_interval, plane_offsets
from .common import ray_box
from .exact_geometry import surface_behind, surface_hits
from ..model.field import gradient, gradient_epsilon
from .shading import sample_terms, scene_lights, shade_blinn_phong

__all__ = ["render", "VERSION"]

# Changes whenever the integrator's output can change: part of the cache key.
VERSION = "exact-2"   # 2: windows no longer skip grid planes (rays nearly along an axis)

_TOL = 1e-11             # accepted |K15 - G7| per part (optical depth and colour), times T
_MAX_DEPTH = 52          # halving beyond this is below float64 resolution of the piece
_T_STOP = 1e-14          # the rest of a ray cannot change the pixel by more than this
_CHUNK = 8192            # rays at a time (bounds memory)
_WINDOW = {"composite": 12, "other": 32}   # cells per ray per step (composite rays stop early)
_BATCH = 2048            # quadrature parts evaluated at a time
_MESH_BUDGET = 1 << 21   # mesh: (tet, ray) candidates per block of image rows (bounds memory)
_ALPHA_MAX = np.nextafter(1.0, 0.0)      # keeps tau finite at nodes next to alpha = 1


# --------------------------------------------------------------------------- quadrature
def _gauss_kronrod():
    xk = np.array([0.991455371120812639206854697526329, 0.949107912342758524526189684047851,
                   0.864864423359769072789712788640926, 0.741531185599394439863864773280788,
                   0.586087235467691130294144845693013, 0.405845151377397166906606412076961,
                   0.207784955007898467600689403773245, 0.0])
    wk = np.array([0.022935322010529224963732008058970, 0.063092092629978553290700663189204,
                   0.104790010322250183839876322541518, 0.140653259715525918745189590510238,
                   0.169004726639267902826583426598550, 0.190350578064785409913256402421014,
                   0.204432940075298892414161999234649, 0.209482141084727828012999174891714])
    wg = np.array([0.129484966168869693270611432679082, 0.279705391489276667901467771423780,
                   0.381830050505118944950369775488975, 0.417959183673469387755102040816327])
    x = np.concatenate([-xk[:-1], xk[::-1]])          # ascending, 15 nodes
    w = np.concatenate([wk[:-1], wk[::-1]])
    gi = np.array([1, 3, 5, 7, 9, 11, 13])             # the Gauss-7 nodes among them
    g = np.concatenate([wg[:-1], wg[::-1]])
    return x, w, gi, g


def _integration_matrix(x):
    """S[i, j] = integral from -1 to x_i of the j-th Lagrange basis polynomial on nodes x:
    ``S @ f`` integrates the interpolant of f from the left end to every node."""
    from numpy.polynomial import legendre as L
    n = len(x)
    V = L.legvander(x, n - 1)
    Q = np.empty((n, n))
    for k in range(n):
        c = np.zeros(n)
        c[k] = 1.0
        Q[:, k] = L.legval(x, L.legint(c, lbnd=-1))
    return np.linalg.solve(V.T, Q.T).T


_XK, _WK, _GI, _WG = _gauss_kronrod()
_SK = _integration_matrix(_XK)
_SG = _integration_matrix(_XK[_GI])


# --------------------------------------------------------------------------- cubics
def _peval(c, x):
    """Cubic with coefficients c (..., 4) (constant first) at x (broadcast on the last axis)."""
    if x.ndim == c.ndim:
        return ((c[..., 3:4] * x + c[..., 2:3]) * x + c[..., 1:2]) * x + c[..., 0:1]
    return ((c[..., 3] * x + c[..., 2]) * x + c[..., 1]) * x + c[..., 0]


def _dpeval(c, x):
    return (3 * c[..., 3] * x + 2 * c[..., 2]) * x + c[..., 1]


def _monotone_split(c, fa, fb):
    """Ends and interior critical points of each cubic on [-1, 1]: E (P, 4) ascending (absent
    critical points repeat an end), and the field's values there, PE (P, 4), with the end
    values fa, fb given (trilinear at the end points, exact at samples). Between
    consecutive columns the cubic is monotone."""
    A, B, C = 3 * c[:, 3], 2 * c[:, 2], c[:, 1]
    disc = B * B - 4 * A * C
    sq = np.sqrt(np.maximum(disc, 0.0))
    q = -0.5 * (B + np.where(B >= 0, sq, -sq))      # no cancellation (stable quadratic)
    r1 = q / A
    r2 = C / q
    lin = -C / B                                     # A == 0: p' is linear
    roots = np.stack([np.where(A == 0, lin, r1), np.where(A == 0, np.nan, r2)], axis=1)
    inside = (disc >= 0)[:, None] & (roots > -1) & (roots < 1)
    roots = np.where(inside, roots, 1.0)
    E = np.concatenate([np.full((len(c), 1), -1.0), roots, np.ones((len(c), 1))], axis=1)
    E.sort(axis=1)
    PE = np.where(E == -1.0, fa[:, None], np.where(E == 1.0, fb[:, None], _peval(c, E)))
    return E, PE


def _knot_crossings(K, coef, E, PE):
    """Where each piece's cubic crosses a knot of K: (piece, knot value, tau of the
    crossing). The knots strictly between the values at the ends of each of a piece's
    three monotone stretches (``_monotone_split``'s E, PE) are found by search, so that
    many control points cost no more memory than a few; each crossing is then solved on
    its stretch."""
    lo_v, hi_v = np.minimum(PE[:, :-1], PE[:, 1:]), np.maximum(PE[:, :-1], PE[:, 1:])
    k_first = np.searchsorted(K, lo_v, side="right")
    n_cross = np.maximum(np.searchsorted(K, hi_v, side="left") - k_first, 0).ravel()
    stretch = np.repeat(np.arange(n_cross.size), n_cross)
    pi, j = np.divmod(stretch, 3)
    k = (np.repeat(k_first.ravel(), n_cross)
         + np.arange(stretch.size) - np.repeat(np.cumsum(n_cross) - n_cross, n_cross))
    tau = _solve(coef[pi], E[pi, j], E[pi, j + 1], K[k]) if pi.size else np.zeros(0)
    return pi, K[k], tau


def _solve(c, lo, hi, target):
    """The root of cubic(x) = target in [lo, hi], where the cubic is monotone and
    cubic(lo) - target is zero or of the opposite sign to cubic(hi) - target. Newton
    steps safeguarded by bisection of the bracket, to a few ulps."""
    lo = lo.astype(np.float64, copy=True)
    hi = hi.astype(np.float64, copy=True)
    flo = _peval(c, lo) - target
    fhi = _peval(c, hi) - target
    x = lo - flo * (hi - lo) / (fhi - flo)
    x = np.where(np.isfinite(x) & (x > lo) & (x < hi), x, 0.5 * (lo + hi))
    x = np.where(flo == 0, lo, x)
    lo_neg = flo < 0
    act = np.flatnonzero(flo != 0)
    for _ in range(200):
        if act.size == 0:
            break
        ca, xa = c[act], x[act]
        f = _peval(ca, xa) - target[act]
        on_lo_side = (f < 0) == lo_neg[act]
        la = np.where(on_lo_side, xa, lo[act])
        ha = np.where(on_lo_side, hi[act], xa)
        lo[act], hi[act] = la, ha
        xn = xa - f / _dpeval(ca, xa)
        xn = np.where((xn > la) & (xn < ha), xn, 0.5 * (la + ha))
        conv = (f == 0) | (np.abs(xn - xa) <= 4e-16 * np.maximum(1.0, np.abs(xa))) | (ha - la <= 4e-16)
        x[act] = np.where(f == 0, xa, xn)
        act = act[~conv]
    return x


def _segmented_exclusive_sum(x, seg):
    """Sum of the preceding x within each run of equal seg (seg sorted): a log-step scan,
    so that sums never mix rays (no cancellation across segments)."""
    inc = x.copy()
    dist = 1
    while dist < inc.size:
        same = seg[dist:] == seg[:-dist]
        if not same.any():
            break
        inc[dist:] = inc[dist:] + np.where(same, inc[:-dist], 0.0)
        dist *= 2
    excl = np.zeros_like(inc)
    if inc.size > 1:
        excl[1:] = np.where(seg[1:] == seg[:-1], inc[:-1], 0.0)
    return excl


# --------------------------------------------------------------------------- the scene
class _Classified:
    """The transfer function's tables and the composite integrator over pieces on which
    the field is a cubic in the ray parameter: shared by grids and meshes."""

    # composite samples with lighting or illustration terms (grids): ``lighting(points,
    # dirs)`` gives (colour factor, added colour, extinction scale) at world points seen
    # along dirs (``shading.SampleTerms.at``); None leaves samples plain. ``scale_floor``
    # bounds the extinction scale from below (for the error weights).
    lighting = None
    scale_floor = 1.0
    # what each piece carries for them: its geometry (grids, terms per node) or its own
    # constant colour factor and added colour (a mesh's cell, lit with its gradient)
    piece_keys = ()
    # a 2D transfer function (grids): ``classify_2d(points, dirs, s)`` gives (rgba,
    # transparency, factor, offset, scale) at the nodes (``shading.SampleTerms.classify``);
    # ``tf`` is then its envelope, which only says where nothing is visible
    classify_2d = None

    def __init__(self, tf, optical_model="emission_absorption"):
        self.tf = tf
        self.inv_u = 1.0 / tf.unit_distance
        # emission only: nothing absorbs (T = 1 throughout); absorption only: no colour
        self.emission = optical_model == "emission"
        self.absorption = optical_model in ("absorption", "sabella")   # no colour along the ray
        K = tf.knots
        self.K = K
        nk = len(K)
        # Interval m holds K[m-1] <= s < K[m] (m = 0: below K[0], m = nk: from K[-1] on).
        # On it colour and opacity are lines anchored at the interval's lower knot, so
        # they are exact at knots and continue smoothly a few ulps beyond them.
        aK = tf.opacity(K)
        cK = tf.color(K)
        anchor = np.concatenate([K[:1], K])
        a0 = np.concatenate([aK[:1], aK])
        c0 = np.concatenate([cK[:1], cK])
        a1 = np.zeros(nk + 1)
        c1 = np.zeros((nk + 1, 3))
        if nk > 1:
            dK = np.diff(K)
            a1[1:nk] = np.diff(aK) / dK
            c1[1:nk] = np.diff(cK, axis=0) / dK[:, None]
        if self.absorption:
            c0, c1 = np.zeros_like(c0), np.zeros_like(c1)
        self.anchor, self.a0, self.a1 = anchor, a0, a1
        self.c0, self.c1 = c0, c1
        # Intervals where opacity is not identically zero, as a prefix count.
        nzint = np.concatenate([[aK[0] > 0], (aK[:-1] > 0) | (aK[1:] > 0), [aK[-1] > 0]])
        self.nzint = nzint
        self.nzcum = np.concatenate([[0], np.cumsum(nzint)])

    def interval(self, s):
        return np.searchsorted(self.K, s, side="right")

    def window(self, P, Tray, na):
        """(optical depth, colour relative to the window's start, ended by alpha = 1) of
        each ray over one window of pieces."""
        OD = np.zeros(na)
        C = np.zeros((na, 3))
        term = np.zeros(na, bool)
        coef = P["coef"]
        if len(coef) == 0:
            return OD, C, term
        E, PE = _monotone_split(coef, P["fa"], P["fb"])
        # pieces whose value range lies where opacity is 0 emit and absorb nothing
        lo_m = self.interval(PE.min(axis=1))
        hi_m = self.interval(PE.max(axis=1))
        busy = np.flatnonzero(self.nzcum[hi_m + 1] - self.nzcum[lo_m] > 0)
        if busy.size == 0:
            return OD, C, term
        coef, E, PE = coef[busy], E[busy], PE[busy]
        rows, h = P["rows"][busy], P["h"][busy]
        # a lit scene: each piece's midpoint, half-length vector and direction (world)
        geometry = {k: P[k][busy] for k in self.piece_keys} if self.piece_keys else None
        npc = len(busy)

        # breakpoints: crossings of knots (s known exactly there) ...
        pi, knot_s, knot_tau = _knot_crossings(self.K, coef, E, PE)
        bt, bs, bp = [knot_tau], [knot_s], [pi]
        # ... and interior critical points where alpha reaches 1 (a touch of an opaque value)
        crit = (E[:, 1:3] > -1) & (E[:, 1:3] < 1) & (self.tf.opacity(PE[:, 1:3]) >= 1)
        ci, cj = np.nonzero(crit)
        bt.append(E[ci, cj + 1])
        bs.append(PE[ci, cj + 1])
        bp.append(ci)
        bt, bs, bp = np.concatenate(bt), np.concatenate(bs), np.concatenate(bp)
        order = np.argsort(bp, kind="stable")
        bt, bs, bp = bt[order], bs[order], bp[order]
        counts = np.bincount(bp, minlength=npc)
        rank = np.arange(bp.size) - np.repeat(np.cumsum(counts) - counts, counts)
        width = 2 + (counts.max() if bp.size else 0)
        BT = np.full((npc, width), 2.0)          # 2 > 1: padding sorts to the end
        BS = np.zeros((npc, width))
        BT[:, 0], BS[:, 0] = -1.0, PE[:, 0]
        BT[bp, 1 + rank], BS[bp, 1 + rank] = bt, bs
        BT[np.arange(npc), 1 + counts], BS[np.arange(npc), 1 + counts] = 1.0, PE[:, 3]
        srt = np.argsort(BT, axis=1, kind="stable")
        BT = np.take_along_axis(BT, srt, axis=1)
        BS = np.take_along_axis(BS, srt, axis=1)
        ok = (BT[:, 1:] <= 1.0) & (BT[:, 1:] > BT[:, :-1])
        sp, sc = np.nonzero(ok)                 # sub-pieces, ordered by piece then tau
        ta, tb = BT[sp, sc], BT[sp, sc + 1]
        sa, sb = BS[sp, sc], BS[sp, sc + 1]
        m = self.interval(_peval(coef[sp], 0.5 * (ta + tb)))
        keep = self.nzint[m]
        sp, ta, tb, sa, sb, m = sp[keep], ta[keep], tb[keep], sa[keep], sb[keep], m[keep]
        srow = rows[sp]

        # alpha = 1 at a point ends the ray there: find each ray's first such point
        op_a = self.tf.opacity(sa) >= 1
        op_b = self.tf.opacity(sb) >= 1
        ev = np.flatnonzero(op_a | op_b)
        first = np.full(na, np.iinfo(np.int64).max)
        if ev.size:
            r_ev, i_ev = np.unique(srow[ev], return_index=True)
            first[r_ev] = ev[i_ev]
            term[r_ev] = True
        ns = len(sp)
        pos = np.arange(ns)
        fr = first[srow]
        integrate = (pos < fr) | ((pos == fr) & ~op_a)
        singular = (pos == fr) & ~op_a           # ends where alpha = 1: integrand uses c - c_end
        geo = None if geometry is None else {k: v[sp] for k, v in geometry.items()}
        cend = np.zeros((ns, 3))
        cend[singular] = self.color_at(sb[singular], tb[singular], geo, singular)
        # a zero-thickness part carrying T * c at the ray's opaque point
        pseudo = np.flatnonzero(pos == fr)
        pseudo_c = np.where(op_a[pseudo, None], self.color_at(sa[pseudo], ta[pseudo], geo, pseudo), cend[pseudo])

        ii = np.flatnonzero(integrate)
        sub = dict(coef=coef[sp[ii]], crit=E[sp[ii], 1:3], h=h[sp[ii]], m=m[ii], cend=cend[ii])
        if geo is not None:
            sub.update({k: v[ii] for k, v in geo.items()})
        # weight of each sub-piece's errors: the ray's transmittance at the window start
        # times a rigorous upper bound of the transmittance from there to the sub-piece
        lower = self.od_lower(sub, np.arange(ii.size), ta[ii], tb[ii])
        weight = Tray[srow[ii]] * np.exp(-_segmented_exclusive_sum(lower, srow[ii]))
        psub, pta, pod, pcol = self.quadrature(sub, ta[ii], tb[ii], weight)
        psub = np.concatenate([ii[psub], pseudo])
        pta = np.concatenate([pta, np.full(pseudo.size, -np.inf)])
        pod = np.concatenate([pod, np.zeros(pseudo.size)])
        pcol = np.concatenate([pcol, pseudo_c], axis=0)
        order = np.lexsort((pta, psub))
        psub, pod, pcol = psub[order], pod[order], pcol[order]
        prow = srow[psub]
        # transmittance from the window's start to each part (1 where nothing absorbs)
        wgt = np.ones(len(pod)) if self.emission else np.exp(-_segmented_exclusive_sum(pod, prow))
        OD = np.bincount(prow, pod, na)
        for ch in range(3):
            C[:, ch] = np.bincount(prow, wgt * pcol[:, ch], na)
        return OD, C, term

    def od_lower(self, sub, i, ta, tb):
        """A lower bound of the optical depth of parts [ta, tb] of sub-pieces i: the
        smallest opacity over the part's value range (ends and interior critical points;
        opacity is linear in s on a sub-piece) times its length. Emission only: 0, since
        nothing in front of a part absorbs."""
        if self.emission or self.classify_2d is not None:   # a 2D TF's envelope bounds from above
            return np.zeros(len(ta))
        c = sub["coef"][i]
        sa, sb = _peval(c, ta), _peval(c, tb)
        lo, hi = np.minimum(sa, sb), np.maximum(sa, sb)
        for j in (0, 1):
            x = sub["crit"][i, j]
            inside = (x > ta) & (x < tb)
            sx = _peval(c, x)
            lo = np.where(inside, np.minimum(lo, sx), lo)
            hi = np.where(inside, np.maximum(hi, sx), hi)
        m = sub["m"][i]
        line = lambda v: self.a0[m] + self.a1[m] * (v - self.anchor[m])   # noqa: E731
        a = np.minimum(line(lo), line(hi))
        a = np.clip(a, 0.0, _ALPHA_MAX)
        return -np.log1p(-a) * self.inv_u * self.scale_floor * sub["h"][i] * (tb - ta)

    def quadrature(self, sub, ta, tb, weight):
        """Adaptive Gauss-Kronrod over sub-pieces [ta, tb] (tau units of each piece): a
        part is halved until its error estimate, times an upper bound of the transmittance
        at its start, is below _TOL. Returns the accepted parts: sub-piece index, start,
        optical depth, colour (transmittance 1 at the part's start)."""
        out_sub, out_ta, out_od, out_c = [np.zeros(0, np.int64)], [np.zeros(0)], [np.zeros(0)], [np.zeros((0, 3))]
        idx = np.arange(len(ta))
        pre = np.zeros(len(ta))        # lower bound of the optical depth from the sub-piece start
        depth = 0
        while idx.size:
            ODk = np.empty(idx.size)
            Ck = np.empty((idx.size, 3))
            err = np.empty(idx.size)
            for b0 in range(0, idx.size, _BATCH):
                sl = slice(b0, b0 + _BATCH)
                i = idx[sl]
                geo = {k: sub[k][i] for k in self.piece_keys} if self.piece_keys else None
                ODk[sl], Ck[sl], err[sl] = self.gk(sub["coef"][i], sub["h"][i], sub["m"][i], sub["cend"][i],
                                                   ta[sl], tb[sl], geo)
            ok = (err * weight[idx] * np.exp(-pre) <= _TOL) | (depth >= _MAX_DEPTH)
            out_sub.append(idx[ok])
            out_ta.append(ta[ok])
            out_od.append(ODk[ok])
            out_c.append(Ck[ok])
            bad = ~ok
            idx, ta, tb, pre = idx[bad], ta[bad], tb[bad], pre[bad]
            mid = 0.5 * (ta + tb)
            pre_right = pre + self.od_lower(sub, idx, ta, mid)
            idx = np.concatenate([idx, idx])
            ta, tb = np.concatenate([ta, mid]), np.concatenate([mid, tb])
            pre = np.concatenate([pre, pre_right])
            depth += 1
        return (np.concatenate(out_sub), np.concatenate(out_ta), np.concatenate(out_od),
                np.concatenate(out_c, axis=0))

    def color_at(self, s, tau, geo, rows):
        """The (lit) colour of field values s at piece parameters tau; ``geo`` holds
        the pieces' geometry (None: unlit), ``rows`` picks the pieces."""
        c = np.zeros((len(s), 3)) if self.absorption else self.tf.color(s)
        if geo is None or len(s) == 0:
            return c
        if "factor" in geo:
            return c * geo["factor"][rows][:, None] + geo["offset"][rows]
        points = geo["base"][rows] + tau[:, None] * geo["hd"][rows]
        factor, offset, _ = self.lighting(points, geo["dir"][rows], grad=geo["grad"][rows] if "grad" in geo else None)
        return c * factor[:, None] + offset

    def gk(self, coef, h, m, cend, ta, tb, geo=None):
        """K15 optical depth and colour of each part, and max |K15 - G7| of the two.
        With ``geo`` (sample terms) each node's colour and extinction get the terms at
        the node's position."""
        mid = 0.5 * (ta + tb)
        half = 0.5 * (tb - ta)
        x = mid[:, None] + half[:, None] * _XK
        s = _peval(coef, x)
        ds = s - self.anchor[m][:, None]
        alpha = np.clip(self.a0[m][:, None] + self.a1[m][:, None] * ds, 0.0, _ALPHA_MAX)
        tau = -np.log1p(-alpha) * self.inv_u
        factor = offset = None
        if geo is not None and "factor" in geo:      # constant over the piece
            factor = np.broadcast_to(geo["factor"][:, None], x.shape)
            offset = np.broadcast_to(geo["offset"][:, None, :], x.shape + (3,))
            tau = tau * geo["scale"][:, None]
        elif geo is not None:
            points = geo["base"][:, None, :] + x[..., None] * geo["hd"][:, None, :]
            if self.classify_2d is not None:    # the table at each node's gradient magnitude
                rgba, _, factor, offset, scale = self.classify_2d(points, geo["dir"][:, None, :], s)
                alpha = np.clip(rgba[..., 3], 0.0, _ALPHA_MAX)
                tau = -np.log1p(-alpha) * self.inv_u
                node_color = np.zeros(rgba.shape[:-1] + (3,)) if self.absorption else rgba[..., :3]
            else:   # (a mesh's pieces carry their cell's gradient)
                factor, offset, scale = self.lighting(points, geo["dir"][:, None, :],
                                                      grad=geo["grad"][:, None, :] if "grad" in geo else None)
            tau = tau * scale
        hw = h * half                             # half-length of the part in t
        Tk = np.exp(-hw[:, None] * (tau @ _SK.T))   # transmittance from the part's start
        tg = tau[:, _GI]
        Tg = np.exp(-hw[:, None] * (tg @ _SG.T))
        if self.emission:
            Tk, Tg = np.ones_like(Tk), np.ones_like(Tg)
        ODk = hw * (tau @ _WK)
        gk = tau * Tk
        gg = tg * Tg
        # colour is linear in ds on the part: two weighted sums serve all channels; with
        # sample terms it is c(s) * factor + offset, both from the node's position
        G0k, G0g = hw * (gk @ _WK), hw * (gg @ _WG)
        if factor is not None:
            gk, gg = gk * factor, gg * factor[:, _GI]
        D0k, D1k = hw * (gk @ _WK), hw * ((ds * gk) @ _WK)
        D0g, D1g = hw * (gg @ _WG), hw * ((ds[:, _GI] * gg) @ _WG)
        if self.classify_2d is not None and geo is not None:    # colour per node, not linear in ds
            Ck = hw[:, None] * np.einsum("pn,pnc,n->pc", gk, node_color, _WK) - cend * G0k[:, None]
            Cg = hw[:, None] * np.einsum("pn,pnc,n->pc", gg, node_color[:, _GI], _WG) - cend * G0g[:, None]
        else:
            c0, c1 = self.c0[m], self.c1[m]
            Ck = c0 * D0k[:, None] + c1 * D1k[:, None] - cend * G0k[:, None]
            Cg = c0 * D0g[:, None] + c1 * D1g[:, None] - cend * G0g[:, None]
        if offset is not None:
            Ck += hw[:, None] * np.einsum("pn,pnc,n->pc", tau * Tk, offset, _WK)
            Cg += hw[:, None] * np.einsum("pn,pnc,n->pc", tg * Tg, offset[:, _GI], _WG)
        err = np.maximum(np.abs(ODk - hw * (tg @ _WG)), np.abs(Ck - Cg).max(axis=1))
        # with c = 1 the colour integral is 1 - exp(-OD) exactly: a transmittance that
        # falls too fast for the nodes (both rules missing it) shows up here
        if not self.emission:
            err = np.maximum(err, np.abs(G0k + np.expm1(-ODk)))
        return ODk, Ck, err


class _Exact(_Classified):
    def __init__(self, scene):
        vol = scene.volume
        self.scene = scene
        self.vol = vol
        self.values = vol.values(np.float64)
        self.flat = self.values.ravel()
        nz, ny, nx = vol.shape
        self.nx, self.nxy = nx, nx * ny
        self.dims = vol.dims.astype(np.float64)
        self.origin = vol.origin
        self.spacing = vol.spacing
        self.valid = None if vol.cell_valid is None else vol.cell_valid.ravel()
        super().__init__(scene.tf, scene.optical_model)
        terms = sample_terms(scene, self.values)
        if terms is not None:
            self.lighting = terms.at
            self.piece_keys = ("base", "hd", "dir")
            self.scale_floor = terms.scale_floor
            if scene.tf_2d is not None:
                self.classify_2d = terms.classify

    # -- traversal ------------------------------------------------------------
    def pieces(self, o, d, tcur, t1, M):
        """The next (at most) M cell pieces of each ray from tcur on, masked cells left
        out. Returns the flat pieces (ordered by ray, then t) and the new tcur.

        Per axis the candidates are the planes base, base +- 1, ..., base +- (M+1), where
        base is the plane at or just behind tcur. A window starts on a plane (or on the
        box face), so rounding may put base and base +- 1 at or behind tcur: only the
        planes from base +- 2 on are sure to lie ahead, and M + 2 candidates leave at
        least M of them per axis. The first M of all axes merged are then the true next M
        planes. The window also never reaches past any axis's last candidate (the horizon),
        so that no piece can skip a plane of an axis whose candidates ran out (on a ray
        nearly along one axis almost all planes crossed are that axis's)."""
        steps = np.arange(M + 2)
        cands = []
        horizon = t1.copy()
        for a in range(3):
            da = d[:, a]
            p = (o[:, a] + tcur * da - self.origin[a]) / self.spacing[a]
            base = np.where(da > 0, np.floor(p), np.ceil(p))
            k = base[:, None] + np.sign(da)[:, None] * steps
            t = (self.origin[a] + k * self.spacing[a] - o[:, a, None]) / da[:, None]
            # planes beyond the last candidate are not known: stop the window there
            horizon = np.minimum(horizon, np.where(da != 0, t[:, -1], np.inf))
            # base (+- 1) may lie just behind tcur; parallel axes give inf/nan
            t[~(t > tcur[:, None])] = np.inf
            cands.append(t)
        c = np.concatenate(cands, axis=1)
        c.sort(axis=1)
        c = np.minimum(c[:, :M], horizon[:, None])
        bounds = np.concatenate([tcur[:, None], c], axis=1)
        ta, tb = bounds[:, :-1], bounds[:, 1:]
        rows, cols = np.nonzero(tb > ta)
        ta, tb = ta[rows, cols], tb[rows, cols]
        tm = 0.5 * (ta + tb)
        h = 0.5 * (tb - ta)
        idx = (o[rows] + tm[:, None] * d[rows] - self.origin) / self.spacing
        # the cell is the one holding the midpoint: robust for pieces on cell faces
        cell = np.clip(np.floor(idx), 0, self.dims - 2).astype(np.int64)
        flat = (cell[:, 2] * self.nxy + cell[:, 1] * self.nx + cell[:, 0])
        keep = None if self.valid is None else self.valid[(cell[:, 2] * (self.vol.shape[1] - 1) + cell[:, 1])
                                                          * (self.vol.shape[2] - 1) + cell[:, 0]]
        if keep is not None:
            rows, cols, ta, tb, tm, h, idx, cell, flat = (x[keep] for x in
                                                          (rows, cols, ta, tb, tm, h, idx, cell, flat))
        ends = [(o[rows] + t[:, None] * d[rows] - self.origin) / self.spacing - cell for t in (ta, tb)]
        coef, fa, fb = self.cubic(flat, idx - cell, h[:, None] * d[rows] / self.spacing, ends)
        return dict(rows=rows, cols=cols, ta=ta, tb=tb, tm=tm, h=h, coef=coef, fa=fa, fb=fb), bounds[:, -1]

    def cubic(self, flat, u, hu, ends):
        """Coefficients (P, 4) in tau in [-1, 1] of the trilinear field on the segment
        u + hu * tau (cell-local coordinates): the exact Taylor expansion about u; and the
        field at the local points ``ends`` (trilinear, as ``common.trilinear`` computes it,
        so that values at samples are exact)."""
        nx, nxy = self.nx, self.nxy
        v = self.flat
        corner = {}
        for y in (0, 1):
            for z in (0, 1):
                b = flat + y * nx + z * nxy
                corner[y, z] = v[b], v[b + 1]
        end_values = []
        for p in ends:
            px, py, pz = p[:, 0], p[:, 1], p[:, 2]
            ex_ = {k: v0 * (1 - px) + v1 * px for k, (v0, v1) in corner.items()}
            end_values.append((ex_[0, 0] * (1 - py) + ex_[1, 0] * py) * (1 - pz)
                              + (ex_[0, 1] * (1 - py) + ex_[1, 1] * py) * pz)
        # corner values lerped along x first
        e, dx = {}, {}
        for (y, z), (v0, v1) in corner.items():
            dx[y, z] = v1 - v0
            e[y, z] = v0 + u[:, 0] * dx[y, z]
        vy, vz = u[:, 1], u[:, 2]

        def bilerp(g):
            return (g[0, 0] * (1 - vy) + g[1, 0] * vy) * (1 - vz) + (g[0, 1] * (1 - vy) + g[1, 1] * vy) * vz

        F = bilerp(e)
        Fx = bilerp(dx)
        Fy = (e[1, 0] - e[0, 0]) * (1 - vz) + (e[1, 1] - e[0, 1]) * vz
        Fz = (e[0, 1] - e[0, 0]) * (1 - vy) + (e[1, 1] - e[1, 0]) * vy
        Fxy = (dx[1, 0] - dx[0, 0]) * (1 - vz) + (dx[1, 1] - dx[0, 1]) * vz
        Fxz = (dx[0, 1] - dx[0, 0]) * (1 - vy) + (dx[1, 1] - dx[1, 0]) * vy
        Fyz = e[1, 1] - e[1, 0] - e[0, 1] + e[0, 0]
        Fxyz = dx[1, 1] - dx[1, 0] - dx[0, 1] + dx[0, 0]
        hx, hy, hz = hu[:, 0], hu[:, 1], hu[:, 2]
        coef = np.stack([F, Fx * hx + Fy * hy + Fz * hz,
                         Fxy * hx * hy + Fxz * hx * hz + Fyz * hy * hz,
                         Fxyz * hx * hy * hz], axis=1)
        return coef, end_values[0], end_values[1]

    def march(self, o, d, t0, t1, M, step):
        """Calls step(active, pieces) window after window; step returns rays now done."""
        tcur = t0.copy()
        active = np.ones(len(t0), bool)
        # inf and nan are expected (parallel axes, absent roots) and filtered; underflow
        # of exp(-large) is the intended 0
        with np.errstate(divide="ignore", invalid="ignore", over="ignore", under="ignore"):
            while True:
                a = np.flatnonzero(active)
                if a.size == 0:
                    return
                P, tend = self.pieces(o[a], d[a], tcur[a], t1[a], M)
                tcur[a] = tend
                done = step(a, P)
                active[a] = ~(done | (tend >= t1[a]))

    # -- simple modes ------------------------------------------------------------
    def extreme(self, o, d, t0, t1, sign, where=False):
        """The largest (sign 1) or smallest (-1) value on each ray; with ``where``, also
        the ray distance where it is first reached."""
        best = np.full(len(t0), -np.inf)
        t_best = np.full(len(t0), np.nan)

        def first_top(v):
            """Index of the first entry within rounding (8 ulp) of each row's largest: the
            first place a tie is reached, whatever the last bits of the evaluation."""
            top = v.max(axis=1)
            slack = np.where(np.isfinite(top), 8 * np.finfo(float).eps * np.abs(top), 0.0)
            return np.argmax(v >= (top - slack)[:, None], axis=1)

        def step(a, P):
            E, PE = _monotone_split(P["coef"], P["fa"], P["fb"])
            m = np.full((len(a), _WINDOW["other"]), -np.inf)
            k = first_top(sign * PE)                    # the piece's first extreme
            top = (sign * PE)[np.arange(len(k)), k]
            m[P["rows"], P["cols"]] = top
            tm = np.full((len(a), _WINDOW["other"]), np.nan)
            tm[P["rows"], P["cols"]] = P["tm"] + P["h"] * E[np.arange(len(k)), k]
            col = first_top(m)                          # pieces are in ray order: the first
            window_best = m[np.arange(len(a)), col]
            slack = np.where(np.isfinite(best[a]), 8 * np.finfo(float).eps * np.abs(best[a]), 0.0)
            higher = window_best > best[a] + slack
            best[a[higher]] = window_best[higher]
            t_best[a[higher]] = tm[np.flatnonzero(higher), col[higher]]
            return np.zeros(len(a), bool)

        self.march(o, d, t0, t1, _WINDOW["other"], step)
        value = np.where(np.isfinite(best), sign * best, np.nan)
        return (value, t_best) if where else value

    def average(self, o, d, t0, t1):
        integral = np.zeros(len(t0))
        length = np.zeros(len(t0))

        def step(a, P):
            c, h = P["coef"], P["h"]
            # integral of the cubic over tau in [-1, 1], times dt/dtau = h
            integral[a] += np.bincount(P["rows"], h * (2 * c[:, 0] + (2.0 / 3.0) * c[:, 2]), len(a))
            length[a] += np.bincount(P["rows"], 2 * h, len(a))
            return np.zeros(len(a), bool)

        self.march(o, d, t0, t1, _WINDOW["other"], step)
        return np.where(length > 0, integral / np.where(length > 0, length, 1.0), np.nan)

    def isosurface(self, o, d, t0, t1):
        v = self.scene.iso_value
        side = np.full(len(t0), -1, np.int8)     # -1 unknown, 1: f >= v at entry, 0: f < v
        thit = np.full(len(t0), np.nan)
        M = _WINDOW["other"]

        def step(a, P):
            rows = P["rows"]
            E, PE = _monotone_split(P["coef"], P["fa"], P["fb"])
            sa = side[a]
            if rows.size:
                first_rows, first = np.unique(rows, return_index=True)
                unset = sa[first_rows] < 0
                sa[first_rows[unset]] = PE[first[unset], 0] >= v
                side[a] = sa
            inside = sa[rows] == 1
            # strictly on the other side: a touch of v without crossing is not a hit
            opp = np.where(inside[:, None], PE < v, PE > v)
            anyo = opp.any(axis=1)
            q = np.argmax(opp, axis=1)
            pi = np.flatnonzero(anyo)
            tau = np.full(len(rows), np.nan)
            q0 = pi[q[pi] == 0]
            tau[q0] = -1.0
            qn = pi[q[pi] > 0]
            if qn.size:
                j = q[qn]
                tau[qn] = _solve(P["coef"][qn], E[qn, j - 1], E[qn, j], np.full(qn.size, v))
            m = np.full((len(a), M), np.nan)
            m[rows[pi], P["cols"][pi]] = P["tm"][pi] + P["h"][pi] * tau[pi]
            hitw = ~np.isnan(m).all(axis=1)
            kf = np.argmax(~np.isnan(m), axis=1)
            thit[a[hitw]] = m[np.flatnonzero(hitw), kf[hitw]]
            return hitw

        self.march(o, d, t0, t1, M, step)
        return thit

    # -- composite -------------------------------------------------------------------
    def composite(self, o, d, t0, t1):
        n = len(t0)
        od = np.zeros(n)
        col = np.zeros((n, 3))
        opaque = np.zeros(n, bool)
        od_stop = -np.log(_T_STOP)

        def step(a, P):
            T = np.exp(-od[a])
            if self.lighting is not None:
                r = a[P["rows"]]
                P["base"] = o[r] + P["tm"][:, None] * d[r]
                P["hd"] = P["h"][:, None] * d[r]
                P["dir"] = d[r]
            OD, C, term = self.window(P, T, len(a))
            col[a] += T[:, None] * C
            if not self.emission:          # emission only: nothing absorbs, T stays 1
                od[a] += OD
            opaque[a] |= term
            return term | (od[a] > od_stop)

        self.march(o, d, t0, t1, _WINDOW["composite"], step)
        A = np.where(opaque, 1.0, -np.expm1(-od))
        if self.emission:
            A = np.zeros(n)
        return np.concatenate([col, A[:, None]], axis=1)

    # -- shading -----------------------------------------------------------------------
    def shade(self, points, dirs):
        c = np.broadcast_to(self.tf.color(self.scene.iso_value), points.shape)
        g = gradient(self.vol, self.values, points)
        return shade_blinn_phong(c, g, dirs, self.scene.phong, gradient_epsilon(self.vol), scene_lights(self.scene))


class _MeshExact(_Classified):
    """A tetrahedral mesh: each ray's segments through the tets (``mesh_rays``), sorted
    by t with overlapping coverage removed, are pieces on which the field is linear in t
    (coefficients ``[s_mid, (s1 - s0) / 2, 0, 0]`` in tau), integrated as the grid's
    pieces are. Gaps between segments (a non-convex domain) add nothing.

    Every method takes ``seg``, a dict of flat arrays sorted by ray then t (``ray``: the
    local ray index in [0, n), ``t0``, ``t1``, ``s0``, ``s1``, ``tet``), and ``n``."""

    def __init__(self, scene):
        super().__init__(scene.tf, scene.optical_model)
        self.scene = scene
        self.mesh = scene.volume
        self.terms = sample_terms(scene, None)
        if self.terms is not None:
            from ..model.mesh import cell_fields
            self.gradients = cell_fields(self.mesh)[:, 0, :3]
            origins, dirs = scene.camera.rays(scene.width, scene.height)
            self.origins, self.dirs = origins.reshape(-1, 3), dirs.reshape(-1, 3)
            self.piece_keys = ("factor", "offset", "scale")
            self.scale_floor = self.terms.scale_floor
            if "depth_cue" in scene.illustration:   # varies along a piece: the terms at every node
                self.lighting = self.terms.at
                self.piece_keys = ("base", "hd", "dir", "grad")

    @staticmethod
    def _pieces(seg, idx, rows):
        ta, tb, fa, fb = seg["t0"][idx], seg["t1"][idx], seg["s0"][idx], seg["s1"][idx]
        coef = np.zeros((idx.size, 4))
        coef[:, 0] = 0.5 * (fa + fb)
        coef[:, 1] = 0.5 * (fb - fa)
        return dict(rows=rows, ta=ta, tb=tb, tm=0.5 * (ta + tb), h=0.5 * (tb - ta), coef=coef, fa=fa, fb=fb)

    def composite(self, seg, n):
        ray = seg["ray"]
        od = np.zeros(n)
        col = np.zeros((n, 3))
        opaque = np.zeros(n, bool)
        if ray.size:
            od_stop = -np.log(_T_STOP)
            # window w holds the pieces of rank w*M .. (w+1)*M - 1 of each ray
            M = _WINDOW["composite"]
            rank = np.arange(ray.size) - np.searchsorted(ray, ray, side="left")
            wid = rank // M
            order = np.argsort(wid, kind="stable")     # still by ray, then t, per window
            edges = np.searchsorted(wid[order], np.arange(int(wid.max()) + 2))
            active = np.ones(n, bool)
            for w in range(int(wid.max()) + 1):
                idx = order[edges[w]:edges[w + 1]]
                idx = idx[active[ray[idx]]]
                if idx.size == 0:                     # later windows hold no other rays
                    break
                a, rows = np.unique(ray[idx], return_inverse=True)
                T = np.exp(-od[a])
                P = self._pieces(seg, idx, rows)
                if "base" in self.piece_keys:     # the terms at every node (the depth cue)
                    pixel = seg["pixel"][idx]
                    P["base"] = self.origins[pixel] + P["tm"][:, None] * self.dirs[pixel]
                    P["hd"] = P["h"][:, None] * self.dirs[pixel]
                    P["dir"] = self.dirs[pixel]
                    P["grad"] = self.gradients[seg["tet"][idx]]
                elif self.piece_keys:     # each cell's terms are constant along its piece
                    dirs = self.dirs[seg["pixel"][idx]]
                    P["factor"], P["offset"], P["scale"] = self.terms.at(
                        np.zeros_like(dirs), dirs, grad=self.gradients[seg["tet"][idx]])
                OD, C, term = self.window(P, T, len(a))
                col[a] += T[:, None] * C
                if not self.emission:
                    od[a] += OD
                opaque[a] |= term
                active[a] &= ~(term | (od[a] > od_stop))
        A = np.where(opaque, 1.0, -np.expm1(-od))
        if self.emission:
            A = np.zeros(n)
        return np.concatenate([col, A[:, None]], axis=1)

    def extreme(self, seg, n, sign):
        """mip (sign 1) / minip (-1): a linear piece's extremes are at its ends."""
        best = np.full(n, -np.inf)
        np.maximum.at(best, seg["ray"], np.maximum(sign * seg["s0"], sign * seg["s1"]))
        return np.where(np.isfinite(best), sign * best, np.nan)

    def average(self, seg, n):
        length = seg["t1"] - seg["t0"]
        total = np.bincount(seg["ray"], length, n)
        integral = np.bincount(seg["ray"], 0.5 * (seg["s0"] + seg["s1"]) * length, n)
        return np.where(total > 0, integral / np.where(total > 0, total, 1.0), np.nan)

    def isosurface(self, seg, n):
        """Distance to the first crossing of iso_value (nan: none), and the tet hit. As for
        grids: the side is taken at the ray's first point in the domain; the hit is the first
        point strictly on the other side (a touch is no hit); re-entering the domain on the
        other side after a gap is a hit at the re-entry point."""
        v = self.scene.iso_value
        ray, t0, t1, s0, s1 = (seg[k] for k in ("ray", "t0", "t1", "s0", "s1"))
        thit = np.full(n, np.nan)
        cell = np.full(n, -1, np.int64)
        if ray.size == 0:
            return thit, cell
        first_rows, first = np.unique(ray, return_index=True)
        side = np.zeros(n, bool)
        side[first_rows] = s0[first] >= v
        inside = side[ray]
        at0 = np.where(inside, s0 < v, s0 > v)
        at1 = np.where(inside, s1 < v, s1 > v)
        hit = np.flatnonzero(at0 | at1)
        if hit.size:
            rows, j = np.unique(ray[hit], return_index=True)   # the first hit of each ray
            k = hit[j]
            frac = np.where(at0[k], 0.0, (s0[k] - v) / (s0[k] - s1[k]))
            thit[rows] = t0[k] + np.clip(frac, 0.0, 1.0) * (t1[k] - t0[k])
            cell[rows] = seg["tet"][k]
        return thit, cell

    def shade(self, cells, dirs):
        """Shading with the tet's own gradient (the field is linear in each tet; the
        contract's central differences are a grid's), threshold ``gradient_epsilon``."""
        from ..model.mesh import cell_fields
        c = np.broadcast_to(self.tf.color(self.scene.iso_value), dirs.shape)
        g = cell_fields(self.mesh)[cells, 0, :3]
        return shade_blinn_phong(c, g, dirs, self.scene.phong, gradient_epsilon(self.mesh), scene_lights(self.scene))


def _classify(tf, s):
    out = np.zeros((len(s), 4))
    ok = ~np.isnan(s)
    a = tf.opacity(s[ok])
    out[ok, :3] = tf.color(s[ok]) * a[:, None]
    out[ok, 3] = a
    return out


def _sabella(scene, ex, o, d, t0, t1):
    """Sabella's pixels: the intensity from composite with the colour left out (the
    integrator holds the model's colour at 0, as for absorption only), the peak value and
    its first position from the max search."""
    from .common import sabella_color
    from ..model.field import depth_range
    intensity = ex.composite(o, d, t0, t1)[:, 3]
    peak, t_peak = ex.extreme(o, d, t0, t1, 1.0, where=True)
    out = np.zeros((len(t0), 4))
    ok = ~np.isnan(peak) & (intensity > 0)
    if ok.any():
        cam = scene.camera
        near, far = depth_range(scene)
        depth = ((o[ok] + t_peak[ok, None] * d[ok] - cam.eye) @ cam.forward - near) / (far - near)
        out[ok] = sabella_color(scene.tf.color(peak[ok]), intensity[ok], depth)
    return out


def _render(scene):
    if scene.is_mesh:
        return _render_mesh(scene)
    ex = _Exact(scene)
    W, H = scene.width, scene.height
    origins, dirs = scene.camera.rays(W, H)
    o = origins.reshape(-1, 3)
    d = dirs.reshape(-1, 3)
    lo, hi = scene.volume.bounds
    t0, t1 = ray_box(o, d, lo, hi)
    if scene.clips:                   # the contract over the kept part of the domain only
        t0, t1 = clip_interval(o, d, t0, t1, plane_offsets(scene.clip_planes), scene.crop_box)
    if scene.geometry:                # opaque surfaces end the rays (whole: clips cut the data only)
        t_surface, surface_color = surface_hits(scene, o, d)
        t1 = np.minimum(t1, t_surface)
    out = np.zeros((W * H, 4))
    hit = np.flatnonzero(t1 > t0)
    chunks = range(0, hit.size, _CHUNK)
    progress = _progress(len(chunks), scene)
    for c0 in chunks:
        r = hit[c0:c0 + _CHUNK]
        args = (o[r], d[r], t0[r], t1[r])
        mode = scene.mode
        if mode == "composite" and scene.optical_model == "sabella":
            out[r] = _sabella(scene, ex, *args)
        elif mode == "composite":
            out[r] = ex.composite(*args)
        elif mode in ("mip", "minip"):
            out[r] = _classify(scene.tf, ex.extreme(*args, 1.0 if mode == "mip" else -1.0))
        elif mode == "average":
            out[r] = _classify(scene.tf, ex.average(*args))
        elif mode == "isosurface":
            th = ex.isosurface(*args)
            got = np.flatnonzero(~np.isnan(th))
            if got.size:
                rr = r[got]
                out[rr, :3] = ex.shade(o[rr] + th[got, None] * d[rr], d[rr])
                out[rr, 3] = 1.0
        else:  # pragma: no cover - Scene validates the mode
            raise ValueError(f"unknown mode {mode!r}")
        if progress is not None:
            progress.advance(f"exact image {W}x{H}")
    if progress is not None:
        progress.close()
    if scene.geometry:                # each surface behind what its ray gathered in front of it
        out = surface_behind(out, t_surface, surface_color)
    if not np.all(np.isfinite(out)):
        raise FloatingPointError("exact: non-finite pixel values (a bug in the integrator)")
    return out.reshape(H, W, 4)


def _progress(steps, scene):
    """A progress bar for exact images of more than a few blocks of rays (seconds)."""
    if steps < 4:
        return None
    from ..util.progress import Progress
    return Progress(steps)


def _render_mesh(scene):
    from .mesh_rays import MeshRays, clip_segments, kept_intervals, union_segments
    W, H = scene.width, scene.height
    rays = MeshRays(scene)
    cut = scene.clips or scene.geometry
    if cut:                           # each ray's kept interval, world coordinates
        kept = kept_intervals(scene)
    if scene.geometry:                # ... ended by the first surface (which clips leave whole)
        t_surface, surface_color = surface_hits(scene)
        kept = (kept[0], np.minimum(kept[1], t_surface))
    ex = _MeshExact(scene)
    out = np.zeros((W * H, 4))
    mode = scene.mode
    d = None
    blocks = list(rays.row_blocks(_MESH_BUDGET))
    progress = _progress(len(blocks), scene)
    for r0, r1 in blocks:
        if progress is not None:
            progress.advance(f"exact image {W}x{H}")
        seg = union_segments(rays.segments(r0, r1))
        if cut:                       # the contract over the kept part of the domain only
            seg = clip_segments(seg, *kept)
        if seg["pixel"].size == 0:
            continue
        pix, seg["ray"] = np.unique(seg["pixel"], return_inverse=True)
        n = pix.size
        if mode == "composite":
            out[pix] = ex.composite(seg, n)
        elif mode in ("mip", "minip"):
            out[pix] = _classify(scene.tf, ex.extreme(seg, n, 1.0 if mode == "mip" else -1.0))
        elif mode == "average":
            out[pix] = _classify(scene.tf, ex.average(seg, n))
        elif mode == "isosurface":
            th, cell = ex.isosurface(seg, n)
            got = np.flatnonzero(~np.isnan(th))
            if got.size:
                if d is None:
                    d = scene.camera.rays(W, H)[1].reshape(-1, 3)
                out[pix[got], :3] = ex.shade(cell[got], d[pix[got]])
                out[pix[got], 3] = 1.0
        else:  # pragma: no cover - Scene validates the mode
            raise ValueError(f"unknown mode {mode!r}")
    if progress is not None:
        progress.close()
    if scene.geometry:
        out = surface_behind(out, t_surface, surface_color)
    if not np.all(np.isfinite(out)):
        raise FloatingPointError("exact: non-finite pixel values (a bug in the integrator)")
    return out.reshape(H, W, 4)


def render(scene):
    """The exact image of a one-volume (or mesh) scene, float64 (H, W, 4)."""
    return _render(scene)
