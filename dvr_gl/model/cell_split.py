"""Splitting hexahedra, wedges (prisms) and pyramids into tetrahedra, conformingly.

A mesh of mixed cells becomes a :class:`dvr_gl.TetMesh` only if two cells sharing a
quadrilateral face cut it along the same diagonal; otherwise the two halves of the face
do not match and the tetrahedral mesh has cracks (and overlaps). The rule here is that
of Dompierre, Labbé, Vallet and Camarero, "How to subdivide pyramids, prisms and
hexahedra into tetrahedra" (8th International Meshing Roundtable, 1999): **every quad
face is cut by the diagonal through its vertex with the smallest global index.** It
depends on the face's four indices only, so both cells of a shared face agree without
knowing of each other.

Per cell type (VTK's vertex ordering, which meshio uses too; cells "positively
oriented" as VTK's parametric cell, e.g. hexahedron face 0-1-2-3 turning counter-
clockwise seen from 4-5-6-7):

- pyramid (base 0-1-2-3, apex 4): the base diagonal decides, 2 tetrahedra.
- wedge (triangles 0-1-2 and 3-4-5, edges 0-3, 1-4, 2-5): the cell is relabelled by one
  of its 6 orientation-preserving symmetries so that its smallest vertex is vertex 0;
  the quads through 0 are then cut from 0, and the diagonal of the quad 1-2-5-4
  picks one of two sets of 3 tetrahedra.
- hexahedron: relabelled by one of its 24 rotations so that its smallest vertex is 0
  (quads through 0 cut from 0); of the three quads opposite, ``n`` have their diagonal
  through vertex 6. A rotation about the 0-6 axis brings the case to a canonical one,
  and the paper's table gives 5 tetrahedra (n = 0) or 6 (n = 1, 2, 3).

Every tetrahedron keeps the cell's orientation (positive volume for a convex, positively
oriented cell; negative for a mirrored one, which TetMesh accepts as well). Cells with a
collapsed face give zero-volume tetrahedra, which are kept; tetrahedra that repeat a
vertex *index* (cells written with duplicate indices, a common way to store a wedge as a
hexahedron) have no volume and no valid connectivity, and are dropped.

:func:`grid_to_tets` turns a structured :class:`dvr_gl.Volume` into the conforming
TetMesh of the same samples (6 tetrahedra per grid cell around the main diagonal, Kuhn's
triangulation), so a field can be rendered as a grid and as its tetrahedralisation.
"""

from __future__ import annotations

import itertools

import numpy as np

__all__ = ["split_pyramids", "split_wedges", "split_hexahedra", "split_cells", "grid_to_tets",
           "CELL_VERTEX_COUNT", "REFERENCE_CELLS"]

#: vertices per cell type (meshio's names)
CELL_VERTEX_COUNT = {"tetra": 4, "pyramid": 5, "wedge": 6, "hexahedron": 8}

#: VTK's parametric corner positions: the positively oriented cell of each type.
REFERENCE_CELLS = {
    "tetra": np.array([(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)], float),
    "pyramid": np.array([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1)], float),
    "wedge": np.array([(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (0, 1, 1)], float),
    "hexahedron": np.array([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0),
                            (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)], float),
}

# -- templates (local vertex numbers of the canonical cell) ---------------------------

# Pyramid: base diagonal 0-2 or 1-3.
_PYRAMID_02 = np.array([(0, 1, 2, 4), (0, 2, 3, 4)])
_PYRAMID_13 = np.array([(0, 1, 3, 4), (1, 2, 3, 4)])

# Wedge with its smallest vertex at 0; the quad 1-2-5-4 cut along 1-5 or 2-4.
_WEDGE_15 = np.array([(0, 1, 2, 5), (0, 1, 5, 4), (0, 4, 5, 3)])
_WEDGE_24 = np.array([(0, 1, 2, 4), (0, 4, 2, 5), (0, 4, 5, 3)])
# Orientation-preserving relabellings: row k puts old vertex k at position 0.
_WEDGE_SYMMETRY = np.array([(0, 1, 2, 3, 4, 5), (1, 2, 0, 4, 5, 3), (2, 0, 1, 5, 3, 4),
                            (3, 5, 4, 0, 2, 1), (4, 3, 5, 1, 0, 2), (5, 4, 3, 2, 1, 0)])

