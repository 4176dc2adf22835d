"""Which cells of a TetMesh a transfer function makes visible (once per TF), and the
visibility order of those cells (once per view), for projected tetrahedra.

Visibility order (Williams 1992, MPVO). For a face shared by cells a and b, the cell on
the eye's side of the face's plane is in front of the other and must be drawn after it.
These constraints form a graph whose topological order (Kahn's algorithm, one frontier
of independent cells at a time) is a back-to-front order for a convex, acyclic mesh.
A domain that is not convex (and the visible subset of any mesh, which is what is sorted)
also needs the order of cells that are not face neighbours: a ray that leaves the domain
through a boundary face and re-enters it further on must see the cell it re-enters drawn
before the cell it left. Those constraints are taken where they matter, at the pixel
centres the image is made of: every pixel's ray is intersected with the boundary faces
(float64), and each exit followed by an entry along the ray adds the constraint. The
order is then exact at every pixel of the image (MPVO with the non-convex treatment
done per pixel rather than approximated as in Williams' MPVONC). Cycles (possible in
meshes that are not Delaunay, and from coplanar ties) are broken deterministically: when
no cell is free, the farthest remaining cell (by centroid depth) is released; the number
of such breaks is reported.

``sort="centroid"`` orders cells by the depth of their centroid: cheap, exact for no mesh
in general; its error is measured in the tests and in docs/notes/tetra_vs_vtk.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.mesh import topology

_PAIR_CHUNK = 1 << 21  # (face, pixel) candidates per batch in the per-pixel pass


def visible_cells(mesh, tf):
    """Indices of the cells whose scalar range meets non-zero opacity (exact TF): the
    only ones that can emit or absorb. Zero-volume cells are included (they are sorted,
    never drawn)."""
    topo = topology(mesh)
    lo, hi = topo.cell_min, topo.cell_max
    keep = (tf.opacity(lo) > 0) | (tf.opacity(hi) > 0)
    pts = tf.opacity_points
    for s, a in pts:
        if a > 0:
            keep |= (lo <= s) & (s <= hi)
    return np.flatnonzero(keep)


def view_depth(points, scene):
    """Distance along the view direction from the eye (box-relative points)."""
    cam = scene.camera
    eye = cam.eye - scene.volume.bounds[0]
    return (points - eye) @ cam.forward


@dataclass
class Order:
    cells: np.ndarray     # cell indices, back to front (draw order)
    cycles_broken: int    # cells released to break a cycle
    gap_constraints: int  # constraints added across gaps of the domain (per pixel)


def centroid_order(mesh, cells, scene):
    """Cells sorted far to near by the distance of their centroid from the eye (depth
    along the view for orthographic cameras)."""
    topo = topology(mesh)
    c = topo.centroids[cells]
    cam = scene.camera
    if cam.is_ortho:
        key = view_depth(c, scene)
    else:
        key = np.linalg.norm(c - (cam.eye - mesh.bounds[0]), axis=1)
    return Order(cells=cells[np.argsort(-key, kind="stable")], cycles_broken=0, gap_constraints=0)


def mpvo_order(mesh, cells, scene):
    """A back-to-front order of ``cells`` exact at every pixel centre of the scene's image
    (module docstring)."""
    topo = topology(mesh)
    M = len(topo.tets)
    member = np.zeros(M, bool)
    member[cells] = True
    fc = topo.face_cells
    shared = (fc[:, 1] >= 0)
    shared &= member[fc[:, 0]] & member[np.maximum(fc[:, 1], 0)]
    shared &= ~topo.flat[fc[:, 0]] & ~topo.flat[np.maximum(fc[:, 1], 0)]   # see _across_flat_cells
    f = np.flatnonzero(shared)
    side = _eye_side(topo.normals[f], topo.offsets[f], scene, mesh)
    a, b = fc[f, 0], fc[f, 1]
    # across a layer of flat cells: "above" plays b, "below" a
    pairs = topo.flat_pairs
    pairs_in = member[pairs[:, 0]] & member[pairs[:, 1]]
    side = np.concatenate([side, _eye_side(topo.flat_planes[pairs_in, :3], topo.flat_planes[pairs_in, 3],
                                           scene, mesh)])
    a, b = np.concatenate([a, pairs[pairs_in, 0]]), np.concatenate([b, pairs[pairs_in, 1]])
    # side > 0: the eye is beyond the face, on b's side: b is in front, a drawn first
    src = np.concatenate([a[side > 0], b[side < 0]])
    dst = np.concatenate([b[side > 0], a[side < 0]])
    whole = len(cells) == M
    gaps = 0
    if not (whole and topo.convex):
        # flat cells stay members here: a layer of them inside the domain is no boundary
        # (as a gap of no depth, its exits and entries would tie in depth and pair wrongly)
        gs, gd = _gap_constraints(mesh, topo, member, scene)
        gaps = len(gs)
        src = np.concatenate([src, gs])
        dst = np.concatenate([dst, gd])
    depth = view_depth(topo.centroids, scene)
    order, broken = _kahn(cells, src, dst, depth, M)
    return Order(cells=order, cycles_broken=broken, gap_constraints=gaps)


def _eye_side(normals, offsets, scene, mesh):
    """Sign of the eye's side of each plane (+ where the normal points towards the eye);
    orthographic eyes are at infinity against the view direction."""
    cam = scene.camera
    if cam.is_ortho:
        return np.sign(-(normals @ cam.forward))
    eye = cam.eye - mesh.bounds[0]
    return np.sign(normals @ eye - offsets)


def _kahn(cells, src, dst, depth, M):
    """Topological order of ``cells`` under edges src -> dst (src drawn first), one
    frontier at a time; cycles broken at the farthest remaining cell."""
    # repeated constraints are harmless: each adds one to the in-degree and removes one
    indeg = np.bincount(dst, minlength=M)
    order_src = np.argsort(src, kind="stable")
    dst_sorted = dst[order_src]
    starts = np.searchsorted(src[order_src], np.arange(M + 1))
    alive = np.zeros(M, bool)
    alive[cells] = True
    frontier = cells[indeg[cells] == 0]
    out = []
    done = 0
    broken = 0
    n = len(cells)
    while done < n:
        if frontier.size == 0:
            rest = np.flatnonzero(alive)
            pick = rest[np.argmax(depth[rest])]      # farthest first: deterministic
            frontier = np.array([pick])
            broken += 1
        # far to near within a frontier (any order is valid there; this one is deterministic)
        frontier = frontier[np.argsort(-depth[frontier], kind="stable")]
        alive[frontier] = False
        out.append(frontier)
        done += frontier.size
        lo, hi = starts[frontier], starts[frontier + 1]
        cnt = hi - lo
        if cnt.sum() == 0:
            frontier = np.zeros(0, np.int64)
            continue
        idx = np.repeat(lo - np.cumsum(cnt) + cnt, cnt) + np.arange(cnt.sum())
        targets = dst_sorted[idx]
        targets = targets[alive[targets]]
        if targets.size > M // 64:
            indeg -= np.bincount(targets, minlength=M)
        else:
            np.subtract.at(indeg, targets, 1)
        cand = targets[indeg[targets] <= 0]
        cand.sort()
        frontier = cand[np.concatenate([[True], cand[1:] != cand[:-1]])] if cand.size else cand
    return np.concatenate(out) if out else np.zeros(0, np.int64), broken


def _gap_constraints(mesh, topo, member, scene):
    """Constraints between cells that follow each other along some pixel's ray across a
    gap of the (visible) domain: (cell entered further on) -> (cell left)."""
    fc = topo.face_cells
    in0 = member[fc[:, 0]]
    in1 = (fc[:, 1] >= 0) & member[np.maximum(fc[:, 1], 0)]
    boundary = np.flatnonzero(in0 != in1)
    if boundary.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    # a face on the convex hull has nothing beyond it: no ray leaves the domain there and
    # re-enters, nor enters there after leaving (module docstring)
    boundary = boundary[~topo.on_hull[boundary]]
    if boundary.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    cell = np.where(in0[boundary], fc[boundary, 0], fc[boundary, 1])
    sign = np.where(in0[boundary], 1.0, -1.0)          # normal out of the member cell
    normal = topo.normals[boundary] * sign[:, None]
    offset = topo.offsets[boundary] * sign
    side = _eye_side(normal, offset, scene, mesh)
    # eye outside the member cell's face: the ray enters the cell there
    entering = side > 0
    keep = side != 0
    boundary, cell, entering, normal, offset = (x[keep] for x in (boundary, cell, entering, normal, offset))
    lo = mesh.bounds[0]
    tri = mesh.points[topo.faces[boundary]] - lo        # (B, 3, 3)
    pixel, depth = _rasterise_triangles(tri, normal, offset, scene, lo)
    if pixel.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    face = pixel[1]
    pixel = pixel[0]
    # per pixel, by depth; at equal depth an exit comes before an entry
    ent = entering[face]
    order = np.lexsort((ent, depth, pixel))
    pixel, face, ent = pixel[order], face[order], ent[order]
    nxt = np.flatnonzero((pixel[1:] == pixel[:-1]) & ~ent[:-1] & ent[1:])
    src = cell[face[nxt + 1]]
    dst = cell[face[nxt]]
    diff = src != dst
    return src[diff], dst[diff]


def _rasterise_triangles(tri, normal, offset, scene, lo):
    """(pixel, triangle) pairs whose pixel-centre ray (t > 0) crosses the triangle
    (closed: edges and vertices count), with the crossing's distance along the ray."""
    cam = scene.camera
    W, H = scene.width, scene.height
    sx, sy = cam.screen_scale(W, H)
    eye = cam.eye - lo
    rel = tri - eye
    z = rel @ cam.forward                                   # (B, 3) depth
    x = rel @ cam.right
    y = rel @ cam.true_up
    if cam.is_ortho:
        px, py = x / sx, y / sy
        ok = np.ones(len(tri), bool)
    else:
        zz = np.where(z > 0, z, 1.0)
        px, py = x / zz / sx, y / zz / sy
        ok = (z > 1e-12 * np.abs(rel).max()).all(axis=1)
    # NDC -> pixel column/row coordinates of pixel centres
    col = (px + 1) * W / 2 - 0.5
    row = (1 - py) * H / 2 - 0.5
    c0 = np.where(ok, np.ceil(col.min(1)), 0).clip(0, W).astype(np.int64)
    c1 = np.where(ok, np.floor(col.max(1)), W - 1).clip(-1, W - 1).astype(np.int64)
    r0 = np.where(ok, np.ceil(row.min(1)), 0).clip(0, H).astype(np.int64)
    r1 = np.where(ok, np.floor(row.max(1)), H - 1).clip(-1, H - 1).astype(np.int64)
    nc = np.maximum(c1 - c0 + 1, 0)
    nr = np.maximum(r1 - r0 + 1, 0)
    area = nc * nr
    tri_ids = np.flatnonzero(area > 0)
    out_pix, out_tri, out_t = [], [], []
    csum = np.cumsum(area[tri_ids])
    start = 0
    while start < tri_ids.size:
        stop = int(np.searchsorted(csum, (csum[start - 1] if start else 0) + _PAIR_CHUNK, side="right"))
        stop = max(stop, start + 1)
        ids = tri_ids[start:stop]
        a = area[ids]
        t_of = np.repeat(ids, a)
        k = np.arange(a.sum()) - np.repeat(np.cumsum(a) - a, a)
        cc = c0[t_of] + k % nc[t_of]
        rr = r0[t_of] + k // nc[t_of]
        # in front of the eye, lines project to lines: the closed test on the projected
        # triangle (edge functions in pixel units) is the ray-triangle test
        proj = ok[t_of]
        inside = np.zeros(t_of.size, bool)
        e = [(col[t_of, (i + 1) % 3] - col[t_of, i]) * (rr - row[t_of, i])
             - (row[t_of, (i + 1) % 3] - row[t_of, i]) * (cc - col[t_of, i]) for i in range(3)]
        e = np.stack(e, axis=1)
        inside[proj] = ((e[proj] >= 0).all(axis=1) | (e[proj] <= 0).all(axis=1))
        rest = np.flatnonzero(~proj)
        if rest.size:
            o, d = _pixel_rays(cam, W, H, rr[rest], cc[rest], eye)
            inside[rest] = _ray_triangle(o, d, tri[t_of[rest]], normal[t_of[rest]], offset[t_of[rest]])[0]
        hit = np.flatnonzero(inside)
        o, d = _pixel_rays(cam, W, H, rr[hit], cc[hit], eye)
        f = t_of[hit]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (offset[f] - np.einsum("ij,ij->i", normal[f], o)) / np.einsum("ij,ij->i", normal[f], d)
        good = np.isfinite(t) & (t > 0)
        out_pix.append((rr * W + cc)[hit][good])
        out_tri.append(f[good])
        out_t.append(t[good])
        start = stop
    if not out_pix:
        return np.zeros(0, np.int64), np.zeros(0)
    return np.stack([np.concatenate(out_pix), np.concatenate(out_tri)]), np.concatenate(out_t)


