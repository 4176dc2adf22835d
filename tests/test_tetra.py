"""Projected tetrahedra (technique "tetra") on the GPU: closed forms, visibility order,
what is drawn, and the shader's segment integral against its NumPy twin.

Tolerances. The GL path works in float32: planes, ray and distances carry a relative
error of a few 1e-7 of the distance from the eye (here at most ~5 world units, so
~2e-6 absolute in a chord), the segment integral's transcendental functions a few 1e-7
relative, and each blend rounds to float32. A chord error dL changes A by at most
tau * dL <= 2 * 2e-6; over the at most 12 segments a ray meets in these meshes the
bound is 12 * (4e-6 + 3e-7) ~ 5e-5; we assert 1e-4 on the largest channel error.
"""

import numpy as np
import pytest

import dvr_gl
from dvr_gl import Camera, Scene, TetMesh, TransferFunction
from dvr_gl.model import mesh as M
from dvr_gl.techniques import cell_order
from dvr_gl.reference.common import ray_box
from dvr_gl.model.transfer import SegmentKnots
from dvr_gl.reference.linear_segment import linear_segment
from dvr_gl.reference.mesh_rays import ray_tet_segments
from dvr_gl.techniques import tetra

GL_TOL = 1e-4

CUBE = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], float)
# The cube's corners are numbered x + 2y + 4z.
SIX = np.array([[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]])
FIVE = np.array([[0, 1, 2, 4], [1, 3, 2, 7], [1, 4, 5, 7], [2, 6, 4, 7], [1, 2, 4, 7]])


def cube_mesh(split, value=0.5, offset=(0, 0, 0), scale=1.0):
    return TetMesh(CUBE * scale + np.asarray(offset, float), split, np.full(8, value))


def blocks_mesh(cells, split=SIX):
    """Unit cubes at the integer positions ``cells`` (x, y, z), sharing points, each split
    by ``split`` (the Kuhn split is conforming across cubes), constant value 0.5."""
    index = {}
    points, tets = [], []
    for c in cells:
        ids = []
        for k in range(8):
            p = (c[0] + (k & 1), c[1] + ((k >> 1) & 1), c[2] + ((k >> 2) & 1))
            if p not in index:
                index[p] = len(points)
                points.append(p)
            ids.append(index[p])
        tets.extend([[ids[i] for i in t] for t in split])
    return TetMesh(np.array(points, float), np.array(tets), np.full(len(points), 0.5))


TF = TransferFunction([(0, 1.0, 0.5, 0.2), (1, 1.0, 0.5, 0.2)], [(0, 0.3), (1, 0.3)], unit_distance=0.5)


def closed_form_boxes(scene, boxes, tf=TF, value=0.5):
    """Constant-field image of a union of disjoint axis-aligned boxes: per pixel the
    summed chord length L, A = 1 - (1 - alpha)^(L/u), C = c A."""
    o, d = scene.camera.rays(scene.width, scene.height)
    o, d = o.reshape(-1, 3), d.reshape(-1, 3)
    L = np.zeros(len(o))
    for lo, hi in boxes:
        t0, t1 = ray_box(o, d, np.asarray(lo, float), np.asarray(hi, float))
        L += np.maximum(t1 - t0, 0)
    a = float(tf.opacity(value))
    A = 1 - (1 - a) ** (L / tf.unit_distance)
    c = tf.color(value)
    return np.concatenate([c * A[:, None], A[:, None]], axis=1).reshape(scene.height, scene.width, 4)


VIEWS = {
    "along_z": Camera((0.5, 0.5, 3.0), (0.5, 0.5, 0.5), ortho_height=1.6),
    "face_diagonal": Camera((3.0, 3.0, 0.5), (0.5, 0.5, 0.5), up=(0, 0, 1), ortho_height=2.0),
    "body_diagonal": Camera((3.0, 3.0, 3.0), (0.5, 0.5, 0.5), up=(0, 0, 1), ortho_height=2.0),
    "perspective": Camera((2.4, 1.7, 3.1), (0.5, 0.5, 0.5), fov=30),
    "eye_inside": Camera((0.3, 0.6, 0.4), (0.9, 0.2, 0.8), fov=60),
}


