"""What renderers derive from a TetMesh: connectivity and planes (once per mesh), the
cells a transfer function makes visible (once per TF), and the visibility order of
those cells (once per view).

Connectivity. Tetrahedra are stored positively oriented (two vertices swapped where the
signed volume is negative: either orientation is accepted). Every distinct triangle is
one *face*, with its one or two cells and one plane, ``n . x = d`` in coordinates
relative to the mesh's lower corner, ``n`` pointing out of its first cell. A cell's four
planes are its faces' planes, negated where the cell is the face's second one: the two
cells of a shared face hold exactly opposite planes, so a ray leaves one at exactly the
distance at which it enters the other (no crack, no overlap, in any precision).
A folded mesh (both cells of a face on the same side of it) is the exception: there the
second cell takes the plane unnegated, so every cell is bounded by its own four faces.

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
in general; its error is measured in the tests and the README.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# Local faces of a positively oriented tet (p0, p1, p2, p3): face i is opposite vertex i,
# wound counter-clockwise seen from outside.
LOCAL_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]], np.int64)

_FLAT = 1e-12          # |6 V| below this times the cube of the longest edge: zero volume
_PAIR_CHUNK = 1 << 21  # (face, pixel) candidates per batch in the per-pixel pass


@dataclass
class Topology:
    tets: np.ndarray          # (M, 4) int64, positively oriented
    flat: np.ndarray          # (M,) bool: zero-volume cells (drawn never, sorted as any)
    faces: np.ndarray         # (F, 3) int64, vertex indices of each distinct face
    face_cells: np.ndarray    # (F, 2) int64: the face's cells, -1 where on the boundary
    tet_faces: np.ndarray     # (M, 4) int64: face opposite local vertex i
    tet_face_sign: np.ndarray  # (M, 4) float64: +1 where the face's normal points out of the cell
    normals: np.ndarray       # (F, 3) float64, unit (zero for a degenerate face)
    offsets: np.ndarray       # (F,) float64, relative to the mesh's lower corner
    centroids: np.ndarray     # (M, 3) float64, relative to the mesh's lower corner
    cell_min: np.ndarray      # (M,) smallest and largest vertex scalar
    cell_max: np.ndarray
    convex: bool              # the whole mesh fills its convex hull (MPVO alone is exact)
    on_hull: np.ndarray       # (F,) bool: boundary faces in a supporting plane of all points
    flat_pairs: np.ndarray    # (P, 2) int64: (cell below, cell above) a group of flat cells
    flat_planes: np.ndarray   # (P, 4) float64: that group's plane (unit normal up, offset)

    def cell_planes(self):
        """(M, 4, 4) float64: per cell and local face, (outward unit normal, offset)."""
        n = self.normals[self.tet_faces] * self.tet_face_sign[..., None]
        d = self.offsets[self.tet_faces] * self.tet_face_sign
        return np.concatenate([n, d[..., None]], axis=-1)


def topology(mesh) -> Topology:
    """The mesh's connectivity and planes, computed on first use and kept on the mesh."""
    topo = mesh._derived.get("topology")
    if topo is None:
        topo = mesh._derived["topology"] = _build_topology(mesh)
    return topo


