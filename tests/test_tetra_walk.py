"""Projected tetrahedra walked on the GPU (``technique="tetra", sort="walk"``,
``dvr_gl.techniques.tetra_walk``): each pixel's ray goes from cell to cell through the
face adjacency, no visibility sort; depth peeling of the boundary's entry faces for
non-convex domains.

Tolerances. The walk finds each cell's segment with tetra's own arithmetic (the same
planes, the same float32 operations: tetra/walk_cell.glsl), so per segment its error is
tetra's, and ``GL_TOL`` of test_tetra.py (1e-4, derived there) bounds it where a ray
meets a dozen cells (the closed-form and small meshes below). What the walk adds is the
order of compositing (front to back, one float32 rounding of 2^-24 relative per cell:
at most 300 x 6e-8 = 2e-5 on the meshes here) and entries decided by the rasteriser at
the boundary's silhouette (a pixel within its snapping of a silhouette edge has a chord
of that order). On the NASA blunt fin (up to 210 cells on a ray) the tetra tests also hold
GL to ``GL_TOL`` of exact (test_clip_tetra.py); the walk is held to the same against its
twin and exact. The twin itself (the same segments in float64, composited in the order of
distance) agrees with the exact image to 1e-7 wherever test_tetra.py says tetra's does.
"""

import os

import numpy as np
import pytest

import dvr_gl
from dvr_gl import Camera, Scene, TetMesh, TransferFunction, metrics, reference
from dvr_gl.data import delaunay_ball, synthetic_tf
from dvr_gl.model import mesh as M
from dvr_gl.techniques import tetra, tetra_walk, walk_entries
from dvr_gl.gl.context import current

from test_tetra import CUBE, FIVE, GL_TOL, SIX, TF, VIEWS, blocks_mesh, closed_form_boxes, cube_mesh, _lattice_mesh


def walk(renderer, scene, stage="auto"):
    """(image, plan) of one walk render, with the plan's pass counts."""
    plan = tetra.make_plan(scene, sort="walk", stage=stage, tables=renderer.tables)
    with current(renderer.ctx):
        fbo = tetra.draw(renderer, plan)
        image = renderer.read_target(fbo, scene.width, scene.height)
    return image, plan


@pytest.mark.parametrize("split", ["five", "six"])
@pytest.mark.parametrize("view", sorted(VIEWS))
def test_constant_cube_is_the_constant_box(renderer, split, view):
    """No cracks, no double counting where the walk crosses shared faces, edges and
    vertices (the diagonal views put rays in shared faces and along the cube's body
    diagonal, an edge of all six cells of the six-way split); the eye inside."""
    scene = Scene(cube_mesh(FIVE if split == "five" else SIX), TF, VIEWS[view], 49, 49)
    img, plan = walk(renderer, scene)
    want = closed_form_boxes(scene, [((0, 0, 0), (1, 1, 1))])
    assert np.abs(img - want).max() < GL_TOL
    assert img[..., 3].max() > 0.3
    assert plan.walk_passes == 1 and tetra_walk.walk_counts(renderer, plan)[1] == 0   # convex: one layer, no guard


@pytest.fixture(params=["topology", "planes"])
def exits(request, monkeypatch):
    """The walk's two rules for its exit faces (tetra_walk.EXITS_BY_TOPOLOGY): the
    topology's, where the mesh and view allow (the default), and the planes' (the
    others: folded faces, a perspective eye inside)."""
    monkeypatch.setattr(tetra_walk, "EXITS_BY_TOPOLOGY", request.param == "topology")
    return request.param


def test_rays_through_lattice_vertices_and_edges(renderer, exits):
    """A 3 x 3 x 3 block of cubes seen along its body diagonal (orthographic, odd size):
    the middle pixel's ray runs along the edges shared by six cells of every cube and
    through four lattice vertices; others pass through edges between cubes. The walk
    passes them with empty segments: the image is the box's closed form, no guard."""
    cells = [(x, y, z) for x in range(3) for y in range(3) for z in range(3)]
    mesh = blocks_mesh(cells)
    cam = Camera((7.5, 7.5, 7.5), (1.5, 1.5, 1.5), up=(0, 0, 1), ortho_height=6.0)
    scene = Scene(mesh, TF, cam, 33, 33)
    img, plan = walk(renderer, scene)
    want = closed_form_boxes(scene, [((0, 0, 0), (3, 3, 3))])
    assert np.abs(img - want).max() < GL_TOL
    assert img[16, 16, 3] > 0.6                         # the middle ray: the whole diagonal
    steps, guarded = tetra_walk.walk_counts(renderer, plan)
    assert guarded == 0 and steps.max() < 4 * mesh.n_tets


def test_non_convex_meshes_are_peeled(renderer):
    """An L of three cubes seen into its notch, and two separate blocks one behind the
    other: a ray leaves the domain and enters it again; the next layer of entries picks
    it up. The closed form; two layers where a ray meets both blocks, one more layer than
    needed at most (the pass that finds no entry is not walked)."""
    cam = Camera((4.5, 3.5, 4.0), (1.0, 0.8, 0.5), fov=35)
    behind = Camera((9.5, 0.5, 6.5), (0.5, 0.5, 0.5), fov=20)       # along the line through both
    for cells, view, layers in (([(0, 0, 0), (1, 0, 0), (0, 1, 0)], cam, (1, 2)), ([(0, 0, 0), (3, 0, 2)], cam, (1, 2)),
                                ([(0, 0, 0), (3, 0, 2)], behind, (2,))):
        scene = Scene(blocks_mesh(cells), TF, view, 48, 48)
        img, plan = walk(renderer, scene)
        want = closed_form_boxes(scene, [(c, np.add(c, 1)) for c in cells])
        assert np.abs(img - want).max() < GL_TOL
        assert plan.walk_passes in layers and plan.walk_left == 0


