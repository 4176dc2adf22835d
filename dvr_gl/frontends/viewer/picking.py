"""Point picking: the point a user means by double-clicking a window point.

The ray under the cursor (:meth:`Orbit.ray <dvr_gl.frontends.viewer.orbit.Orbit.ray>`)
is sampled on the CPU (one ray is cheap) and one rule picks the point: the first crossing
of the iso value in isosurface mode, the maximum in mip, else where the accumulated
opacity reaches 0.5 (or the strongest contribution if it never does). Grids are sampled
trilinearly (:func:`pick_point`); a :class:`dvr_gl.TetMesh` is picked through its cells
themselves (:func:`pick_point_mesh`: the ray is intersected with every tetrahedron, the
piecewise-linear field is sampled inside the mesh only).
"""

from __future__ import annotations

import numpy as np

from ...model.mesh import TetMesh


def pick_point(volume, tf, mode, iso_value, origin, direction, samples=512, values=None):
    """The point a user means by clicking this ray: the first crossing of the iso value
    (isosurface mode), the maximum (mip), else where the accumulated opacity reaches 0.5
    (or the strongest contribution if it never does). None when the ray shows nothing.
    Trilinear samples from scipy, on the CPU: one ray is cheap. A :class:`TetMesh` is
    picked by :func:`pick_point_mesh` (``values``: its :func:`mesh_pick_data`)."""
    if isinstance(volume, TetMesh):
        return pick_point_mesh(volume, tf, mode, iso_value, origin, direction, samples, cells=values)
    from scipy.ndimage import map_coordinates

    span = _ray_box(*volume.bounds, origin, direction)
    if span is None:
        return None
    t0, t1 = span
    dt = (t1 - t0) / samples
    t = t0 + (np.arange(samples) + 0.5) * dt
    p = origin + t[:, None] * direction
    index = ((p - volume.origin) / volume.spacing).T[::-1]          # (z, y, x) rows
    if values is None:
        values = volume.values(np.float32)
    s = map_coordinates(values, index, order=1, mode="nearest")
    return _pick_along(p, s, dt, tf, mode, iso_value)


def _ray_box(lo, hi, origin, direction):
    """(t_enter, t_exit) of the ray in the box [lo, hi] (t_enter >= 0), or None."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t_a = (lo - origin) / direction
        t_b = (hi - origin) / direction
    t_near = np.where(np.isnan(t_a), -np.inf, np.minimum(t_a, t_b))
    t_far = np.where(np.isnan(t_b), np.inf, np.maximum(t_a, t_b))
    t0, t1 = max(float(np.max(t_near)), 0.0), float(np.min(t_far))
    return (t0, t1) if t1 > t0 else None


def _pick_along(p, s, dt, tf, mode, iso_value):
    """The picking rule of :func:`pick_point` on samples ``s`` at points ``p`` (in ray
    order, ``dt`` world units apart)."""
    if mode == "isosurface":
        inside = s >= iso_value
        hit = np.nonzero(inside != inside[0])[0]
        return p[hit[0]] if hit.size else None
    if mode == "mip":
        k = int(np.argmax(s))
        return p[k] if tf.opacity(s[k]) > 0 else None
    alpha = 1.0 - (1.0 - np.clip(tf.opacity(s), 0.0, 1.0)) ** (dt / tf.unit_distance)
    transmittance = np.concatenate([[1.0], np.cumprod(1.0 - alpha)[:-1]])
    reached = np.nonzero(1.0 - transmittance * (1.0 - alpha) >= 0.5)[0]
    if reached.size:
        return p[reached[0]]
    weight = alpha * transmittance
    k = int(np.argmax(weight))
    return p[k] if weight[k] > 1e-3 else None


def mesh_pick_data(mesh):
    """What picking on ``mesh`` needs, made once per mesh: for every cell of non-zero
    volume its first vertex, the inverse of its edge matrix (world point to barycentric
    coordinates) and its four vertex values."""
    tets = mesh.tets
    vol = np.abs(mesh.signed_volumes())
    ok = np.flatnonzero(vol > 1e-12 * max(float(np.max(vol, initial=0.0)), 1e-300))
    p = mesh.points[tets[ok]]                                     # (m, 4, 3)
    edges = np.transpose(p[:, 1:] - p[:, :1], (0, 2, 1))         # columns p1-p0, p2-p0, p3-p0
    return {"p0": p[:, 0], "inverse": np.linalg.inv(edges), "values": mesh.scalars[tets[ok]]}


def ray_cells(mesh, origin, direction, cells=None):
    """The cells the ray crosses, as ``(t_in, t_out, value_in, slope)`` arrays sorted by
    ``t_in`` (the ray is ``origin + t * direction``, ``t >= 0``; the field in a cell is
    ``value_in + slope * (t - t_in)``): each cell's barycentric coordinates are linear in
    t, and the ray is inside while all four are non-negative."""
    cells = cells if cells is not None else mesh_pick_data(mesh)
    inv = cells["inverse"]
    a = np.einsum("mij,mj->mi", inv, origin - cells["p0"])        # lambda_1..3 at t = 0
    b = np.einsum("mij,j->mi", inv, direction)                    # and their rates
    a = np.concatenate([1.0 - a.sum(axis=1, keepdims=True), a], axis=1)
    b = np.concatenate([-b.sum(axis=1, keepdims=True), b], axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        root = -a / b
    lower = np.where(b > 0, root, np.where((b == 0) & (a < 0), np.inf, -np.inf)).max(axis=1)
    upper = np.where(b < 0, root, np.inf).min(axis=1)
    t_in, t_out = np.maximum(lower, 0.0), upper
    hit = np.flatnonzero(t_out > t_in)
    order = hit[np.argsort(t_in[hit], kind="stable")]
    values = cells["values"][order]
    rate = (b[order] * values).sum(axis=1)
    start = (a[order] * values).sum(axis=1) + rate * t_in[order]
    return t_in[order], t_out[order], start, rate


def pick_point_mesh(mesh, tf, mode, iso_value, origin, direction, samples=512, cells=None):
    """:func:`pick_point` on a TetMesh: the ray is intersected with every cell
    (:func:`ray_cells`; non-convex meshes and gaps included), the linear field is sampled
    at ``samples`` points between where it first enters and last leaves the mesh, the
    samples outside every cell are dropped (they are empty space), and the grid's rule
    picks among the rest. None when the ray misses the mesh or shows nothing."""
    origin, direction = np.asarray(origin, np.float64), np.asarray(direction, np.float64)
    if _ray_box(*mesh.bounds, origin, direction) is None:
        return None
    t_in, t_out, start, rate = ray_cells(mesh, origin, direction, cells)
    if t_in.size == 0:
        return None
    t0, t1 = float(t_in[0]), float(t_out.max())
    dt = (t1 - t0) / samples
    t = t0 + (np.arange(samples) + 0.5) * dt
    k = np.searchsorted(t_in, t, side="right") - 1
    inside = (k >= 0) & (t <= t_out[np.maximum(k, 0)] + 1e-9 * (t1 - t0))
    if not inside.any():
        return None
    t, k = t[inside], k[inside]
    s = start[k] + rate[k] * (t - t_in[k])
    return _pick_along(origin + t[:, None] * direction, s, dt, tf, mode, iso_value)


def pick_data(volume):
    """What picking on ``volume`` samples, made once per data set (the viewer keeps it):
    a grid's float32 values, or a mesh's :func:`mesh_pick_data`."""
    return mesh_pick_data(volume) if isinstance(volume, TetMesh) else volume.values(np.float32)
