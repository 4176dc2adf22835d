"""The scalar field between its samples, in NumPy (float64): world points to sample
indices, trilinear interpolation with clamp-to-edge, the cells a mask leaves valid, and
the field's gradients (contract section 6). The techniques, their NumPy twins and the
exact integrator all read the field through these functions, so that none of them
depends on another (GLSL twins: shaders/common/sampling.glsl and shading.glsl)."""

from __future__ import annotations

import numpy as np


def world_to_index(volume, points):
    """World points (..., 3) to continuous sample indices (..., 3) in x, y, z order."""
    return (np.asarray(points, np.float64) - volume.origin) / volume.spacing


def trilinear(values, idx):
    """Trilinear interpolation of ``values`` (nz, ny, nx) at continuous indices ``idx``
    (..., 3) in x, y, z order, clamped to the domain (clamp-to-edge sampling)."""
    nz, ny, nx = values.shape
    upper = np.array([nx - 1, ny - 1, nz - 1], dtype=np.float64)
    p = np.clip(idx, 0.0, upper)
    i0 = np.minimum(np.floor(p).astype(np.int64), (upper - 1).astype(np.int64))
    f = p - i0
    x0, y0, z0 = i0[..., 0], i0[..., 1], i0[..., 2]
    fx, fy, fz = f[..., 0], f[..., 1], f[..., 2]
    v = values

    def lerp(a, b, t):
        # exact where a == b: a plateau samples to its value, not a value 1 ulp off
        # (a Sabella peak search took a random sample of a plateau for its first)
        return a + (b - a) * t

    c00 = lerp(v[z0, y0, x0], v[z0, y0, x0 + 1], fx)
    c10 = lerp(v[z0, y0 + 1, x0], v[z0, y0 + 1, x0 + 1], fx)
    c01 = lerp(v[z0 + 1, y0, x0], v[z0 + 1, y0, x0 + 1], fx)
    c11 = lerp(v[z0 + 1, y0 + 1, x0], v[z0 + 1, y0 + 1, x0 + 1], fx)
    return lerp(lerp(c00, c10, fy), lerp(c01, c11, fy), fz)


def cell_is_valid(volume, idx):
    """True where the point (continuous indices) lies in a cell whose corners are all
    finite; always True for volumes without masking."""
    if volume.cell_valid is None:
        return np.ones(np.shape(idx)[:-1], dtype=bool)
    nz, ny, nx = volume.shape
    upper = np.array([nx - 2, ny - 2, nz - 2])
    c = np.clip(np.floor(idx).astype(np.int64), 0, upper)
    return volume.cell_valid[c[..., 2], c[..., 1], c[..., 0]]


def gradient(volume, values, points):
    """Central differences of the trilinear field one spacing apart per axis, in world
    units; sample points outside the domain are clamped to it (as clamp-to-edge
    texture sampling does) and the divisor stays 2 * spacing. points: (..., 3) world."""
    idx = world_to_index(volume, points)
    g = np.empty(idx.shape, np.float64)
    for axis in range(3):
        h = np.zeros(3)
        h[axis] = 1.0
        g[..., axis] = (trilinear(values, idx + h) - trilinear(values, idx - h)) / (2 * volume.spacing[axis])
    return g


def sample_gradients(volume, values, at=None):
    """The gradient at every sample, (nz, ny, nx, 3) in x, y, z order: what the
    ``gradients="texture"`` option uploads; with ``at`` ((N, 3) integer sample indices,
    x, y, z), only at those samples, (N, 3).

    Its trilinear interpolant equals ``gradient`` everywhere, not only at samples: along
    x, f(p + sx) - f(p - sx) interpolates the differences v[i+1] - v[i-1] and v[i+2] - v[i]
    of the two samples around p with the same weights as f itself, and at the edges the
    clamped points read the edge sample, as ``v[-1] -> v[0]`` does here."""
    if at is not None:
        at = np.asarray(at, np.int64)
        g = np.empty(at.shape, np.float64)
        upper = np.array(values.shape[::-1]) - 1          # x, y, z
        for axis in range(3):
            ahead, behind = at.copy(), at.copy()
            ahead[:, axis] = np.minimum(at[:, axis] + 1, upper[axis])
            behind[:, axis] = np.maximum(at[:, axis] - 1, 0)
            g[:, axis] = (values[ahead[:, 2], ahead[:, 1], ahead[:, 0]]
                          - values[behind[:, 2], behind[:, 1], behind[:, 0]]) / (2 * volume.spacing[axis])
        return g
    g = np.empty(values.shape + (3,), np.float64)
    for axis in range(3):
        array_axis = 2 - axis                   # values are (z, y, x)
        n = values.shape[array_axis]
        ahead = np.take(values, np.minimum(np.arange(n) + 1, n - 1), axis=array_axis)
        behind = np.take(values, np.maximum(np.arange(n) - 1, 0), axis=array_axis)
        g[..., axis] = (ahead - behind) / (2 * volume.spacing[axis])
    return g