def test_layers_drawn_without_their_counts_change_nothing(renderer):
    """A frame draws as many layers as the last one did without reading their entry
    counts: after a view of two layers, a view of one (its second layer drawn without
    entries) and then a view of two again give, bit for bit, the images drawn alone."""
    cells = [(0, 0, 0), (3, 0, 2)]
    near = Camera((4.5, 3.5, 4.0), (1.0, 0.8, 0.5), fov=35)
    behind = Camera((9.5, 0.5, 6.5), (0.5, 0.5, 0.5), fov=20)       # along the line through both
    mesh = blocks_mesh(cells)
    alone = {}
    for name, cam in (("near", near), ("behind", behind)):
        with dvr_gl.Renderer() as fresh:
            alone[name] = walk(fresh, Scene(blocks_mesh(cells), TF, cam, 40, 40))
    _, first = walk(renderer, Scene(mesh, TF, behind, 40, 40))
    img_near, plan_near = walk(renderer, Scene(mesh, TF, near, 40, 40))
    img_behind, _ = walk(renderer, Scene(mesh, TF, behind, 40, 40))
    assert first.walk_passes == 2 and alone["near"][1].walk_passes == 1 and plan_near.walk_passes == 2
    assert np.array_equal(img_near, alone["near"][0]) and np.array_equal(img_behind, alone["behind"][0])
    assert alone["behind"][0][..., 3].max() > 0.3


def test_the_pass_cap_counts_what_it_leaves(renderer, monkeypatch):
    """With one layer allowed, the block behind is not walked: the image is the front
    block's alone, and the pixels that still had an entry are counted."""
    cells = [(0, 0, 0), (0, 0, 3)]
    cam = Camera((0.5, 0.5, 8.0), (0.5, 0.5, 0.0), fov=20)
    scene = Scene(blocks_mesh(cells), TF, cam, 32, 32)
    monkeypatch.setattr(tetra_walk, "MAX_PASSES", 1)
    with pytest.warns(RuntimeWarning, match="still had an entry after 1 layers"):
        img, plan = walk(renderer, scene)
    assert plan.walk_passes == 1 and plan.walk_left > 0
    front = closed_form_boxes(scene, [((0, 0, 3), (1, 1, 4))])
    assert np.abs(img - front).max() < GL_TOL


def test_eighty_layers_are_peeled(renderer):
    """Eighty unit cubes in a row, a gap between each, seen along the row: a ray enters
    eighty times (more than the first cap of 64 layers, which cut such rays silently)."""
    cells = [(0, 0, 2 * k) for k in range(80)]
    cam = Camera((0.5, 0.5, 200.0), (0.5, 0.5, 0.0), fov=1.0)
    tf = TransferFunction([(0, 0.9, 0.5, 0.2), (1, 0.9, 0.5, 0.2)], [(0, 0.02), (1, 0.02)], unit_distance=1.0)
    scene = Scene(blocks_mesh(cells), tf, cam, 16, 16)
    img, plan = walk(renderer, scene)
    assert plan.walk_passes >= 80 and plan.walk_left == 0
    exact = closed_form_boxes(scene, [(c, (1, 1, c[2] + 1)) for c in cells], tf=tf)
    assert np.abs(img - exact).max() < GL_TOL and img[8, 8, 3] > 0.6


def test_the_step_guard_ends_a_ray_and_is_counted(renderer, monkeypatch):
    """The guard (more steps than cells: only a cycle made by rounding reaches it) ends
    the ray where it is: forced down to 3 cells, rays that meet more are cut short,
    counted, and what they composited so far is kept (less opacity, never more)."""
    scene = Scene(cube_mesh(SIX), TF, VIEWS["perspective"], 32, 32)
    whole, _ = walk(renderer, scene)
    monkeypatch.setattr(tetra_walk, "max_steps", lambda mesh: 3)
    cut, plan = walk(renderer, scene)
    steps, guarded = tetra_walk.walk_counts(renderer, plan)
    assert guarded > 0
    assert (cut[..., 3] <= whole[..., 3] + 1e-7).all() and (cut[..., 3] < whole[..., 3] - 1e-3).any()