@pytest.mark.parametrize("split", ["five", "six"])
@pytest.mark.parametrize("view", sorted(VIEWS))
def test_constant_cube_is_the_constant_box(renderer, split, view):
    """No cracks, no double counting on shared faces and edges, under any view (rays
    lying in shared faces on the diagonal views), eye inside included."""
    mesh = cube_mesh(FIVE if split == "five" else SIX)
    scene = Scene(mesh, TF, VIEWS[view], 48, 48)
    img = renderer.render(scene, technique="tetra", sort="mpvo")
    want = closed_form_boxes(scene, [((0, 0, 0), (1, 1, 1))])
    assert np.abs(img - want).max() < GL_TOL
    assert img[..., 3].max() > 0.3


def test_either_orientation_and_zero_volume_cells_change_nothing(renderer):
    mesh = cube_mesh(SIX)
    flipped = TetMesh(mesh.points, mesh.tets[:, [0, 1, 3, 2]], mesh.scalars)
    # a flat cell glued to the bottom face (four coplanar points), as a collapsed hex leaves
    pts = np.vstack([mesh.points, [[0.5, 0.25, 0.0]]])
    flat = TetMesh(pts, np.vstack([mesh.tets, [[0, 1, 3, 8]]]), np.concatenate([mesh.scalars, [0.5]]))
    scene = Scene(mesh, TF, VIEWS["perspective"], 40, 40)
    base = renderer.render(scene, technique="tetra", sort="mpvo")
    assert np.array_equal(renderer.render(scene.replace(volume=flipped), technique="tetra", sort="mpvo"), base)
    assert M.topology(flat).flat.sum() == 1
    assert np.abs(renderer.render(scene.replace(volume=flat), technique="tetra", sort="mpvo") - base).max() < GL_TOL


@pytest.mark.parametrize("sort", ["mpvo", "centroid"])
def test_folded_cells_are_bounded_by_their_own_faces(renderer, sort):
    """A folded mesh (a curvilinear grid turned inside out somewhere, as in real CFD data):
    two cells share a face but lie on the same side of it, overlapping. Each cell must
    still be cut by its own four planes. Projection counts the overlap once per cell
    (reference.exact counts covered length once; the folds of real meshes are a few
    cells), so the image is the constant field's over both chords, summed (float64
    chords from reference.mesh_rays)."""
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0.2, 0.25, 0.3]], float)
    mesh = TetMesh(pts, np.array([[0, 1, 2, 3], [1, 2, 3, 4]]), np.full(5, 0.5))
    topo = M.topology(mesh)
    planes = topo.cell_planes()
    for c in range(2):      # every vertex of a cell on the inner side of its four planes
        p = mesh.points[topo.tets[c]] - mesh.bounds[0]
        assert (p @ planes[c, :, :3].T - planes[c, :, 3] <= 1e-12).all()
    scene = Scene(mesh, TF, Camera((2.0, 1.5, 1.8), (0.3, 0.3, 0.3), fov=35), 40, 40)
    img = renderer.render(scene, technique="tetra", sort=sort)
    seg = ray_tet_segments(scene)
    assert set(seg["tet"].tolist()) == {0, 1}
    L = np.bincount(seg["pixel"], seg["t1"] - seg["t0"], minlength=40 * 40).reshape(40, 40)
    A = 1 - (1 - float(TF.opacity(0.5))) ** (L / TF.unit_distance)
    want = np.concatenate([TF.color(0.5) * A[..., None], A[..., None]], axis=-1)
    assert np.abs(img - want).max() < GL_TOL
    assert img[..., 3].max() > 0.2


