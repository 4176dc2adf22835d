"""The exact integrator's mesh path (dvr_gl/reference/exact.py with reference/mesh_rays.py)
against closed forms and fine 1-D integration: one tet with a linear field (rays through
an edge and a vertex), unit cubes split into 5 and 6 tets (rays along an axis, along a face
diagonal lying in shared faces, oblique, from inside), non-convex domains (a U of cubes and
two separate blobs: rays leave and re-enter), slivers and zero-volume tets, mip / minip /
average / isosurface, and the cache. Small images: the whole file runs in seconds."""

import importlib
from itertools import permutations

import numpy as np
import pytest

from dvr_gl import Camera, Scene, TetMesh, TransferFunction
from dvr_gl.reference.common import ray_box
from dvr_gl.reference.mesh_rays import MeshRays, ray_tet_segments, union_segments

ex = importlib.import_module("dvr_gl.reference.exact")

COLOR = np.array([0.2, 0.6, 0.9])


# ------------------------------------------------------------------------------- helpers
def render(scene, **kw):
    kw.setdefault("cache", False)
    return ex.exact(scene, **kw)


def constant_tf(alpha, unit_distance=1.0):
    return TransferFunction([(0.0, *COLOR), (1.0, *COLOR)], [(0.0, alpha), (1.0, alpha)],
                            unit_distance=unit_distance)


def cube_corners(origin=(0.0, 0.0, 0.0), size=1.0):
    """The 8 corners of a cube; corner i = x + 2y + 4z (bits of i)."""
    i = np.arange(8)
    return np.asarray(origin, float) + size * np.stack([i & 1, (i >> 1) & 1, (i >> 2) & 1], axis=1).astype(float)


# 5 tets: the 4 corners 0, 3, 5, 6 cut off (each with its 3 neighbours), the middle tet
# on the odd corners 1, 2, 4, 7. Mirrored cubes are needed for conforming neighbours.
CUBE5 = [[0, 1, 2, 4], [3, 1, 2, 7], [5, 1, 4, 7], [6, 2, 4, 7], [1, 2, 4, 7]]
# 6 tets (Kuhn): x_a >= x_b >= x_c for each order (a, b, c) of the axes, all on the
# diagonal 0-7; translated copies are conforming.
CUBE6 = [[0, 1 << a, (1 << a) | (1 << b), 7] for a, b, _ in permutations(range(3))]