def test_zero_volume_cells_and_slivers(renderer, exits):
    """A flat cell glued to the cube's bottom face changes nothing; slivers 1e-6 thick
    glued below it, seen from above, below and grazing: GL within its bound of exact.
    The lattice Delaunay has layers of flat cells inside, which the walk passes through."""
    mesh = cube_mesh(SIX)
    pts = np.vstack([mesh.points, [[0.5, 0.25, 0.0]]])
    flat = TetMesh(pts, np.vstack([mesh.tets, [[0, 1, 3, 8]]]), np.concatenate([mesh.scalars, [0.5]]))
    scene = Scene(mesh, TF, VIEWS["perspective"], 40, 40)
    assert np.abs(walk(renderer, scene.replace(volume=flat))[0] - walk(renderer, scene)[0]).max() < GL_TOL
    apex = [[0.6, 0.3, -1e-6], [0.3, 0.6, -1e-6]]
    bottom = [t for t in SIX if sum(CUBE[i][2] == 0 for i in t) == 3]
    faces = [[i for i in t if CUBE[i][2] == 0] for t in bottom]
    sliver = TetMesh(np.vstack([mesh.points, apex]), np.vstack([mesh.tets, [faces[0] + [8]], [faces[1] + [9]]]),
                     np.full(10, 0.5))
    for cam in (Camera((0.5, 0.5, 3.0), (0.5, 0.5, 0.5), fov=40), Camera((0.7, 0.2, -2.5), (0.5, 0.5, 0.5), fov=40),
                Camera((-2.0, -1.5, 0.0), (0.5, 0.5, 0.0), up=(0, 0, 1), fov=50)):
        s = Scene(sliver, TF, cam, 40, 40)
        assert np.abs(walk(renderer, s)[0] - reference.exact(s)).max() < GL_TOL
    lattice = _lattice_mesh((4, 4, 4), (1, 1, 1))
    assert M.topology(lattice).flat.sum() > 0
    lo, hi = float(lattice.scalars.min()), float(lattice.scalars.max())
    tf = TransferFunction(color=[(lo, 0.2, 0.3, 0.9), (hi, 0.9, 0.3, 0.2)], opacity=[(lo, 0.3), (hi, 0.9)],
                          unit_distance=0.5)
    for az, el in ((30, 20), (0, 0), (90, 45)):
        s = Scene(lattice, tf, dvr_gl.default_camera(lattice, azimuth=az, elevation=el), 40, 40)
        exact = reference.exact(s)
        assert np.abs(reference.render(s, technique="tetra", sort="walk") - exact).max() < 1e-7
        img, plan = walk(renderer, s)
        assert np.abs(img - exact).max() < GL_TOL and tetra_walk.walk_counts(renderer, plan)[1] == 0


def test_slivers_thinner_than_float32_resolves(renderer, exits):
    """A rotated lattice stored as float32 (as a file of a structured grid holds it),
    tetrahedralised by Delaunay: the rounding leaves slivers some 1e-6 of the mesh thick,
    not of zero volume, but thinner than the walk's float32 crossings can order. Walked
    by their planes they sent rays into cells the rays never cross (RMSE 0.03 to 0.07,
    whole rays lost); passed as zero-volume cells (walk_flat), or walked by the
    topology, GL is within its bound."""
    c, s = np.cos(0.5), np.sin(0.5)
    turn = np.array([[c, -s, 0.0], [s * c, c * c, -s], [s * s, c * s, c]])
    axes = np.arange(5) * 0.37
    points = (np.stack(np.meshgrid(axes, axes, axes, indexing="ij"), -1).reshape(-1, 3) + 100.0) @ turn.T
    points = points.astype(np.float32).astype(float)
    mesh = TetMesh.from_points(points, np.sin(3.0 * points[:, 0]) + points[:, 1] - points[:, 2])
    assert (tetra_walk.walk_flat(mesh) & ~M.topology(mesh).flat).sum() > 20
    lo, hi = float(mesh.scalars.min()), float(mesh.scalars.max())
    tf = TransferFunction(color=[(lo, 0.2, 0.3, 0.9), (hi, 0.9, 0.3, 0.2)], opacity=[(lo, 0.3), (hi, 0.9)],
                          unit_distance=0.5)
    for az, el in ((30, 20), (0, 0)):
        scene = Scene(mesh, tf, dvr_gl.default_camera(mesh, azimuth=az, elevation=el), 48, 48)
        img, plan = walk(renderer, scene)
        assert np.abs(img - reference.exact(scene)).max() < GL_TOL and img[..., 3].mean() > 0.05


def _unit_lattice(n, jitter=0.0, seed=0):
    """The points of an n^3 lattice on the unit cube (x fastest), each moved by a normal
    jitter of that scale (none: the exact lattice)."""
    axes = np.linspace(0.0, 1.0, n)
    z, y, x = np.meshgrid(axes, axes, axes, indexing="ij")
    points = np.stack([x, y, z], -1).reshape(-1, 3)
    return points + np.random.default_rng(seed).normal(scale=jitter, size=points.shape) if jitter else points


def _waves(p, k=(2.1, 1.7, 1.3)):
    """A smooth field on the unit cube, of wave numbers k along x, y and z."""
    return 0.5 + 0.3 * np.sin(k[0] * p[:, 0] + 0.3) * np.cos(k[1] * p[:, 1] - 0.2) + 0.2 * np.sin(k[2] * p[:, 2] + 0.5)


