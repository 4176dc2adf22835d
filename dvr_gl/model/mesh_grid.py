"""A tetrahedral mesh's field resampled once onto a regular grid.

:func:`resample_to_grid` gives each sample of a grid over the mesh's bounding box the
value of the linear field of the tetrahedron that contains it, and NaN where no
tetrahedron does (outside the domain: a non-convex mesh's gaps and hollows, the corners
of a ball's box). The :class:`dvr_gl.Volume` it returns masks those samples
(``mask_nonfinite=True``), so the ray caster renders the same field at the samples; in
between it is trilinear instead of linear, and a grid cell with a corner outside the
domain is dropped, so near the boundary the grid's domain is up to a cell smaller than
the mesh's. How much that changes an image is measured, never assumed
(``dvr_gl.rendering.mesh_tolerance``).

Samples are located by the mesh's own cells, not by a Delaunay search (which only holds
for a Delaunay mesh of its points): every tetrahedron visits the grid columns (x, y)
within its bounding box (along the axis that makes the fewest columns), cuts each
column with its four face planes, each moved out by
``INSIDE_EPS`` times the mesh's diagonal (a sample on a shared face is kept by either
cell, both giving the same value: the field is continuous), and sets the samples of
that z interval from its linear field. The work is vectorised in chunks of at most
``CHUNK_PAIRS`` (cell, column) pairs and costs in proportion to the columns the cells'
boxes cover plus the samples, not the samples in every box.
"""

from __future__ import annotations

import numpy as np

from .mesh import TetMesh, topology
from .volume import Volume

INSIDE_EPS = 1e-9          # slack of the face planes (times the diagonal): samples on a face are inside
CHUNK_PAIRS = 1 << 20      # (cell, grid column) pairs handled at once


def check_shape(shape):
    """(nz, ny, nx) of ints >= 2, or an error naming ``shape``."""
    try:
        dims = tuple(shape)
    except TypeError:
        raise TypeError(f"shape must be three sample counts (nz, ny, nx), got {shape!r}") from None
    if len(dims) != 3 or any(isinstance(n, bool) or not isinstance(n, (int, np.integer)) for n in dims):
        raise TypeError(f"shape must be three integer sample counts (nz, ny, nx), got {shape!r}")
    if min(dims) < 2:
        raise ValueError(f"shape must have at least 2 samples on every axis, got {shape!r}")
    return tuple(int(n) for n in dims)


def grid_shape(mesh, samples):
    """(nz, ny, nx) for a grid over ``mesh``'s bounding box with ``samples`` samples along
    its longest side and about the same spacing along the others (2 at least)."""
    if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or samples < 2:
        raise ValueError(f"samples must be an integer >= 2 (along the longest side), got {samples!r}")
    extent = np.asarray(mesh.extent, np.float64)
    h = float(extent.max()) / (samples - 1)
    nx, ny, nz = (max(2, int(round(e / h)) + 1) for e in extent)
    return nz, ny, nx


def grid_geometry(mesh, shape):
    """(origin, spacing) (x, y, z) of the grid of ``shape`` over ``mesh``'s bounding box:
    its first and last samples on the box's faces."""
    lo, hi = mesh.bounds
    counts = np.array(shape[::-1], np.float64)
    extent = hi - lo
    spacing = np.where(extent > 0, extent / (counts - 1), 1.0)
    return lo.astype(np.float64), spacing


