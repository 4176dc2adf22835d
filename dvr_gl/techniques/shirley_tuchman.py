"""Shirley and Tuchman's (1990) projected-tetrahedra classification on the CPU, in NumPy.

Not used for rendering: ``dvr_gl.techniques.tetra`` never splits cells into triangles on
the CPU; it draws each cell's back faces and lets every fragment clip its own pixel ray
against the cell's planes, so the per-view CPU work is the visibility order alone. This
module is the classic alternative written out, vectorised over cells, so that what that
choice saves can be measured (and so the two can be compared cell by cell).

Per cell and view: the four vertices are projected to pixel coordinates (Camera.rays'
convention: row 0 on top, pixel (r, c) centred at (c + 0.5, r + 0.5)). The projected
signed areas of the four faces (``A_f``, face f opposite vertex f, outward winding) sum
to zero; their signs classify the cell:

- one sign once, the other three times: class 1. The vertex k opposite the lone face
  projects inside the triangle of the other three; 3 triangles fan from it. Its ray's
  other end lies on face k, at screen barycentrics ``|A_v| / |A_k|``.
- two and two: class 2. The edge shared by the two faces of one sign crosses, in
  projection, the edge shared by the other two; 4 triangles fan from the crossing.

Points on the thick vertex's ray are found with perspective-correct weights (screen
weight / view depth, normalised), so under perspective they lie on the ray from the eye
through the projected point. Degenerate projections (a face of zero area: a vertex on
an edge, or an edge seen end-on) take the class-1 path without the zero-area triangles
(2 or 1 triangles) and are reported as class 0, as are flat cells, cells whose projection
has no area and, under perspective, cells not wholly in front of the eye (not projected).
"""

from __future__ import annotations

import numpy as np

from ..model.mesh import LOCAL_FACES, topology

_CHUNK = 1 << 17       # cells per batch
_ZERO_AREA = 1e-12     # |A_f| below this times the cell's largest |A_f|: zero


