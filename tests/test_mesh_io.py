"""Mesh input: splitting hexahedra, wedges and pyramids into tetrahedra conformingly
(dvr_gl.model.cell_split), grids as tetrahedral meshes, and reading mesh files
(dvr_gl.formats.load_mesh) with clear errors for what cannot be rendered."""

import itertools
import os

import meshio
import numpy as np
import pytest

import dvr_gl
from dvr_gl.model import cell_split
from dvr_gl.formats import InputError, MissingFileError, is_mesh_file, load_mesh, point_arrays
from dvr_gl.model.transfer import auto_preset

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DATA = os.environ.get("DVR_GL_DATA") or os.path.join(os.path.dirname(ROOT), "shared", "data")
# the real files live in the shared data folder beside the checkout (CI has it)
needs_shared_data = pytest.mark.skipif(not os.path.isdir(DATA), reason="the shared data folder is not beside the "
                                                                       "checkout (or at $DVR_GL_DATA)")
POST = os.path.join(DATA, "vtk_post_tets", "post.vtk")
BLUNTFIN = os.path.join(DATA, "nasa_bluntfin", "bluntfin_tets")

SPLIT = {"pyramid": cell_split.split_pyramids, "wedge": cell_split.split_wedges,
         "hexahedron": cell_split.split_hexahedra}


def _volumes(points, tets):
    p = points[tets]
    a, b, c = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
    return np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0


def _face_counts(tets):
    """How many tetrahedra hold each triangle (as a sorted index tuple)."""
    faces = np.sort(tets[:, [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]]].reshape(-1, 3), axis=1)
    keys, counts = np.unique(faces, axis=0, return_counts=True)
    return dict(zip(map(tuple, keys.tolist()), counts.tolist()))


def _boundary_quads(cell_type):
    """The quad faces of each cell type, VTK order."""
    return {"pyramid": [(0, 1, 2, 3)],
            "wedge": [(0, 1, 4, 3), (1, 2, 5, 4), (2, 0, 3, 5)],
            "hexahedron": [(0, 1, 2, 3), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)],
            }[cell_type]


# ============================================================================ one cell

@pytest.mark.parametrize("cell_type", ["pyramid", "wedge", "hexahedron"])
def test_every_labelling_of_the_reference_cell_splits_into_positive_tets(cell_type):
    """All k! ways to number a cell's vertices globally: positive tets filling it, and
    each quad face cut through its smallest vertex."""
    ref = cell_split.REFERENCE_CELLS[cell_type]
    k = len(ref)
    labels = np.array(list(itertools.permutations(range(k))))
    if len(labels) > 5000:
        labels = labels[np.random.default_rng(1).choice(len(labels), 5000, replace=False)]
    cells = labels + k * np.arange(len(labels))[:, None]
    points = np.zeros((cells.size, 3))
    points[cells] = ref
    tets = SPLIT[cell_type](cells)
    v = _volumes(points, tets)
    assert v.min() > 0
    owner = tets[:, 0] // k
    assert np.allclose(np.bincount(owner, weights=v), {"pyramid": 1 / 3, "wedge": 0.5, "hexahedron": 1}[cell_type])
    # each quad face appears as the two triangles on its smallest vertex's diagonal
    counts = _face_counts(tets)
    for cell in cells[:200]:
        for quad in _boundary_quads(cell_type):
            q = cell[list(quad)]
            m = int(np.argmin(q))
            a, b, c, d = (q[(m + i) % 4] for i in range(4))
            for tri in ((a, b, c), (a, c, d)):
                assert counts.get(tuple(sorted(int(x) for x in tri))) == 1, (cell, quad)