def cubes_mesh(origins, split=CUBE6, scalars=None):
    """Unit cubes at ``origins`` (integer corners), each split into tets; shared corners
    merged so that neighbouring cubes share points. ``scalars``: a function of (N, 3)
    points (default 0.5)."""
    pts = np.concatenate([cube_corners(o) for o in origins])
    pts, inverse = np.unique(pts, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    tets = np.concatenate([inverse[8 * k + np.asarray(split)] for k in range(len(origins))])
    s = np.full(len(pts), 0.5) if scalars is None else scalars(pts)
    return TetMesh(pts, tets, s)


def ray_arrays(scene):
    o, d = scene.camera.rays(scene.width, scene.height)
    return o.reshape(-1, 3), d.reshape(-1, 3)


def chord_boxes(scene, boxes):
    """Length inside the union of disjoint boxes [lo, hi] per ray (rays not in shared faces)."""
    o, d = ray_arrays(scene)
    L = np.zeros(len(o))
    for lo, hi in boxes:
        t0, t1 = ray_box(o, d, np.asarray(lo, float), np.asarray(hi, float))
        L += np.maximum(t1 - t0, 0.0)
    return L


def closed_form(L, alpha, unit_distance=1.0):
    A = -np.expm1(L / unit_distance * np.log1p(-alpha))     # 1 - (1 - alpha)^(L/u)
    return np.concatenate([A[:, None] * COLOR, A[:, None]], axis=1)


def assert_constant(scene, L, alpha, unit_distance=1.0, atol=1e-12):
    img = render(scene).reshape(-1, 4)
    np.testing.assert_allclose(img, closed_form(L, alpha, unit_distance), rtol=0, atol=atol)


def rays_in_planes(scene, normals_offsets):
    """Number of rays lying exactly (in float64) in one of the given planes n . x = c."""
    o, d = ray_arrays(scene)
    inside = np.zeros(len(o), bool)
    for n, c in normals_offsets:
        n = np.asarray(n, float)
        inside |= (d @ n == 0) & (o @ n == c)
    return int(inside.sum())


# ----------------------------------------------------------- one tet, linear field vs 1-D
TET_PTS = np.array([[-11 / 16, -13 / 16, -0.5], [13 / 16, -13 / 16, 0.3], [-3 / 16, 13 / 16, 0.1],
                    [1 / 16, -1 / 16, 0.9]])
GRAD, S0 = np.array([0.5, -0.2, 0.7]), 0.3
TET = TetMesh(TET_PTS, [[0, 2, 1, 3]], S0 + TET_PTS @ GRAD)    # negative orientation
TET_TF = TransferFunction([(-0.5, 1.0, 0.2, 0.0), (0.2, 0.1, 0.9, 0.3), (0.5, 0.0, 0.3, 1.0), (1.2, 0.8, 0.8, 0.1)],
                          [(-0.5, 0.05), (0.1, 0.9), (0.3, 0.2), (0.6, 0.97), (1.2, 0.4)], unit_distance=0.3)
# 16 x 16 orthographic along -z: pixel centres at odd multiples of 1/16 in x and y, so the
# ray of pixel (x, y) = (1/16, -1/16) passes through vertex 3, rays (-1/16 - 2k/16, -3/16 -
# 2k/16) through the interior edge 3-0, and the rows y = -13/16 along the edge 0-1 on the
# silhouette (zero length there).
TET_CAMERAS = {
    "ortho-vertex-edge": Camera((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), ortho_height=2.0),
    "perspective": Camera((1.5, -2.0, 2.5), (0.0, -0.1, 0.2), fov=50),
    "inside": Camera((-0.1, -0.3, 0.2), (1.0, 0.3, 0.9), fov=100),   # the eye inside the tet
}


def tet_chords(o, d):
    """Entry and exit of each ray through TET, from the barycentric coordinates as a
    4 x 4 matrix inverse (independent of the face planes of mesh_rays)."""
    M = np.vstack([TET_PTS.T, np.ones(4)])
    B = np.linalg.inv(M)                     # lambda = B @ [x, 1]
    a = o @ B[:, :3].T + B[:, 3]             # lambda at t = 0
    b = d @ B[:, :3].T                       # d lambda / dt
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -a / b
    t_in = np.max(np.where(b > 0, t, np.where((b == 0) & (a < 0), np.inf, -np.inf)), axis=1)
    t_out = np.min(np.where(b < 0, t, np.where((b == 0) & (a < 0), -np.inf, np.inf)), axis=1)
    return np.maximum(t_in, 0.0), t_out


def march_reference(tf, a, b, t0, t1, n=800):
    """Composite of rays on which the field is s = a + b t, t in [t0, t1] (per ray), cut at
    the transfer function's knots (smooth integrands between cuts); on each part the
    midpoint rule on n steps (colour and extinction constant per step, the transmittance
    across it exact), Richardson-extrapolated from n and 2n. Returns (rays, 4)."""
    def once(ta, tb, aa, bb, m):
        u = (np.arange(m) + 0.5) / m
        t = ta[:, None] + (tb - ta)[:, None] * u
        s = aa[:, None] + bb[:, None] * t
        dt = ((tb - ta) / m)[:, None]
        od = -np.log1p(-np.minimum(tf.opacity(s), 1 - 1e-16)) / tf.unit_distance * dt
        after = np.cumsum(od, axis=1)
        C = (tf.color(s) * (np.exp(-(after - od)) - np.exp(-after))[..., None]).sum(axis=1)
        return C, after[:, -1]

    knots = tf.knots
    with np.errstate(divide="ignore", invalid="ignore"):
        tk = (knots[None, :] - a[:, None]) / b[:, None]
    tk = np.where((tk > t0[:, None]) & (tk < t1[:, None]), tk, np.inf)
    cuts = np.sort(np.concatenate([t0[:, None], tk, t1[:, None]], axis=1), axis=1)
    cuts = np.where(np.isinf(cuts), t1[:, None], cuts)
    out = np.zeros((len(a), 4))
    od = np.zeros(len(a))
    for k in range(cuts.shape[1] - 1):           # per part (a few), all rays at once
        ta, tb = cuts[:, k], cuts[:, k + 1]
        C1, od1 = once(ta, tb, a, b, n)
        C2, od2 = once(ta, tb, a, b, 2 * n)
        C, dod = (4 * C2 - C1) / 3, (4 * od2 - od1) / 3
        out[:, :3] += np.exp(-od)[:, None] * C
        od += dod
    out[:, 3] = -np.expm1(-od)
    return out


@pytest.mark.parametrize("camera", list(TET_CAMERAS))
def test_single_tet_linear_field_vs_fine_integration(camera):
    cam = TET_CAMERAS[camera]
    scene = Scene(TET, TET_TF, cam, 16, 16)
    img = render(scene).reshape(-1, 4)
    o, d = ray_arrays(scene)
    t0, t1 = tet_chords(o, d)
    hit = np.flatnonzero(t1 - t0 > 1e-12)
    assert hit.size >= 20
    ref = np.zeros((len(o), 4))
    oh, dh = o[hit], d[hit]
    ref[hit] = march_reference(TET_TF, S0 + oh @ GRAD, dh @ GRAD, t0[hit], t1[hit])
    np.testing.assert_allclose(img, ref, rtol=0, atol=1e-11)
    # the segments themselves: ends and values against the independent chords
    seg = ray_tet_segments(scene)
    assert np.all(seg["t0"] >= 0) and np.all(seg["t1"] > seg["t0"])
    assert seg["pixel"].dtype == np.int64 and seg["tet"].dtype == np.int64
    assert np.array_equal(np.unique(seg["pixel"]), np.sort(seg["pixel"]))   # one per ray
    p = seg["pixel"]
    np.testing.assert_allclose(seg["t0"], t0[p], atol=1e-13)
    np.testing.assert_allclose(seg["t1"], t1[p], atol=1e-13)
    for k in ("0", "1"):
        x = o[p] + seg["t" + k][:, None] * d[p]
        np.testing.assert_allclose(seg["s" + k], S0 + x @ GRAD, atol=1e-13)
    missed = np.setdiff1d(np.arange(len(o)), p)
    assert np.all(t1[missed] - t0[missed] <= 1e-12) and np.all(img[missed] == 0)


def test_single_tet_camera_hits_vertex_and_edges():
    # what the ortho test above claims: a ray through vertex 3, rays through edge 3-0
    scene = Scene(TET, TET_TF, TET_CAMERAS["ortho-vertex-edge"], 16, 16)
    o, d = ray_arrays(scene)
    xy = np.round(o[:, :2] * 16, 9)
    assert np.any(np.all(xy == [1, -1], axis=1))                     # vertex 3
    for k in range(1, 6):                                           # interior edge 3-0
        assert np.any(np.all(xy == [1 - 2 * k, -1 - 2 * k], axis=1))
    t0, t1 = tet_chords(o, d)
    vert = np.flatnonzero(np.all(xy == [1, -1], axis=1))[0]
    assert t1[vert] - t0[vert] > 0.5                                # the vertex ray crosses the tet
    seg = ray_tet_segments(scene)
    # rays meeting the silhouette edge 0-1 (row y = -13/16) have chord 0: at most
    # rounding-level segments (the edge's two face planes cross them a few ulps apart)
    row = np.isin(seg["pixel"], np.flatnonzero(xy[:, 1] == -13))
    assert np.all(seg["t1"][row] - seg["t0"][row] < 1e-14)
    img = render(scene).reshape(-1, 4)
    assert np.all(img[xy[:, 1] == -13] < 1e-13)


# ------------------------------------------------------------- unit cube, 5 and 6 tets
CUBE_CAMERAS = {
    # along -z; pixel centres on x = y (the boundary faces' diagonals), on x = 0.5 and y = 0.5
    "axis": Camera((0.5, 0.5, 4.0), (0.5, 0.5, 0.0), ortho_height=1.5),
    # along the face diagonal (1, 1, 0): the middle column (x = y) lies in the 6-split's
    # inner faces x = y
    "face-diagonal": Camera((-1.75, -1.75, 0.5), (1.25, 1.25, 0.5), (0.0, 0.0, 1.0), ortho_height=2.0),
    # along (1, -1, 0) with x + y = 0.5: the middle ray lies in the plane x + y + z = 1 of
    # the 5-split's inner face (1, 2, 4)
    "face-diagonal-2": Camera((-1.75, 2.25, 0.5), (1.25, -0.75, 0.5), (0.0, 0.0, 1.0), ortho_height=2.0),
    "oblique": Camera((2.5, 1.9, 3.1), (0.5, 0.45, 0.55), fov=35),
    "inside": Camera((0.3, 0.6, 0.45), (1.0, 0.2, 0.9), fov=100),
}


@pytest.mark.parametrize("split", ["5", "6"])
@pytest.mark.parametrize("camera", list(CUBE_CAMERAS))
@pytest.mark.parametrize("alpha,unit_distance", [(0.3, 1.0), (0.99, 0.2), (1e-6, 5.0)])
def test_cube_constant_field_closed_form(split, camera, alpha, unit_distance):
    mesh = cubes_mesh([(0, 0, 0)], CUBE5 if split == "5" else CUBE6)
    scene = Scene(mesh, constant_tf(alpha, unit_distance), CUBE_CAMERAS[camera], 15, 13)
    o, d = ray_arrays(scene)
    t0, t1 = ray_box(o, d, np.zeros(3), np.ones(3))
    L = np.maximum(t1 - t0, 0.0)
    assert (L > 0).sum() >= 20
    assert_constant(scene, L, alpha, unit_distance)


def test_cube_cameras_put_rays_in_inner_faces():
    # what the face-diagonal cameras claim (15 x 13: middle column 7, middle row 6)
    s6 = Scene(cubes_mesh([(0, 0, 0)], CUBE6), constant_tf(0.5), CUBE_CAMERAS["face-diagonal"], 15, 13)
    assert rays_in_planes(s6, [((1, -1, 0), 0.0)]) == 13
    s5 = Scene(cubes_mesh([(0, 0, 0)], CUBE5), constant_tf(0.5), CUBE_CAMERAS["face-diagonal-2"], 15, 13)
    assert rays_in_planes(s5, [((1, 1, 1), 1.0)]) == 1
    # those rays do see two tets over the same stretch (coverage to be counted once)
    seg = ray_tet_segments(s6)
    mid = seg["pixel"] % 15 == 7
    assert np.bincount(seg["pixel"][mid]).max() >= 2
    u = union_segments(seg)
    total = np.bincount(u["pixel"], u["t1"] - u["t0"], 15 * 13)
    raw = np.bincount(seg["pixel"], seg["t1"] - seg["t0"], 15 * 13)
    assert np.any(raw > total + 0.5)                       # the raw segments double count
    o, d = ray_arrays(s6)
    t0, t1 = ray_box(o, d, np.zeros(3), np.ones(3))
    np.testing.assert_allclose(total, np.maximum(t1 - t0, 0), atol=1e-13)


def test_cube_composite_with_linear_field_vs_fine_integration():
    # a linear field is linear on every tet of the split: the cube image equals the 1-D
    # integral along each ray (also where rays lie in inner faces)
    g = np.array([0.3, -0.5, 0.8])
    for split, cam in (("5", "oblique"), ("6", "face-diagonal")):
        mesh = cubes_mesh([(0, 0, 0)], CUBE5 if split == "5" else CUBE6, scalars=lambda p: 0.4 + p @ g)
        scene = Scene(mesh, TET_TF, CUBE_CAMERAS[cam], 11, 9)
        img = render(scene).reshape(-1, 4)
        o, d = ray_arrays(scene)
        t0, t1 = ray_box(o, d, np.zeros(3), np.ones(3))
        hit = np.flatnonzero(t1 > t0)
        ref = np.zeros_like(img)
        ref[hit] = march_reference(TET_TF, 0.4 + o[hit] @ g, d[hit] @ g, t0[hit], t1[hit])
        np.testing.assert_allclose(img, ref, rtol=0, atol=1e-11)


def jittered_block():
    """3 x 3 x 3 unit cubes (6-split) on [0, 3]^3 with the 8 interior points moved randomly
    by up to 0.2 per axis: faces in general position, the domain still the box."""
    mesh = cubes_mesh([(i, j, k) for i in range(3) for j in range(3) for k in range(3)], CUBE6)
    pts = mesh.points.copy()
    interior = np.all((pts > 0) & (pts < 3), axis=1)
    pts[interior] += np.random.default_rng(7).uniform(-0.2, 0.2, (interior.sum(), 3))
    out = TetMesh(pts, mesh.tets, np.full(len(pts), 0.5))
    assert np.all(np.sign(out.signed_volumes()) == np.sign(mesh.signed_volumes()))   # still valid
    return out


@pytest.mark.parametrize("camera", [Camera((5.1, 4.3, 6.2), (1.5, 1.4, 1.6), fov=40),
                                    Camera((1.2, 1.7, 0.9), (2.0, 2.5, 2.9), fov=110),      # inside
                                    Camera((1.5, 1.5, 9.0), (1.5, 1.5, 0.0), ortho_height=3.6)])
def test_jittered_block_has_no_cracks(camera):
    scene = Scene(jittered_block(), constant_tf(0.5), camera, 32, 32)
    o, d = ray_arrays(scene)
    t0, t1 = ray_box(o, d, np.zeros(3), np.full(3, 3.0))
    L = np.maximum(t1 - t0, 0.0)
    assert (L > 0).sum() >= 200
    assert_constant(scene, L, 0.5)
    # the union of the segments is each ray's chord, to rounding
    u = union_segments(ray_tet_segments(scene))
    np.testing.assert_allclose(np.bincount(u["pixel"], u["t1"] - u["t0"], 32 * 32), L, rtol=0, atol=1e-13)


# ---------------------------------------------------------------------- non-convex domains
# A U of five cubes in the xy plane, one deep in z: (0,0), (1,0), (2,0), (0,1), (2,1); the
# notch (1,1) is empty. Viewed along -x, rays with y in (1, 2) cross cube (2,1), a gap, then
# cube (0,1): chord 2 in two parts; rays with y in (0, 1) cross 3 cubes: chord 3.
U_ORIGINS = [(0, 0, 0), (1, 0, 0), (2, 0, 0), (0, 1, 0), (2, 1, 0)]
U_BOXES = [(o, np.add(o, 1)) for o in U_ORIGINS]
U_CAMERAS = {
    "along-x": Camera((6.0, 1.0, 0.5), (0.0, 1.0, 0.5), ortho_height=2.4),
    "along-z": Camera((1.5, 1.0, 5.0), (1.5, 1.0, 0.0), ortho_height=2.6),
    "oblique": Camera((4.5, 3.7, 3.2), (1.5, 1.0, 0.5), fov=45),
}


@pytest.mark.parametrize("camera", list(U_CAMERAS))
@pytest.mark.parametrize("alpha", [0.35, 0.995])
def test_non_convex_u_closed_form(camera, alpha):
    mesh = cubes_mesh(U_ORIGINS, CUBE6)
    scene = Scene(mesh, constant_tf(alpha, 0.7), U_CAMERAS[camera], 24, 20)
    L = chord_boxes(scene, U_BOXES)
    if camera == "along-x":
        o, _ = ray_arrays(scene)
        y = o[:, 1]
        inside_z = (o[:, 2] > 0) & (o[:, 2] < 1)
        expected = np.where(inside_z & (y > 0) & (y < 1), 3.0, np.where(inside_z & (y > 1) & (y < 2), 2.0, 0.0))
        np.testing.assert_allclose(L, expected, atol=1e-12)
        assert np.any(expected == 2.0) and np.any(expected == 3.0)
    assert (L > 0).sum() >= 40
    assert_constant(scene, L, alpha, 0.7)


def test_two_blobs_and_gap_with_linear_field():
    # two separate cubes (5-split and 6-split) on the x axis with a gap of 1.5 between them
    a, b = cubes_mesh([(0, 0, 0)], CUBE5), cubes_mesh([(0, 0, 0)], CUBE6)
    pts = np.concatenate([a.points, b.points + [2.5, 0.0, 0.0]])
    tets = np.concatenate([a.tets, b.tets + len(a.points)])
    g = np.array([0.2, 0.1, -0.3])
    mesh = TetMesh(pts, tets, 0.3 + pts @ g)
    boxes = [((0, 0, 0), (1, 1, 1)), ((2.5, 0, 0), (3.5, 1, 1))]
    for cam in (Camera((7.0, 0.5, 0.5), (0.0, 0.5, 0.5), ortho_height=1.6),
                Camera((7.0, 0.7, 0.6), (0.5, 0.5, 0.5), fov=20)):
        # constant field: closed form of the summed chord
        sc = Scene(TetMesh(pts, tets, np.full(len(pts), 0.5)), constant_tf(0.6), cam, 20, 16)
        L = chord_boxes(sc, boxes)
        assert_constant(sc, L, 0.6)
        # linear field: front blob then back blob, the gap adds nothing
        scene = Scene(mesh, TET_TF, cam, 20, 16)
        img = render(scene).reshape(-1, 4)
        o, d = ray_arrays(scene)
        front, back = [ray_box(o, d, np.asarray(lo, float), np.asarray(hi, float)) for lo, hi in boxes[::-1]]
        ref = np.zeros_like(img)
        both = np.flatnonzero((front[1] > front[0]) & (back[1] > back[0]))
        assert both.size >= 10
        a, b = 0.3 + o[both] @ g, d[both] @ g
        first = march_reference(TET_TF, a, b, front[0][both], front[1][both])
        second = march_reference(TET_TF, a, b, back[0][both], back[1][both])
        ref[both] = first + (1 - first[:, 3:4]) * second
        np.testing.assert_allclose(img[both], ref[both], rtol=0, atol=1e-11)


# -------------------------------------------------------------- slivers and zero volume
def test_zero_volume_tet_gives_nothing_and_sliver_is_harmless():
    cube = cubes_mesh([(0, 0, 0)], CUBE6)
    # a flat tet (4 points on the plane z = 0.5) and a sliver (0.5e-9 high) inside the
    # cube, both with scalars far from the cube's 0.5
    flat = np.array([[0.1, 0.1, 0.5], [0.9, 0.2, 0.5], [0.3, 0.8, 0.5], [0.5, 0.4, 0.5]])
    sliver = np.array([[0.1, 0.2, 0.3], [0.9, 0.1, 0.3], [0.2, 0.9, 0.3], [0.5, 0.5, 0.3 + 5e-10]])
    n = len(cube.points)
    pts = np.concatenate([cube.points, flat, sliver])
    tets = np.concatenate([cube.tets, [[n, n + 1, n + 2, n + 3], [n + 4, n + 5, n + 6, n + 7]]])
    s = np.concatenate([cube.scalars, [1.0] * 4, [0.9] * 4])
    mesh = TetMesh(pts, tets, s)
    cam = Camera((0.5, 0.5, 4.0), (0.5, 0.5, 0.0), ortho_height=1.5)
    # the flat tet: no segment at all, also when asked for alone
    scene = Scene(mesh, constant_tf(0.5), cam, 16, 16)
    assert ray_tet_segments(scene, tets=np.array([len(tets) - 2]))["pixel"].size == 0
    seg = ray_tet_segments(scene)
    assert not np.any(seg["tet"] == len(tets) - 2)
    # the sliver: segments about 5e-10 long with values within its vertex range
    sl = seg["tet"] == len(tets) - 1
    assert sl.any() and np.all(seg["t1"][sl] - seg["t0"][sl] < 1e-9)
    for k in ("s0", "s1"):      # a convex combination of the vertex values (to rounding)
        np.testing.assert_allclose(seg[k][sl], 0.9, rtol=4e-16, atol=0)
    # composite: the extra length is below 1e-9 (and overlaps the cube: counted once)
    base = render(Scene(cube, constant_tf(0.5), cam, 16, 16))
    img = render(Scene(mesh, constant_tf(0.5), cam, 16, 16))
    np.testing.assert_allclose(img, base, rtol=0, atol=1e-12)
    # mip sees the sliver's value where it covers the ray (it is in the domain), never the
    # flat tet's 1.0
    mip = render(Scene(mesh, constant_tf(0.5), cam, 16, 16, mode="mip"))
    tf = constant_tf(0.5)
    assert np.all(mip[..., 3] <= tf.opacity(0.9))
    # a mesh of nothing but zero-volume tets is an empty image
    only_flat = TetMesh(flat, [[0, 1, 2, 3]], [1.0] * 4)
    assert np.all(render(Scene(only_flat, tf, cam, 8, 8)) == 0)


# ----------------------------------------------------------------------- the other modes
LIN_G = np.array([0.25, 0.5, 0.125])
LIN_TF = TransferFunction([(0.0, 1.0, 0.0, 0.0), (1.0, 0.0, 0.0, 1.0)], [(0.0, 0.1), (1.0, 0.9)])


def classified(s):
    a = LIN_TF.opacity(s)
    return np.concatenate([LIN_TF.color(s) * a[:, None], a[:, None]], axis=1)


@pytest.mark.parametrize("mode", ["mip", "minip", "average"])
def test_extremes_and_average_of_linear_field(mode):
    # s = x/4 + y/2 + z/8 on the U, viewed along -z: per ray s runs from s(x, y, 0) to
    # s(x, y, 1), so max = s + 1/8, min = s, mean = s + 1/16
    mesh = cubes_mesh(U_ORIGINS, CUBE6, scalars=lambda p: p @ LIN_G)
    cam = U_CAMERAS["along-z"]
    scene = Scene(mesh, LIN_TF, cam, 24, 20, mode=mode)
    img = render(scene).reshape(-1, 4)
    o, _ = ray_arrays(scene)
    hit = chord_boxes(scene, U_BOXES) > 0
    base = o[:, 0] * LIN_G[0] + o[:, 1] * LIN_G[1]
    s = base + {"mip": 0.125, "minip": 0.0, "average": 0.0625}[mode]
    np.testing.assert_allclose(img[hit], classified(s[hit]), rtol=0, atol=1e-14)
    assert np.all(img[~hit] == 0) and hit.sum() > 100


def test_average_over_a_gap_and_mip_along_x():
    # along -x through the U's notch: the rays with y in (1, 2) see x in [2, 3] and [0, 1]:
    # the mean of s over both parts is s(1.5, y, z) (symmetric), the max s(3, y, z)
    mesh = cubes_mesh(U_ORIGINS, CUBE6, scalars=lambda p: p @ LIN_G)
    cam = U_CAMERAS["along-x"]
    for mode, x in (("average", 1.5), ("mip", 3.0), ("minip", 0.0)):
        scene = Scene(mesh, LIN_TF, cam, 24, 20, mode=mode)
        img = render(scene).reshape(-1, 4)
        o, _ = ray_arrays(scene)
        notch = (o[:, 1] > 1) & (o[:, 1] < 2) & (o[:, 2] > 0) & (o[:, 2] < 1)
        assert notch.sum() >= 20
        s = x * LIN_G[0] + o[notch, 1] * LIN_G[1] + o[notch, 2] * LIN_G[2]
        np.testing.assert_allclose(img[notch], classified(s), rtol=0, atol=1e-14)


def test_isosurface_of_linear_field():
    # s = x/4 + y/2 + z/8, iso 0.5, viewed along -z from above: the ray enters at z = 1
    # with s = b + 1/8 and leaves at z = 0 with s = b (b = x/4 + y/2), so it crosses 0.5
    # iff b < 0.5 < b + 1/8. Shading: g constant, N = -g/|g|, L = +z.
    mesh = cubes_mesh(U_ORIGINS, CUBE6, scalars=lambda p: p @ LIN_G)
    cam = U_CAMERAS["along-z"]
    scene = Scene(mesh, LIN_TF, cam, 24, 20, mode="isosurface", iso_value=0.5)
    img = render(scene).reshape(-1, 4)
    o, d = ray_arrays(scene)
    inside = chord_boxes(scene, U_BOXES) > 0
    b = o[:, 0] * LIN_G[0] + o[:, 1] * LIN_G[1]
    cross = inside & (b < 0.5) & (b + 0.125 > 0.5)
    assert cross.sum() >= 10 and (inside & ~cross).sum() >= 10
    ka, kd, ks, sh = scene.phong
    ndotl = abs(LIN_G[2]) / np.linalg.norm(LIN_G)
    rgb = LIN_TF.color(0.5) * (ka + kd * ndotl) + ks * ndotl ** sh
    np.testing.assert_allclose(img[cross], np.broadcast_to(np.append(rgb, 1.0), (cross.sum(), 4)), atol=1e-13)
    assert np.all(img[~cross] == 0)


# ---------------------------------------------------------------------- API and the cache
def test_segments_subset_and_blocks_agree():
    mesh = cubes_mesh(U_ORIGINS, CUBE6)
    scene = Scene(mesh, constant_tf(0.5), U_CAMERAS["oblique"], 24, 20)
    full = ray_tet_segments(scene)
    sub = np.arange(3, len(mesh.tets), 2)
    part = ray_tet_segments(scene, tets=sub)
    assert set(np.unique(part["tet"])) <= set(sub)
    pick = np.isin(full["tet"], sub)
    key = lambda s, m=slice(None): np.lexsort((s["tet"][m], s["pixel"][m]))   # noqa: E731
    a, b = key(full, pick), key(part)
    for k in ("pixel", "tet", "t0", "t1", "s0", "s1"):
        assert np.array_equal(full[k][pick][a], part[k][b])
    # row blocks cover the image and give the same segments
    rays = MeshRays(scene)
    blocks = rays.row_blocks(50)
    assert blocks[0][0] == 0 and blocks[-1][1] == 20 and len(blocks) > 2
    joined = [rays.segments(r0, r1) for r0, r1 in blocks]
    pix = np.concatenate([j["pixel"] for j in joined])
    assert np.array_equal(np.sort(pix), np.sort(full["pixel"]))


def test_mesh_cache_round_trip(tmp_path, monkeypatch):
    mesh = cubes_mesh(U_ORIGINS, CUBE6, scalars=lambda p: p @ LIN_G)
    scene = Scene(mesh, LIN_TF, U_CAMERAS["oblique"], 10, 8)
    first = ex.exact(scene, cache_dir=tmp_path)
    name = f"{scene.digest()}-{ex.VERSION}.npy"
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]

    def fail(_scene):
        raise AssertionError("should have been loaded from the cache")

    monkeypatch.setattr(ex, "render_one", fail)
    second = ex.exact(scene, cache_dir=tmp_path)
    assert np.array_equal(first, second) and first[..., 3].max() > 0.1
    # another field on the same geometry is another key
    other = Scene(cubes_mesh(U_ORIGINS, CUBE6), LIN_TF, U_CAMERAS["oblique"], 10, 8)
    assert other.digest() != scene.digest()
    with pytest.raises(AssertionError, match="loaded from the cache"):
        ex.exact(other, cache_dir=tmp_path)
