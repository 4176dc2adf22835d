"""Proxy polygons for 3D texture slicing with view-aligned planes.

About this geometry
-------------------
The volume box is cut by a family of parallel planes ``{x : dot(normal, x) = offset}``,
``normal`` the camera's unit forward direction. Each cut is a convex polygon of 3 to 6
vertices; the slices are drawn far to near and composited. Two ways to make them:

* on the CPU (:func:`plane_polygons`, vectorised over all planes, then
  :func:`fan_triangles` for a triangle list with a per-vertex slice index);
* in the vertex shader ``shaders/slice3d/proxy_vertex.vert`` from a fixed vertex count
  per slice, all slices in one instanced draw. This is the idea of Rezk-Salama and Kolb
  (2005): the box corner nearest the eye and the farthest one are joined by three
  disjoint paths of three edges; any plane between them meets each path exactly once,
  and between two neighbouring paths it may also meet one "cross" edge. So a polygon has
  six slots: path A, cross A-B, path B, cross B-C, path C, cross C-A, a cross slot
  repeating the path point before it when its edge is missed.
  :func:`vertex_path_tables` gives the shader its per-frame edge table;
  :func:`path_slots` is the shader's NumPy twin, :func:`polygons_by_paths` the same
  polygons in the layout of :func:`plane_polygons`.

Conventions
-----------
Coordinates are box-relative world units. The box's 8 corners are numbered
``i = x_bit + 2 * y_bit + 4 * z_bit`` (bit set: the upper bound on that axis), as
:func:`box_corners` makes them. Polygons are wound counter-clockwise as seen from the
eye, i.e. by a viewer looking along ``+normal``: the cross product of consecutive edges
points along ``-normal``. After any projection that keeps the eye in front, they are
front-facing under OpenGL's default ``GL_CCW`` rule.

Tolerance: :func:`box_tolerance` = ``1e-10 * (diagonal + largest |coordinate|)``, a
length. Where a plane meets an edge within that distance of one of its ends, the point
becomes that corner, so the (up to three) points a plane through a corner makes on the
corner's edges merge into one; and a vertex within that distance of the line through
its neighbours is dropped. Every polygon is then within about that distance of the
exact cut, up to rounding, with no duplicate or flat vertices and no zero-area slivers
from planes through corners, edges or faces. The distance is measured along the edges,
not from the plane: a plane nearly parallel to an edge may pass a corner closely yet
meet the edge far from it. The constant is far above float64 rounding and far below
any sensible box proportion (a box 2 samples thick in a 1000-sample volume is 2e-3 of
its diagonal).
"""

from __future__ import annotations

import math

import numpy as np

TOLERANCE = 1e-10

#: The 12 box edges as pairs of corner indices (lower index first): the 4 edges along x,
#: then along y, then along z.
EDGES = np.array([(i, i | bit) for bit in (1, 2, 4) for i in range(8) if not i & bit], np.int64)

#: Vertex slots of the 4 fan triangles over a 6-slot polygon, in drawing order.
FAN_SLOTS = np.array([0, 1, 2, 0, 2, 3, 0, 3, 4, 0, 4, 5], np.int64)


def box_corners(lo, hi):
    """The 8 corners of the box ``[lo, hi]`` as (8, 3) float64, corner ``i`` taking ``hi``
    on axis ``a`` when bit ``a`` of ``i`` is set."""
    lo = np.asarray(lo, np.float64).reshape(3)
    hi = np.asarray(hi, np.float64).reshape(3)
    bits = (np.arange(8)[:, None] >> np.arange(3)[None, :]) & 1
    return np.where(bits == 1, hi, lo)


def box_tolerance(corners):
    """The length below which two points, or a corner and a plane, count as coincident:
    ``TOLERANCE * (diagonal + largest |coordinate|)`` of the box."""
    corners = _corners(corners)
    diagonal = float(np.linalg.norm(corners.max(axis=0) - corners.min(axis=0)))
    return TOLERANCE * (diagonal + float(np.abs(corners).max()))


def _corners(corners):
    corners = np.asarray(corners, np.float64)
    if corners.shape != (8, 3):
        raise ValueError(f"corners must be (8, 3), got {corners.shape}")
    return corners


def _unit(normal):
    n = np.asarray(normal, np.float64).reshape(3)
    length = float(np.linalg.norm(n))
    if not math.isfinite(length) or length == 0:
        raise ValueError(f"normal must be a finite non-zero vector, got {normal!r}")
    return n / length


def _offsets(offsets):
    return np.atleast_1d(np.asarray(offsets, np.float64)).reshape(-1)


