"""NumPy twin of the walk by crossings (``shaders/common/crossing_walk.glsl``, a ray-casting
plan with ``refine_walk="crossings"``; ``dvr_gl.techniques.crossing_walk``), in float64:
the same cells passed over, the same cubics from the same corners (the shader's from
their trilinear coefficients, stored in float32), the same crossings and pieces, read
from the same pre-integrated table."""

from __future__ import annotations

import numpy as np

from ..techniques.crossing_walk import cube_reach
from .common import blend_under, box_rays
from .exact_geometry import surface_behind, surface_hits
from .shading import RayLighting, sample_terms

HALLEY = 2           # CW_HALLEY
ULPS = 4.8e-7        # CW_ULPS


def cubic_at(c, u):
    return c[..., 0] + u * (c[..., 1] + u * (c[..., 2] + u * c[..., 3]))


def cell_cubic(values, cell, xa, xb):
    """Twin of ``cellCubic``: (n, 4) coefficients of the trilinear field of each ``cell``
    (n, 3 as x, y, z) along xa + u (xb - xa), cell-local coordinates."""
    nz, ny, nx = values.shape
    i, j, k = cell[:, 0], cell[:, 1], cell[:, 2]
    i1, j1, k1 = np.minimum(i + 1, nx - 1), np.minimum(j + 1, ny - 1), np.minimum(k + 1, nz - 1)
    v000, v100, v010, v110 = values[k, j, i], values[k, j, i1], values[k, j1, i], values[k, j1, i1]
    v001, v101, v011, v111 = values[k1, j, i], values[k1, j, i1], values[k1, j1, i], values[k1, j1, i1]
    cx, cy, cz = v100 - v000, v010 - v000, v001 - v000
    cxy = v110 - v100 - v010 + v000
    cxz = v101 - v100 - v001 + v000
    cyz = v011 - v010 - v001 + v000
    cxyz = v111 - v110 - v101 - v011 + v100 + v010 + v001 - v000
    d = xb - xa
    ax, ay, az = xa[:, 0], xa[:, 1], xa[:, 2]
    dx, dy, dz = d[:, 0], d[:, 1], d[:, 2]
    xy = (ax * ay, ax * dy + dx * ay, dx * dy)
    xz = (ax * az, ax * dz + dx * az, dx * dz)
    yz = (ay * az, ay * dz + dy * az, dy * dz)
    xyz = (xy[0] * az, xy[0] * dz + xy[1] * az, xy[1] * dz + xy[2] * az, xy[2] * dz)
    c = np.stack([v000 + cx * ax + cy * ay + cz * az, cx * dx + cy * dy + cz * dz,
                  np.zeros_like(ax), np.zeros_like(ax)], axis=1)
    for m in range(3):
        c[:, m] += cxy * xy[m] + cxz * xz[m] + cyz * yz[m]
    for m in range(4):
        c[:, m] += cxyz * xyz[m]
    return c


def next_turn(c, u):
    """Twin of ``nextTurn``: the first turning point of the cubic beyond u, else 1."""
    qa, qb, qc = 3.0 * c[:, 3], 2.0 * c[:, 2], c[:, 1]
    scale = np.maximum(np.abs(qb), np.abs(qc))
    linear = np.abs(qa) <= 1e-7 * scale
    with np.errstate(divide="ignore", invalid="ignore"):
        r_lin = np.where(np.abs(qb) > 0, -qc / np.where(qb != 0, qb, 1.0), 2.0)
        disc = qb * qb - 4.0 * qa * qc
        q = -0.5 * (qb + np.where(qb >= 0, 1.0, -1.0) * np.sqrt(np.maximum(disc, 0.0)))
        r1q = np.where(disc >= 0, q / np.where(qa != 0, qa, 1.0), 2.0)
        r2q = np.where((disc >= 0) & (q != 0), qc / np.where(q != 0, q, 1.0), 2.0)
    r1 = np.where(linear, r_lin, r1q)
    r2 = np.where(linear, 2.0, r2q)
    nxt = np.ones_like(u)
    nxt = np.where((r1 > u) & (r1 < nxt), r1, nxt)
    nxt = np.where((r2 > u) & (r2 < nxt), r2, nxt)
    return nxt


def crossing_of(c, u, s, u_end, s_end, target):
    """Twin of ``crossingOf``: Halley's method from the chord's crossing."""
    x = u + (u_end - u) * np.clip((target - s) / np.where(s_end != s, s_end - s, 1.0), 0.0, 1.0)
    with np.errstate(invalid="ignore"):      # (an infinite target: a result the caller drops)
        for _ in range(HALLEY):
            f = cubic_at(c, x) - target
            slope = c[:, 1] + x * (2.0 * c[:, 2] + x * 3.0 * c[:, 3])
            curve = 2.0 * c[:, 2] + 6.0 * c[:, 3] * x
            den = 2.0 * slope * slope - f * curve
            step = np.where(den != 0, 2.0 * f * slope / np.where(den != 0, den, 1.0), 0.0)
            x = np.clip(x - step, u, u_end)
    return np.minimum(np.maximum(x, u + 1e-5), u_end)