@pytest.mark.parametrize("cell_type", ["pyramid", "wedge", "hexahedron"])
def test_distorted_convex_cells_keep_positive_volume(cell_type):
    """Reference cells moved by random affine maps (positive determinant) and jittered
    corners: every tet stays positive and their sum is the cell's volume."""
    rng = np.random.default_rng(7)
    ref = cell_split.REFERENCE_CELLS[cell_type]
    k = len(ref)
    n = 300
    maps = np.eye(3) + 0.3 * rng.standard_normal((n, 3, 3))
    maps[np.linalg.det(maps) < 0, :, 0] *= -1
    corners = np.einsum("nij,kj->nki", maps, ref) + rng.standard_normal((n, 1, 3))
    labels = np.array([rng.permutation(k) for _ in range(n)]) + k * np.arange(n)[:, None]
    points = np.zeros((n * k, 3))
    points[labels] = corners
    tets = SPLIT[cell_type](labels)
    v = _volumes(points, tets)
    assert v.min() > 0
    expected = {"pyramid": 1 / 3, "wedge": 0.5, "hexahedron": 1.0}[cell_type] * np.linalg.det(maps)
    assert np.allclose(np.bincount(tets[:, 0] // k, weights=v, minlength=n), expected)


def test_mirrored_cells_give_negative_tets():
    """A cell numbered against VTK's orientation keeps it: all tets negative (TetMesh
    accepts either orientation)."""
    hexa = cell_split.REFERENCE_CELLS["hexahedron"] * (1, 1, -1)
    tets = cell_split.split_hexahedra(np.array([[3, 0, 5, 1, 7, 2, 6, 4]]))
    assert np.all(_volumes(hexa[np.argsort([3, 0, 5, 1, 7, 2, 6, 4])], tets) < 0)


def test_collapsed_cells():
    """A geometrically collapsed face gives zero-volume tets, kept; indices repeated in
    a cell (a wedge stored as a hexahedron) drop the tets that would repeat a vertex."""
    hexa = cell_split.REFERENCE_CELLS["hexahedron"].copy()
    hexa[[2, 6]] = hexa[[1, 5]]  # face 1-2-6-5 collapsed to an edge: a wedge's shape
    tets = cell_split.split_hexahedra(np.arange(8)[None])
    v = _volumes(hexa, tets)
    assert len(tets) in (5, 6) and np.isclose(v.sum(), 0.5) and (v >= -1e-15).all() and (np.abs(v) < 1e-15).any()
    dvr_gl.TetMesh(hexa, tets, np.zeros(8))  # accepted as it is
    repeated = cell_split.split_hexahedra(np.array([[0, 1, 1, 3, 4, 5, 5, 7]]))
    assert all(len(set(t)) == 4 for t in repeated.tolist())
    assert np.isclose(_volumes(hexa, repeated).sum(), 0.5)


def test_bad_cell_arrays():
    with pytest.raises(ValueError, match=r"hexahedra must have shape \(M, 8\)"):
        cell_split.split_hexahedra(np.zeros((3, 6), int))
    with pytest.raises(TypeError, match="integer"):
        cell_split.split_wedges(np.zeros((3, 6)))
    with pytest.raises(ValueError, match="'polyhedron'"):
        cell_split.split_cells([("polyhedron", np.zeros((1, 8), int))])


# ============================================================================ meshes of cells

def _hex_grid(n=4, seed=3):
    """A jittered n^3-cell hexahedral grid with shuffled point numbers (so the smallest
    vertex of a cell is anywhere); returns points, hexahedra and a point field."""
    rng = np.random.default_rng(seed)
    k, j, i = np.meshgrid(*(np.arange(n + 1),) * 3, indexing="ij")
    points = np.stack([i, j, k], -1).reshape(-1, 3).astype(float)
    points += rng.uniform(-0.2, 0.2, points.shape)
    ids = np.arange(len(points)).reshape((n + 1,) * 3)
    base = ids[:-1, :-1, :-1]
    cube = cell_split.REFERENCE_CELLS["hexahedron"].astype(int)
    hexa = np.stack([base + dz * (n + 1) ** 2 + dy * (n + 1) + dx for dx, dy, dz in cube], -1).reshape(-1, 8)
    shuffle = rng.permutation(len(points))  # new number of old point p: shuffle[p]
    new_points = np.empty_like(points)
    new_points[shuffle] = points
    return new_points, shuffle[hexa], np.sin(new_points).sum(axis=1)


def _hex_to_wedges(hexa):
    """Each hexahedron as two wedges, cut through 0-2-6-4 or 1-3-7-5, whichever diagonals
    the smallest-vertex rule puts on its bottom and top faces; None where the bottom's
    and the top's rules disagree (no such pair of wedges conforms)."""
    bottom_02 = np.minimum(hexa[:, 0], hexa[:, 2]) < np.minimum(hexa[:, 1], hexa[:, 3])
    top_46 = np.minimum(hexa[:, 4], hexa[:, 6]) < np.minimum(hexa[:, 5], hexa[:, 7])
    a, b = hexa[bottom_02 & top_46], hexa[~bottom_02 & ~top_46]
    wedges = np.concatenate([a[:, [0, 1, 2, 4, 5, 6]], a[:, [0, 2, 3, 4, 6, 7]],
                             b[:, [1, 2, 3, 5, 6, 7]], b[:, [1, 3, 0, 5, 7, 4]]])
    return wedges, bottom_02 == top_46


def _enclosed_volume(points, tets):
    """The volume inside the triangles held by one tetrahedron only (outward faces)."""
    faces = tets[:, [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]]].reshape(-1, 3)
    keys, inverse, counts = np.unique(np.sort(faces, axis=1), axis=0, return_inverse=True, return_counts=True)
    outer = faces[counts[inverse.ravel()] == 1]
    p = points[outer]
    return np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6.0


def _check_conforming(points, tets, total_volume):
    """Positive tets, every face held by one or two of them, and their volume the one
    their boundary encloses (faces cut differently on two sides would break that)."""
    v = _volumes(points, tets)
    assert v.min() > 0 and np.isclose(v.sum(), total_volume)
    assert np.isclose(_enclosed_volume(points, tets), total_volume)
    counts = np.array(list(_face_counts(tets).values()))
    assert set(counts.tolist()) <= {1, 2}
    return counts


def test_hex_mesh_is_conforming():
    points, hexa, _ = _hex_grid()
    tets = cell_split.split_hexahedra(hexa)
    counts = _check_conforming(points, tets, _volumes(points, tets).sum())
    assert (counts == 1).sum() == 6 * 16 * 2  # boundary triangles: 6 sides x 16 quads x 2


def test_mixed_mesh_is_conforming():
    """Hexahedra, wedges (pairs in the hexahedra whose top and bottom rules allow it) and
    pyramids (six per hexahedron, apex at an added centre point) side by side share
    every face exactly, and fill the same domain as the hexahedra alone."""
    points, hexa, _ = _hex_grid()
    whole = _volumes(points, cell_split.split_hexahedra(hexa)).sum()
    n = len(hexa)
    first, second, third = hexa[: n // 3], hexa[n // 3: 2 * n // 3], hexa[2 * n // 3:]
    wedges, as_wedges = _hex_to_wedges(second)
    assert 0 < as_wedges.sum() < len(second)
    centres = points[third].mean(axis=1)
    centre_ids = len(points) + np.arange(len(third))
    pyramids = np.concatenate([np.column_stack([third[:, list(q)], centre_ids])
                               for q in ((0, 1, 2, 3), (4, 7, 6, 5), (0, 4, 5, 1), (1, 5, 6, 2),
                                         (2, 6, 7, 3), (3, 7, 4, 0))])  # bases facing the centre
    all_points = np.concatenate([points, centres])
    tets = cell_split.split_cells([("hexahedron", first), ("wedge", wedges),
                                   ("hexahedron", second[~as_wedges]), ("pyramid", pyramids)])
    counts = _check_conforming(all_points, tets, whole)
    assert (counts == 1).sum() == 6 * 16 * 2


def test_prism_mesh_is_conforming():
    """A mesh of wedges only: each hexahedron cut the same way (not by the rule, so the
    top and bottom triangles come from the cut; the quads from the rule)."""
    points, hexa, _ = _hex_grid(3, seed=5)
    wedges = np.concatenate([hexa[:, [0, 1, 2, 4, 5, 6]], hexa[:, [0, 2, 3, 4, 6, 7]]])
    tets = cell_split.split_wedges(wedges)
    assert len(tets) == 3 * len(wedges)
    counts = _check_conforming(points, tets, _volumes(points, tets).sum())
    assert (counts == 1).sum() == 6 * 9 * 2


def test_grid_to_tets():
    rng = np.random.default_rng(0)
    data = rng.random((3, 4, 5)).astype(np.float32)
    vol = dvr_gl.Volume(data, spacing=(0.5, 1, 2), origin=(1, 2, 3))
    mesh = cell_split.grid_to_tets(vol)
    assert mesh.n_points == 60 and mesh.n_tets == 6 * 2 * 3 * 4
    assert np.allclose(mesh.points[7], vol.origin + (2 * 0.5, 1 * 1, 0))  # sample (k, j, i) = (0, 1, 2)
    assert np.array_equal(mesh.scalars, data.ravel().astype(np.float64))
    v = mesh.signed_volumes()
    assert v.min() > 0 and np.isclose(v.sum(), np.prod(vol.extent))
    counts = np.array(list(_face_counts(mesh.tets).values()))
    assert set(counts.tolist()) == {1, 2} and (counts == 1).sum() == 2 * 2 * (3 * 4 + 4 * 2 + 3 * 2)
    # the linear field reproduces a linear function of position exactly
    lin = vol.origin[0] + 0.5 * np.arange(5)
    ramp = dvr_gl.Volume(np.broadcast_to(lin, (3, 4, 5)).astype(np.float64), spacing=(0.5, 1, 2), origin=(1, 2, 3))
    m2 = cell_split.grid_to_tets(ramp)
    assert np.allclose(m2.scalars, m2.points[:, 0])
    masked = data.copy()
    masked[0, 0, 0] = np.nan
    m3 = cell_split.grid_to_tets(dvr_gl.Volume(masked, mask_nonfinite=True))
    assert m3.n_tets == 6 * (2 * 3 * 4 - 1)


# ============================================================================ files

def _write(tmp_path, name, points, cells, **point_data):
    path = tmp_path / name
    meshio.write(str(path), meshio.Mesh(points, cells, point_data=point_data))
    return path


def _unit_hex_mesh():
    points = cell_split.REFERENCE_CELLS["hexahedron"] * 2.0
    return points, {"T": points[:, 0] + 10 * points[:, 2], "V": points * 3}


@pytest.mark.parametrize("name", ["m.vtu", "m.vtk"])
@pytest.mark.parametrize("cell_type", ["tetra", "pyramid", "wedge", "hexahedron"])
def test_load_each_cell_type(tmp_path, name, cell_type):
    ref = cell_split.REFERENCE_CELLS[cell_type]
    points = np.concatenate([ref, [(5.0, 5, 5)]])  # and a point no cell uses
    path = _write(tmp_path, name, points, [(cell_type, np.arange(len(ref))[None])],
                  V=np.ones((len(points), 3)), s=points.sum(axis=1))
    assert is_mesh_file(path)
    mesh = load_mesh(path)
    assert mesh.n_points == len(points)
    expected = {"tetra": 1, "pyramid": 2, "wedge": 3, "hexahedron": 6}[cell_type]
    assert mesh.n_tets == expected and mesh.signed_volumes().min() > 0
    assert np.array_equal(mesh.scalars, points.sum(axis=1))  # the first *scalar* array, V skipped
    assert point_arrays(path) == {"V": 3, "s": 1}


def test_load_mixed_cells_ignoring_surfaces_and_choosing_scalars(tmp_path):
    points, hexa, field = _hex_grid(2)
    wedges = np.concatenate([hexa[4:, [0, 1, 2, 4, 5, 6]], hexa[4:, [0, 2, 3, 4, 6, 7]]])
    pyramid = np.array([[0, 1, 2, 3, len(points) - 1]])
    cells = [("triangle", np.array([[0, 1, 2]])), ("hexahedron", hexa[:4]), ("wedge", wedges),
             ("line", np.array([[0, 1]])), ("pyramid", pyramid), ("vertex", np.array([[3]]))]
    path = _write(tmp_path, "mixed.vtu", points, cells, f=field, g=2 * field)
    mesh = load_mesh(path, scalars="g")
    solid = cell_split.split_cells([("hexahedron", hexa[:4]), ("wedge", wedges), ("pyramid", pyramid)])
    assert np.array_equal(mesh.tets, solid) and len(solid) >= 4 * 5 + 8 * 3 + 2
    assert np.allclose(mesh.scalars, 2 * field)


def test_load_npz_mesh(tmp_path):
    points, fields = _unit_hex_mesh()
    tets = cell_split.split_hexahedra(np.arange(8)[None]).astype(np.int32)
    np.savez(tmp_path / "m.npz", points=points.astype(np.float32), tets=tets, V=fields["V"], T=fields["T"])
    np.savez(tmp_path / "grid.npz", data=np.zeros((2, 2, 2)))
    assert is_mesh_file(tmp_path / "m.npz") and not is_mesh_file(tmp_path / "grid.npz")
    mesh = load_mesh(tmp_path / "m.npz")
    assert np.array_equal(mesh.scalars, fields["T"]) and np.array_equal(mesh.tets, tets)
    with pytest.raises(InputError, match=r"lacks \['points', 'tets'\]"):
        load_mesh(tmp_path / "grid.npz")


def test_is_mesh_file(tmp_path):
    for name, header in (("u.vtk", "DATASET UNSTRUCTURED_GRID"), ("s.vtk", "DATASET STRUCTURED_POINTS")):
        (tmp_path / name).write_text(f"# vtk DataFile Version 3.0\nx\nASCII\n{header}\n")
    assert is_mesh_file(tmp_path / "u.vtk") and not is_mesh_file(tmp_path / "s.vtk")
    assert is_mesh_file("x.msh") and is_mesh_file("x.VTU") and is_mesh_file("x.xdmf")
    for name in ("x.npy", "x.nrrd", "x.nhdr", "x.mha", "x.raw", "x.raw.gz", "missing.npz", "x.bin"):
        assert not is_mesh_file(tmp_path / name), name
    if os.path.isdir(DATA):
        assert not is_mesh_file(os.path.join(DATA, "vtk_carotid", "carotid.vtk"))


def test_bad_mesh_files(tmp_path):
    points, fields = _unit_hex_mesh()
    hexa = np.arange(8)[None]
    with pytest.raises(MissingFileError, match="no such file"):
        load_mesh(tmp_path / "missing.vtu")
    path = _write(tmp_path, "m.vtu", points, [("hexahedron", hexa)], **fields)
    with pytest.raises(InputError, match=r"no point array 'P'; available: T, V \(3 components\)") as e:
        load_mesh(path, scalars="P")
    assert e.value.field == "scalars"
    with pytest.raises(InputError, match="'V' .* has 3 components"):
        load_mesh(path, scalars="V")
    quadratic = _write(tmp_path, "q.vtu", np.random.default_rng(0).random((10, 3)),
                       [("tetra10", np.arange(10)[None])], s=np.zeros(10))
    with pytest.raises(InputError, match="'tetra10'") as e:
        load_mesh(quadratic)
    assert e.value.field == "cells"
    surface = _write(tmp_path, "s.vtu", points, [("quad", np.array([[0, 1, 2, 3]]))], s=np.zeros(8))
    with pytest.raises(InputError, match="no 3-D cells .*quad"):
        load_mesh(surface)
    no_scalar = _write(tmp_path, "v.vtu", points, [("hexahedron", hexa)], V=fields["V"])
    with pytest.raises(InputError, match=r"no scalar point array .*V \(3 components\)"):
        load_mesh(no_scalar)
    # a file of cell data (finite-volume solvers write one value per cell): the error
    # names the cell arrays as the reason there is no field
    cell_data = tmp_path / "c.vtu"
    meshio.write(str(cell_data), meshio.Mesh(points, [("hexahedron", hexa)], cell_data={"p": [np.array([1.0])]}))
    for scalars in (None, "p"):
        with pytest.raises(InputError, match=r"point array.*cell arrays are not rendered .*: p$") as e:
            load_mesh(cell_data, scalars=scalars)
        assert e.value.field == "scalars"
    np.savez(tmp_path / "bad.npz", points=points, tets=np.array([[0, 1, 2, 9]]), s=np.zeros(8))
    with pytest.raises(ValueError, match=r"tets\[0\] has index 9 out of range for 8 points"):
        load_mesh(tmp_path / "bad.npz")
    (tmp_path / "junk.vtu").write_text("not xml")
    with pytest.raises(InputError, match="cannot read .*junk.vtu"):
        load_mesh(tmp_path / "junk.vtu")
    with pytest.raises(InputError, match="directory"):
        load_mesh(tmp_path)


# ============================================================================ shared data

@needs_shared_data
def test_post_vtk():
    mesh = load_mesh(POST)
    assert (mesh.n_points, mesh.n_tets) == (2288, 8750)
    assert np.isclose(mesh.data_range[0], 0.35537, atol=1e-5) and np.isclose(mesh.data_range[1], 1.64124, atol=1e-5)
    assert point_arrays(POST) == {"Pressure": 1}
    assert load_mesh(POST, scalars="Pressure").digest() == mesh.digest()


@needs_shared_data
def test_bluntfin_npz_and_vtu_agree():
    from_npz = load_mesh(BLUNTFIN + ".npz")
    from_vtu = load_mesh(BLUNTFIN + ".vtu")
    assert (from_npz.n_points, from_npz.n_tets) == (40960, 187395)
    assert np.array_equal(from_npz.points, from_vtu.points) and np.array_equal(from_npz.tets, from_vtu.tets)
    assert np.array_equal(from_npz.scalars, from_vtu.scalars)  # Density, the first scalar
    assert np.isclose(from_npz.data_range[0], 0.1926, atol=1e-4) and np.isclose(from_npz.data_range[1], 4.9775, atol=1e-4)
    arrays = point_arrays(BLUNTFIN + ".vtu")
    assert arrays["Momentum"] == 3 and arrays["Pressure"] == 1
    with pytest.raises(InputError, match="'Momentum' .* has 3 components"):
        load_mesh(BLUNTFIN + ".npz", scalars="Momentum")


# ============================================================================ transfer preset

@needs_shared_data
def test_auto_preset_for_a_mesh():
    mesh = load_mesh(POST)
    tf = auto_preset(mesh)        # the coolwarm ramp over the 1st to 99th percentile
    lo, hi = np.percentile(mesh.scalars, [1, 99])
    assert np.allclose(tf.knots[[0, -1]], [lo, hi]) and tf.unit_distance == mesh.cell_size
    assert np.allclose(tf.opacity_points, [[lo, 0.0], [hi, 0.5]])
    assert auto_preset(mesh, unit_distance=0.25).unit_distance == 0.25
    vol = dvr_gl.Volume(np.arange(27, dtype=np.float32).reshape(3, 3, 3), spacing=(2, 0.5, 1))
    grid_tf = auto_preset(vol)    # the warm ramp from the median to the 99.5th percentile
    assert grid_tf.unit_distance == 0.5
    assert np.allclose(grid_tf.knots[[0, -1]], np.percentile(vol.data, [50, 99.5]))
