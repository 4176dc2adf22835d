"""The exact image of a scene of several volumes (docs/contract.md, "Several volumes"), in float64.

Method (blend "mix"). Each layer sees the camera's rays in its own frame: a world ray
``o + t d`` is ``to_local(o) + t direction_to_local(d)`` there, with the same t (the
placement is rigid), so every layer's box, grid planes and field are met at the same ray
parameters. A ray's interval is the union of the layers' boxes (each intersected in its
own frame by ``ray_box``), cut by the clip planes and crop box (``clip_interval``, world
units) and ended by the first opaque surface (``exact_geometry.surface_hits``).

The ray is broken wherever some layer's field or classification is not smooth: at each
layer's box entry and exit, at its grid planes (a scan's integer index planes, where the
trilinear field changes cell; a label volume's half-integer planes, where the nearest
sample changes), and inside the resulting pieces where a scan's cubic (the trilinear
field along the ray within its cell, expanded as ``exact_one._Exact.cubic`` does) crosses a
control point of its transfer function, found as ``exact_one`` finds them (``_monotone_split``,
``_solve``). On every sub-piece between consecutive breakpoints each scan's colour and
opacity are linear in its value, each label's are constant, and ``tau = sum tau_i`` and
``c tau = sum c_i tau_i`` are analytic. Sub-pieces go through adaptive Gauss-Kronrod 7/15
as in ``exact_one`` (the transmittance at the nodes by the spectral integration matrix;
halving until the G7/K15 differences of optical depth and colour, and of
``sum w tau T`` against ``1 - exp(-OD)``, times a rigorous upper bound of the
transmittance in front, are below ``_TOL``), and the transmittance is chained across
them. Sub-pieces behind a transmittance bound below ``_T_STOP`` are left out.

A point where some layer has alpha = 1 ends the ray (the contract): the first such point
is a knot crossing or a touch of an opaque value by a scan, a piece end where a scan's
value is opaque, or the start of a piece in an opaque label's cell. The rest of the
transmittance goes to the mean colour of the layers opaque there, with the integrand of
the last sub-piece written as ``sum (c_i - c_end) tau_i T`` (bounded where a scan's tau
has its log singularity), as ``exact_one`` does for one volume; A = 1.

Blend "add": each layer's image alone on the same (clipped, shortened) rays: composite by
the integrator above with that layer alone; mip, minip and average by ``exact_one._Exact`` of
the layer's own volume, run on the rays carried into the layer's frame. The images add,
``C = sum C_i``, ``A = 1 - prod (1 - A_i)``, and the opaque surface goes once behind the sum.

Choices where the contract is silent: an opaque label cell ends the ray where the ray
enters it (at the face between two cells, whichever label the halves-upward rule gives the
face itself), with that label's colour; a masked cell of a scan layer is outside that
layer's domain only.

The machinery is the one-volume integrator's (``exact_one``), reused: its helpers and
quadrature rules, and each scan layer gets its ``_Exact`` of the layer's own volume for its cubics and
transfer-function tables. Rays are processed in blocks of about ``_PIECE_BUDGET``
breakpoints, each block vectorised over its rays, pieces and parts (no loop over rays).

Accuracy: against closed forms (constant boxes, one turned about an oblique axis, with a
clip plane or a surface; label volumes, opaque boxes and labels) and against the
one-volume exact image (one layer; a placed layer against its volume seen from the moved
camera; two equal layers against one of doubled tau; add against the sum of one-volume
images), the differences are below 1e-14. Rays that lie exactly in a face plane of a
placed layer's box meet it or not as the rounding of the motion decides.
"""

from __future__ import annotations

import numpy as np

from ..model.clipping import clip_interval, plane_offsets
from ..model.scene import Scene
from .common import ray_box
from . import exact_one as one
from .exact_geometry import surface_behind, surface_hits

__all__ = ["render_layers"]