def next_crossing(c, u, s, u_end, s_end, knots, tol):
    """Twin of ``nextCrossing``: (u there, the value there: the knot where one was crossed)."""
    up = np.where(s_end >= s, 1.0, -1.0)
    target = np.zeros_like(u)
    found = np.zeros(u.shape, bool)
    for knot in knots:
        ahead = ((knot - s) * up > tol) & ((s_end - knot) * up >= 0)
        take = ahead & (~found | ((knot - target) * up < 0))
        target = np.where(take, knot, target)
        found |= take
    return np.where(found, crossing_of(c, u, s, u_end, s_end, target), u_end), np.where(found, target, s_end)


def _box_exit(o, d, spacing, lo, hi):
    """Twin of ``boxExit``: where rays (o, d) leave the cells [lo, hi] (inclusive)."""
    far = np.where(d > 0, hi + 1, lo) * spacing
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(d != 0, (far - o) / d, np.inf).min(axis=1)


def _beyond(t, nudge):
    """Twin of ``beyond``: a hundred-thousandth of a cell past t, or four float32 steps of t."""
    return t + np.maximum(nudge, np.abs(t) * ULPS)


def _cell_ahead(o, d, t, spacing, dims):
    index = (o + t[:, None] * d) / spacing + 1e-4 * np.sign(d)
    return np.clip(np.floor(index).astype(np.int64), 0, dims - 2)


