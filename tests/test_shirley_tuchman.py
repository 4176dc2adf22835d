"""Shirley-Tuchman classification (dvr_gl.techniques.shirley_tuchman) against independent float64
geometry: each cell's triangles tile its projected convex hull (scipy) exactly once, and
every triangle vertex's front/back distances are those of the pixel ray through it
clipped against the cell's four planes (computed here from the points, not from
dvr_gl.model.mesh), with the cell's linear field's values there."""

import numpy as np
import pytest
from scipy.spatial import ConvexHull, QhullError

from dvr_gl import Camera, Scene, TetMesh, TransferFunction
from dvr_gl.techniques.shirley_tuchman import classify, project
from dvr_gl.techniques.common import data_projection

CUBE = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], float)
SIX = np.array([[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]])
TF = TransferFunction([(0, 1.0, 0.5, 0.2), (1, 1.0, 0.5, 0.2)], [(0, 0.3), (1, 0.3)], unit_distance=0.5)
CAMERAS = {
    "ortho": Camera((3.0, 2.2, 4.0), (0.5, 0.5, 0.5), ortho_height=2.5),
    "perspective": Camera((2.4, 1.7, 3.1), (0.5, 0.5, 0.5), fov=40),
    "perspective_near": Camera((-0.9, 0.4, 1.3), (0.5, 0.5, 0.5), up=(0, 0, 1), fov=90),
}
REL = 1e-9


def scene_of(mesh, cam, w=320, h=200):
    return Scene(mesh, TF, cam, w, h)


def random_tets(seed, n=300):
    """n separate tets in the unit cube, none nearly flat, random scalars."""
    rng = np.random.default_rng(seed)
    pts = rng.random((4 * n * 3, 4, 3))
    e = pts[:, 1:] - pts[:, :1]
    vol = np.abs(np.linalg.det(e))
    longest = np.linalg.norm(pts[:, [1, 2, 3, 2, 3, 3]] - pts[:, [0, 0, 0, 1, 1, 2]], axis=-1).max(axis=1)
    pts = pts[vol > 0.02 * longest ** 3][:n]
    assert len(pts) == n
    return TetMesh(pts.reshape(-1, 3), np.arange(4 * n).reshape(n, 4), rng.normal(size=4 * n))


def pixel_rays(scene, xy):
    """Rays through continuous pixel positions, built as Camera.rays builds them."""
    cam = scene.camera
    sx, sy = cam.screen_scale(scene.width, scene.height)
    x = (2 * xy[:, 0] / scene.width - 1) * sx
    y = (1 - 2 * xy[:, 1] / scene.height) * sy
    off = x[:, None] * cam.right + y[:, None] * cam.true_up
    if cam.is_ortho:
        return cam.eye + off, np.broadcast_to(cam.forward, off.shape)
    d = cam.forward + off
    return np.broadcast_to(cam.eye, d.shape), d / np.linalg.norm(d, axis=1, keepdims=True)


def clip(o, d, P):
    """[t_in, t_out] of rays o + t d in tets P (N, 4, 3), from outward face planes; a ray
    in a face's plane (to rounding) is taken as parallel to it."""
    t_in = np.full(len(o), -np.inf)
    t_out = np.full(len(o), np.inf)
    for v in range(4):
        a, b, c = (P[:, u] for u in range(4) if u != v)
        n = np.cross(b - a, c - a)
        n *= np.sign(np.einsum("ij,ij->i", n, a - P[:, v]))[:, None]     # away from vertex v
        nd = np.einsum("ij,ij->i", n, d)
        nd[np.abs(nd) <= 1e-12 * np.linalg.norm(n, axis=1)] = 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.einsum("ij,ij->i", n, a - o) / nd
        t_in = np.where(nd < 0, np.maximum(t_in, t), t_in)
        t_out = np.where(nd > 0, np.minimum(t_out, t), t_out)
    return t_in, t_out


def linear_field(mesh, cells, x):
    P = mesh.points[mesh.tets[cells]]
    s = mesh.scalars[mesh.tets[cells]]
    g = np.linalg.solve(P[:, 1:] - P[:, :1], (s[:, 1:] - s[:, :1])[..., None])[..., 0]
    return s[:, 0] + np.einsum("ij,ij->i", g, x - P[:, 0])