def _tables():
    """Everything combinatorial, per pattern of face-area signs (code = sum (sign_f + 1) 3^f):
    class; triangles as slots (0-3 the vertices, 4 the thick vertex) and which exist;
    the thick vertex's two ray ends as screen weights ``|A| * mask`` over the vertices."""
    cls = np.zeros(81, np.int8)
    tri = np.zeros((81, 4, 3), np.int64)
    valid = np.zeros((81, 4), bool)
    mask = np.zeros((2, 81, 4))
    for code in range(81):
        sg = np.array([code // 3 ** f % 3 - 1 for f in range(4)])
        npos, nneg = int((sg > 0).sum()), int((sg < 0).sum())
        if not (npos and nneg):
            continue                                   # no area: nothing
        if npos == nneg == 2:
            # faces opposite l, m (+) share edge (i, j); faces opposite i, j (-) share (l, m):
            # the edges cross at screen weights |A_i|, |A_j| (normalised) on i, j: the
            # distance of i from line (l, m) is proportional to |A_j|
            i, j, l, m = np.argsort(sg, kind="stable")
            cls[code] = 2
            tri[code] = [[4, i, l], [4, l, j], [4, j, m], [4, m, i]]
            valid[code] = True
            mask[0, code, [i, j]] = mask[1, code, [l, m]] = 1.0
            continue
        # vertex k, opposite the lone-signed face (ties: the + face), projects inside the
        # others' triangle, at screen barycentrics |A_v| / |A_k|; an edge end-on or a vertex
        # on an edge (zero faces) drops the triangles of zero area: (k, a, b) is face c's
        k = int(np.flatnonzero(sg == (1 if npos <= nneg else -1))[0])
        o = [v for v in range(4) if v != k]
        cls[code] = 1 if npos + nneg == 4 else 0
        tri[code, :3] = [[4, o[0], o[1]], [4, o[1], o[2]], [4, o[2], o[0]]]
        valid[code, :3] = sg[[o[2], o[0], o[1]]] != 0
        mask[0, code, k] = 1.0
        mask[1, code, o] = 1.0
    return cls, tri, valid, mask


_CLASS, _TRI, _VALID, _MASK = _tables()


def project(points, scene):
    """Box-relative points (..., 3) -> (pixel xy (..., 2), view depth (...), distance
    along their pixel ray (...)); xy is meaningless where the depth is not positive
    under perspective."""
    cam = scene.camera
    sx, sy = cam.screen_scale(scene.width, scene.height)
    rel = points - (cam.eye - scene.volume.bounds[0])
    z = rel @ cam.forward
    x, y = rel @ cam.right, rel @ cam.true_up
    if cam.is_ortho:
        t, w = z, 1.0
    else:
        t, w = np.linalg.norm(rel, axis=-1), np.where(z > 0, z, 1.0)
    xy = np.stack([(x / w / sx + 1) * (scene.width / 2), (1 - y / w / sy) * (scene.height / 2)], axis=-1)
    return xy, z, t


def classify(mesh, cells, scene):
    """Shirley-Tuchman triangles of ``cells`` (mesh cell indices) for the scene's view.

    Returns a dict of arrays, triangles grouped by cell in the order of ``cells``; float64:
    ``tri_xy`` (T, 3, 2) pixel positions; ``tri_front``, ``tri_back`` (T, 3) distances
    along the pixel ray through each triangle vertex where it enters and leaves the cell
    (equal at silhouette vertices; vertex 0 of every triangle is the thick vertex);
    ``tri_s_front``, ``tri_s_back`` (T, 3) the scalar there; ``cell_of_tri`` (T,) int64
    mesh cell index; ``cell_class`` (len(cells),) int8: 1, 2, or 0 (module docstring).
    """
    cells = np.asarray(cells, np.int64).ravel()
    topo = topology(mesh)
    parts = [_classify_chunk(mesh, topo, cells[i:i + _CHUNK], scene) for i in range(0, len(cells), _CHUNK)]
    if not parts:
        parts = [_classify_chunk(mesh, topo, cells, scene)]
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def _classify_chunk(mesh, topo, ids, scene):
    C = len(ids)
    tets = topo.tets[ids]
    P = mesh.points[tets] - mesh.bounds[0]              # (C, 4, 3) box-relative
    s = mesh.scalars[tets]                              # (C, 4)
    xy, z, t = project(P, scene)
    ortho = scene.camera.is_ortho
    w = np.ones_like(z) if ortho else z                 # perspective divide per vertex
    ok = ~topo.flat[ids]
    if not ortho:
        ok &= (z > 0).all(axis=1)
        w = np.where(ok[:, None], w, 1.0)

    # projected signed area (x2) of each face, opposite vertex f, outward winding
    f = xy[:, LOCAL_FACES]                              # (C, 4, 3, 2)
    e1, e2 = f[:, :, 1] - f[:, :, 0], f[:, :, 2] - f[:, :, 0]
    A = e1[..., 0] * e2[..., 1] - e1[..., 1] * e2[..., 0]
    aA = np.abs(A)
    zero = aA <= _ZERO_AREA * aA.max(axis=1, keepdims=True)
    aA[zero] = 0.0
    code = ((np.sign(A) * ~zero + 1) @ [1, 3, 9, 27]).astype(np.int64)
    code[~ok] = 40                                      # all zero: nothing
    live = _VALID[code].any(axis=1)

    # the thick vertex's two ray ends: screen weights, then perspective-correct ones
    ends = []
    for e in range(2):
        mu = aA * _MASK[e][code]
        mu /= np.where(live, mu.sum(axis=1), 1.0)[:, None]
        lam = mu / w
        lam /= np.where(live, lam.sum(axis=1), 1.0)[:, None]
        ends.append((mu, project(np.einsum("ck,ckd->cd", lam, P), scene)[2], (lam * s).sum(axis=1)))
    (mu, ta, sa), (_, tb, sb) = ends
    swap = tb < ta
    slot_xy = np.concatenate([xy, np.einsum("ck,ckd->cd", mu, xy)[:, None]], axis=1)
    slot_f = np.concatenate([t, np.where(swap, tb, ta)[:, None]], axis=1)
    slot_b = np.concatenate([t, np.where(swap, ta, tb)[:, None]], axis=1)
    slot_sf = np.concatenate([s, np.where(swap, sb, sa)[:, None]], axis=1)
    slot_sb = np.concatenate([s, np.where(swap, sa, sb)[:, None]], axis=1)

    c, q = np.nonzero(_VALID[code])                     # cell-major: grouped by cell
    flat = _TRI[code[c], q] + 5 * c[:, None]            # (T, 3) flat slot index

    def take(a):
        return np.take(a.reshape(5 * C, *a.shape[2:]), flat, axis=0)
    return dict(tri_xy=take(slot_xy), tri_front=take(slot_f), tri_back=take(slot_b),
                tri_s_front=take(slot_sf), tri_s_back=take(slot_sb), cell_of_tri=ids[c],
                cell_class=_CLASS[code])