def test_lattice_delaunay_is_walked_by_its_topology(renderer):
    """Delaunay of a 6^3 lattice jittered by 1e-10: slivers and flat cells in chains along
    the lattice planes, whose float32 plane crossings disagree from cell to cell (the
    planes' rule lost whole rays here: RMSE 0.09 to 0.15, 200 to 570 pixels off by more
    than 0.01 at 80x80). By the topology every exit is decided once per edge, the same
    in every cell around it: GL within its bound of exact, no guard. And the unjittered
    lattice seen along an axis, its rays in the planes of faces (ties); the jittered one
    from an eye inside it, clear of its cell's faces, and on a face; and an 8^3 one from
    the centre of a lattice cube, on an edge of five cells (each ray starts in one of
    them that holds it by the signs: by the planes, 0.09 off)."""
    tf = TransferFunction(color=[(0.0, 0.2, 0.4, 0.9), (1.0, 0.9, 0.2, 0.1)], opacity=[(0.0, 0.1), (1.0, 0.8)],
                          unit_distance=0.3)
    grid, jittered, jittered8 = _unit_lattice(6), _unit_lattice(6, 1e-10, 5), _unit_lattice(8, 1e-10, 5)
    inside = Camera((0.47, 0.33, 0.55), (0.9, 0.5, 0.1), fov=70)
    on_face = Camera((0.43, 0.37, 0.61), (0.9, 0.5, 0.1), fov=70)     # x + y = 0.8: a plane of faces
    on_edge = Camera((0.5, 0.5, 0.5), (0.5, 0.5, -1.0), fov=70)
    default = dvr_gl.default_camera
    for points, views in ((jittered, [(30, 20, False), (45, 35.264, True), inside, on_face]),
                          (grid, [(90, 0, True), (0, 0, False)]), (jittered8, [on_edge])):
        mesh = TetMesh.from_points(points, _waves(points, (6.3, 5.1, 3.9)))
        assert tetra_walk.rare_paths(mesh)["WALK_TOPO"] == 1 and tetra_walk.walk_flat(mesh).sum() > 50
        planes = M.topology(mesh).cell_planes()
        for view in views:
            camera = view if isinstance(view, Camera) else default(mesh, azimuth=view[0], elevation=view[1],
                                                                      ortho=view[2])
            if isinstance(view, Camera):
                flat = tetra_walk.walk_flat(mesh)
                cell = walk_entries.eye_cell(mesh, camera, planes, flat)
                assert walk_entries.eye_clear_of_faces(mesh, camera, planes, cell) == (view is inside)
                assert view is inside or len(walk_entries.cells_around_eye(mesh, camera, planes, cell, flat)) >= 2
            scene = Scene(mesh, tf, camera, 48, 48)
            img, plan = walk(renderer, scene)
            assert np.abs(img - reference.exact(scene)).max() < GL_TOL
            assert img[..., 3].mean() > 0.1 and tetra_walk.walk_counts(renderer, plan)[1] == 0


def test_lattice_seen_along_its_diagonal_is_entered_where_its_hull_folds(renderer):
    """Jittered lattices seen along their diagonal from (3, 3, 3): the centre column's rays
    run in the plane x = y, through the hull's edge x = y = 1, where the Delaunay cells are
    flat (collinear points jittered by less than float32 holds: their faces are needles, or
    lines). Three faults lost whole rays there (alpha 0 or 2e-7 against 0.4 to 0.8):
    (4, 1e-6) the entry pass's barycentric test, ill-conditioned on a needle, dropped the
    face the signs say the ray enters by (its margin now grows with the face's
    conditioning); (4, 1e-8) the rounded positions fold the hull's surface there, and the
    first entry led through flat cells alone and out again beside it, where the next layer
    tried only faces off the hull (such a walk is now no progress, and the hull faces next
    to flat cells are tried again at its t); (6, 1e-8) the first layer's depth test tied
    that entry with the true one at a smaller t, which the next layer then passed over
    (the tied entries of larger cells are tried too)."""
    tf = TransferFunction(color=[(0.0, 0.2, 0.4, 0.9), (1.0, 0.9, 0.2, 0.1)], opacity=[(0.0, 0.05), (1.0, 0.6)],
                          unit_distance=0.5)
    for n, jitter, seed, ortho in ((4, 1e-6, 1, True), (4, 1e-8, 2, True), (6, 1e-8, 2, True), (6, 1e-6, 0, False)):
        points = _unit_lattice(n, jitter, seed)
        mesh = TetMesh.from_points(points, _waves(points))
        assert tetra_walk.rare_paths(mesh)["WALK_TOPO"] == 1 and tetra_walk.walk_flat(mesh).any()
        camera = Camera((3, 3, 3), (0.5, 0.5, 0.5), up=(0, 0, 1), **({"ortho_height": 2.0} if ortho else {"fov": 30}))
        scene = Scene(mesh, tf, camera, 63, 63)
        img, plan = walk(renderer, scene)
        assert np.abs(img - reference.exact(scene)).max() < GL_TOL, (n, jitter, seed)
        assert tetra_walk.walk_counts(renderer, plan)[1] == 0