def _pixel_rays(cam, W, H, rows, cols, eye):
    """Origins and unit directions of the given pixels' rays, as Camera.rays makes them."""
    sx, sy = cam.screen_scale(W, H)
    x = (2 * (cols + 0.5) / W - 1) * sx
    y = (1 - 2 * (rows + 0.5) / H) * sy
    offset = x[:, None] * cam.right + y[:, None] * cam.true_up
    if cam.is_ortho:
        return eye + offset, np.broadcast_to(cam.forward, offset.shape)
    d = cam.forward + offset
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    return np.broadcast_to(eye, d.shape), d


def _ray_triangle(o, d, tri, normal, offset):
    """Closed ray-triangle test in float64: the crossing with the plane, then the signs
    of the three edge functions about the normal (all >= 0 or all <= 0)."""
    denom = np.einsum("ij,ij->i", normal, d)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (offset - np.einsum("ij,ij->i", normal, o)) / denom
    p = o + t[:, None] * d
    e = []
    for i in range(3):
        a, b = tri[:, i], tri[:, (i + 1) % 3]
        e.append(np.einsum("ij,ij->i", np.cross(b - a, p - a), normal))
    e = np.stack(e, axis=1)
    inside = (e >= 0).all(axis=1) | (e <= 0).all(axis=1)
    return inside & (denom != 0) & (t > 0) & np.isfinite(t), t

