"""Error targets for meshes (dvr_gl.rendering.mesh_tolerance) and the mesh resampled onto a
grid (dvr_gl.model.mesh_grid).

The pilot picks a way of rendering the mesh (tetra's sorts, or the ray caster on the mesh
resampled once onto a grid) by measuring each against the exact image; the test asks
for three tolerances on the bundled Delaunay ball and NASA's blunt fin and checks the
frame against its own exact image, for the view the pilot saw and for the view turned
by 25 degrees, which reuses the choice without a pilot. The resampling is checked
against an independent brute-force location of every sample (its value is the linear
field of the containing cell, to float32 rounding) and on a non-convex domain.
"""

import os

import numpy as np
import pytest

import dvr_gl
from dvr_gl import Scene, TetMesh, Volume, metrics, reference
from dvr_gl.frontends import cli
from dvr_gl.model import cell_split, mesh_grid
from dvr_gl.model.camera import default_camera
from dvr_gl.rendering import mesh_tolerance
from dvr_gl.techniques import tetra

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DATA = os.environ.get("DVR_GL_DATA") or os.path.join(os.path.dirname(ROOT), "shared", "data")
BLUNTFIN = os.path.join(DATA, "nasa_bluntfin", "bluntfin_tets.npz")
SIZE = 32


def _ball():
    from dvr_gl.data import delaunay_ball, synthetic_tf
    return delaunay_ball(), synthetic_tf()


def _bluntfin():
    if not os.path.exists(BLUNTFIN):
        pytest.skip("the shared data folder is not beside the checkout (or at $DVR_GL_DATA)")
    from dvr_gl.bench.common import mesh_tf
    z = np.load(BLUNTFIN)
    mesh = TetMesh(z["points"], z["tets"], z["Density"])
    return mesh, mesh_tf(mesh)


def _scene(mesh, tf, azimuth=30.0):
    return Scene(mesh, tf, default_camera(mesh, azimuth=azimuth, elevation=20.0), SIZE, SIZE)


# ----------------------------------------------------------------------- the error target
@pytest.mark.parametrize("data", ["delaunay ball", "blunt fin"])
def test_the_choice_is_within_the_tolerance_on_the_view_and_the_turned_view(renderer, data):
    mesh, tf = _ball() if data == "delaunay ball" else _bluntfin()
    scene, turned = _scene(mesh, tf), _scene(mesh, tf, azimuth=55.0)
    exact, exact_turned = reference.exact(scene), reference.exact(turned)
    labels = set()
    for tolerance in (1e-2, 3e-3, 1e-3):
        image = renderer.render(scene, "tetra", tolerance=tolerance)
        choice = renderer.last_choice
        assert isinstance(choice, mesh_tolerance.MeshChoice) and choice.tolerance == tolerance
        assert metrics.rmse(image, exact) <= tolerance, (tolerance, choice.label)
        assert choice.pilot_rmse <= mesh_tolerance.SAFETY * tolerance or choice.label == "tetra mpvo"
        labels.add(choice.label)
        again = renderer.render(turned, "tetra", tolerance=tolerance)
        assert renderer.last_choice is choice                      # the view family's choice, no pilot
        assert metrics.rmse(again, exact_turned) <= tolerance, (tolerance, choice.label, "turned")
    # the tolerance matters: not the exact mode for all three
    assert labels != {"tetra mpvo"}, labels


def test_every_way_the_pilot_measured_has_its_error_and_the_choice_is_the_fastest_within(renderer):
    mesh, tf = _ball()
    scene = _scene(mesh, tf)
    fresh = dvr_gl.Renderer()             # its own record: every time below was taken for this request
    try:
        fresh.render(scene, "tetra", tolerance=5e-3)
        choice = fresh.last_choice
    finally:
        fresh.release()
    measured = {label: (error, seconds) for label, error, seconds in choice.measured}
    assert {"tetra mpvo", "tetra centroid"} <= set(measured)
    assert measured["tetra mpvo"][0] < 1e-4                       # the exact mode, measured
    timed = {label: s for label, (e, s) in measured.items() if s is not None}
    assert all(measured[label][0] <= mesh_tolerance.SAFETY * 5e-3 for label in timed)
    if timed:
        assert choice.label == min(timed, key=timed.get)
    # grid ways dearer than the cheapest grid way within the margin are not rendered
    grids = [w for w in mesh_tolerance.available_ways() if w.grid and w.label in measured]
    met = [w for w in grids if measured[w.label][0] <= mesh_tolerance.SAFETY * 5e-3]
    assert met and all(w.cost <= min(m.cost for m in met) for w in grids)