def _build_topology(mesh):
    lo = mesh.bounds[0]
    pts = mesh.points - lo
    tets = mesh.tets.copy()
    vol6 = mesh.signed_volumes() * 6.0
    neg = vol6 < 0
    tets[neg, 2], tets[neg, 3] = mesh.tets[neg, 3], mesh.tets[neg, 2]
    p = pts[tets]
    edges = p[:, [1, 2, 3, 2, 3, 3]] - p[:, [0, 0, 0, 1, 1, 2]]
    longest = np.sqrt((edges ** 2).sum(-1).max(axis=1))
    flat = np.abs(vol6) <= _FLAT * longest ** 3

    M = len(tets)
    local = tets[:, LOCAL_FACES]                     # (M, 4, 3)
    key = np.sort(local.reshape(-1, 3), axis=1)
    n = len(pts)
    if n < 2_000_000:            # one int64 per face: much faster to sort than rows
        code = (key[:, 0] * n + key[:, 1]) * n + key[:, 2]
        _, first, inverse = np.unique(code, return_index=True, return_inverse=True)
        faces = key[first]
    else:
        faces, inverse = np.unique(key, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    F = len(faces)
    tet_faces = inverse.reshape(M, 4)
    cell_of = np.repeat(np.arange(M), 4)
    order = np.argsort(inverse, kind="stable")
    counts = np.bincount(inverse, minlength=F)
    if counts.max() > 2:
        f = int(np.argmax(counts))
        raise ValueError(f"tets: face {faces[f].tolist()} is shared by {int(counts[f])} cells "
                         "(a valid mesh shares a face between at most two)")
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    face_cells = np.full((F, 2), -1, np.int64)
    face_cells[:, 0] = cell_of[order[start]]
    two = counts == 2
    face_cells[two, 1] = cell_of[order[start[two] + 1]]

    # each face's plane, oriented out of its first cell (taken from that cell's winding)
    first_slot = order[start]                        # flat (cell, local face) index
    tri = pts[local.reshape(-1, 3)[first_slot]]      # (F, 3, 3), outward winding of cell 0
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(normal, axis=1)
    ok = length > 0
    normal[ok] /= length[ok, None]
    normal[~ok] = 0.0
    offsets = np.einsum("ij,ij->i", normal, tri.mean(axis=1))
    sign = np.where(cell_of.reshape(M, 4) == face_cells[tet_faces, 0], 1.0, -1.0)
    # A folded mesh (curvilinear grids have them) puts both cells of a face on the same
    # side of it; the second cell's plane must then point the same way as the first's,
    # or the cell's four planes bound nothing. The cell's own opposite vertex decides.
    inside = np.einsum("mkj,mkj->mk", normal[tet_faces], p) - offsets[tet_faces]
    sign = np.where(sign * inside > 0, -sign, sign)
    s = mesh.scalars[tets]
    convex, hull_points = _convex_hull(pts, np.abs(vol6).sum() / 6.0)
    on_hull = np.zeros(F, bool)
    boundary = np.flatnonzero(face_cells[:, 1] < 0)
    if hull_points is not None and boundary.size:
        eps = 1e-9 * float(np.linalg.norm(pts.max(axis=0)))
        n_b, d_b = normal[boundary], offsets[boundary]
        beyond = np.zeros(boundary.size)
        for start in range(0, len(hull_points), 256):
            chunk = hull_points[start:start + 256]
            beyond = np.maximum(beyond, (n_b @ chunk.T - d_b[:, None]).max(axis=1))
        on_hull[boundary] = beyond <= eps
    flat_pairs, flat_planes = _across_flat_cells(pts, tets, flat, face_cells, tet_faces, faces)
    return Topology(tets=tets, flat=flat, faces=faces, face_cells=face_cells, tet_faces=tet_faces,
                    tet_face_sign=sign, normals=normal, offsets=offsets, centroids=p.mean(axis=1),
                    cell_min=s.min(axis=1), cell_max=s.max(axis=1), convex=convex, on_hull=on_hull,
                    flat_pairs=flat_pairs, flat_planes=flat_planes)


def _across_flat_cells(pts, tets, flat, face_cells, tet_faces, faces):
    """The cells that face each other across a layer of zero-volume cells.

    A flat cell (Delaunay meshes of lattice or cospherical points have them, between two
    triangulations of one planar quad) has no inside, so its winding says nothing about
    which side its neighbours are on, and a face constraint through it can point the
    wrong way (and close a cycle). Flat cells are therefore left out of the face
    constraints; each group of them joined by faces lies in one plane, and every real
    cell below that plane faces every real cell above it across the group. Which side a
    neighbour is on comes from its own vertex off the shared face, never from a flat
    cell's winding. Returns (below, above) cell pairs and each pair's plane, oriented
    from below to above."""
    none = np.zeros((0, 2), np.int64), np.zeros((0, 4))
    flat_cells = np.flatnonzero(flat)
    if flat_cells.size == 0:
        return none
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    a, b = face_cells[:, 0], face_cells[:, 1]
    inner = b >= 0
    both = inner & flat[a] & flat[np.maximum(b, 0)]
    M = len(tets)
    graph = coo_matrix((np.ones(both.sum()), (a[both], b[both])), shape=(M, M))
    _, group = connected_components(graph, directed=False)
    # faces between one flat cell and one real cell: the real cell's vertex off the face
    one = inner & (flat[a] != flat[np.maximum(b, 0)])
    f = np.flatnonzero(one)
    flat_side = np.where(flat[a[f]], a[f], b[f])
    real = np.where(flat[a[f]], b[f], a[f])
    if f.size == 0:
        return none
    local = np.argmax(tet_faces[real] == f[:, None], axis=1)   # face i is opposite vertex i
    off_face = pts[tets[real, local]]
    # each group's plane from its largest face (the flat cells' faces all lie in it)
    tri = pts[faces[f]]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = np.linalg.norm(cross, axis=1)
    g = group[flat_side]
    best = np.full(M, -1.0)
    np.maximum.at(best, g, area)
    pick = np.full(M, -1, np.int64)
    pick[g[area == best[g]]] = np.flatnonzero(area == best[g])
    normal = cross[pick[g]] / np.maximum(area[pick[g]], 1e-300)[:, None]
    offset = np.einsum("ij,ij->i", normal, tri[pick[g]].mean(axis=1))
    height = np.einsum("ij,ij->i", normal, off_face) - offset
    below, above = height < 0, height > 0
    # join below and above records of the same group
    ob, oa = np.flatnonzero(below), np.flatnonzero(above)
    ob, oa = ob[np.argsort(g[ob], kind="stable")], oa[np.argsort(g[oa], kind="stable")]
    ga = g[oa]
    lo, hi = np.searchsorted(ga, g[ob], "left"), np.searchsorted(ga, g[ob], "right")
    cnt = hi - lo
    if cnt.sum() == 0:
        return none
    rec_b = np.repeat(ob, cnt)
    rec_a = oa[np.repeat(lo - np.cumsum(cnt) + cnt, cnt) + np.arange(cnt.sum())]
    pairs = np.stack([real[rec_b], real[rec_a]], axis=1)
    planes = np.concatenate([normal[rec_b], offset[rec_b, None]], axis=1)
    keep = pairs[:, 0] != pairs[:, 1]
    return pairs[keep], planes[keep]


def _convex_hull(points, volume):
    """(the cells fill the convex hull, the hull's vertices): a convex domain needs no
    order across gaps, and a boundary face in a supporting plane of the hull can never
    be part of a gap (nothing lies beyond it)."""
    from scipy.spatial import ConvexHull
    try:
        hull = ConvexHull(points)
    except Exception:          # flat point sets: nothing to order across gaps
        return True, None
    convex = abs(hull.volume - volume) <= 1e-9 * max(hull.volume, 1e-300)
    return convex, points[hull.vertices]


# ------------------------------------------------------------------------- visibility
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
