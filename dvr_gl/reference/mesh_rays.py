"""Every pixel ray's segment through every tetrahedron of a mesh, in float64.

Method. Each tetrahedron's vertices are projected to pixel coordinates; its pixel bounding
box (the whole image where a vertex lies at or behind the eye plane of a perspective
camera, where the projection stops being a convex map) lists the candidate rays. The
(tet, pixel) candidates are enumerated in chunks of bounded size and every candidate ray
is clipped against the tet's four face planes (Cyrus-Beck).

Robustness. A face plane is computed once per *face*, from its three point indices in
ascending order (``n = (p_b - p_a) x (p_c - p_a)``, offset ``n . p_a``, points relative to
the mesh's lower corner), then oriented outwards for each of the (one or two) tets that
hold it by negation, which is exact. Two tets sharing a face therefore see bitwise
opposite planes, and a ray crossing the face leaves one tet at exactly the distance at
which it enters the other: no crack, no overlap, also for rays through edges and vertices
(where the union of the tets' intervals covers the ray up to rounding of the crossing
distances). A ray parallel to a face plane (``n . d == 0``) is outside that face's half
space iff its origin is strictly outside (``n . o > offset``); a ray lying in a face
shared by two tets is then inside both or one of them, never neither (consumers keep the
union of overlapping coverage: ``union_segments``). Tets of zero volume
(``|6 V| <= 1e-13 * (longest edge)^3``, rounding level) give no segment.

Values. The field at a point of the segment is ``sum_i lambda_i s_i`` with the barycentric
weights ``lambda_i = (n_i . x - offset_i) / (n_i . v_i - offset_i)`` from the same face
planes (exactly the tet's linear function), clamped to [0, 1] and normalised, so values
stay within the tet's vertex range also for slivers.
"""

from __future__ import annotations

import numpy as np

__all__ = ["ray_tet_segments", "union_segments", "clip_segments", "kept_intervals", "MeshRays"]

_CANDIDATES = 1 << 18      # (tet, pixel) pairs clipped at a time (bounds memory)
_MARGIN = 1e-6             # pixels added around each projected bounding box
_DEGENERATE = 1e-13        # |6V| / (longest edge)^3 at or below this: zero volume

# faces opposite vertex 0, 1, 2, 3
_FACES = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])
_KEYS = ("pixel", "tet", "t0", "t1", "s0", "s1")


def _empty():
    return {k: np.zeros(0, np.int64 if k in ("pixel", "tet") else np.float64) for k in _KEYS}