# Hexahedron with its smallest vertex at 0. The quads opposite 0 are A = 1-2-6-5 (x = 1),
# B = 2-3-7-6 (y = 1) and C = 4-5-6-7 (z = 1); n of them have their diagonal through 6.
# Canonical cases: n = 1 with A's diagonal through 6, n = 2 with A's not.
_HEX_BY_N = {
    0: np.array([(0, 1, 2, 5), (0, 2, 3, 7), (0, 5, 7, 4), (2, 7, 5, 6), (0, 2, 7, 5)]),
    1: np.array([(0, 5, 7, 4), (0, 1, 7, 5), (1, 6, 7, 5), (0, 7, 2, 3), (0, 7, 1, 2), (1, 7, 6, 2)]),
    2: np.array([(0, 4, 5, 6), (0, 3, 7, 6), (0, 7, 4, 6), (0, 1, 2, 5), (0, 3, 6, 2), (0, 6, 5, 2)]),
    3: np.array([(0, 1, 2, 6), (0, 2, 3, 6), (0, 3, 7, 6), (0, 7, 4, 6), (0, 4, 5, 6), (0, 5, 1, 6)]),
}


def _hex_relabellings():
    """The 24 rotations of the cube as vertex relabellings ``p`` (new vertex j is old
    vertex ``p[j]``): for each old vertex k one that moves it to 0, and the two turns
    about the 0-6 diagonal."""
    corners = REFERENCE_CELLS["hexahedron"]
    index = {tuple(c): i for i, c in enumerate(corners.astype(int).tolist())}
    to_zero = {}
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1, -1), repeat=3):
            matrix = np.zeros((3, 3))
            matrix[range(3), perm] = signs
            if np.linalg.det(matrix) < 0:
                continue
            moved = np.rint((corners - 0.5) @ matrix.T + 0.5).astype(int)
            p = tuple(index[tuple(c)] for c in moved.tolist())
            to_zero.setdefault(p[0], p)
    by_vertex = np.array([to_zero[k] for k in range(8)])
    # turning (x, y, z) -> (z, x, y) puts old face B where A was; twice, old C.
    turns = []
    for shift in (1, 2):
        moved = np.roll(corners.astype(int), shift, axis=1)
        turns.append([index[tuple(c)] for c in moved.tolist()])
    return by_vertex, np.array([list(range(8))] + turns)


_HEX_TO_ZERO, _HEX_TURNS = _hex_relabellings()


def _relabel(cells, relabellings, choice):
    """``cells[i]`` relabelled by ``relabellings[choice[i]]``."""
    return np.take_along_axis(cells, relabellings[choice], axis=1)


def _check_cells(name, cells, width):
    arr = np.asarray(cells)
    if arr.dtype.kind not in "iu":
        raise TypeError(f"{name} must be integer indices, got dtype {arr.dtype}")
    if arr.ndim != 2 or arr.shape[1] != width:
        raise ValueError(f"{name} must have shape (M, {width}), got shape {arr.shape}")
    return arr.astype(np.int64, copy=False)


def _less(cells, a, b, c, d):
    """True where the diagonal a-b goes through the face's smallest vertex (not c-d)."""
    return np.minimum(cells[:, a], cells[:, b]) < np.minimum(cells[:, c], cells[:, d])


def _apply(cells, template):
    """Tetrahedra (len(cells) * len(template), 4), cell by cell."""
    return cells[:, template].reshape(-1, 4)


def _drop_repeats(tets):
    s = np.sort(tets, axis=1)
    return tets[np.all(s[:, 1:] != s[:, :-1], axis=1)]


def split_pyramids(pyramids):
    """(M, 5) pyramids (VTK order: base 0-1-2-3, apex 4) -> (2M, 4) tetrahedra, minus any
    that repeat an index; the base is cut through its smallest vertex."""
    cells = _check_cells("pyramids", pyramids, 5)
    through_02 = _less(cells, 0, 2, 1, 3)
    tets = np.empty((len(cells), 2, 4), np.int64)
    tets[through_02] = cells[through_02][:, _PYRAMID_02]
    tets[~through_02] = cells[~through_02][:, _PYRAMID_13]
    return _drop_repeats(tets.reshape(-1, 4))