def hull_area(xy):
    try:
        return ConvexHull(xy).volume
    except QhullError:          # collinear or coincident: no area
        return 0.0


def check(mesh, scene, cells=None):
    cells = np.arange(mesh.n_tets) if cells is None else cells
    r = classify(mesh, cells, scene)
    for k, v in r.items():
        assert np.all(np.isfinite(v)), k
    T = len(r["cell_of_tri"])
    assert r["tri_xy"].shape == (T, 3, 2) and r["cell_class"].shape == (len(cells),)
    # coverage: per cell, triangle areas sum to the projected hull's area
    e1 = r["tri_xy"][:, 1] - r["tri_xy"][:, 0]
    e2 = r["tri_xy"][:, 2] - r["tri_xy"][:, 0]
    area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    xy = project(mesh.points[mesh.tets[cells]] - mesh.bounds[0], scene)[0]
    for c in range(len(cells)):
        hull = hull_area(xy[c])
        mine = r["cell_of_tri"] == cells[c]
        got = area[mine].sum()
        assert got == pytest.approx(hull, rel=REL, abs=1e-12 * max(hull, 1.0)), (c, r["cell_class"][c])
        expected = {1: 3, 2: 4}.get(int(r["cell_class"][c]))
        if expected is not None:
            assert mine.sum() == expected
        else:
            assert mine.sum() <= 2
    # every triangle vertex: front/back = the clipped pixel ray, scalars = the field there
    cell = np.repeat(r["cell_of_tri"], 3)
    o, d = pixel_rays(scene, r["tri_xy"].reshape(-1, 2))
    t_in, t_out = clip(o, d, mesh.points[mesh.tets[cell]])
    front, back = r["tri_front"].ravel(), r["tri_back"].ravel()
    size = np.linalg.norm(np.ptp(mesh.points, axis=0)) + np.linalg.norm(scene.camera.eye)
    np.testing.assert_allclose(front, t_in, rtol=REL, atol=REL * size)
    np.testing.assert_allclose(back, t_out, rtol=REL, atol=REL * size)
    # the thick vertex (vertex 0 of every triangle): its chord to 1e-9 of itself
    thick = np.arange(0, 3 * T, 3)
    chord = (t_out - t_in)[thick]
    np.testing.assert_allclose((back - front)[thick], chord, rtol=REL, atol=1e-12 * size)
    sf = linear_field(mesh, cell, o + front[:, None] * d)
    sb = linear_field(mesh, cell, o + back[:, None] * d)
    srange = np.abs(mesh.scalars).max()
    np.testing.assert_allclose(r["tri_s_front"].ravel(), sf, rtol=REL, atol=REL * srange)
    np.testing.assert_allclose(r["tri_s_back"].ravel(), sb, rtol=REL, atol=REL * srange)
    return r


def test_pixel_convention_matches_camera_rays_and_gl_projection():
    mesh = random_tets(0, 10)
    for cam in CAMERAS.values():
        scene = scene_of(mesh, cam)
        o, d = cam.rays(scene.width, scene.height)
        r_, c_ = 37, 251
        point = o[r_, c_] + 2.5 * d[r_, c_] - mesh.bounds[0]
        xy, z, t = project(point[None], scene)
        np.testing.assert_allclose(xy[0], [c_ + 0.5, r_ + 0.5], atol=1e-9)
        assert t[0] == pytest.approx(2.5)
        # the GL path's matrix (row vectors) puts mesh-relative points at the same pixels
        pts = mesh.points - mesh.bounds[0]
        clip_ = np.c_[pts, np.ones(len(pts))] @ data_projection(scene)
        ndc = clip_[:, :2] / clip_[:, 3:]
        gl_xy = np.c_[(ndc[:, 0] + 1) * scene.width / 2, (1 - ndc[:, 1]) * scene.height / 2]
        np.testing.assert_allclose(project(pts, scene)[0], gl_xy, atol=1e-9)