def test_hollow_lattice_is_entered_again_where_its_parts_touch(renderer):
    """A 7^3 lattice jittered by 1e-6 with the middle of its Delaunay mesh taken out (a
    cavity whose walls are lattice planes, flat cells among them): seen along a diagonal,
    one wall's boundary face and the next part's are different faces of a flat cell taken
    out, so the entry beyond the cavity came a ulp before the stop there and was passed
    over (a pixel 0.13 off): entries a rounding before a stop are now taken, once a stop.
    Seen along another diagonal, off the lattice planes by 1e-6, taking them without that
    bound went back and forth between two such entries up to the layers' cap."""
    tf = TransferFunction(color=[(0.0, 0.2, 0.4, 0.9), (0.5, 0.9, 0.8, 0.2), (1.0, 0.9, 0.2, 0.1)],
                          opacity=[(0.0, 0.05), (0.5, 0.3), (1.0, 0.6)], unit_distance=0.5)
    points = _unit_lattice(7, 1e-6, 18)
    mesh = TetMesh.from_points(points, _waves(points))
    keep = np.abs(mesh.points[mesh.tets].mean(axis=1) - 0.5).max(axis=1) > 0.25
    hollow = TetMesh(mesh.points, mesh.tets[keep], mesh.scalars)
    shift = np.array([1e-6, 2e-6, -1.5e-6])
    for eye, moved in (((-2.0, 3.0, 3.0), 0.0), ((3.0, -2.0, 3.0), 1.0)):
        camera = Camera(tuple(np.array(eye) + moved * shift), tuple(0.5 + moved * shift), up=(0, 0, 1), ortho_height=1.9)
        scene = Scene(hollow, tf, camera, 47, 47)
        img, plan = walk(renderer, scene)
        exact = reference.exact(scene)
        assert plan.walk_left == 0 and plan.walk_passes <= 8 and tetra_walk.walk_counts(renderer, plan)[1] == 0
        # the second view's rays pass within 1e-6 of the lattice's planes, where exact
        # itself moves by 1e-3 when the view moves by that much: its RMSE is the bound
        if moved:
            assert metrics.rmse(img, exact) < GL_TOL
        else:
            assert np.abs(img - exact).max() < GL_TOL


def test_blocks_touching_turned_are_entered_where_they_are_left(renderer, exits):
    """Two blocks touching along a face, with their own points there (not joined), turned
    so that no plane is axis-aligned: a ray leaves the first through a boundary face and
    enters the second through a face in the same plane, at the same t by the same
    arithmetic (an entry one ulp before the exit is not "beyond" it, and was lost)."""
    turn = np.array([[0.64, -0.48, 0.6], [0.6, 0.8, 0.0], [-0.48, 0.36, 0.8]])
    first, second = blocks_mesh([(0, 0, 0)]), blocks_mesh([(1, 0, 0)])
    points = np.vstack([first.points, second.points]) @ turn.T
    mesh = TetMesh(points, np.vstack([first.tets, second.tets + first.n_points]),
                   0.3 + 0.2 * np.sin(2.0 * points[:, 0]) + 0.3 * points[:, 1] ** 2)
    for az, el in ((70, 25), (20, -30)):
        scene = Scene(mesh, TF, dvr_gl.default_camera(mesh, azimuth=az, elevation=el), 48, 48)
        img, plan = walk(renderer, scene)
        assert np.abs(img - reference.exact(scene)).max() < GL_TOL and plan.walk_passes >= 2


def test_folded_cells_are_walked_as_their_union(renderer):
    """test_tetra.py's folded pair (two cells sharing a face, both on one side of it, the
    second inside the first): no plane of either says the ray crosses into the other, so
    the walk neither enters the union through the shared face (unless it is an entry face
    too) nor passes the ray back and forth across it (the combustor's four folded cells
    did, 10,000 steps a pixel). The walk counts the covered length once, as the exact
    image does (projection counts the overlap twice: 0.07 off there)."""
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0.2, 0.25, 0.3]], float)
    mesh = TetMesh(pts, np.array([[0, 1, 2, 3], [1, 2, 3, 4]]), np.full(5, 0.5))
    assert tetra_walk.folded_faces(mesh).sum() == 2
    for cam in (Camera((2.0, 1.5, 1.8), (0.3, 0.3, 0.3), fov=35), Camera((-1.5, -1.0, -1.2), (0.3, 0.3, 0.3), fov=35)):
        scene = Scene(mesh, TF, cam, 40, 40)
        img, plan = walk(renderer, scene)
        assert np.abs(img - reference.exact(scene)).max() < GL_TOL
        assert img[..., 3].max() > 0.2
        steps, guarded = tetra_walk.walk_counts(renderer, plan)
        assert guarded == 0 and steps.max() <= 4


def test_the_rare_paths_are_compiled_in_where_the_mesh_has_them():
    """walk.frag's code for zero-volume cells and folded faces costs every step on
    llvmpipe (both sides of a per-pixel branch run), so it is compiled in per mesh: the
    cube has neither, the tests above (a flat cell, a folded pair) each one. The exits by
    topology are for every mesh but the folded one."""
    cube = cube_mesh(SIX)
    assert tetra_walk.rare_paths(cube) == {"WALK_FLAT": 0, "WALK_FOLDS": 0, "WALK_TOPO": 1}
    flat = TetMesh(np.vstack([cube.points, [[0.5, 0.25, 0.0]]]), np.vstack([cube.tets, [[0, 1, 3, 8]]]),
                   np.concatenate([cube.scalars, [0.5]]))
    assert tetra_walk.rare_paths(flat) == {"WALK_FLAT": 1, "WALK_FOLDS": 0, "WALK_TOPO": 1}
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0.2, 0.25, 0.3]], float)
    folded = TetMesh(pts, np.array([[0, 1, 2, 3], [1, 2, 3, 4]]), np.full(5, 0.5))
    assert tetra_walk.rare_paths(folded) == {"WALK_FLAT": 0, "WALK_FOLDS": 1, "WALK_TOPO": 0}