def split_wedges(wedges):
    """(M, 6) wedges (VTK order: triangles 0-1-2 and 3-4-5, edges 0-3, 1-4, 2-5) ->
    (3M, 4) tetrahedra, minus any that repeat an index."""
    cells = _check_cells("wedges", wedges, 6)
    cells = _relabel(cells, _WEDGE_SYMMETRY, np.argmin(cells, axis=1))
    through_15 = _less(cells, 1, 5, 2, 4)
    tets = np.empty((len(cells), 3, 4), np.int64)
    tets[through_15] = cells[through_15][:, _WEDGE_15]
    tets[~through_15] = cells[~through_15][:, _WEDGE_24]
    return _drop_repeats(tets.reshape(-1, 4))


def split_hexahedra(hexahedra):
    """(M, 8) hexahedra (VTK order: 0-1-2-3 and 4-5-6-7 above it) -> 5 or 6 tetrahedra
    each (Dompierre et al.'s cases), minus any that repeat an index."""
    cells = _check_cells("hexahedra", hexahedra, 8)
    cells = _relabel(cells, _HEX_TO_ZERO, np.argmin(cells, axis=1))
    via6 = np.stack([_less(cells, 1, 6, 2, 5),     # face A
                     _less(cells, 3, 6, 2, 7),     # face B
                     _less(cells, 4, 6, 5, 7)],    # face C
                    axis=1)
    n = via6.sum(axis=1)
    # n = 1: turn the face through 6 to A; n = 2: turn the face not through 6 to A.
    odd_face = np.where(n == 1, np.argmax(via6, axis=1), np.argmin(via6, axis=1))
    turn = np.where((n == 1) | (n == 2), odd_face, 0)
    cells = _relabel(cells, _HEX_TURNS, turn)
    parts = [_apply(cells[n == k], _HEX_BY_N[k]) for k in range(4)]
    order = np.argsort(np.concatenate([np.flatnonzero(n == k).repeat(len(_HEX_BY_N[k])) for k in range(4)]),
                       kind="stable")
    return _drop_repeats(np.concatenate(parts)[order])


_SPLITTERS = {"tetra": lambda cells: _drop_repeats(_check_cells("tetra", cells, 4)),
              "pyramid": split_pyramids, "wedge": split_wedges, "hexahedron": split_hexahedra}


def split_cells(blocks):
    """Tetrahedra of cell blocks ``[(type, (M, k) indices), ...]`` (types ``tetra``,
    ``pyramid``, ``wedge``, ``hexahedron``), concatenated in block order."""
    out = []
    for cell_type, cells in blocks:
        if cell_type not in _SPLITTERS:
            raise ValueError(f"cell type must be one of {', '.join(_SPLITTERS)}, got {cell_type!r}")
        out.append(_SPLITTERS[cell_type](cells))
    return np.concatenate(out) if out else np.zeros((0, 4), np.int64)


def grid_to_tets(volume):
    """The :class:`dvr_gl.TetMesh` of a structured volume: a point at every sample's
    world position with its value, each grid cell split into 6 tetrahedra around its
    diagonal from the (i, j, k) corner to the (i+1, j+1, k+1) one (Kuhn's triangulation,
    which is also what the hexahedron rule gives for lexicographic indices). The same
    diagonal in every cell makes it conforming. The mesh's linear field differs from the
    grid's trilinear one inside a cell, but both agree at the samples and on cell edges.
    A masked volume (``mask_nonfinite``) leaves out the cells outside its domain."""
    from .mesh import TetMesh
    from .volume import Volume

    if not isinstance(volume, Volume):
        raise TypeError(f"volume must be a dvr_gl.Volume, got {type(volume).__name__}")
    nz, ny, nx = volume.shape
    k, j, i = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    points = volume.origin + np.stack([i, j, k], axis=-1).reshape(-1, 3) * volume.spacing
    ids = np.arange(nz * ny * nx).reshape(nz, ny, nx)
    base = ids[:-1, :-1, :-1]
    offsets = REFERENCE_CELLS["hexahedron"].astype(np.int64)  # (x, y, z) per VTK corner
    corners = np.stack([base + dz * ny * nx + dy * nx + dx for dx, dy, dz in offsets.tolist()], axis=-1)
    if volume.cell_valid is not None:
        corners = corners[volume.cell_valid]
    tets = _apply(corners.reshape(-1, 8), _HEX_BY_N[3])
    return TetMesh(points, tets, volume.values(np.float64).reshape(-1))
