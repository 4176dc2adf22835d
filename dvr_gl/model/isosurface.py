"""Isosurfaces as triangle meshes: the level set ``f = level`` of a volume or a mesh as a
:class:`~dvr_gl.model.geometry.Surface`, to place in a scene or to save
(:func:`dvr_gl.formats.save_surface`).

- :func:`marching_cubes`: a :class:`~dvr_gl.model.volume.Volume` through scikit-image's
  ``skimage.measure.marching_cubes`` (Lewiner et al.'s cases, which resolve the
  ambiguous faces and interior of a cell so that the surface has no holes). Its vertices
  lie on the grid's edges where the linear interpolation along the edge crosses the
  level. Needs scikit-image: ``pip install "dvr-gl[iso]"``.
- :func:`marching_tetrahedra`: a :class:`~dvr_gl.model.mesh.TetMesh`, dvr_gl's own. The
  field is linear in each tetrahedron, so its level set there is one flat polygon: a
  triangle when one vertex lies on the other side of the level from the other three, a
  quadrilateral (two triangles) when two do. Its corners are where the level crosses the
  cell's edges, found by linear interpolation: exact for the linear field.
- :func:`isosurface`: either, by the kind of data.

Conventions both keep:

- **Inside** is ``value >= level``: a sample (or mesh vertex) exactly at the level counts
  as inside, so neighbouring cells agree on every shared corner.
- **Orientation**: each triangle is wound so that its right-handed normal (``(b - a) x
  (c - a)`` for corners ``a, b, c``) points towards lower values, out of the region
  above the level. A closed surface around a maximum has outward normals (a positive
  enclosed volume by the divergence theorem); around a minimum, inward ones.
- **Shared vertices**: a corner where the level crosses an edge is one vertex for every
  cell that has that edge, so the surface is watertight wherever the data is
  (a conforming mesh; a grid everywhere inside its domain). It is open only where it
  meets the data's boundary or a masked region.
- **Masked data**: a grid cell with a non-finite corner (``Volume.cell_valid``) gives no
  triangles, as it is outside the domain the techniques render.
- A ``level`` outside the data's range is a ``ValueError`` naming it and the range; so is
  a level inside the range whose surface is empty (only masked cells cross it).
"""

from __future__ import annotations

import math
from numbers import Real

import numpy as np

from .geometry import Surface
from .mesh import TetMesh
from .volume import Volume

__all__ = ["marching_cubes", "marching_tetrahedra", "isosurface", "DEFAULT_COLOR"]

#: the colour a surface gets unless told (Surface's own default)
DEFAULT_COLOR = (0.85, 0.85, 0.85)

_SKIMAGE_MISSING = ("marching_cubes needs scikit-image (skimage.measure.marching_cubes): "
                    "pip install \"dvr-gl[iso]\" (or pip install scikit-image)")


def isosurface(data, level, color=DEFAULT_COLOR) -> Surface:
    """The level set of ``data`` at ``level``: :func:`marching_cubes` for a Volume,
    :func:`marching_tetrahedra` for a TetMesh."""
    if isinstance(data, Volume):
        return marching_cubes(data, level, color=color)
    if isinstance(data, TetMesh):
        return marching_tetrahedra(data, level, color=color)
    raise TypeError(f"data must be a dvr_gl.Volume or a dvr_gl.TetMesh, got {type(data).__name__}")


def _level(level, data_range):
    """``level`` as a float inside ``data_range``, or an error naming it."""
    if isinstance(level, bool) or not isinstance(level, (Real, np.integer, np.floating)):
        raise TypeError(f"level must be a number, got {level!r}")
    value = float(level)
    if not math.isfinite(value):
        raise ValueError(f"level must be finite, got {level!r}")
    lo, hi = data_range
    if not lo <= value <= hi:
        raise ValueError(f"level {value:g} is outside the data's range {lo:g}..{hi:g}: there is no surface")
    return value


def _empty(level, why):
    return ValueError(f"level {level:g} gives no surface: {why}")


# ----------------------------------------------------------------------------- grids