@pytest.mark.parametrize("sort", ["mpvo", "centroid"])
def test_non_convex_meshes(renderer, sort):
    """An L of three cubes seen into its notch, and two separate blocks one behind the
    other: MPVO's order (with the per-pixel gap constraints) is exact; the centroid sort
    is exact here too (its failures need interleaved cells, measured elsewhere)."""
    L_cells = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
    blobs = [(0, 0, 0), (3, 0, 2)]
    cam = Camera((4.5, 3.5, 4.0), (1.0, 0.8, 0.5), fov=35)
    for cells in (L_cells, blobs):
        mesh = blocks_mesh(cells)
        scene = Scene(mesh, TF, cam, 48, 48)
        img = renderer.render(scene, technique="tetra", sort=sort)
        want = closed_form_boxes(scene, [(c, np.add(c, 1)) for c in cells])
        assert np.abs(img - want).max() < GL_TOL


def test_mpvo_order_respects_depth_along_every_pixel():
    """The order's contract checked directly: along each pixel's ray, a cell met later is
    drawn earlier (non-convex blocks with a gap, perspective)."""
    cells = [(0, 0, 0), (2, 0, 0), (1, 0, 2), (0, 1, 3)]
    mesh = blocks_mesh(cells)
    cam = Camera((6.0, 4.0, 7.0), (1.0, 0.5, 1.5), fov=40)
    scene = Scene(mesh, TF, cam, 40, 40)
    visible = cell_order.visible_cells(mesh, TF)
    order = cell_order.mpvo_order(mesh, visible, scene)
    assert sorted(order.cells.tolist()) == list(range(mesh.n_tets))
    assert order.gap_constraints > 0 and order.cycles_broken == 0
    rank = np.empty(mesh.n_tets, int)
    rank[order.cells] = np.arange(mesh.n_tets)
    # sample each cell's ray segments on the CPU: centroid-ray test per pixel
    o, d = cam.rays(40, 40)
    o, d = o.reshape(-1, 3) - mesh.bounds[0], d.reshape(-1, 3)
    planes = M.topology(mesh).cell_planes()
    n, off = planes[..., :3], planes[..., 3]
    along = np.einsum("mfk,pk->pmf", n, d)
    room = off[None] - np.einsum("mfk,pk->pmf", n, o)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = room / along
    t_in = np.where(along < 0, t, -np.inf).max(-1).clip(0)
    t_out = np.where(along > 0, t, np.inf).min(-1)
    outside = ((along == 0) & (room < 0)).any(-1)
    hit = (t_out > t_in + 1e-9) & ~outside
    for p in np.flatnonzero(hit.any(1)):
        cells_p = np.flatnonzero(hit[p])
        by_depth = cells_p[np.argsort(t_in[p, cells_p])]
        assert np.all(np.diff(rank[by_depth]) < 0), "a nearer cell is drawn before a farther one"


def _lattice_mesh(counts=(4, 4, 4), spacing=(1.0, 1.0, 1.0)):
    """The Delaunay mesh of a regular lattice: every cube's eight corners are cospherical,
    so scipy splits some planar quads two ways with zero-volume cells between them."""
    axes = [np.arange(n) * h for n, h in zip(counts, spacing)]
    points = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    field = np.sin(1.3 * points[:, 0]) + 0.2 * points[:, 1] ** 2 + 0.4 * points[:, 2]
    return TetMesh.from_points(points, field)