_PIECE_BUDGET = 1 << 17    # geometric pieces per block of rays (bounds memory)
_BATCH = 8192              # quadrature parts evaluated at a time


# --------------------------------------------------------------------------- one layer
class _Placed:
    """A layer and every ray carried into its frame: ``o``, ``d`` (local), and the part
    ``[a, b]`` of each ray inside its box and the kept interval (b <= a: none)."""

    def __init__(self, layer, scene, o, d, t0, t1):
        vol = layer.volume
        self.layer = layer
        self.labels = layer.is_labels
        self.origin, self.spacing = vol.origin, vol.spacing
        self.dims = vol.dims
        self.o = layer.to_local(o)
        self.d = layer.direction_to_local(d)
        a, b = ray_box(self.o, self.d, *vol.bounds)
        self.a, self.b = np.maximum(a, t0), np.minimum(b, t1)
        if self.labels:
            self.data = vol.data.astype(np.int64)
            self.rgba = layer.tf.rgba
            self.inv_u = 1.0 / layer.tf.unit_distance
        else:   # the one-volume integrator of this layer's own volume: cubics and TF tables
            self.ex = one._Exact(Scene(vol, layer.tf, scene.camera, width=scene.width, height=scene.height))

    def crossings(self, rays, count=False):
        """Breakpoints of rays (global indices): box entry and exit and every grid plane
        strictly between them, as (local ray index, t); with ``count``, their number per ray."""
        o, d, a, b = self.o[rays], self.d[rays], self.a[rays], self.b[rays]
        inside = b > a
        shift = 0.5 if self.labels else 0.0       # labels change halfway between samples
        total = np.where(inside, 2, 0)
        ray_parts, t_parts = [np.flatnonzero(inside)] * 2, [a[inside], b[inside]]
        for ax in range(3):
            da = d[:, ax]
            p0 = (o[:, ax] + a * da - self.origin[ax]) / self.spacing[ax] - shift
            p1 = (o[:, ax] + b * da - self.origin[ax]) / self.spacing[ax] - shift
            first = np.floor(np.minimum(p0, p1)) + 1
            last = np.ceil(np.maximum(p0, p1)) - 1
            n = np.where(inside & (da != 0), np.maximum(last - first + 1, 0), 0).astype(np.int64)
            total = total + n
            if count:
                continue
            ray = np.repeat(np.arange(len(rays)), n)
            k = np.repeat(first, n) + (np.arange(ray.size) - np.repeat(np.cumsum(n) - n, n))
            t = (self.origin[ax] + (k + shift) * self.spacing[ax] - o[ray, ax]) / da[ray]
            ray_parts.append(ray)
            t_parts.append(np.clip(t, a[ray], b[ray]))
        if count:
            return total
        return ray_parts, t_parts

    def local_index(self, rays, t):
        """Index coordinates (x, y, z) of the points at t on the given (global) rays."""
        return (self.o[rays] + t[:, None] * self.d[rays] - self.origin) / self.spacing