def test_a_second_frame_of_the_family_costs_no_pilot(renderer, monkeypatch):
    mesh, tf = _ball()
    calls = []
    choose = mesh_tolerance.choose
    monkeypatch.setattr(mesh_tolerance, "choose", lambda *a, **k: calls.append(1) or choose(*a, **k))
    for azimuth in (10.0, 40.0, 70.0):
        renderer.render(_scene(mesh, tf, azimuth), "tetra", tolerance=7e-3)
    assert len(calls) == 1
    renderer.render(_scene(mesh, tf).replace(width=SIZE + 8), "tetra", tolerance=7e-3)   # another size
    assert len(calls) == 2


def test_a_later_tolerance_from_a_turned_view_is_measured_on_the_family_pilot(renderer):
    """The family's record keeps the pilot view it was measured on: a tolerance asked
    later from another view of the family measures its new ways on that same view."""
    mesh, tf = _ball()
    first, turned = (_scene(mesh, tf, azimuth).replace(width=SIZE + 4) for azimuth in (30.0, 95.0))
    renderer.render(first, "tetra", tolerance=2.1e-2)
    renderer.render(turned, "tetra", tolerance=2.1e-3)
    pilot = mesh_tolerance.scaled_scene(first, mesh_tolerance.PILOT_SIDE)
    reference_image = reference.exact(pilot)
    ways = {w.label: w for w in mesh_tolerance.available_ways()}
    grids = [(label, error) for label, error, _ in renderer.last_choice.measured if ways[label].grid]
    assert len(grids) >= 3
    for label, error in grids:
        s, name, step, options = mesh_tolerance.way_arguments(pilot, ways[label], renderer.tables)
        again = metrics.rmse(renderer.render(s, name, step=step, **options), reference_image)
        assert again == pytest.approx(error, rel=1e-3, abs=1e-7), label


def test_the_walk_sort_is_a_candidate_when_tetra_has_it():
    labels = [w.label for w in mesh_tolerance.available_ways()]
    assert ("tetra walk" in labels) == ("walk" in tetra.SORTS)
    assert "tetra mpvo" in labels and any(w.grid for w in mesh_tolerance.available_ways())


def test_dvr_gl_render_and_the_command_line_take_a_mesh_tolerance(renderer, tmp_path, capsys):
    import meshio
    mesh, tf = _ball()
    image = dvr_gl.render(mesh, tf=tf, size=SIZE, tolerance=2e-2)
    exact = reference.exact(Scene(mesh, tf, dvr_gl.frontends.inputs.first_camera(mesh), SIZE, SIZE))
    assert metrics.rmse(image, exact) <= 2e-2
    path = tmp_path / "ball.vtu"
    meshio.write(str(path), meshio.Mesh(mesh.points, [("tetra", mesh.tets)], point_data={"f": mesh.scalars}))
    out = tmp_path / "ball.png"
    code = cli.main(["render", str(path), "--tolerance", "0.02", "--size", str(SIZE), "--out", str(out)])
    text = capsys.readouterr().out
    assert code == 0 and out.exists()
    assert "for tolerance 0.02 (pilot RMSE" in text
    code = cli.main(["render", str(path), "--tolerance", "0.01", "--sort", "mpvo", "--out", str(out)])
    assert code == 2 and "--tolerance" in capsys.readouterr().err