def sample_values(mesh, shape):
    """(nz, ny, nx) float64: the mesh's linear field at the samples of the grid of
    ``shape`` (``grid_geometry``), NaN outside every tetrahedron."""
    shape = check_shape(shape)
    origin, spacing = grid_geometry(mesh, shape)
    counts = np.array(shape[::-1], np.int64)                     # x, y, z
    values = np.full(shape, np.nan)
    topo = topology(mesh)
    cells = np.flatnonzero(~topo.flat)                           # zero-volume cells hold no sample
    if cells.size == 0:
        return values
    tets = topo.tets[cells]
    p = mesh.points[tets] - origin                               # (K, 4, 3), the grid's origin at 0
    s = mesh.scalars[tets]                                       # (K, 4)
    # the sample index range of each cell's bounding box (a hair wider: samples on a face)
    first = np.maximum(np.ceil(p.min(axis=1) / spacing - 1e-9).astype(np.int64), 0)
    last = np.minimum(np.floor(p.max(axis=1) / spacing + 1e-9).astype(np.int64), counts - 1)
    box = np.maximum(last - first + 1, 0)                        # (K, 3)
    keep = box.min(axis=1) > 0
    cells, p, s, first, last, box = (a[keep] for a in (cells, p, s, first, last, box))
    planes = topo.cell_planes()[cells]                           # outward unit normals, offsets
    planes[..., 3] += INSIDE_EPS * float(np.linalg.norm(mesh.extent))   # samples on a face are inside
    # the cell's linear field: s0 + g . (x - p0), g = inverse(E)^T (s1 - s0, s2 - s0, s3 - s0),
    # E's columns the edges from p0
    inverse = np.linalg.inv(np.transpose(p[:, 1:] - p[:, :1], (0, 2, 1)))
    gradient = np.einsum("kji,kj->ki", inverse, s[:, 1:] - s[:, :1])
    # columns along the axis that makes the fewest (cell, column) pairs: below, axes are
    # renamed so that the columns run along the third ("z")
    volume = box.prod(axis=1).astype(np.float64)
    along = int(np.argmin([(volume / box[:, c]).sum() for c in range(3)]))
    order = [c for c in range(3) if c != along] + [along]
    strides = np.array([1, counts[0], counts[0] * counts[1]], np.int64)[order]
    p, spacing, first, last, box, gradient = (p[..., order], spacing[order], first[:, order], last[:, order],
                                              box[:, order], gradient[:, order])
    planes = planes[..., order + [3]]
    face_planes = [[np.ascontiguousarray(planes[:, f, i]) for i in range(4)] for f in range(4)]
    columns = box[:, 0] * box[:, 1]
    flat_values = values.reshape(-1)
    ends = np.cumsum(columns)
    start = 0
    while start < len(columns):
        base = ends[start - 1] if start else 0
        stop = max(int(np.searchsorted(ends, base + CHUNK_PAIRS, side="right")), start + 1)
        n = columns[start:stop]
        cell = np.repeat(np.arange(start, stop), n)
        k = np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)   # the column within the cell's box
        ix, iy = first[cell, 0] + k % box[cell, 0], first[cell, 1] + k // box[cell, 0]
        x, y = ix * spacing[0], iy * spacing[1]
        # the column's z interval inside the cell's four planes n . x <= d
        top, bottom = np.full(len(cell), np.inf), np.full(len(cell), -np.inf)
        missed = np.zeros(len(cell), bool)
        for na, nb, nz, d in face_planes:
            nz = nz[cell]
            rhs = d[cell] - na[cell] * x - nb[cell] * y
            with np.errstate(divide="ignore", invalid="ignore"):
                bound = rhs / nz
            top = np.where(nz > 0, np.minimum(top, bound), top)
            bottom = np.where(nz < 0, np.maximum(bottom, bound), bottom)
            missed |= (nz == 0) & (rhs < 0)
        with np.errstate(invalid="ignore"):
            z0 = np.maximum(np.ceil(bottom / spacing[2]), first[cell, 2])
            z1 = np.minimum(np.floor(top / spacing[2]), last[cell, 2])
        m = np.where(missed | ~(z1 >= z0), 0, z1 - z0 + 1).astype(np.int64)
        # along the column the field is a + gz z
        g, p0 = gradient[cell], p[cell, 0]
        a = s[cell, 0] + g[:, 0] * (x - p0[:, 0]) + g[:, 1] * (y - p0[:, 1]) - g[:, 2] * p0[:, 2]
        column = np.repeat(np.arange(len(m)), m)
        iz = z0.astype(np.int64)[column] + np.arange(len(column)) - np.repeat(np.cumsum(m) - m, m)
        flat = iz * strides[2] + iy[column] * strides[1] + ix[column] * strides[0]
        flat_values[flat] = a[column] + g[column, 2] * (iz * spacing[2])
        start = stop
    return values


def resample_to_grid(mesh, shape):
    """The :class:`dvr_gl.Volume` (float32, ``mask_nonfinite=True``) of ``mesh``'s field at
    the samples of a grid of ``shape`` (nz, ny, nx) over its bounding box, the first and
    last samples on the box's faces (``grid_geometry``); samples outside the domain are
    NaN, and the grid cells they touch lie outside the volume's domain."""
    if not isinstance(mesh, TetMesh):
        raise TypeError(f"mesh must be a dvr_gl.TetMesh, got {type(mesh).__name__}")
    shape = check_shape(shape)
    values = sample_values(mesh, shape)
    if not np.isfinite(values).any():
        raise ValueError(f"shape {shape} puts no sample inside the mesh's cells; use more samples")
    origin, spacing = grid_geometry(mesh, shape)
    return Volume(values.astype(np.float32), spacing=spacing, origin=origin, mask_nonfinite=True)