@pytest.mark.parametrize("counts,spacing", [((4, 4, 4), (1, 1, 1)), ((5, 4, 3), (0.5, 1.0, 1.5))])
def test_mpvo_through_zero_volume_cells_of_a_lattice_delaunay(renderer, counts, spacing):
    """Zero-volume cells carry no orientation, so a face constraint through one could point
    either way (before the fix: a cycle and 0.069 off the exact image). Across a layer of
    them the order comes from the real cells' own vertices: no cycle, and GL and the
    reference equal the exact image, the whole mesh and a TF that hides part of it (which
    adds the per-pixel gap pass), within the GL bound above, and the reference within
    1e-7 (its colour integral is within 2e-8 of float64 quadrature per segment, and a ray
    meets at most a handful of cells here; a wrong order is 1e-4 to 7e-2 off)."""
    mesh = _lattice_mesh(counts, spacing)
    topo = M.topology(mesh)
    assert topo.flat.sum() > 0 and len(topo.flat_pairs) > 0
    lo, hi = float(mesh.scalars.min()), float(mesh.scalars.max())
    mid = 0.5 * (lo + hi)
    whole = TransferFunction(color=[(lo, 0.2, 0.3, 0.9), (hi, 0.9, 0.3, 0.2)], opacity=[(lo, 0.3), (hi, 0.9)],
                             unit_distance=0.5)
    part = TransferFunction(color=[(lo, 0.2, 0.3, 0.9), (hi, 0.9, 0.3, 0.2)],
                            opacity=[(lo, 0.0), (mid, 0.0), (hi, 0.9)], unit_distance=0.5)
    for tf in (whole, part):
        for az, el in ((30, 20), (45, 35), (0, 0), (90, 45)):
            scene = Scene(mesh, tf, dvr_gl.default_camera(mesh, azimuth=az, elevation=el), 40, 40)
            order = cell_order.mpvo_order(mesh, cell_order.visible_cells(mesh, tf), scene)
            assert order.cycles_broken == 0
            exact = dvr_gl.reference.exact(scene)
            ref = dvr_gl.reference.render(scene, technique="tetra", sort="mpvo")
            assert np.abs(ref - exact).max() < 1e-7
            img = renderer.render(scene, technique="tetra", sort="mpvo")
            assert np.abs(img - exact).max() < GL_TOL


def test_kahn_breaks_cycles_deterministically():
    cells = np.arange(4)
    src = np.array([0, 1, 2, 3])
    dst = np.array([1, 2, 0, 0])       # 0 -> 1 -> 2 -> 0 is a cycle; 3 -> 0
    depth = np.array([1.0, 3.0, 2.0, 0.5])
    order, broken = cell_order._kahn(cells, src, dst, depth, 4)
    again, broken2 = cell_order._kahn(cells, src, dst, depth, 4)
    assert broken == broken2 == 1
    assert order.tolist() == again.tolist()
    assert sorted(order.tolist()) == [0, 1, 2, 3]
    assert order[0] == 3 and order[1] == 1     # the free cell, then the farthest of the cycle


def test_transparent_cells_are_neither_sorted_nor_drawn(renderer):
    """Cells whose whole value range has zero opacity are left out of the order and the
    draw, and that changes no pixel: the mesh renders as the mesh without them."""
    tf = TransferFunction([(0, 1, 0.5, 0.2), (1, 1, 0.5, 0.2)], [(0, 0.3), (0.5, 0.3), (0.6, 0.0)],
                          unit_distance=0.5)

    def row(n):
        m = blocks_mesh([(i, 0, 0) for i in range(n)])
        return TetMesh(m.points, m.tets, np.where(m.points[:, 0] <= 1.0, 0.5, 3.0))

    cam = Camera((5.0, 2.5, 4.0), (1.0, 0.5, 0.5), fov=30)
    three, two = Scene(row(3), tf, cam, 40, 40), Scene(row(2), tf, cam, 40, 40)
    plan = tetra.make_plan(three, sort="mpvo")
    assert plan.visible.size == plan.draw.size == 12     # the third cube (values 3 only) is out
    assert np.abs(renderer.render(three, technique="tetra", sort="mpvo") - renderer.render(two, technique="tetra", sort="mpvo")).max() < GL_TOL
    empty = TransferFunction([(0, 1, 1, 1), (1, 1, 1, 1)], [(0, 0.0), (1, 0.0)])
    scene = three.replace(tf=empty)
    assert tetra.make_plan(scene, sort="mpvo").draw.size == 0
    assert not renderer.render(scene, technique="tetra", sort="mpvo").any()


def test_order_is_made_once_per_view(renderer):
    mesh = cube_mesh(SIX)
    scene = Scene(mesh, TF, VIEWS["perspective"], 24, 24)
    renderer.render(scene, technique="tetra", sort="mpvo")
    calls = []
    original = cell_order.mpvo_order

    def counting(*args, **kwargs):
        calls.append(1)
        return original(*args, **kwargs)

    tetra.mpvo_order = counting
    try:
        renderer.render(scene, technique="tetra", sort="mpvo")
        assert calls == []
        renderer.render(scene.replace(camera=VIEWS["body_diagonal"]), technique="tetra", sort="mpvo")
        assert calls == [1]
    finally:
        tetra.mpvo_order = original