def test_bad_requests_are_named(renderer):
    mesh, tf = _ball()
    scene = _scene(mesh, tf)
    for bad in (0.0, -1e-3, float("nan")):
        with pytest.raises(ValueError, match="tolerance"):
            renderer.render(scene, "tetra", tolerance=bad)
    with pytest.raises(TypeError, match="tolerance"):
        renderer.render(scene, "tetra", tolerance="small")
    with pytest.raises(ValueError, match="sort='centroid'"):
        renderer.render(scene, "tetra", tolerance=1e-2, sort="centroid")
    with pytest.raises(ValueError, match="technique 'tetra'"):
        renderer.render(scene, "particles", tolerance=1e-2)


# ------------------------------------------------------------------------- the resampling
def _brute_force(mesh, x):
    """Per point, the value of the linear field of a cell containing it (NaN if none),
    by testing every cell: independent of mesh_grid's per-cell columns."""
    p = mesh.points[mesh.tets]
    edges = np.transpose(p[:, 1:] - p[:, :1], (0, 2, 1))
    ok = np.abs(np.linalg.det(edges)) > 1e-12 * np.abs(edges).max() ** 3
    out = np.full(len(x), np.nan)
    for n, point in enumerate(x):
        lam = np.linalg.solve(edges[ok], (point - p[ok, 0])[..., None])[..., 0]
        inside = (lam >= -1e-9).all(axis=1) & (lam.sum(axis=1) <= 1 + 1e-9)
        if inside.any():
            c = np.flatnonzero(inside)[0]
            w = np.concatenate([[1 - lam[c].sum()], lam[c]])
            out[n] = w @ mesh.scalars[mesh.tets[ok][c]]
    return out


def test_resampled_samples_are_the_linear_field_of_their_cell():
    mesh, _ = _ball()
    shape = (20, 21, 22)
    grid = mesh_grid.resample_to_grid(mesh, shape)
    assert grid.shape == shape and grid.mask_nonfinite and grid.data.dtype == np.float32
    origin, spacing = mesh_grid.grid_geometry(mesh, shape)
    assert np.allclose(grid.origin, mesh.bounds[0]) and np.allclose(grid.origin + grid.extent, mesh.bounds[1])
    rng = np.random.default_rng(1)
    index = np.stack([rng.integers(0, n, 120) for n in shape], axis=1)       # (k, j, i)
    x = origin + index[:, ::-1] * spacing
    expected = _brute_force(mesh, x)
    got = grid.data[index[:, 0], index[:, 1], index[:, 2]].astype(np.float64)
    assert np.array_equal(np.isnan(got), np.isnan(expected))
    inside = ~np.isnan(expected)
    assert inside.sum() > 40 and (~inside).sum() > 10                        # both kinds drawn
    scale = np.abs(mesh.scalars).max()
    assert np.abs(got[inside] - expected[inside]).max() <= 2 * np.finfo(np.float32).eps * scale


def test_a_linear_field_is_resampled_exactly_and_a_grid_mesh_gives_its_grid_back():
    mesh, _ = _ball()
    a = np.array([0.3, -0.2, 0.7])
    linear = TetMesh(mesh.points, mesh.tets, mesh.points @ a + 2.0)
    grid = mesh_grid.resample_to_grid(linear, (17, 19, 23))
    origin, spacing = mesh_grid.grid_geometry(linear, (17, 19, 23))
    k, j, i = np.meshgrid(*(np.arange(n) for n in (17, 19, 23)), indexing="ij")
    truth = (origin + np.stack([i, j, k], axis=-1) * spacing) @ a + 2.0
    finite = np.isfinite(grid.data)
    assert np.abs(grid.data[finite] - truth[finite]).max() <= 4 * np.finfo(np.float32).eps * np.abs(truth).max()
    # every sample of a grid's own tetrahedralisation is a vertex: the grid comes back
    rng = np.random.default_rng(2)
    volume = Volume(rng.random((5, 6, 7)).astype(np.float32), spacing=(0.5, 1.0, 0.25), origin=(1.0, -2.0, 3.0))
    back = mesh_grid.resample_to_grid(cell_split.grid_to_tets(volume), volume.shape)
    assert not back.has_nonfinite and np.array_equal(back.data, volume.data)