def test_opacity_one_code_is_compiled_in_per_tf(renderer, monkeypatch):
    """The segment integral's code for opacity 1 (a piece that ends the ray; graded parts
    towards a knot of opacity 1) is compiled in only for TFs that have such a knot
    (SEG_OPAQUE, common/linear_segment.glsl), as llvmpipe runs it masked on every segment
    otherwise. Without it the image is the same to the bit; with it the ball is drawn as
    exact draws it, the rays ending in the opaque band."""
    from dvr_gl.model.transfer import SegmentKnots
    scene = _ball(size=32)
    assert tetra.opaque_knots(SegmentKnots(scene.tf)) == 0
    img, plan = walk(renderer, scene)
    assert plan.defines["SEG_OPAQUE"] == 0
    monkeypatch.setattr(tetra, "opaque_knots", lambda knots: 1)
    forced, plan = walk(renderer, scene)
    assert plan.defines["SEG_OPAQUE"] == 1 and np.array_equal(img, forced)
    monkeypatch.undo()
    opaque = TransferFunction([(0.0, 0.2, 0.4, 0.9), (1.0, 0.9, 0.3, 0.1)],
                              [(0.0, 0.0), (0.45, 0.2), (0.6, 1.0), (0.75, 0.3), (1.0, 0.1)], unit_distance=1.0)
    scene = scene.replace(tf=opaque)
    img, plan = walk(renderer, scene)
    assert plan.defines["SEG_OPAQUE"] == 1
    assert np.abs(img - reference.exact(scene)).max() < GL_TOL
    assert img[..., 3].max() > 1.0 - 1e-6     # some rays reach the opaque band


def _ball(view="perspective", mode="composite", size=48, **extra):
    mesh = delaunay_ball()
    lo, hi = mesh.bounds
    centre = (lo + hi) / 2
    cams = {"perspective": dvr_gl.default_camera(mesh, azimuth=30, elevation=20),
            "orthographic": dvr_gl.default_camera(mesh, azimuth=60, elevation=-10, ortho=True),
            "eye inside": Camera(centre + [8.0, -5.0, 3.0], centre + [-10.0, 10.0, 0.0], fov=70)}
    return Scene(mesh, synthetic_tf(), cams[view], size, size, mode=mode, **extra)


@pytest.mark.parametrize("view,mode", [(v, "composite") for v in ("perspective", "orthographic", "eye inside")]
                         + [("perspective", m) for m in ("mip", "minip", "average")] + [("eye inside", "mip")])
def test_ball_against_twin_exact_and_mpvo(renderer, view, mode):
    """The bundled Delaunay ball: the walk against its twin, against the exact image and
    against tetra's MPVO draw; with the eye inside the ball, the first layer starts every
    ray in the eye's cell (found on the CPU)."""
    scene = _ball(view, mode)
    img, plan = walk(renderer, scene)
    twin = reference.render(scene, technique="tetra", sort="walk")
    assert np.abs(img - twin).max() < GL_TOL
    assert np.abs(twin - reference.render(scene, technique="tetra")).max() < 1e-9    # same segments
    assert np.abs(img - renderer.render(scene, technique="tetra", sort="mpvo")).max() < GL_TOL
    if mode == "composite":
        assert np.abs(img - reference.exact(scene)).max() < GL_TOL
    if mode in ("composite", "mip"):
        assert img[..., 3].max() > 0.2
    if view == "eye inside":
        assert walk_entries.eye_cell(scene.volume, scene.camera, M.topology(scene.volume).cell_planes(),
                                     tetra_walk.walk_flat(scene.volume)) >= 0


@pytest.mark.parametrize("mode", ["mip", "average"])
def test_a_projected_frame_after_a_walk_frame_keeps_its_rows(renderer, mode):
    """``render`` has the last pass store rows top down (the read then needs no flip); the
    walk's resolve and tetra's classify pass share a program, so the MPVO frame after a
    walk frame must set its rows again, not keep the walk's setting (it came out upside
    down)."""
    scene = _ball("perspective", mode)
    walked = renderer.render(scene, technique="tetra")
    projected = renderer.render(scene, technique="tetra", sort="mpvo")
    twin = reference.render(scene, technique="tetra")
    assert np.abs(twin - twin[::-1]).max() > 50 * GL_TOL      # a flip would show
    assert np.abs(walked - twin).max() < GL_TOL and np.abs(projected - twin).max() < GL_TOL


def test_clips_geometry_shading_and_optical_models_as_tetra_draws_them(renderer):
    """Clip planes and a crop box cut each segment to the ray's kept interval, an opaque
    surface at its t_hit (the same rasterised t as tetra's), with the surface behind;
    lights and the absorption-only and emission-only models. The walk against tetra's
    MPVO draw of the same scene (both GL: the same t_hit and kept interval), within GL_TOL,
    and the clipped walk against its twin."""
    mesh = delaunay_ball()
    lo, hi = mesh.bounds
    centre = (lo + hi) / 2
    from test_geometry import icosphere
    radius = 0.3 * float(np.min(hi - lo))
    cases = [dict(clip_planes=[(centre, (1.0, 0.3, 0.2))]),
             dict(crop_box=(lo + 0.2 * (hi - lo), lo + 0.7 * (hi - lo))),
             dict(geometry=[icosphere(centre, radius)]),
             dict(geometry=[icosphere(centre, radius)], mode="mip"),
             dict(shading=True), dict(optical_model="absorption"), dict(optical_model="emission")]
    for extra in cases:
        scene = _ball(size=40, **extra)
        img, _ = walk(renderer, scene)
        mpvo = renderer.render(scene, technique="tetra", sort="mpvo")
        assert np.abs(img - mpvo).max() < GL_TOL, extra
        assert img[..., 3 if extra.get("optical_model") == "absorption" else 0].max() > 0.05, extra
        if "geometry" not in extra:
            assert np.abs(img - reference.render(scene, technique="tetra", sort="walk")).max() < GL_TOL, extra