def test_mesh_data_uploaded_once(renderer):
    mesh = cube_mesh(FIVE, value=0.25)
    scene = Scene(mesh, TF, VIEWS["perspective"], 16, 16)
    before = len([c for c in renderer.created if c[0] == "tetra_mesh"])
    for cam in (VIEWS["perspective"], VIEWS["along_z"], VIEWS["body_diagonal"]):
        renderer.render(scene.replace(camera=cam), technique="tetra", sort="mpvo")
    assert len([c for c in renderer.created if c[0] == "tetra_mesh"]) == before + 1


def test_options_and_data_kinds_are_checked(renderer):
    mesh = cube_mesh(SIX)
    scene = Scene(mesh, TF, VIEWS["perspective"], 16, 16)
    with pytest.raises(ValueError, match="sort"):
        renderer.render(scene, technique="tetra", sort="bsp")
    with pytest.raises(ValueError, match="step"):
        renderer.render(scene, technique="tetra", step=0.1)
    with pytest.raises(ValueError, match="TetMesh.*tetra"):
        renderer.render(scene, technique="raycast")
    vol = dvr_gl.Volume(np.zeros((2, 2, 2), np.float32))
    with pytest.raises(ValueError, match="Volume"):
        renderer.render(scene.replace(volume=vol), technique="tetra", sort="mpvo")
    assert dvr_gl.techniques.for_scene(scene) == ("tetra", "particles", "splat")


def test_segment_integral_shader_matches_numpy(renderer):
    """The GLSL segment integral against its float64 twin over many segments: knots
    crossed either way, constant segments, opacity reaching 1, long and tiny segments.
    Each pixel draws one cell with a chosen (s_front, s_back, length): a single tet seen
    along an axis has a chord that is known per pixel."""
    tf = TransferFunction([(0, 1, 0, 0), (0.3, 0, 1, 0), (0.6, 0, 0, 1), (1, 1, 1, 1)],
                          [(0, 0.0), (0.2, 0.4), (0.5, 0.05), (0.8, 0.9), (1.0, 1.0)], unit_distance=0.3)
    # a slab x, y in [0, 1], z in [0, 1] made of six tets, field linear in z: s = a + b z
    rng = np.random.default_rng(3)
    for a, b in rng.uniform(-0.2, 1.2, size=(6, 2)):
        values = a + b * CUBE[:, 2]
        mesh = TetMesh(CUBE, SIX, values)
        scene = Scene(mesh, tf, Camera((0.5, 0.5, 3.0), (0.5, 0.5, 0.5), ortho_height=0.9), 8, 8)
        img = renderer.render(scene, technique="tetra", sort="mpvo")
        want = linear_segment(SegmentKnots(tf), a + b * 1.0, a + b * 0.0, 1.0)[0]
        assert np.abs(img - want).max() < 2e-5, (a, b)


def test_segment_integral_against_independent_quadrature():
    """The NumPy twin against preintegration.exact_segment (nested adaptive quadrature, no
    shared code): random segments crossing knots either way, thin and long, and opacity
    reaching 1 inside a segment (the contract's end-of-ray rule)."""
    from dvr_gl.model.preintegration import exact_segment
    tf = TransferFunction([(0, 1, 0, 0), (0.5, 0, 1, 0), (1, 0, 0, 1)],
                          [(0, 0.0), (0.4, 0.6), (0.6, 0.2), (1, 0.9)], unit_distance=0.5)
    rng = np.random.default_rng(1)
    sf, sb = rng.uniform(-0.2, 1.2, (2, 80))
    length = rng.uniform(0, 3, 80) * rng.choice([1.0, 0.1, 0.01], 80)
    sf[:5] = sb[:5]
    got = linear_segment(SegmentKnots(tf), sf, sb, length)
    want = np.array([exact_segment(tf, a, b, l) for a, b, l in zip(sf, sb, length)])
    assert np.abs(got - want).max() < 2e-8
    opaque = TransferFunction([(0, 1, 1, 1), (1, 1, 0, 0)], [(0, 0.0), (1, 1.0)], unit_distance=1.0)
    a, b, l = [0.0, 0.2, 1.0, 0.5, 0.9], [1.0, 1.0, 0.0, 0.5, 1.0], [1.0, 2.0, 1.0, 1.0, 5.0]
    got = linear_segment(SegmentKnots(opaque), a, b, l)
    want = np.array([exact_segment(opaque, *x) for x in zip(a, b, l)])
    assert np.abs(got - want).max() < 1e-12
    assert np.all(got[[0, 1, 2], 3] == 1.0)


