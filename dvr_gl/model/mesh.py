"""The tetrahedral mesh (TetMesh), and what is derived once per mesh: its connectivity, the planes of its faces, and
each cell's linear field (gradient and range). The techniques, their NumPy twins and the
exact integrator all read a mesh through these (the per-view visibility orders are
``dvr_gl.techniques.cell_order``).

Connectivity. Tetrahedra are stored positively oriented (two vertices swapped where the
signed volume is negative: either orientation is accepted). Every distinct triangle is
one *face*, with its one or two cells and one plane, ``n . x = d`` in coordinates
relative to the mesh's lower corner, ``n`` pointing out of its first cell. A cell's four
planes are its faces' planes, negated where the cell is the face's second one: the two
cells of a shared face hold exactly opposite planes, so a ray leaves one at exactly the
distance at which it enters the other (no crack, no overlap, in any precision).
A folded mesh (both cells of a face on the same side of it) is the exception: there the
second cell takes the plane unnegated, so every cell is bounded by its own four faces.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from .checks import _array

# Local faces of a positively oriented tet (p0, p1, p2, p3): face i is opposite vertex i,
# wound counter-clockwise seen from outside.
LOCAL_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]], np.int64)

_FLAT = 1e-12          # |6 V| below this times the cube of the longest edge: zero volume


def _mesh_points(points):
    """(N, 3) finite float64 points, N >= 4, or an error naming the bad one."""
    pts = _array("points", points, np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 4:
        raise ValueError(f"points must have shape (N, 3) with N >= 4, got shape {pts.shape}")
    if not np.all(np.isfinite(pts)):
        bad = int(np.argwhere(~np.isfinite(pts))[0, 0])
        raise ValueError(f"points must be finite, point {bad} is {tuple(pts[bad].tolist())}")
    return pts


class TetMesh:
    """An unstructured tetrahedral mesh with one scalar per point.

    Parameters
    ----------
    points : (N, 3) finite floats, world units
    tets : (M, 4) integer indices into ``points``; either vertex orientation
    scalars : (N,) finite floats, the field's value at each point

    Inside each tetrahedron the field is the linear (barycentric) interpolant; the domain
    is the union of the tetrahedra and need not be convex. Tetrahedra of zero volume are
    kept (they contribute nothing). Arrays are copied and stored read-only; the
    connectivity and plane equations renderers need are derived once, on first use
    (``dvr_gl.model.mesh.topology``).
    """

    def __init__(self, points, tets, scalars):
        pts = _mesh_points(points)
        raw = np.asarray(tets)
        if raw.dtype.kind not in "iu":
            raise TypeError(f"tets must be integer indices, got dtype {raw.dtype}")
        tt = np.array(raw, dtype=np.int64, order="C")
        if tt.ndim != 2 or tt.shape[1] != 4 or len(tt) < 1:
            raise ValueError(f"tets must have shape (M, 4) with M >= 1, got shape {tt.shape}")
        out = (tt < 0) | (tt >= len(pts))
        if out.any():
            i, j = (int(v) for v in np.argwhere(out)[0])
            raise ValueError(f"tets[{i}] has index {int(tt[i, j])} out of range for {len(pts)} points")
        if np.any(np.sort(tt, axis=1)[:, 1:] == np.sort(tt, axis=1)[:, :-1]):
            i = int(np.flatnonzero((np.sort(tt, axis=1)[:, 1:] == np.sort(tt, axis=1)[:, :-1]).any(axis=1))[0])
            raise ValueError(f"tets[{i}] repeats a vertex: {tt[i].tolist()}")
        sc = _array("scalars", scalars, np.float64)
        if sc.shape != (len(pts),):
            raise ValueError(f"scalars must have shape ({len(pts)},), one per point, got shape {sc.shape}")
        if not np.all(np.isfinite(sc)):
            bad = int(np.flatnonzero(~np.isfinite(sc))[0])
            raise ValueError(f"scalars must be finite, scalars[{bad}] is {sc[bad].item()!r}")
        for a in (pts, tt, sc):
            a.setflags(write=False)
        self.points, self.tets, self.scalars = pts, tt, sc
        self.data_range = (float(sc.min()), float(sc.max()))
        self.has_nonfinite = False
        self._digest = None
        self._derived = {}

    @classmethod
    def from_points(cls, points, scalars):
        """The Delaunay tetrahedralisation of scattered points (``scipy.spatial.Delaunay``;
        Qhull's ``Qbb Qc Qz Q12`` options, so co-spherical points are handled and every
        input point is a vertex). Slivers Qhull leaves on the hull are kept: zero-volume
        cells are harmless."""
        from scipy.spatial import Delaunay
        pts = _mesh_points(points)
        try:
            tri = Delaunay(pts, qhull_options="Qbb Qc Qz Q12")
        except Exception as e:  # Qhull raises its own error type for flat input
            raise ValueError(f"points cannot be tetrahedralised (all on a plane or line?): {e}") from None
        return cls(pts, tri.simplices, scalars)

    @property
    def n_points(self):
        return len(self.points)

    @property
    def n_tets(self):
        return len(self.tets)

    @property
    def bounds(self):
        """(lower corner, upper corner) of the points' bounding box, world units."""
        if "bounds" not in self._derived:     # (points are read-only: made once, asked every frame)
            self._derived["bounds"] = (self.points.min(axis=0), self.points.max(axis=0))
        lo, hi = self._derived["bounds"]
        return lo.copy(), hi.copy()

    @property
    def origin(self):
        return self.bounds[0]

    @property
    def extent(self):
        lo, hi = self.bounds
        return hi - lo

    @property
    def cell_size(self):
        """The median edge length: the scale of one cell (a TF's default unit distance)."""
        if "cell_size" not in self._derived:
            p = self.points[self.tets]
            e = np.linalg.norm(p[:, [1, 2, 3, 2, 3, 3]] - p[:, [0, 0, 0, 1, 1, 2]], axis=-1)
            self._derived["cell_size"] = float(np.median(e)) or float(np.linalg.norm(self.extent)) or 1.0
        return self._derived["cell_size"]

    def signed_volumes(self):
        """Signed volume of every tetrahedron, float64 (M,)."""
        p = self.points[self.tets]
        a, b, c = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
        return np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0

    def digest(self):
        """A content hash (points, tets, scalars) for caches on disk."""
        if self._digest is None:
            h = hashlib.sha256()
            for a in (self.points, self.tets, self.scalars):
                h.update(str(a.shape).encode())
                h.update(a.tobytes())
            self._digest = h.hexdigest()
        return self._digest

    def __repr__(self):
        return f"TetMesh({self.n_points} points, {self.n_tets} tets, range={self.data_range})"


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