@pytest.mark.parametrize("ortho", [True, False])
def test_a_thin_slab_seen_grazing_keeps_every_entry(renderer, ortho):
    """test_tetra.py's Delaunay slab 2e-3 thick seen 1e-4 off its plane: its boundary
    faces project to needles that rasterisation leaves pixel centres beside; drawn as their
    grown bounding boxes with the fragment deciding (walk_entry.geom), no entry is lost
    (0.11 off the reference before). The reference is exact here (a constant field)."""
    rng = np.random.default_rng(1)
    points = rng.uniform(-1, 1, (40, 3))
    points[:, 1] *= 1e-3
    mesh = TetMesh.from_points(points, np.zeros(40))
    tf = TransferFunction([(0, 0.2, 0.6, 1.0)], [(0, 0.7)], unit_distance=2.9)
    d = np.array([1.0, 1e-4, 0.97])
    d /= np.linalg.norm(d)
    cam = Camera(d * 4, (0, 0, 0), ortho_height=2.6) if ortho else Camera(d * 4, (0, 0, 0), fov=40)
    scene = Scene(mesh, tf, cam, 37, 23)
    ref = reference.render(scene, technique="tetra", sort="walk")
    assert ref[..., 3].max() > 0.5
    assert np.abs(walk(renderer, scene)[0] - ref).max() < GL_TOL


def _bluntfin():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    data = os.environ.get("DVR_GL_DATA") or os.path.join(os.path.dirname(root), "shared", "data")
    if not os.path.exists(os.path.join(data, "nasa_bluntfin", "bluntfin_tets.npz")):
        pytest.skip("the shared data folder is not beside the checkout (or at $DVR_GL_DATA)")
    from dvr_gl.bench.common import load_mesh_dataset
    return load_mesh_dataset("bluntfin", data)


def test_nasa_blunt_fin_is_peeled_and_exact(renderer):
    """NASA's blunt fin (a curvilinear CFD grid split into tets: non-convex around the
    fin, with zero-volume cells): rays leave and re-enter, two layers; the walk within
    GL_TOL of its twin and of exact, its RMSE against exact within 3x tetra MPVO's (both
    are float32 arithmetic on the same segments), no guard reached."""
    mesh, tf = _bluntfin()
    scene = Scene(mesh, tf, dvr_gl.default_camera(mesh, azimuth=30, elevation=20), 48, 48)
    img, plan = walk(renderer, scene)
    exact = reference.exact(scene)
    twin = reference.render(scene, technique="tetra", sort="walk")
    assert plan.walk_passes >= 2 and plan.walk_left == 0 and tetra_walk.walk_counts(renderer, plan)[1] == 0
    assert np.abs(twin - exact).max() < 1e-7
    assert np.abs(img - twin).max() < GL_TOL
    assert np.abs(img - exact).max() < GL_TOL
    mpvo = renderer.render(scene, technique="tetra", sort="mpvo")
    assert metrics.rmse(img, exact) < 3 * max(metrics.rmse(mpvo, exact), 1e-7)
    assert img[..., 3].max() > 0.2


@pytest.mark.parametrize("mode", ["composite", "mip"])
def test_orthographic_rays_that_start_inside_the_mesh(renderer, mode):
    """An orthographic view whose start plane cuts the mesh: each ray starts in the cell
    that holds its start (the faces of the cells the plane cuts are drawn in the first
    entry pass, start_faces). The cube from its middle, looking along an axis and along
    its diagonal (starts on shared faces and edges), against exact; the ball from inside,
    against its twin."""
    cube = cube_mesh(SIX)
    for cam in (Camera((0.5, 0.5, 0.5), (0.5, 0.5, -1.0), ortho_height=1.5),
                Camera((0.5, 0.5, 0.5), (3.0, 3.0, 3.0), up=(0, 0, 1), ortho_height=1.5)):
        scene = Scene(cube, TF, cam, 41, 41, mode=mode)
        assert tetra_walk.start_faces(cube, cam, None, tetra_walk.walk_flat(cube)) is not None
        img, plan = walk(renderer, scene)
        assert np.abs(img - reference.exact(scene)).max() < GL_TOL
        assert img[..., 3].max() > 0.2
    ball = delaunay_ball()
    lo, hi = ball.bounds
    centre = (lo + hi) / 2
    scene = Scene(ball, synthetic_tf(), Camera(centre + [3.0, -2.0, 1.0], centre + [-10.0, 10.0, 0.0], ortho_height=40.0),
                  40, 40, mode=mode)
    img, plan = walk(renderer, scene)
    assert np.abs(img - reference.render(scene, technique="tetra", sort="walk")).max() < GL_TOL
    assert img[..., 3].max() > 0.4 and tetra_walk.walk_counts(renderer, plan)[1] == 0