@pytest.mark.parametrize("mode", ["mip", "minip", "average"])
def test_reduction_modes_on_a_linear_field(renderer, mode):
    """A field linear in z seen along z: each pixel's maximum, minimum and mean are known
    (the value at the top, at the bottom, and halfway), classified by the TF."""
    mesh = TetMesh(CUBE, SIX, CUBE[:, 2] + 0.2 * CUBE[:, 0])
    tf = TransferFunction([(0, 1, 0, 0), (1.2, 0, 0, 1)], [(0, 0.1), (1.2, 0.9)], unit_distance=0.5)
    scene = Scene(mesh, tf, Camera((0.5, 0.5, 3.0), (0.5, 0.5, 0.5), ortho_height=1.6), 16, 16, mode=mode)
    img = renderer.render(scene, technique="tetra", sort="mpvo")
    o, _ = scene.camera.rays(16, 16)
    x, y = o[..., 0], o[..., 1]
    inside = (x >= 0) & (x <= 1) & (y >= 0) & (y <= 1)
    s = 0.2 * x + {"mip": 1.0, "minip": 0.0, "average": 0.5}[mode]
    a = np.where(inside, tf.opacity(s), 0.0)
    want = np.concatenate([tf.color(s) * a[..., None], a[..., None]], axis=-1)
    assert np.abs(img - want).max() < 1e-6
    assert tetra.make_plan(scene, sort="mpvo").draw.size == mesh.n_tets     # nothing is culled or sorted


def test_grid_and_its_tetrahedralisation_agree_within_interpolation():
    """A field as a grid (trilinear) and as its Kuhn tetrahedralisation (linear per tet):
    a linear field is the same function both ways, so the images are equal (exact: to
    rounding; GL tetra: within its float32 bound); for a curved field the two interpolants
    differ by O(h^2), and so do the images: halving the spacing quarters the difference."""
    from dvr_gl.model.cell_split import grid_to_tets
    cam = Camera((2.6, 1.9, 3.3), (0.5, 0.5, 0.5), fov=35)

    def field(n, f):
        z, y, x = np.meshgrid(*(np.linspace(0, 1, n),) * 3, indexing="ij")
        return dvr_gl.Volume(f(x, y, z), spacing=(1 / (n - 1),) * 3)

    tf = TransferFunction([(0, 0.1, 0.3, 0.9), (1, 0.9, 0.3, 0.1)], [(0, 0.05), (1, 0.6)], unit_distance=0.3)
    linear = field(5, lambda x, y, z: 0.2 + 0.3 * x + 0.2 * y + 0.25 * z)
    grid = Scene(linear, tf, cam, 24, 24)
    mesh = grid.replace(volume=grid_to_tets(linear))
    exact_grid = dvr_gl.reference.exact(grid)
    assert np.abs(dvr_gl.reference.exact(mesh) - exact_grid).max() < 1e-9
    with dvr_gl.Renderer() as r:
        assert np.abs(r.render(mesh, technique="tetra", sort="mpvo") - exact_grid).max() < GL_TOL
    assert exact_grid[..., 3].max() > 0.3

    def curved(x, y, z):
        return 0.5 + 0.4 * np.sin(2.5 * x + 1) * np.cos(2 * y) * (0.6 + 0.4 * z)

    diffs = []
    for n in (5, 9, 17):
        vol = field(n, curved)
        g = Scene(vol, tf, cam, 24, 24)
        diffs.append(np.sqrt(np.mean((dvr_gl.reference.exact(g.replace(volume=grid_to_tets(vol)))
                                      - dvr_gl.reference.exact(g)) ** 2)))
    assert diffs[0] > 1e-4
    assert 2.8 < diffs[0] / diffs[1] < 5.5 and 2.8 < diffs[1] / diffs[2] < 5.5, diffs