def test_class1_single_tet_known_chord():
    # the corner vertex seen along (1, 1, 1) projects inside the opposite face: chord 1/sqrt(3)
    mesh = TetMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 1, 2, 3]], [4.0, 1.0, 2.0, 3.0])
    for cam in (Camera((3, 3, 3), (0, 0, 0), ortho_height=3), Camera((3, 3, 3), (0, 0, 0), fov=40)):
        r = check(mesh, scene_of(mesh, cam))
        assert r["cell_class"].tolist() == [1] and len(r["cell_of_tri"]) == 3
        chord = r["tri_back"][:, 0] - r["tri_front"][:, 0]
        np.testing.assert_allclose(chord, 1 / np.sqrt(3), rtol=REL)
        # front at the plane x + y + z = 1 (field 2), back at the corner (field 4)
        np.testing.assert_allclose(r["tri_s_front"][:, 0], 2.0, rtol=REL)
        np.testing.assert_allclose(r["tri_s_back"][:, 0], 4.0, rtol=REL)


def test_class2_single_tet_known_chord():
    # edges (0,0,0)-(1,0,0) and (.5,-.5,1)-(.5,.5,1) cross at x = .5, y = 0 seen along z
    mesh = TetMesh([[0, 0, 0], [1, 0, 0], [0.5, -0.5, 1], [0.5, 0.5, 1]], [[0, 1, 2, 3]], [0.0, 2.0, 5.0, 7.0])
    for cam in (Camera((0.5, 0, 4), (0.5, 0, 0), ortho_height=3), Camera((0.2, 0.1, 4), (0.5, 0, 0), fov=40)):
        r = check(mesh, scene_of(mesh, cam))
        assert r["cell_class"].tolist() == [2] and len(r["cell_of_tri"]) == 4
        if cam.is_ortho:
            np.testing.assert_allclose(r["tri_back"][:, 0] - r["tri_front"][:, 0], 1.0, rtol=REL)
            np.testing.assert_allclose(r["tri_s_front"][:, 0], 6.0, rtol=REL)   # top edge, middle
            np.testing.assert_allclose(r["tri_s_back"][:, 0], 1.0, rtol=REL)    # bottom edge, middle


@pytest.mark.parametrize("cam", CAMERAS, ids=list(CAMERAS))
@pytest.mark.parametrize("seed", [1, 2])
def test_random_tets(cam, seed):
    mesh = random_tets(seed)
    r = check(mesh, scene_of(mesh, CAMERAS[cam]))
    cls = r["cell_class"]
    assert set(np.unique(cls)) == {1, 2}         # both classes occur, no degenerate cell
    assert len(r["cell_of_tri"]) == 3 * (cls == 1).sum() + 4 * (cls == 2).sum()


def test_subset_order_and_cube():
    mesh = TetMesh(CUBE, SIX, CUBE @ [1.0, 2.0, 4.0])
    views = [Camera((0.5, 0.5, 3.0), (0.5, 0.5, 0.5), ortho_height=1.6),     # along z: degenerate
             Camera((3.0, 3.0, 3.0), (0.5, 0.5, 0.5), up=(0, 0, 1), ortho_height=2.0),   # body diagonal
             Camera((2.4, 1.7, 3.1), (0.5, 0.5, 0.5), fov=30),
             Camera((0.5, 0.5, 3.0), (0.5, 0.5, 0.5), fov=30)]
    for cam in views:
        check(mesh, scene_of(mesh, cam, 64, 64))
    # along z every cell projects to a triangle with a vertex on an edge or two coincident
    r = classify(mesh, np.arange(6), scene_of(mesh, views[0]))
    assert (r["cell_class"] == 0).all() and 0 < len(r["cell_of_tri"]) <= 12
    # triangles come grouped by cell, in the order cells were given
    sub = np.array([4, 1, 3])
    r = classify(mesh, sub, scene_of(mesh, views[2]))
    first = [r["cell_of_tri"][0]] + list(r["cell_of_tri"][1:][np.diff(r["cell_of_tri"]) != 0])
    assert first == sub.tolist()


def test_flat_and_behind_eye_cells_give_no_triangles():
    pts = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0, 0, 1], [0, 0, 5], [1, 0, 5]]
    mesh = TetMesh(pts, [[0, 1, 2, 3], [0, 1, 2, 4], [0, 1, 4, 5]], np.arange(7.0))
    scene = scene_of(mesh, Camera((0.2, 0.3, 2.0), (0.2, 0.3, 0), fov=60))
    r = classify(mesh, np.arange(3), scene)
    cls = r["cell_class"].tolist()
    assert cls[0] == 0 and cls[1] in (1, 2) and cls[2] == 0   # flat; in front; straddles the eye
    assert set(r["cell_of_tri"].tolist()) == {1}
    check(mesh, scene, np.array([1]))