def gradient_epsilon(volume):
    """``|g|`` at or below this is 'below a small threshold' (contract section 6):
    1e-6 * (data range) / (min spacing). A constant volume has no range; there the scale
    is the values' magnitude instead, so that the rounding of interpolating equal values
    (about 1e-16 of them) stays unlit rather than picking a random normal. A TetMesh (whose
    cells carry their own linear gradients) uses its median edge length for the spacing."""
    lo, hi = volume.data_range
    scale = hi - lo if hi > lo else max(abs(lo), abs(hi))
    length = volume.cell_size if hasattr(volume, "cell_size") else volume.min_spacing
    return 1e-6 * scale / length


def point_gradients(data, points, cells=None, vertices=None):
    """(N, 3) float64 gradients at ``points`` relative to the data's lower corner (the
    point primitives' centres): a grid's contract gradient there; on a mesh, the gradient
    of each point's cell (``cells``, constant in a linear cell) or, for points that are
    the mesh's ``vertices``, the volume-weighted mean of the gradients of the cells that
    meet there."""
    points = np.asarray(points, np.float64)
    if not hasattr(data, "tets"):
        return gradient(data, data.values(np.float64), points + data.bounds[0])
    from .mesh import cell_fields
    g = cell_fields(data)[:, 0, :3].astype(np.float64)
    if cells is not None:
        return g[np.asarray(cells)]
    volume = np.abs(data.signed_volumes())
    total = np.bincount(data.tets.ravel(), np.repeat(volume, 4), minlength=data.n_points)
    out = np.stack([np.bincount(data.tets.ravel(), np.repeat(volume * g[:, a], 4), minlength=data.n_points)
                    for a in range(3)], axis=1)
    return (out / np.where(total > 0, total, 1.0)[:, None])[np.asarray(vertices)]


def gradient_max(volume, values=None):
    """The largest ``|g|`` anywhere in the box: the gradient interpolates the samples'
    gradients, and a norm of a convex combination is at most the largest norm. A
    TetMesh: its cells' largest (constant) gradient."""
    if hasattr(volume, "tets"):
        from .mesh import cell_fields
        return float(np.linalg.norm(cell_fields(volume)[:, 0, :3], axis=-1).max())
    values = volume.values(np.float64) if values is None else values
    return float(np.linalg.norm(sample_gradients(volume, values), axis=-1).max())


def depth_range(scene):
    """Nearest and farthest depth (along the view direction, from the eye) of the box,
    the nearest at least 0: where depth cueing runs from 1 to 1 - strength."""
    cam = scene.camera
    lo, hi = scene.volume.bounds
    corners = np.array([[x, y, z] for z in (lo[2], hi[2]) for y in (lo[1], hi[1]) for x in (lo[0], hi[0])])
    depth = (corners - cam.eye) @ cam.forward
    near = max(float(depth.min()), 0.0)
    return near, max(float(depth.max()), near + 1e-30)


def ray_box(origins, dirs, lo, hi, inside=None):
    """Entry and exit distances of rays against the box [lo, hi] (GLSL ``intersectBox``).

    Rays start at their origin: the entry is clamped to 0. A ray parallel to a pair of
    faces is inside the slab iff its origin is (the 0 * inf case is resolved as such;
    ``inside``, per ray and axis, when given, says so instead: ``box_rays`` decides it in
    world coordinates, where a ray in a face plane is exactly on it).
    Returns (t_enter, t_exit); the ray misses where t_exit <= t_enter.
    """
    o = np.asarray(origins, np.float64)
    d = np.asarray(dirs, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        ta = (lo - o) * inv
        tb = (hi - o) * inv
    tmin = np.minimum(ta, tb)
    tmax = np.maximum(ta, tb)
    parallel = d == 0
    if inside is None:
        inside = (o >= lo) & (o <= hi)
    tmin = np.where(parallel, np.where(inside, -np.inf, np.inf), tmin)
    tmax = np.where(parallel, np.where(inside, np.inf, -np.inf), tmax)
    t0 = np.maximum(tmin.max(axis=-1), 0.0)
    t1 = tmax.min(axis=-1)
    return t0, t1