def marching_cubes(volume, level, color=DEFAULT_COLOR) -> Surface:
    """The isosurface of a :class:`Volume` at ``level``, in world units, by scikit-image's
    marching cubes (Lewiner et al.), as a :class:`Surface` of colour ``color``.

    The samples (nz, ny, nx) are at ``origin + (i, j, k) * spacing`` for index ``i``
    along x, ``j`` along y, ``k`` along z; vertices are where the level crosses a grid
    edge, interpolated linearly along it. Inside is ``value >= level`` (as in
    :func:`marching_tetrahedra`); normals point towards lower values. Cells with a
    non-finite corner (``volume.cell_valid``) give no triangles.

    The level is subtracted from the samples in float64 before scikit-image sees them
    (it works in float32): no sample changes side because of the conversion. The
    vertices come back in float32 index coordinates (good to about 1e-7 of the grid's
    size) and are placed in the world in float64.
    """
    if not isinstance(volume, Volume):
        raise TypeError(f"volume must be a dvr_gl.Volume, got {type(volume).__name__}")
    level = _level(level, volume.data_range)
    try:
        from skimage.measure import marching_cubes as _skimage_marching_cubes
    except ImportError:
        raise ImportError(_SKIMAGE_MISSING) from None

    # Shifted so that the level is 0, in float64, then to float32 for skimage with every
    # sample kept on its side: skimage counts a corner as above the level only where its
    # value is strictly greater, so a difference that is zero in float32 (a sample at the
    # level, or one too close to it for float32) becomes the smallest float32 of its
    # sign, a sample at the level the positive one: inside, as everywhere in dvr_gl.
    difference = volume.data.astype(np.float64) - level
    if volume.has_nonfinite:
        # any finite value will do: every cell with such a corner is dropped below
        difference[~np.isfinite(difference)] = -1.0
    limit = np.finfo(np.float32)
    shifted = np.clip(difference, -limit.max, limit.max).astype(np.float32)
    zero = shifted == 0
    shifted[zero] = np.where(difference[zero] < 0, -limit.tiny, limit.tiny)
    if not (shifted.min() < 0 < shifted.max()):
        raise _empty(level, "no sample lies on each side of it (inside is value >= level)")
    try:
        verts, faces, _, _ = _skimage_marching_cubes(shifted, 0.0, gradient_direction="descent",
                                                     allow_degenerate=False)
    except RuntimeError as e:          # skimage: "No surface found at the given iso value."
        raise _empty(level, str(e)) from None
    # skimage's vertices are fractional indices (k, j, i); reversed to (i, j, k), that is
    # x, y, z, its "descent" winding has right-handed normals pointing down the field
    # (tests/test_isosurface.py checks it)
    index = np.asarray(verts, np.float64)[:, ::-1]
    faces = np.asarray(faces, np.int64)
    if volume.cell_valid is not None:
        faces = faces[_in_valid_cells(index, faces, volume.cell_valid)]
    index, faces = _compact(index, faces)
    if len(faces) == 0:
        raise _empty(level, "every cell it crosses has a non-finite corner")
    return Surface(volume.origin + index * volume.spacing, faces, color)


def _in_valid_cells(index_points, faces, cell_valid):
    """(m,) bool: whether each triangle (its corners in fractional index coordinates
    x, y, z) lies in a valid cell. A triangle from marching cubes lies in one cell, so its
    corners' bounding box spans one cell on each axis, or none where it lies in a face
    between two cells (then either of them may have made it, and it is kept if one of
    them is valid)."""
    t = index_points[faces]                          # (m, 3 corners, 3 axes)
    lo = np.floor(t.min(axis=1) + 1e-9)             # (m, 3): the lower cell index per axis
    hi = np.ceil(t.max(axis=1) - 1e-9)
    flat = hi <= lo                                  # in a face plane on that axis
    limit = np.array(cell_valid.shape[::-1]) - 1     # the largest cell index per axis, x, y, z
    first = np.clip(np.where(flat, lo - 1, lo), 0, limit).astype(np.int64)
    second = np.clip(lo, 0, limit).astype(np.int64)
    keep = np.zeros(len(faces), bool)
    for cx in (first[:, 0], second[:, 0]):
        for cy in (first[:, 1], second[:, 1]):
            for cz in (first[:, 2], second[:, 2]):
                keep |= cell_valid[cz, cy, cx]
    return keep


def _compact(verts, faces):
    """Only the vertices the faces use, renumbered."""
    used, inverse = np.unique(faces.reshape(-1), return_inverse=True)
    return verts[used], inverse.reshape(-1, 3).astype(np.int64)


# ----------------------------------------------------------------------------- meshes

#: a tetrahedron's six edges, as pairs of local vertex indices
TET_EDGES = np.array([(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)], np.int64)