class MeshRays:
    """The prepared acceleration structure of ``scene`` (a mesh scene): face planes and
    projected pixel boxes of the (non-degenerate) tets in ``tets`` (default: all).
    ``segments(row_lo, row_hi)`` gives the segments of the image rows in that range;
    ``row_blocks(budget)`` splits the image into row ranges of at most about ``budget``
    candidates each (for callers that bound memory)."""

    def __init__(self, scene, tets=None):
        mesh = scene.volume
        W, H = scene.width, scene.height
        self.W, self.H = W, H
        cells = np.arange(len(mesh.tets), dtype=np.int64) if tets is None else np.asarray(tets, np.int64).ravel()
        lo = mesh.bounds[0]
        P = mesh.points - lo                       # relative to the lower corner (precision)
        T = mesh.tets[cells]
        # ---- face planes, one per face (sorted point indices), oriented outwards
        fidx = np.sort(T[:, _FACES], axis=2)       # (m, 4, 3)
        pa, pb, pc = P[fidx[..., 0]], P[fidx[..., 1]], P[fidx[..., 2]]
        n = np.cross(pb - pa, pc - pa)             # (m, 4, 3)
        off = np.einsum("mfk,mfk->mf", n, pa)
        opp = P[T]                                 # the vertex opposite face f is vertex f
        h = np.einsum("mfk,mfk->mf", n, opp - pa)  # n . v_f - offset: inward if > 0
        flip = h > 0
        n = np.where(flip[..., None], -n, n)
        off = np.where(flip, -off, off)
        h = np.where(flip, -h, h)                  # now < 0 (or 0: degenerate)
        # ---- zero-volume tets give nothing
        e = opp[:, [1, 2, 3, 2, 3, 3]] - opp[:, [0, 0, 0, 1, 1, 2]]
        longest = np.sqrt((e * e).sum(axis=2).max(axis=1))
        v0 = opp[:, 0]
        vol6 = np.abs(np.einsum("mk,mk->m", opp[:, 1] - v0, np.cross(opp[:, 2] - v0, opp[:, 3] - v0)))
        good = (vol6 > _DEGENERATE * longest ** 3) & (h < 0).all(axis=1)
        # ---- projected pixel boxes
        cam = scene.camera
        sx, sy = cam.screen_scale(W, H)
        q = mesh.points[T] - cam.eye               # (m, 4, 3)
        xr = q @ cam.right
        yu = q @ cam.true_up
        z = q @ cam.forward
        scale = max(float(np.abs(mesh.extent).max()), float(np.abs(q).max(initial=0.0)), 1e-300)
        front = z.max(axis=1) > 0                  # something in front of the eye plane
        if cam.is_ortho:
            full = np.zeros(len(T), bool)
            zz = 1.0
        else:
            full = z.min(axis=1) <= 1e-12 * scale
            zz = np.where(z > 0, z, 1.0)
        col = ((xr / (zz * sx)) + 1) * (W / 2) - 0.5
        row = (1 - yu / (zz * sy)) * (H / 2) - 0.5
        with np.errstate(invalid="ignore", over="ignore"):
            c_lo = np.ceil(col.min(axis=1) - _MARGIN)
            c_hi = np.floor(col.max(axis=1) + _MARGIN)
            r_lo = np.ceil(row.min(axis=1) - _MARGIN)
            r_hi = np.floor(row.max(axis=1) + _MARGIN)
        c_lo = np.where(full, 0, np.clip(c_lo, 0, W))
        c_hi = np.where(full, W - 1, np.clip(c_hi, -1, W - 1))
        r_lo = np.where(full, 0, np.clip(r_lo, 0, H))
        r_hi = np.where(full, H - 1, np.clip(r_hi, -1, H - 1))
        keep = good & front & (c_hi >= c_lo) & (r_hi >= r_lo)
        k = np.flatnonzero(keep)
        self.cells = cells[k]
        self.n, self.off, self.h = n[k], off[k], h[k]
        self.s = mesh.scalars[T[k]]                # (m, 4): value at the vertex opposite face f
        self.c_lo, self.c_hi = c_lo[k].astype(np.int64), c_hi[k].astype(np.int64)
        self.r_lo, self.r_hi = r_lo[k].astype(np.int64), r_hi[k].astype(np.int64)
        origins, dirs = cam.rays(W, H)
        self.o = (origins - lo).reshape(-1, 3)
        self.d = dirs.reshape(-1, 3)

    def rows_range(self, row_lo, row_hi):
        """Per tet, its candidate rows within [row_lo, row_hi) and its column count."""
        r0 = np.maximum(self.r_lo, row_lo)
        r1 = np.minimum(self.r_hi, row_hi - 1)
        nr = np.maximum(r1 - r0 + 1, 0)
        nc = self.c_hi - self.c_lo + 1
        return r0, nr, nc

    def row_blocks(self, budget):
        """Ranges [a, b) of image rows holding at most about ``budget`` candidates each
        (a single row may hold more)."""
        nc = self.c_hi - self.c_lo + 1
        per_row = np.zeros(self.H + 1, np.int64)
        np.add.at(per_row, self.r_lo, nc)
        np.add.at(per_row, self.r_hi + 1, -nc)
        per_row = np.cumsum(per_row[:-1])
        ends = np.cumsum(per_row)
        block = (ends - per_row) // max(int(budget), 1)   # block of each row's first candidate
        cut = np.flatnonzero(np.diff(block) != 0) + 1
        edges = np.concatenate([[0], cut, [self.H]])
        return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]

    def segments(self, row_lo=0, row_hi=None):
        """The segments of rows [row_lo, row_hi) as a dict of flat arrays (see
        ``ray_tet_segments``)."""
        row_hi = self.H if row_hi is None else row_hi
        r0, nr, nc = self.rows_range(row_lo, row_hi)
        count = nr * nc
        live = np.flatnonzero(count > 0)
        if live.size == 0:
            return _empty()
        count = count[live]
        cum = np.cumsum(count)
        # groups of consecutive tets with at most about _CANDIDATES candidates each
        out, g0 = [], 0
        while g0 < live.size:
            before = cum[g0] - count[g0]
            g1 = max(int(np.searchsorted(cum, before + _CANDIDATES, side="right")), g0 + 1)
            out.append(self._clip(live[g0:g1], r0, nr, nc))
            g0 = g1
        return {key: np.concatenate([o[key] for o in out]) for key in _KEYS}

    def _clip(self, ids, r0, nr, nc):
        cnt = nr[ids] * nc[ids]
        rep = np.repeat(np.arange(ids.size), cnt)
        start = np.cumsum(cnt) - cnt
        k = np.arange(rep.size) - start[rep]
        t = ids[rep]                               # prepared-tet index per candidate
        ncr = nc[t]
        pixel = (r0[t] + k // ncr) * self.W + self.c_lo[t] + k % ncr
        o, d = self.o[pixel], self.d[pixel]
        N = self.n[t]                              # (c, 4, 3)
        # written out (a fixed order of operations): a face's two tets get exactly
        # opposite numbers, so the crossing distance is the same for both
        denom = N[..., 0] * d[:, 0, None] + N[..., 1] * d[:, 1, None] + N[..., 2] * d[:, 2, None]
        num = self.off[t] - (N[..., 0] * o[:, 0, None] + N[..., 1] * o[:, 1, None] + N[..., 2] * o[:, 2, None])
        with np.errstate(divide="ignore", invalid="ignore"):
            tc = num / denom
        outside = ((denom == 0) & (num < 0)).any(axis=1)
        t_in = np.maximum(np.where(denom < 0, tc, -np.inf).max(axis=1), 0.0)
        t_out = np.where(denom > 0, tc, np.inf).min(axis=1)
        hit = np.flatnonzero(~outside & (t_out > t_in) & np.isfinite(t_out))
        if hit.size == 0:
            return _empty()
        t, t_in, t_out = t[hit], t_in[hit], t_out[hit]
        denom, num = denom[hit], num[hit]
        h, s = self.h[t], self.s[t]
        vals = []
        for tt in (t_in, t_out):
            lam = np.clip((tt[:, None] * denom - num) / h, 0.0, 1.0)
            tot = lam.sum(axis=1)
            vals.append((lam * s).sum(axis=1) / np.where(tot > 0, tot, 1.0))
        return dict(pixel=pixel[hit], tet=self.cells[t], t0=t_in, t1=t_out, s0=vals[0], s1=vals[1])


def ray_tet_segments(scene, tets=None):
    """Segments of every pixel ray through every tet of ``scene.volume`` (a ``TetMesh``),
    as a dict of flat arrays, one entry per (ray, tet) pair with a segment of positive
    length, in no particular order:

    - ``pixel`` int64, the flat pixel index ``r * W + c`` (row 0 on top);
    - ``tet`` int64, the index into ``mesh.tets``;
    - ``t0 < t1`` float64, distances along the unit ray direction from the ray's origin
      (``scene.camera.rays``); ``t0 >= 0``;
    - ``s0``, ``s1`` float64, the tet's linear field at ``t0`` and ``t1``.

    ``tets`` (int array) restricts the search to those cells."""
    return MeshRays(scene, tets).segments()


def union_segments(seg):
    """The segments sorted by (pixel, t0), with the part of each that earlier segments of
    its pixel already cover removed (its start clipped to the running maximum of the
    previous ends, its value there interpolated): each ray's coverage counted once.
    Empty remainders are dropped."""
    order = np.lexsort((seg["t0"], seg["pixel"]))
    pix = seg["pixel"][order]
    t0, t1, s0, s1, cell = (seg[k][order] for k in ("t0", "t1", "s0", "s1", "tet"))
    reach = t1.copy()                              # running max of ends, per pixel (scan)
    step = 1
    while step < reach.size:
        same = pix[step:] == pix[:-step]
        if not same.any():
            break
        reach[step:] = np.where(same, np.maximum(reach[step:], reach[:-step]), reach[step:])
        step *= 2
    before = np.full(reach.size, -np.inf)
    if reach.size > 1:
        before[1:] = np.where(pix[1:] == pix[:-1], reach[:-1], -np.inf)
    start = np.maximum(t0, before)
    keep = t1 > start
    clipped = keep & (start > t0)
    s_start = s0.copy()
    if clipped.any():
        f = (start[clipped] - t0[clipped]) / (t1[clipped] - t0[clipped])
        s_start[clipped] = s0[clipped] + (s1[clipped] - s0[clipped]) * f
    return dict(pixel=pix[keep], tet=cell[keep], t0=start[keep], t1=t1[keep], s0=s_start[keep], s1=s1[keep])


def kept_intervals(scene, box_coordinates=False):
    """Per pixel, the part ``[lo, hi]`` of its ray (``scene.camera.rays``, t >= 0) that the
    scene's clip planes and crop box keep (``model.clipping.clip_interval``; the whole
    ray for a scene that does not clip). In world coordinates, or with
    ``box_coordinates`` relative to the mesh's lower corner, as the shaders compute it
    (the same t either way: only the origins move)."""
    from ..model.clipping import clip_interval, plane_offsets
    origins, dirs = scene.camera.rays(scene.width, scene.height)
    o, d = origins.reshape(-1, 3), dirs.reshape(-1, 3)
    lo_t, hi_t = np.zeros(len(o)), np.full(len(o), np.inf)
    if not scene.clips:
        return lo_t, hi_t
    if box_coordinates:
        planes, crop = scene.clip_in_box()
        o = o - scene.volume.bounds[0]
    else:
        planes, crop = plane_offsets(scene.clip_planes), scene.crop_box
    return clip_interval(o, d, lo_t, hi_t, planes, crop)


def clip_segments(seg, lo_t, hi_t):
    """The segments cut to their ray's kept interval ``[lo_t[pixel], hi_t[pixel]]``
    (``kept_intervals``): the field's values at a cut end interpolated linearly (the
    field is linear along a segment), ends that are not cut left as they are, empty
    segments dropped. Keeps the segments' order."""
    pix = seg["pixel"]
    t0, t1, s0, s1 = (seg[k] for k in ("t0", "t1", "s0", "s1"))
    a = np.maximum(t0, lo_t[pix])
    b = np.minimum(t1, hi_t[pix])
    keep = np.flatnonzero(b > a)
    t0, t1, s0, s1, a, b = t0[keep], t1[keep], s0[keep], s1[keep], a[keep], b[keep]
    rate = (s1 - s0) / (t1 - t0)
    out = {k: v[keep] for k, v in seg.items()}
    out["t0"], out["t1"] = a, b
    out["s0"] = np.where(a > t0, s0 + (a - t0) * rate, s0)
    out["s1"] = np.where(b < t1, s0 + (b - t0) * rate, s1)
    return out