def cell_fields(mesh):
    """(M, 2, 4) float64: per cell (gradient of the linear field, its value at the mesh's
    lower corner, the origin of the shaders' positions: s(x) = g . x + w) and (smallest,
    largest vertex value, 0, 0): a fragment clamps its end values to that range, which its
    float32 extrapolation can leave in a sliver (a gradient of 3e7 made values 10 data
    units off). The shaders take s at the eye, whose distance from the cell already
    scales their rounding as a point inside it would. Zero-volume cells get a zero
    gradient (they are never drawn)."""
    topo = topology(mesh)
    lo = mesh.bounds[0]
    p = mesh.points[topo.tets] - lo                 # (M, 4, 3)
    s = mesh.scalars[topo.tets]
    A = p[:, 1:] - p[:, :1]
    b = s[:, 1:] - s[:, :1]
    grad = np.zeros((len(p), 3))
    ok = ~topo.flat
    grad[ok] = np.linalg.solve(A[ok], b[ok][..., None])[..., 0]
    out = np.zeros((len(p), 2, 4))
    out[:, 0, :3] = grad
    out[:, 0, 3] = s.mean(axis=1) - np.einsum("mj,mj->m", grad, p.mean(axis=1))
    out[:, 1, 0] = topo.cell_min
    out[:, 1, 1] = topo.cell_max
    return out