@pytest.mark.parametrize("height", [1e-3, 1e-6])
def test_slivers_glued_to_a_cube(renderer, height):
    """Nearly flat cells (height 1e-3 and 1e-6 of the cube) glued to the cube's bottom
    face, seen from above, from below and grazing along the face (the eye in its plane,
    where a sliver's planes are nearly parallel to the rays): GL within its bound of the
    exact image, so no sliver turns into a long segment."""
    base = cube_mesh(SIX)
    apex = [[0.6, 0.3, -height], [0.3, 0.6, -height]]
    pts = np.vstack([base.points, apex])
    bottom = [t for t in SIX if sum(CUBE[i][2] == 0 for i in t) == 3]   # the cells on z = 0
    faces = [[i for i in t if CUBE[i][2] == 0] for t in bottom]
    tets = np.vstack([base.tets, [faces[0] + [8]], [faces[1] + [9]]])
    mesh = TetMesh(pts, tets, np.full(len(pts), 0.5))
    assert len(faces) == 2 and M.topology(mesh).flat.sum() == 0
    for cam in (Camera((0.5, 0.5, 3.0), (0.5, 0.5, 0.5), fov=40),
                Camera((0.7, 0.2, -2.5), (0.5, 0.5, 0.5), fov=40),
                Camera((-2.0, -1.5, 0.0), (0.5, 0.5, 0.0), up=(0, 0, 1), fov=50)):
        scene = Scene(mesh, TF, cam, 40, 40)
        img = renderer.render(scene, technique="tetra", sort="mpvo")
        assert np.abs(img - dvr_gl.reference.exact(scene)).max() < GL_TOL
        assert img[..., 3].max() > 0.2


def test_depth_ranges_restart_and_cells_behind_the_eye_get_their_own_draws(renderer, monkeypatch):
    """Each cell's fragments carry its slot's depth, and depths restart every
    SLOTS_PER_DEPTH_RANGE slots (with the depths cleared): forcing a restart every 7
    cells changes no pixel. With the eye inside, cells reaching behind the eye's plane
    are drawn in runs of their own."""
    mesh = blocks_mesh([(x, y, z) for x in range(3) for y in range(2) for z in range(3)])
    scene = Scene(mesh, TF, Camera((1.5, 1.0, 2.5), (1.5, 1.0, -3.0), fov=70), 40, 32)
    plan = tetra.make_plan(scene, sort="mpvo")
    calls = tetra.draw_calls(plan)
    assert any(exact for _, _, exact in calls) and not all(exact for _, _, exact in calls)
    assert sum(count for _, count, _ in calls) == plan.draw.size
    for s in (scene, scene.replace(camera=Camera((6.0, 5.0, 7.0), (1.5, 1.0, 1.0), fov=30))):
        whole = renderer.render(s, technique="tetra", sort="mpvo")
        monkeypatch.setattr(tetra, "SLOTS_PER_DEPTH_RANGE", 7)
        assert len(tetra.draw_calls(tetra.make_plan(s, sort="mpvo"))) >= plan.draw.size // 7
        chunked = renderer.render(s, technique="tetra", sort="mpvo")
        monkeypatch.undo()
        assert whole[..., 3].max() > 0.3
        assert np.abs(chunked - whole).max() == 0.0