def plane_basis(normal):
    """Unit vectors ``u, v`` spanning the planes, with ``u x v = -normal``: the angle
    from ``u`` towards ``v`` grows counter-clockwise as seen from the eye."""
    n = _unit(normal)
    helper = np.zeros(3)
    helper[int(np.argmin(np.abs(n)))] = 1.0
    u = np.cross(n, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(u, n)


# -- the CPU path ------------------------------------------------------------------------

def plane_polygons(corners, normal, offsets):
    """Cut the box by every plane ``dot(normal, x) = offsets[k]``.

    Returns ``vertices`` (K, 6, 3) float64 and ``counts`` (K,) int64: polygon k is
    ``vertices[k, :counts[k]]``, counter-clockwise seen from the eye, the unused slots
    repeating its last vertex. ``counts[k]`` is 3 to 6, or 0 where the plane misses the
    box or only touches it in a corner or along an edge (within the tolerance; the slots
    then hold what points there are, padded, or zeros). A plane lying on a face gives
    that face. Vertices are the corners on the plane and the points where it crosses
    edges, merged and cleaned up as the module's note on tolerance says, sorted by angle
    around their centroid.
    """
    corners = _corners(corners)
    n = _unit(normal)
    off = _offsets(offsets)
    k = off.size
    tol = box_tolerance(corners)

    # signed distance of every corner from every plane. No tolerance here: for a plane
    # nearly parallel to an edge, a tiny distance at one end still means a long way
    # along the edge; closeness is judged by distance along the edge, below.
    dist = (corners @ n)[None, :] - off[:, None]                    # (K, 8)
    sign = np.sign(dist)
    da, db = dist[:, EDGES[:, 0]], dist[:, EDGES[:, 1]]             # (K, 12)
    crossing = sign[:, EDGES[:, 0]] * sign[:, EDGES[:, 1]] < 0      # strictly inside the edge
    t = np.where(crossing, da / np.where(crossing, da - db, 1.0), 0.0)
    edge_points = corners[EDGES[:, 0]] * (1.0 - t[..., None]) + corners[EDGES[:, 1]] * t[..., None]

    # a crossing within tol of an end of its edge becomes that corner: this merges the
    # up to three points a plane through (or next to) a corner makes on its edges
    length = np.linalg.norm(corners[EDGES[:, 1]] - corners[EDGES[:, 0]], axis=1)   # (12,)
    at_a = crossing & (t * length <= tol)
    at_b = crossing & ~at_a & ((1.0 - t) * length <= tol)
    ends = np.arange(8)[None, :]
    merged = (at_a.astype(np.int64) @ (EDGES[:, 0, None] == ends)
              + at_b.astype(np.int64) @ (EDGES[:, 1, None] == ends)) > 0   # (K, 8)

    # candidates: corners on the plane or merged into, and the remaining crossings.
    # Any two are farther apart than tol (remaining crossings are farther than tol
    # from their edge's ends, and edges meet only at corners, at right angles).
    points = np.concatenate([np.broadcast_to(corners, (k, 8, 3)), edge_points], axis=1)
    valid = np.concatenate([(sign == 0) | merged, crossing & ~at_a & ~at_b], axis=1)   # (K, 20)
    found = valid.sum(axis=1)
    if np.any(found > 6):  # cannot happen for a box thicker than tol
        raise ValueError("the box is too thin for the intersection tolerance")

    centroid = (points * valid[..., None]).sum(axis=1) / np.maximum(found, 1)[:, None]
    u, v = plane_basis(n)
    rel = points - centroid[:, None, :]
    angle = np.where(valid, np.arctan2(rel @ v, rel @ u), np.inf)
    order = np.argsort(angle, axis=1, kind="stable")[:, :6]
    vertices = np.take_along_axis(points, order[..., None], axis=1)
    vertices[found == 0] = 0.0
    return _drop_flat(vertices, found, tol)


def _drop_flat(vertices, counts, tol):
    """Drop the vertices of ordered polygons that lie within ``tol`` of the line through
    their two neighbours (a plane hugging a box edge can leave such a point between two
    merged corners), pad, and give count 0 where fewer than 3 vertices remain or all of
    them are flat (a polygon thinner than ``tol``). Returns (vertices, counts).

    Of a run of neighbouring flat vertices only the first goes in one pass, then the
    rest are judged again: two close vertices at a real corner are each flat against
    the other, and dropping both would cut the corner off."""
    counts = counts.copy()
    for _ in range(vertices.shape[1]):
        flat, prev_flat = _flat_vertices(vertices, counts, tol)
        drop = flat & ~prev_flat
        if not drop.any():
            break
        keep = (np.arange(vertices.shape[1])[None, :] < counts[:, None]) & ~drop
        order = np.argsort(~keep, axis=1, kind="stable")             # kept first, in order
        counts = keep.sum(axis=1)
        vertices = np.take_along_axis(vertices, order[..., None], axis=1)
    flat, _ = _flat_vertices(vertices, counts, tol)
    used = np.arange(vertices.shape[1])[None, :] < counts[:, None]
    thin = np.all(flat | ~used, axis=1)
    return _pad(vertices, counts), np.where((counts >= 3) & ~thin, counts, 0)


def _flat_vertices(vertices, counts, tol):
    """Per slot: is the vertex within ``tol`` of its neighbours' chord (polygons of 3 or
    more vertices only), and is its predecessor."""
    slot = np.arange(vertices.shape[1])[None, :]
    m = np.maximum(counts, 1)[:, None]
    prev = np.take_along_axis(vertices, ((slot - 1) % m)[..., None], axis=1)
    nxt = np.take_along_axis(vertices, ((slot + 1) % m)[..., None], axis=1)
    chord = nxt - prev
    height = np.linalg.norm(np.cross(chord, vertices - prev), axis=-1)
    flat = (height <= tol * np.linalg.norm(chord, axis=-1)) & (slot < counts[:, None]) & (counts[:, None] >= 3)
    prev_flat = np.take_along_axis(flat, (slot - 1) % m, axis=1)
    return flat, prev_flat


def _pad(vertices, counts):
    """A copy of ``vertices`` with vertex ``counts - 1`` repeated in the slots after it."""
    last = np.maximum(counts - 1, 0)
    slot = np.arange(vertices.shape[1])[None, :]
    index = np.minimum(slot, last[:, None])
    return np.take_along_axis(vertices, index[..., None], axis=1)


def fan_triangles(vertices, counts):
    """Triangle list of the polygons, slice by slice in the given order: a fan from vertex
    0, ``count - 2`` triangles per polygon. Returns positions (T*3, 3) float32 and each
    vertex's slice index (T*3,) int32 (an integer vertex attribute)."""
    vertices = np.asarray(vertices, np.float64)
    counts = np.asarray(counts).reshape(-1)
    fan = FAN_SLOTS.reshape(4, 3)
    keep = np.arange(4)[None, :] < (counts - 2)[:, None]            # (K, 4) triangle used
    slices, tris = np.nonzero(keep)                                 # slice-major order
    positions = vertices[slices[:, None], fan[tris]]                # (T, 3, 3)
    return (positions.reshape(-1, 3).astype(np.float32),
            np.repeat(slices, 3).astype(np.int32))


# -- the vertex-shader path --------------------------------------------------------------

def vertex_path_tables(normal):
    """The per-frame uniform the vertex shader needs for ``normal``, as a dict of uniform
    name to value:

    ``"u_edges"``: (12, 2) int32, edges as (corner, corner) pairs. Rows 0-2 are path A,
    3-5 path B, 6-8 path C, each from the nearest corner to the farthest in order (the
    order the shader tries them); rows 9, 10, 11 are the cross edges A-B, B-C, C-A, each
    from its nearer end. ``u_edges[0][0]`` is the nearest corner (minimal
    ``dot(normal, corner)``; ties to the lower bound), ``u_edges[2][1]`` the farthest.

    Path p flips the axes ``(a[p], a[p+1], a[p+2])`` (cyclically) in turn. The axis order
    ``a`` is chosen so that the slots A, A-B, B, B-C, C, C-A run counter-clockwise as
    seen from the eye: the directions in which paths A and B leave the nearest corner
    have a cross product pointing along ``-normal`` (or perpendicular to it).
    """
    n = _unit(normal)
    bit = (1, 2, 4)
    near = sum(bit[a] for a in range(3) if n[a] < 0)
    signs = np.where(n < 0, -1.0, 1.0)
    # det(d[a0], d[a1], d[a2]) of the leaving directions must be negative
    axes = (0, 1, 2) if signs.prod() < 0 else (0, 2, 1)
    rows = []
    for p in range(3):
        corner = near
        for i in range(3):
            nxt = corner ^ bit[axes[(p + i) % 3]]
            rows.append((corner, nxt))
            corner = nxt
    for p in range(3):
        b0, b1 = bit[axes[p]], bit[axes[(p + 1) % 3]]
        rows.append((near ^ b1, near ^ b0 ^ b1))
    return {"u_edges": np.array(rows, np.int32)}


def path_slots(corners, normal, offsets, depth_origin=None):
    """The NumPy twin of the vertex shader: the six slot points of every plane, (K, 6, 3)
    float64, exactly as the shader chooses them, and whether the plane lies between the
    nearest and farthest corners (K,) bool. A plane outside that range gets the nearest
    corner in all six slots.

    The shader compares depths ``dot(normal, x - eye)``; ``depth_origin`` (the eye) lets
    the twin do the same, with ``offsets`` then being those depths. By default depths
    are ``dot(normal, x)``, ``offsets`` as in :func:`plane_polygons`.
    """
    corners = _corners(corners)
    n = _unit(normal)
    off = _offsets(offsets)
    edges = vertex_path_tables(n)["u_edges"].astype(np.int64)
    origin = np.zeros(3) if depth_origin is None else np.asarray(depth_origin, np.float64).reshape(3)
    depth = (corners - origin) @ n                                  # (8,)
    near, far = edges[0, 0], edges[2, 1]
    inside = (off >= depth[near]) & (off <= depth[far])

    da, db = depth[edges[:, 0]][None, :], depth[edges[:, 1]][None, :]   # (1, 12)
    d = off[:, None]
    hit = (da != db) & (d >= np.minimum(da, db)) & (d <= np.maximum(da, db))   # (K, 12)
    with np.errstate(over="ignore"):  # a huge ratio (edge all but parallel) clips to 0 or 1
        t = np.clip((d - da) / np.where(da != db, db - da, 1.0), 0.0, 1.0)[..., None]
    points = corners[edges[:, 0]] * (1.0 - t) + corners[edges[:, 1]] * t     # (K, 12, 3)

    slots = np.empty((off.size, 6, 3))
    for p in range(3):  # the three paths (a fixed loop over slots, not over planes)
        first = np.argmax(hit[:, 3 * p:3 * p + 3], axis=1)          # first edge hit
        on_path = points[np.arange(off.size), 3 * p + first]
        slots[:, 2 * p] = on_path
        cross = hit[:, 9 + p, None]
        slots[:, 2 * p + 1] = np.where(cross, points[:, 9 + p], on_path)
    slots[~inside] = corners[near]
    return slots, inside


def polygons_by_paths(corners, normal, offsets):
    """The shader's polygons (:func:`path_slots`) in the layout of
    :func:`plane_polygons`, cleaned up by the same rules: a slot point within
    :func:`box_tolerance` of a box corner becomes that corner, slots equal to an earlier
    slot are dropped, the rest kept in slot order (counter-clockwise seen from the eye),
    flat vertices dropped, the unused slots repeating the last vertex; count 0 where
    fewer than 3 vertices remain (a plane outside the box, or touching it in a corner
    or along an edge)."""
    corners = _corners(corners)
    slots, inside = path_slots(corners, normal, offsets)
    tol = box_tolerance(corners)
    to_corner = np.linalg.norm(slots[:, :, None, :] - corners[None, None], axis=-1)   # (K, 6, 8)
    nearest = np.argmin(to_corner, axis=2)
    snap = np.take_along_axis(to_corner, nearest[..., None], axis=2)[..., 0] <= tol
    slots = np.where(snap[..., None], corners[nearest], slots)
    gap = np.linalg.norm(slots[:, :, None, :] - slots[:, None, :, :], axis=-1)     # (K, 6, 6)
    earlier = np.tril(np.ones((6, 6), bool), k=-1)[None]
    repeat = np.any((gap <= tol) & earlier, axis=2)                  # same as an earlier slot
    keep = ~repeat & inside[:, None]
    found = keep.sum(axis=1)
    order = np.argsort(~keep, axis=1, kind="stable")                 # kept slots first, in order
    vertices = np.take_along_axis(slots, order[..., None], axis=1)
    return _drop_flat(vertices, found, tol)


# -- slab positions ----------------------------------------------------------------------

def slice_depths(corners, normal, eye, step):
    """The slab midplanes that can meet the box, far to near.

    Planes lie at depths ``(j + 0.5) * step`` (integer j) from the eye along ``normal``,
    only in front of it (depth > 0) and within the box's depth range. Returns
    ``(far_depth, count)``: plane k = 0 .. count-1 is at depth ``far_depth - k * step``.
    Each end of the range is widened by 1e-6 step against rounding, so a plane exactly
    at a corner's depth is always included (and at most one plane that misses the box by
    less than that). ``(0.0, 0)`` when no plane meets the box."""
    corners = _corners(corners)
    n = _unit(normal)
    step = float(step)
    if not math.isfinite(step) or step <= 0:
        raise ValueError(f"step must be positive and finite, got {step!r}")
    depth = (corners - np.asarray(eye, np.float64).reshape(3)) @ n
    nearest, farthest = float(depth.min()), float(depth.max())
    slack = 1e-6
    j_far = math.floor(farthest / step - 0.5 + slack)
    j_near = max(0, math.ceil(nearest / step - 0.5 - slack))
    count = j_far - j_near + 1
    if count <= 0:
        return 0.0, 0
    return (j_far + 0.5) * step, int(count)


def plane_offsets(normal, eye, far_depth, step, count):
    """Offsets ``dot(normal, x)`` of the planes at depths ``far_depth - k * step`` from
    ``eye``, k = 0 .. count-1, for :func:`plane_polygons`."""
    n = _unit(normal)
    base = float(np.asarray(eye, np.float64).reshape(3) @ n)
    return base + far_depth - np.arange(int(count)) * float(step)