def render_plan(plan):
    """The reference image of a ray-casting plan with the walk by crossings, (H, W, 4)."""
    scene = plan.scene
    volume, cw = scene.volume, plan.crossings
    H, W = scene.height, scene.width
    origins, dirs, t0, t1 = box_rays(scene)
    if scene.geometry:
        t_surface, surface_color = surface_hits(scene)
        t1 = np.minimum(t1, t_surface)
    out = np.zeros((origins.shape[0], 4))
    hit = np.flatnonzero(t1 > t0)
    o, d, t, t1 = origins[hit], dirs[hit], t0[hit].copy(), t1[hit]
    values = volume.values(np.float64)
    terms = sample_terms(scene, values)
    spacing = np.asarray(volume.spacing, np.float64)
    dims = np.array(volume.shape[::-1])
    lo_s, hi_s, tol = cw.support[0], cw.support[1], cw.tol
    nudge = 1e-5 * spacing.min()
    falls = (d < 0).astype(np.int64)                       # the rays' octants (walk_cells)
    octant = falls[:, 0] + 2 * falls[:, 1] + 4 * falls[:, 2]
    cubes = cw.empty_cubes
    m = hit.size
    acc = np.zeros((m, 4))
    alive = np.ones(m, bool)
    counts = {"skip": 0, "cell": 0, "shows": 0, "piece": 0}
    pieces = np.zeros(m, np.int64)       # per ray

    def in_support(s):
        return (s >= lo_s - tol) & (s <= hi_s + tol)

    while True:
        # find each live ray's next cell whose cubic reaches the support
        rows = np.flatnonzero(alive & (t < t1))
        alive[:] = False
        shows = np.zeros(m, bool)
        cubic, t_a, span = np.zeros((m, 4)), np.zeros(m), np.zeros(m)
        while rows.size:
            cell = _cell_ahead(o[rows], d[rows], t[rows], spacing, dims)
            code = cubes[octant[rows], cell[:, 2], cell[:, 1], cell[:, 0]].astype(np.int64)
            going = np.flatnonzero((code > 0) & (t[rows] < t1[rows]))
            while going.size:        # cubes of empty cells, from the cell towards the ray's octant
                counts["skip"] += going.size
                r = rows[going]
                grow = cube_reach(code[going])[:, None]
                lo, hi = cell[going] - grow * falls[r], cell[going] + grow * (1 - falls[r])
                t[r] = np.maximum(_box_exit(o[r], d[r], spacing, lo, hi), _beyond(t[r], nudge))
                cell[going] = _cell_ahead(o[r], d[r], t[r], spacing, dims)
                code[going] = cubes[octant[r], cell[going, 2], cell[going, 1], cell[going, 0]]
                going = going[(code[going] > 0) & (t[r] < t1[r])]
            keep = t[rows] < t1[rows]
            rows, cell = rows[keep], cell[keep]
            if rows.size == 0:
                break
            t_out = _box_exit(o[rows], d[rows], spacing, cell, cell)
            ta = t[rows]
            tb = np.minimum(t_out, t1[rows])
            t[rows] = np.where(tb > ta, tb, np.maximum(t_out, _beyond(ta, nudge)))
            ok = tb > ta
            r, cell, ta, tb = rows[ok], cell[ok], ta[ok], tb[ok]
            counts["cell"] += r.size
            c = cell_cubic(values, cell, (o[r] + ta[:, None] * d[r]) / spacing - cell,
                           (o[r] + tb[:, None] * d[r]) / spacing - cell)
            cubic[r], t_a[r], span[r] = c, ta, tb - ta
            # the range of the cubic's Bernstein coefficients holds it
            bern = np.stack([c[:, 0], c[:, 0] + c[:, 1] / 3.0, c[:, 0] + (2.0 * c[:, 1] + c[:, 2]) / 3.0, c.sum(axis=1)])
            found = (bern.max(axis=0) >= lo_s) & (bern.min(axis=0) <= hi_s)
            shows[r[found]] = True
            rows = np.concatenate([rows[~ok], r[~found]])
            rows = rows[t[rows] < t1[rows]]
        rows = np.flatnonzero(shows)
        if rows.size == 0:
            break
        counts["shows"] += rows.size
        # the cell's pieces
        c = cubic[rows]
        u1 = next_turn(c, np.zeros(rows.size))
        u2 = next_turn(c, u1)
        e1, e2, e_end = cubic_at(c, u1), cubic_at(c, u2), cubic_at(c, 1.0)
        u, s = np.zeros(rows.size), c[:, 0].copy()
        cell_acc = acc[rows]
        live = np.flatnonzero(u < 1.0)
        while live.size:
            cl, ul, sl = c[live], u[live], s[live]
            a1, a2, b1, b2, be = u1[live], u2[live], e1[live], e2[live], e_end[live]

            def turn(x):
                return (np.where(a1 > x, a1, np.where(a2 > x, a2, 1.0)),
                        np.where(a1 > x, b1, np.where(a2 > x, b2, be)))
            u_turn, s_turn = turn(ul)
            outside = ~in_support(sl)
            edge = np.where(sl < lo_s, lo_s, hi_s)
            enters = (s_turn - edge) * (sl - edge) <= 0
            moved = np.where(enters, crossing_of(cl, ul, sl, u_turn, s_turn, edge), u_turn)
            moved_s = np.where(enters, edge, s_turn)
            ul = np.where(outside, moved, ul)
            sl = np.where(outside, moved_s, sl)
            piece_rows = ~outside | enters
            u_turn2, s_turn2 = turn(ul)
            u_turn = np.where(outside, u_turn2, u_turn)
            s_turn = np.where(outside, s_turn2, s_turn)
            u[live], s[live] = ul, sl
            p = np.flatnonzero(piece_rows)
            if p.size:
                counts["piece"] += p.size
                rp = rows[live[p]]
                pieces[rp] += 1
                cp, up, sp, spn = cl[p], ul[p], sl[p], span[rp]
                u_end = np.minimum(u_turn[p], up + cw.part / spn)
                s_end = np.where(u_end == u_turn[p], s_turn[p], cubic_at(cp, u_end))
                u_next, s_next = next_crossing(cp, up, sp, u_end, s_end, cw.knots, tol)
                length = (u_next - up) * spn
                shift = (4.0 * cubic_at(cp, 0.5 * (up + u_next)) - 2.0 * (sp + s_next)) / 6.0
                piece = plan.preint_fine.segment(sp + shift, s_next + shift, length)
                if terms is not None:
                    t_mid = t_a[rp] + 0.5 * (up + u_next) * spn
                    piece = RayLighting(terms, o[rp], d[rp]).segments(piece, t_mid)
                lp = live[p]
                cell_acc[lp] = blend_under(cell_acc[lp], piece)
                a1p, a2p = u1[lp], u2[lp]
                ahead = np.stack([e_end[lp], np.where(a2p > u_next, e2[lp], e_end[lp]),
                                  np.where(a1p > u_next, e1[lp], e_end[lp])])
                returns = np.where(s_next < lo_s, ahead.max(axis=0) >= lo_s, ahead.min(axis=0) <= hi_s)
                s_ahead = np.where(a1p > u_next, e1[lp], np.where(a2p > u_next, e2[lp], e_end[lp]))
                leaving = (((s_next >= hi_s - tol) & (s_ahead > s_next))
                           | ((s_next <= lo_s + tol) & (s_ahead < s_next)))
                u[lp] = np.where((in_support(s_next) & ~leaving) | returns, u_next, 1.0)
                s[lp] = s_next
            live = live[u[live] < 1.0]
        acc[rows] = cell_acc
        stop = acc[rows, 3] >= 1
        if plan.ert_transmittance > 0:
            stop |= 1 - acc[rows, 3] < plan.ert_transmittance
        alive[rows[~stop]] = True
    out[hit] = acc
    render_plan.counts = dict(counts, rays=int(m), max_pieces=int(pieces.max(initial=0)))
    if scene.geometry:
        out = surface_behind(out, t_surface, surface_color)
    return out.reshape(H, W, 4)