@pytest.mark.parametrize("azimuth", [0, 60, 120])
def test_sliver_cells_of_near_coincident_points_keep_their_values(renderer, azimuth):
    """Points duplicated 1e-7 apart make sliver cells whose gradients reach 3e7: the
    field extrapolated in float32 from the eye left the cell's vertex range by 10 data
    units, and a TF opaque only outside the data's range painted opaque pixels (alpha 1
    where the reference has 0.04). The ends are now clamped to the cell's vertex range
    (a linear field's extremes): GL within this module's bound of the reference."""
    rng = np.random.default_rng(3)
    base = rng.uniform(-1, 1, (20, 3))
    points = np.concatenate([base, base[:7] + rng.normal(size=(7, 3)) * 1e-7])
    mesh = TetMesh.from_points(points, rng.random(len(points)))
    tf = TransferFunction([(0, 1, 0.2, 0.2), (2, 1, 0.2, 0.2)], [(0, 0.02), (1.0, 0.02), (1.5, 1.0)], unit_distance=1.0)
    scene = Scene(mesh, tf, dvr_gl.default_camera(mesh, azimuth=azimuth, elevation=20), 48, 48)
    ref = dvr_gl.reference.render(scene, technique="tetra", sort="mpvo")
    assert ref[..., 3].max() < 0.05
    assert np.abs(renderer.render(scene, technique="tetra", sort="mpvo") - ref).max() < GL_TOL


@pytest.mark.parametrize("ortho", [True, False])
def test_rays_in_a_boundary_face_plane_of_an_odd_sized_image(renderer, ortho):
    """The eye on the plane of a convex mesh's lower y face, looking along it: the middle
    row of a 47-pixel-high image lies in that plane, inside the closed cells (exact and
    the reference have it). The shader's pixel centre used to come out 1e-7 off the
    plane (c * (2 / n) - 1 in float32), so the whole row was dropped; now within this
    module's bound of the reference."""
    g = np.stack(np.meshgrid(*[np.arange(3) * s for s in (0.59, 0.685, 0.475)], indexing="ij"), -1).reshape(-1, 3)
    mesh = TetMesh.from_points(g, g @ [0.3, 0.5, 0.2])
    lo, hi = mesh.bounds
    tf = TransferFunction([(0, 0.9, 0.4, 0.1), (2, 0.1, 0.4, 0.9)], [(0, 0.5), (2, 0.5)], unit_distance=1.0)
    eye, target = (lo[0] - 2, lo[1], 0.5 * (lo[2] + hi[2])), (hi[0], lo[1], 0.5 * (lo[2] + hi[2]))
    cam = Camera(eye, target, ortho_height=2.0) if ortho else Camera(eye, target, fov=40.0)
    scene = Scene(mesh, tf, cam, 38, 47)
    ref = dvr_gl.reference.render(scene, technique="tetra", sort="mpvo")
    assert ref[23, :, 3].max() > 0.5
    assert np.abs(renderer.render(scene, technique="tetra", sort="mpvo") - ref).max() < GL_TOL


@pytest.mark.parametrize("ortho", [True, False])
def test_a_thin_slab_seen_grazing_keeps_every_cell(renderer, ortho):
    """A Delaunay slab 2e-3 thick seen 1e-4 off its plane: cells project to needles 0.004
    by 7 pixels, and only the miters at their sharp tips can grow them past the
    rasteriser's vertex snapping. Capped at 2.8 times the growth, those miters left pixel
    centres just inside the needles uncovered and whole cells were lost (0.1 off the
    reference). Every pixel now within this module's bound of the reference, which is
    exact here (a constant field)."""
    rng = np.random.default_rng(1)
    points = rng.uniform(-1, 1, (40, 3))
    points[:, 1] *= 1e-3
    mesh = TetMesh.from_points(points, np.zeros(40))
    tf = TransferFunction([(0, 0.2, 0.6, 1.0)], [(0, 0.7)], unit_distance=2.9)
    d = np.array([1.0, 1e-4, 0.97])
    d /= np.linalg.norm(d)
    cam = Camera(d * 4, (0, 0, 0), ortho_height=2.6) if ortho else Camera(d * 4, (0, 0, 0), fov=40)
    scene = Scene(mesh, tf, cam, 37, 23)
    ref = dvr_gl.reference.render(scene, technique="tetra", sort="mpvo")
    assert ref[..., 3].max() > 0.5
    assert np.abs(renderer.render(scene, technique="tetra", sort="mpvo") - ref).max() < GL_TOL