# --------------------------------------------------------------------------- the mixture
class _Mix:
    """The composite integral of a mixture of layers (one medium: extinctions and
    emissions add) over each ray's kept interval."""

    def __init__(self, placed):
        self.placed = placed

    def blocks(self, rays):
        """The positions in ``rays`` of the rays that meet a layer, in blocks of about
        ``_PIECE_BUDGET`` breakpoints."""
        counts = sum(p.crossings(rays, count=True) for p in self.placed)
        busy = np.flatnonzero(counts > 0)
        edges = np.searchsorted(np.cumsum(counts[busy]), np.arange(1, counts.sum() // _PIECE_BUDGET + 1)
                                * _PIECE_BUDGET)
        return [b for b in np.split(busy, np.unique(edges)) if b.size]

    def render(self, rays, blocks, progress=None, label=""):
        """(len(rays), 4) premultiplied RGBA of the given (global) rays."""
        out = np.zeros((len(rays), 4))
        for block in blocks:
            out[block] = self.block(rays[block])
            if progress is not None:
                progress.advance(label)
        return out

    # -- pieces -----------------------------------------------------------------------
    def block(self, rays):
        """The pixels of one block of rays: its pieces (between consecutive breakpoints of
        all layers), each layer's field on them, then the integral."""
        n = len(rays)
        ray_parts, t_parts = [], []
        for p in self.placed:
            r, t = p.crossings(rays)
            ray_parts += r
            t_parts += t
        ray, t = np.concatenate(ray_parts), np.concatenate(t_parts)
        order = np.lexsort((t, ray))
        ray, t = ray[order], t[order]
        ok = (ray[1:] == ray[:-1]) & (t[1:] > t[:-1])
        prow, ta, tb = ray[:-1][ok], t[:-1][ok], t[1:][ok]
        tm = 0.5 * (ta + tb)
        pres = [(tm > p.a[rays][prow]) & (tm < p.b[rays][prow]) for p in self.placed]
        keep = np.any(pres, axis=0)
        prow, ta, tb, tm = prow[keep], ta[keep], tb[keep], tm[keep]
        pres = [q[keep] for q in pres]
        piece = dict(row=prow, ta=ta, tb=tb, tm=tm, h=0.5 * (tb - ta), ray=rays[prow])
        fields, cuts, events = [], [], []
        for L, p in enumerate(self.placed):
            f, c, e = (self.label_field if p.labels else self.scan_field)(p, piece, pres[L])
            fields.append(f)
            cuts.append(c)
            events.append(e)
        return self.integrate(piece, fields, cuts, events, n)

    def scan_field(self, p, piece, pres):
        """A scan on the pieces: its cubic per piece, the knot crossings inside them, and
        the points where it is opaque (events: piece, tau, layer, colour)."""
        ex = p.ex
        npc = len(piece["ta"])
        j = np.flatnonzero(pres)
        r = piece["ray"][j]
        idx = p.local_index(r, piece["tm"][j])
        cell = np.clip(np.floor(idx), 0, p.dims - 2).astype(np.int64)
        if ex.valid is not None:       # masked cells are outside this layer's domain
            nz, ny, nx = ex.vol.shape
            good = ex.valid[(cell[:, 2] * (ny - 1) + cell[:, 1]) * (nx - 1) + cell[:, 0]]
            j, r, idx, cell = j[good], r[good], idx[good], cell[good]
        flat = cell[:, 2] * ex.nxy + cell[:, 1] * ex.nx + cell[:, 0]
        ends = [p.local_index(r, piece[k][j]) - cell for k in ("ta", "tb")]
        hu = piece["h"][j, None] * p.d[r] / p.spacing
        coef, fa, fb = ex.cubic(flat, idx - cell, hu, ends)
        E, PE = one._monotone_split(coef, fa, fb)
        # pieces whose value range lies where opacity is 0 neither emit nor absorb
        busy = ex.nzcum[ex.interval(PE.max(axis=1)) + 1] - ex.nzcum[ex.interval(PE.min(axis=1))] > 0
        j, coef, E, PE, fa, fb = j[busy], coef[busy], E[busy], PE[busy], fa[busy], fb[busy]
        field = dict(pres=np.zeros(npc, bool), coef=np.zeros((npc, 4)), crit=np.zeros((npc, 2)))
        field["pres"][j] = True
        field["coef"][j] = coef
        field["crit"][j] = E[:, 1:3]
        # crossings of the TF's knots by each piece's cubic
        pi, knot_s, knot_tau = one._knot_crossings(ex.K, coef, E, PE)
        # interior critical points where alpha reaches 1 (a touch of an opaque value)
        ci, cj = np.nonzero((E[:, 1:3] > -1) & (E[:, 1:3] < 1) & (ex.tf.opacity(PE[:, 1:3]) >= 1))
        cuts = (np.concatenate([j[pi], j[ci]]), np.concatenate([knot_tau, E[ci, cj + 1]]))
        # opaque points: piece ends, knots and touches where alpha = 1
        ev_piece = np.concatenate([j, j, j[pi], j[ci]])
        ev_tau = np.concatenate([np.full(j.size, -1.0), np.ones(j.size), knot_tau, E[ci, cj + 1]])
        ev_s = np.concatenate([fa, fb, knot_s, PE[ci, cj + 1]])
        opaque = ex.tf.opacity(ev_s) >= 1
        events = (ev_piece[opaque], ev_tau[opaque], ex.tf.color(ev_s[opaque]))
        return field, cuts, events

    def label_field(self, p, piece, pres):
        """A label volume on the pieces: the label of the nearest sample (halves upward),
        constant on each piece; an opaque label is an event at the piece's start."""
        npc = len(piece["ta"])
        j = np.flatnonzero(pres)
        idx = p.local_index(piece["ray"][j], piece["tm"][j])
        near = np.clip(np.floor(idx + 0.5), 0, p.dims - 1).astype(np.int64)
        rgba = p.rgba(p.data[near[:, 2], near[:, 1], near[:, 0]])
        alpha = rgba[:, 3]
        field = dict(pres=np.zeros(npc, bool), tau=np.zeros(npc), rgb=np.zeros((npc, 3)))
        field["pres"][j] = alpha > 0
        field["tau"][j] = -np.log1p(-np.clip(alpha, 0.0, one._ALPHA_MAX)) * p.inv_u
        field["rgb"][j] = rgba[:, :3]
        op = alpha >= 1
        events = (j[op], np.full(int(op.sum()), -1.0), rgba[op, :3])
        return field, (np.zeros(0, np.int64), np.zeros(0)), events

    # -- integration ------------------------------------------------------------------
    def integrate(self, piece, fields, cuts, events, n):
        npc = len(piece["ta"])
        prow = piece["row"]
        # sub-pieces: between consecutive breakpoints of every layer inside each piece
        cp = np.concatenate([np.arange(npc), np.arange(npc)] + [c[0] for c in cuts])
        ct = np.concatenate([np.full(npc, -1.0), np.ones(npc)] + [c[1] for c in cuts])
        order = np.lexsort((ct, cp))
        cp, ct = cp[order], ct[order]
        ok = (cp[1:] == cp[:-1]) & (ct[1:] > ct[:-1])
        sp, sa, sb = cp[:-1][ok], ct[:-1][ok], ct[1:][ok]

        # the first opaque point of each ray, and the mean colour of the layers opaque there
        opaque = np.zeros(n, bool)
        p_star = np.full(n, np.iinfo(np.int64).max)
        tau_star = np.full(n, np.inf)
        cend_ray = np.zeros((n, 3))
        ev_piece = np.concatenate([e[0] for e in events]).astype(np.int64)
        if ev_piece.size:
            ev_tau = np.concatenate([e[1] for e in events])
            ev_rgb = np.concatenate([e[2] for e in events])
            ev_layer = np.concatenate([np.full(len(e[0]), L) for L, e in enumerate(events)])
            ev_t = np.where(ev_tau == -1, piece["ta"][ev_piece],
                            np.where(ev_tau == 1, piece["tb"][ev_piece],
                                     piece["tm"][ev_piece] + piece["h"][ev_piece] * ev_tau))
            ev_ray = prow[ev_piece]
            order = np.lexsort((ev_tau, ev_piece, ev_t, ev_ray))
            rows, first = np.unique(ev_ray[order], return_index=True)
            f = order[first]
            opaque[rows] = True
            p_star[rows], tau_star[rows] = ev_piece[f], ev_tau[f]
            t_star = np.full(n, np.nan)
            t_star[rows] = ev_t[f]
            tie = np.flatnonzero(ev_t == t_star[ev_ray])
            _, once = np.unique(ev_ray[tie] * len(events) + ev_layer[tie], return_index=True)
            tie = tie[once]                        # each layer opaque there counted once
            count = np.bincount(ev_ray[tie], minlength=n)
            for ch in range(3):
                cend_ray[:, ch] = np.bincount(ev_ray[tie], ev_rgb[tie, ch], n) / np.maximum(count, 1)

        srow = prow[sp]
        before = ~opaque[srow] | (sp < p_star[srow]) | ((sp == p_star[srow]) & (sb <= tau_star[srow]))
        sp, sa, sb, srow = sp[before], sa[before], sb[before], srow[before]
        singular = opaque[srow] & (sp == p_star[srow]) & (sb == tau_star[srow])

        # each layer on each sub-piece (absent where its opacity is 0 there)
        mid = 0.5 * (sa + sb)
        sub = dict(h=piece["h"][sp], cend=np.where(singular[:, None], cend_ray[srow], 0.0), layers=[])
        for p, f in zip(self.placed, fields):
            g = {k: v[sp] for k, v in f.items()}
            if not p.labels:
                g["m"] = p.ex.interval(one._peval(g["coef"], mid))
                g["pres"] &= p.ex.nzint[g["m"]]
            sub["layers"].append(g)
        live = np.any([g["pres"] for g in sub["layers"]], axis=0) | singular
        keep = np.flatnonzero(live)
        # weights: a rigorous upper bound of the transmittance in front of each sub-piece
        lower = self.od_lower(sub, keep, sa[keep], sb[keep])
        weight = np.exp(-one._segmented_exclusive_sum(lower, srow[keep]))
        keep, weight = keep[weight >= one._T_STOP], weight[weight >= one._T_STOP]
        psub, pta, pod, pcol = self.quadrature(sub, keep, sa[keep], sb[keep], weight)

        # a zero-thickness part at the start of each opaque ray's last sub-piece (at the
        # opaque point itself when it has none) carries T there times the opaque colour
        rows = np.flatnonzero(opaque)
        last = np.full(n, -1)
        si = np.flatnonzero(singular)
        last[srow[si]] = si
        pseudo_key = tau_star[rows]
        own = last[rows] >= 0
        pseudo_key[own] = sa[last[rows[own]]]
        part_piece = np.concatenate([sp[psub], p_star[rows]])
        part_ta = np.concatenate([pta, pseudo_key])
        real = np.concatenate([np.ones(psub.size, bool), np.zeros(rows.size, bool)])
        pod = np.concatenate([pod, np.zeros(rows.size)])
        pcol = np.concatenate([pcol, cend_ray[rows]], axis=0)
        order = np.lexsort((real, part_ta, part_piece))
        prow_p = prow[part_piece[order]]
        pod, pcol = pod[order], pcol[order]
        front = np.exp(-one._segmented_exclusive_sum(pod, prow_p))
        out = np.zeros((n, 4))
        for ch in range(3):
            out[:, ch] = np.bincount(prow_p, front * pcol[:, ch], n)
        out[:, 3] = np.where(opaque, 1.0, -np.expm1(-np.bincount(prow_p, pod, n)))
        return out

    def layer_tau(self, g, p, i, x):
        """Extinction (parts, nodes) and colour (parts, nodes, 3) of one layer at the
        part parameters x of sub-pieces i (rows where it is absent: 0)."""
        if p.labels:
            tau = np.broadcast_to(g["tau"][i][:, None], x.shape)
            return tau, np.broadcast_to(g["rgb"][i][:, None, :], x.shape + (3,))
        ex, m = p.ex, g["m"][i]
        ds = one._peval(g["coef"][i], x) - ex.anchor[m][:, None]
        alpha = np.clip(ex.a0[m][:, None] + ex.a1[m][:, None] * ds, 0.0, one._ALPHA_MAX)
        tau = -np.log1p(-alpha) * ex.inv_u
        return tau, ex.c0[m][:, None, :] + ex.c1[m][:, None, :] * ds[..., None]

    def gk(self, sub, i, ta, tb):
        """K15 optical depth and colour of parts [ta, tb] of sub-pieces i, and the largest
        |K15 - G7| of optical depth, colour and sum(w tau T) against 1 - exp(-OD)."""
        mid, half = 0.5 * (ta + tb), 0.5 * (tb - ta)
        x = mid[:, None] + half[:, None] * one._XK
        tau = np.zeros(x.shape)
        emit = np.zeros(x.shape + (3,))
        for p, g in zip(self.placed, sub["layers"]):
            j = np.flatnonzero(g["pres"][i])
            if j.size:
                t_l, c_l = self.layer_tau(g, p, i[j], x[j])
                tau[j] += t_l
                emit[j] += c_l * t_l[..., None]
        emit -= sub["cend"][i][:, None, :] * tau[..., None]     # 0 but on a ray's last sub-piece
        hw = sub["h"][i] * half
        Tk = np.exp(-hw[:, None] * (tau @ one._SK.T))
        tg = tau[:, one._GI]
        Tg = np.exp(-hw[:, None] * (tg @ one._SG.T))
        ODk, ODg = hw * (tau @ one._WK), hw * (tg @ one._WG)
        Ck = hw[:, None] * np.einsum("pn,pnc->pc", Tk * one._WK, emit)
        Cg = hw[:, None] * np.einsum("pn,pnc->pc", Tg * one._WG, emit[:, one._GI])
        G0k = hw * ((tau * Tk) @ one._WK)
        err = np.maximum(np.maximum(np.abs(ODk - ODg), np.abs(Ck - Cg).max(axis=1)), np.abs(G0k + np.expm1(-ODk)))
        return ODk, Ck, err

    def od_lower(self, sub, i, ta, tb):
        """A lower bound of the optical depth of parts [ta, tb] of sub-pieces i: per layer
        the smallest opacity over the part's value range (ends and interior critical
        points; opacity is linear in a scan's value on a sub-piece), summed, times the length."""
        total = np.zeros(len(i))
        for p, g in zip(self.placed, sub["layers"]):
            j = np.flatnonzero(g["pres"][i])
            if not j.size:
                continue
            ij = i[j]
            if p.labels:
                total[j] += g["tau"][ij]
                continue
            c = g["coef"][ij]
            a_, b_ = ta[j], tb[j]
            s0, s1 = one._peval(c, a_), one._peval(c, b_)
            lo, hi = np.minimum(s0, s1), np.maximum(s0, s1)
            for k in (0, 1):
                x = g["crit"][ij, k]
                inside = (x > a_) & (x < b_)
                sx = one._peval(c, x)
                lo = np.where(inside, np.minimum(lo, sx), lo)
                hi = np.where(inside, np.maximum(hi, sx), hi)
            ex, m = p.ex, g["m"][ij]
            line = ex.a0[m] + ex.a1[m] * (np.stack([lo, hi]) - ex.anchor[m])
            alpha = np.clip(line.min(axis=0), 0.0, one._ALPHA_MAX)
            total[j] += -np.log1p(-alpha) * ex.inv_u
        return total * sub["h"][i] * (tb - ta)

    def quadrature(self, sub, idx, ta, tb, weight):
        """Adaptive Gauss-Kronrod over sub-pieces idx: a part is halved until its error
        estimate times an upper bound of the transmittance in front is below ``_TOL``.
        Returns the accepted parts (sub-piece, start, optical depth, colour from T = 1)."""
        out = [(np.zeros(0, np.int64), np.zeros(0), np.zeros(0), np.zeros((0, 3)))]
        pre = np.zeros(len(idx))
        depth = 0
        while idx.size:
            OD, C, err = np.empty(idx.size), np.empty((idx.size, 3)), np.empty(idx.size)
            for b0 in range(0, idx.size, _BATCH):
                sl = slice(b0, b0 + _BATCH)
                OD[sl], C[sl], err[sl] = self.gk(sub, idx[sl], ta[sl], tb[sl])
            ok = (err * weight * np.exp(-pre) <= one._TOL) | (depth >= one._MAX_DEPTH)
            out.append((idx[ok], ta[ok], OD[ok], C[ok]))
            bad = ~ok
            idx, ta, tb, pre, weight = idx[bad], ta[bad], tb[bad], pre[bad], weight[bad]
            mid = 0.5 * (ta + tb)
            pre_right = pre + self.od_lower(sub, idx, ta, mid)
            idx, weight = np.concatenate([idx, idx]), np.concatenate([weight, weight])
            ta, tb = np.concatenate([ta, mid]), np.concatenate([mid, tb])
            pre = np.concatenate([pre, pre_right])
            depth += 1
        return tuple(np.concatenate([o[k] for o in out]) for k in range(4))


# --------------------------------------------------------------------------- the scene
def _one_layer(placed, scene, rays):
    """One layer's own image on the given rays, in the scene's mode (blend "add")."""
    out = np.zeros((len(rays), 4))
    hit = rays[placed.b[rays] > placed.a[rays]]
    if hit.size:
        args = (placed.o[hit], placed.d[hit], placed.a[hit], placed.b[hit])
        if scene.mode in ("mip", "minip"):
            value = placed.ex.extreme(*args, 1.0 if scene.mode == "mip" else -1.0)
        else:
            value = placed.ex.average(*args)
        out[np.searchsorted(rays, hit)] = one._classify(placed.layer.tf, value)
    return out


def render_layers(scene):
    """The exact (H, W, 4) image of a scene with layers. ``one`` is the one-volume
    integrator's module (``dvr_gl.reference.exact``, which calls this and hands itself
    in): its cubics, knot search, quadrature rule and tolerances serve every layer."""
    W, H = scene.width, scene.height
    origins, dirs = scene.camera.rays(W, H)
    o, d = origins.reshape(-1, 3), dirs.reshape(-1, 3)
    t0, t1 = ray_box(o, d, *scene.bounds)
    if scene.clips:                   # the contract over the kept part of the domain only
        t0, t1 = clip_interval(o, d, t0, t1, plane_offsets(scene.clip_planes), scene.crop_box)
    if scene.geometry:                # opaque surfaces end the rays (whole: clips cut the data only)
        t_surface, surface_color = surface_hits(scene, o, d)
        t1 = np.minimum(t1, t_surface)
    placed = [_Placed(layer, scene, o, d, t0, t1) for layer in scene.all_layers]
    out = np.zeros((W * H, 4))
    rays = np.flatnonzero(t1 > t0)
    label = f"exact image {W}x{H}, {len(placed)} volumes"
    if scene.blend == "mix":
        mix = _Mix(placed)
        blocks = mix.blocks(rays)
        progress = one._progress(len(blocks), scene)
        out[rays] = mix.render(rays, blocks, progress, label)
    else:                             # each layer alone, the images added
        mixes = [_Mix([p]) for p in placed] if scene.mode == "composite" else []
        blocks = [m.blocks(rays) for m in mixes]
        progress = one._progress(sum(len(b) for b in blocks), scene)
        transparency = np.ones(len(rays))
        for k, p in enumerate(placed):
            image = mixes[k].render(rays, blocks[k], progress, label) if mixes else _one_layer(p, scene, rays)
            out[rays, :3] += image[:, :3]
            transparency *= 1.0 - image[:, 3]
        out[rays, 3] = 1.0 - transparency
    if progress is not None:
        progress.close()
    if scene.geometry:                # the surface once, behind what the ray gathered
        out = surface_behind(out, t_surface, surface_color)
    if not np.all(np.isfinite(out)):
        raise FloatingPointError("exact: non-finite pixel values (a bug in the layer integrator)")
    return out.reshape(H, W, 4)