def test_what_the_walk_does_not_do_is_a_named_error(renderer, monkeypatch):
    """Cell numbers travel as float32: a mesh of 2^24 cells or more is refused by name,
    with what to use instead (here the limit is lowered to the cube's six cells). The
    option is listed and checked."""
    mesh = cube_mesh(SIX)
    scene = Scene(mesh, TF, VIEWS["perspective"], 16, 16)
    monkeypatch.setattr(tetra_walk, "MAX_CELLS", 6)
    with pytest.raises(tetra_walk.WalkUnsupported, match="sort='walk' takes meshes of fewer than 6 tets.*centroid"):
        renderer.render(scene, technique="tetra", sort="walk")
    monkeypatch.undo()
    assert "walk" in tetra.SORTS
    with pytest.raises(ValueError, match="sort must be auto or one of mpvo, centroid, walk, got 'bsp'"):
        tetra.make_plan(scene, sort="bsp")


def test_mesh_data_uploaded_once_and_no_cpu_order(renderer, monkeypatch):
    """Per view the CPU makes no order: MPVO and the centroid sort are never called; the
    walk's own per-mesh data (neighbours, boundary faces) are made once for many views."""
    mesh = cube_mesh(FIVE, value=0.25)
    scene = Scene(mesh, TF, VIEWS["perspective"], 16, 16)

    def refuse(*args, **kwargs):
        raise AssertionError("the walk sorted on the CPU")

    monkeypatch.setattr(tetra, "mpvo_order", refuse)
    monkeypatch.setattr(tetra, "centroid_order", refuse)
    before = len([c for c in renderer.created if c[0] == "tetra_walk_mesh"])
    for cam in (VIEWS["perspective"], VIEWS["along_z"], VIEWS["body_diagonal"]):
        renderer.render(scene.replace(camera=cam), technique="tetra", sort="walk")
    assert len([c for c in renderer.created if c[0] == "tetra_walk_mesh"]) == before + 1


def test_neighbours_and_boundary_faces():
    """The adjacency the walk follows: across local face k of cell c lies the cell that
    shares those three points (or -1), symmetric; the boundary faces are the faces of one
    cell only, each with its cell and local face."""
    mesh = blocks_mesh([(0, 0, 0), (1, 0, 0)])
    topo = M.topology(mesh)
    nb = tetra_walk.neighbours(mesh)
    for c in range(mesh.n_tets):
        for k in range(4):
            face = set(np.delete(topo.tets[c], k).tolist())
            others = [d for d in range(mesh.n_tets) if d != c and face <= set(topo.tets[d].tolist())]
            assert nb[c, k] == (others[0] if others else -1)
            if nb[c, k] >= 0:
                assert c in nb[nb[c, k]]
    faces = tetra_walk.boundary_faces(mesh).reshape(-1, 3)
    assert len(faces) == (nb < 0).sum()
    slots = faces["slot"][:, 0]
    assert (nb.reshape(-1)[slots] == -1).all()


def test_tiles_give_the_same_pixels():
    """An image larger than one target is rendered in tiles, each a window of the same
    camera: the walk's passes per tile give exactly the single render's pixels, the
    orthographic start inside the mesh included."""
    ball = delaunay_ball()
    lo, hi = ball.bounds
    centre = (lo + hi) / 2
    scene = _ball(size=40).replace(width=50)
    inside = scene.replace(camera=Camera(centre, centre + [0, 0, -5.0], ortho_height=60.0))
    with dvr_gl.Renderer() as whole, dvr_gl.Renderer(max_tile=24) as tiled:
        for s in (scene, inside):
            img = whole.render(s, technique="tetra", sort="walk")
            assert img[..., 3].max() > 0.5
            assert np.array_equal(tiled.render(s, technique="tetra", sort="walk"), img)


def test_first_layer_entries_by_the_depth_test(renderer, monkeypatch):
    """The first layer's entries found in one draw by the depth test (the nearest t; among
    equal t the first drawn, the faces being in the order of their cells) and in two by
    MIN blending (the nearest t, then the smallest cell there) give the same images: a
    non-convex ball seen whole, rays through the lattice's edges and vertices, the blunt
    fin's boundary."""
    cells = [(x, y, z) for x in range(3) for y in range(3) for z in range(3)]
    lattice = Scene(blocks_mesh(cells), TF, Camera((7.5, 7.5, 7.5), (1.5, 1.5, 1.5), up=(0, 0, 1), ortho_height=6.0),
                    33, 33)
    scenes = [_ball(size=48), lattice, lattice.replace(camera=Camera((6.0, 5.0, 4.0), (1.5, 1.5, 1.5), fov=40))]
    faces = tetra_walk.boundary_faces(delaunay_ball()).reshape(-1, 3)["slot"][:, 0]
    assert (np.diff(faces) > 0).all()             # in the order of their cells
    for scene in scenes:
        one, plan = walk(renderer, scene)
        steps_one = tetra_walk.walk_counts(renderer, plan)[0]
        monkeypatch.setattr(walk_entries, "FIRST_LAYER_PICK", False)
        two, plan = walk(renderer, scene)
        monkeypatch.setattr(walk_entries, "FIRST_LAYER_PICK", True)
        assert one[..., 3].max() > 0.3
        assert np.array_equal(one, two)
        # the same entry cells: the same cells visited, pixel by pixel
        assert np.array_equal(steps_one, tetra_walk.walk_counts(renderer, plan)[0])