def test_samples_outside_a_non_convex_domain_are_masked():
    # an L of three unit cubes (the cube at x, y = 1, 1 missing), Kuhn-split
    cubes = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
    index, points, tets = {}, [], []
    six = np.array([[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]])
    for c in cubes:
        ids = []
        for k in range(8):
            p = (c[0] + (k & 1), c[1] + ((k >> 1) & 1), c[2] + ((k >> 2) & 1))
            ids.append(index.setdefault(p, len(points)))
            if ids[-1] == len(points):
                points.append(p)
        tets.extend([[ids[v] for v in t] for t in six])
    points = np.array(points, float)
    mesh = TetMesh(points, np.array(tets), points.sum(axis=1))
    grid = mesh_grid.resample_to_grid(mesh, (3, 9, 9))                       # spacing 1/4 in x, y
    data = grid.data
    x = np.arange(9) / 4
    gap = (x[None, :] > 1) & (x[:, None] > 1)                                # (y, x) in the missing cube
    assert np.isnan(data[:, gap]).all() and np.isfinite(data[:, ~gap]).all()
    assert grid.has_nonfinite and not grid.cell_valid[:, 4:, 4:].any() and grid.cell_valid[:, :4, :].all()


def test_bad_shapes_are_named():
    mesh, _ = _ball()
    for bad, error in (((4, 4), TypeError), ((4, 4, 1), ValueError), ((4.0, 4, 4), TypeError), (8, TypeError)):
        with pytest.raises(error, match="shape"):
            mesh_grid.resample_to_grid(mesh, bad)
    with pytest.raises(TypeError, match="mesh"):
        mesh_grid.resample_to_grid(np.zeros((4, 4, 4)), (4, 4, 4))
    with pytest.raises(ValueError, match="samples"):
        mesh_grid.grid_shape(mesh, 1)


# --------------------------------------------------------------------- the grown boundary
def test_the_grown_boundary_extends_a_linear_field_by_one_sample():
    """Each outside sample next to the domain along an axis takes the linear field
    extrapolated from inside (exactly, for a linear field); inside samples keep their
    values, samples two away stay outside."""
    z, y, x = np.mgrid[0:6, 0:7, 0:8].astype(np.float32)
    linear = 1.0 + 2.0 * x + 3.0 * y + 5.0 * z
    values = np.full(linear.shape, np.nan, np.float32)
    values[2:4, 2:5, 2:6] = linear[2:4, 2:5, 2:6]
    grown = mesh_tolerance.grow_boundary(Volume(values, mask_nonfinite=True)).data
    assert np.array_equal(grown[2:4, 2:5, 2:6], values[2:4, 2:5, 2:6])
    added = np.isfinite(grown) & ~np.isfinite(values)
    assert added.sum() == 2 * (3 * 4 + 2 * 4 + 2 * 3)               # the six faces of the block
    assert np.allclose(grown[added], linear[added], atol=1e-5)
    assert not np.isfinite(grown[0]).any() and not np.isfinite(grown[:, :, 0]).any()


def test_the_grown_grid_is_closer_to_exact_on_a_non_convex_mesh(renderer):
    """The plain grid's domain is up to a cell smaller than the mesh's, and that is most
    of its error at a curvilinear mesh's walls; grown by one sample the grid is measured
    closer to exact (blunt fin, 48 samples: 1.6e-2 to 1.0e-2; the combustor and the LOX
    post: 2x, docs/notes/mesh_tolerance.md). (On the bundled ball the TF hides the cells
    at the boundary, and the two grids give the same image.)"""
    mesh, tf = _bluntfin()
    scene = _scene(mesh, tf)
    exact = reference.exact(scene)
    shape = mesh_grid.grid_shape(mesh, 48)
    plain = mesh_grid.resample_to_grid(mesh, shape)
    errors = [metrics.compare(renderer.render(scene.replace(volume=v), "raycast", step=v.min_spacing), exact)["rmse"]
              for v in (plain, mesh_tolerance.grow_boundary(plain))]
    assert errors[1] < 0.8 * errors[0], errors