def _case_table():
    """(16, 2, 3) local edge indices of the (up to) two triangles for each case, -1 where
    there is none. The case is the bit set of the vertices inside (bit i: vertex i)."""
    edge_of = {tuple(e): i for i, e in enumerate(TET_EDGES.tolist())}

    def edge(a, b):
        return edge_of[(min(a, b), max(a, b))]

    table = np.full((16, 2, 3), -1, np.int64)
    for case in range(16):
        inside = [v for v in range(4) if case >> v & 1]
        outside = [v for v in range(4) if not case >> v & 1]
        if len(inside) in (1, 3):
            lone, rest = (inside[0], outside) if len(inside) == 1 else (outside[0], inside)
            table[case, 0] = [edge(lone, r) for r in rest]
        elif len(inside) == 2:
            (a, b), (c, d) = inside, outside
            quad = [edge(a, c), edge(a, d), edge(b, d), edge(b, c)]    # around the quadrilateral
            table[case, 0] = [quad[0], quad[1], quad[2]]
            table[case, 1] = [quad[0], quad[2], quad[3]]
    return table


_CASES = _case_table()


def marching_tetrahedra(mesh, level, color=DEFAULT_COLOR) -> Surface:
    """The isosurface of a :class:`TetMesh` at ``level`` as a :class:`Surface` of colour
    ``color``: per cell the flat polygon where its linear field equals the level (a
    triangle, or a quadrilateral split into two triangles), vectorised over all cells.

    A vertex is where the level crosses a mesh edge, ``p = a + t (b - a)`` with ``t =
    (level - f(a)) / (f(b) - f(a))``, computed once per edge (its endpoints in index
    order), so the cells around an edge share that vertex exactly: on a conforming mesh
    the surface is closed wherever it does not reach the mesh's boundary, each of its
    edges shared by two triangles. Inside is ``value >= level``; a level equal to vertex
    values gives zero-area triangles at those vertices, which are kept so that the
    surface stays closed as a mesh. Normals point towards lower values.
    """
    if not isinstance(mesh, TetMesh):
        raise TypeError(f"mesh must be a dvr_gl.TetMesh, got {type(mesh).__name__}")
    level = _level(level, mesh.data_range)
    points, tets, scalars = mesh.points, mesh.tets, mesh.scalars
    inside = scalars >= level
    case = (inside[tets] * np.array([1, 2, 4, 8])).sum(axis=1)
    cut = (case != 0) & (case != 15)
    tets, case = tets[cut], case[cut]
    if len(tets) == 0:
        raise _empty(level, "no cell has vertices on both sides of it (inside is value >= level)")

    # the triangles, as local edge indices, and the cell each comes from
    tri_cells, tri_edges = [], []
    for slot in (0, 1):
        edges = _CASES[case, slot]                       # (n, 3)
        has = edges[:, 0] >= 0
        tri_cells.append(np.flatnonzero(has))
        tri_edges.append(edges[has])
    cells = np.concatenate(tri_cells)
    local = np.concatenate(tri_edges)                    # (m, 3) local edge indices
    ends = tets[cells[:, None, None], TET_EDGES[local]]  # (m, 3, 2) global vertex indices
    lo, hi = ends.min(axis=-1), ends.max(axis=-1)
    n = np.int64(len(points))
    keys, corner = np.unique(lo * n + hi, return_inverse=True)
    corner = corner.reshape(-1, 3).astype(np.int64)
    a, b = keys // n, keys % n                           # each crossed edge once, a < b
    fa, fb = scalars[a], scalars[b]
    t = (level - fa) / (fb - fa)                         # fa != fb: one is inside, one is not
    verts = points[a] + t[:, None] * (points[b] - points[a])

    # wind every triangle so that its normal points from the inside vertices of its cell
    # towards the outside ones: down the field (the level plane separates them strictly)
    p = verts[corner]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    cell_points = points[tets[cells]]                    # (m, 4, 3)
    w_in = inside[tets[cells]].astype(np.float64)
    mean_in = (cell_points * w_in[..., None]).sum(axis=1) / w_in.sum(axis=1)[:, None]
    mean_out = (cell_points * (1 - w_in)[..., None]).sum(axis=1) / (1 - w_in).sum(axis=1)[:, None]
    flip = np.einsum("ij,ij->i", normal, mean_in - mean_out) > 0
    corner[flip] = corner[flip][:, ::-1]
    return Surface(verts, corner, color)
