"""Proxy polygons for view-aligned 3D texture slicing (dvr_gl.techniques.proxy): the CPU
cut, the vertex-path algorithm's NumPy twin, the GLSL vertex shader, and slab depths.

Tolerances
----------
* CPU path (float64): points where a plane meets an edge within ``box_tolerance``
  (1e-10 of the box's size) of a corner become that corner, and vertices within it of
  their neighbours' chord are dropped, so the polygon may differ from the exact cut by
  that distance (vertices may sit that far from their plane); the rest is float64
  rounding. So areas may differ by tolerance x perimeter (perimeter <= 4 diagonals),
  plus rounding of a distance to the plane (~64 eps of the coordinates) divided by the
  smallest non-zero |normal component| times the perimeter: that is how far rounding
  moves a point along an edge nearly parallel to the plane (nearly axis-aligned
  normals are ill-conditioned). The independent clip builds its square exactly in the
  plane for axis-aligned normals, so a plane exactly on a face keeps the face.
* Shader (float32, u = 2**-24): corner and plane depths carry ~4u R of error (R the
  largest distance from the eye or the origin), an edge parameter t that error over the
  edge's depth span; with every |normal component| >= 0.1 that moves a point by <= ~80u R
  along its edge. The bound used is 128u R. Slot choice near a corner's depth is
  ambiguous (a cross edge hit at its end, or the previous slot): those planes are left
  out of the slot-by-slot comparison and checked by area instead.
"""

import itertools
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dvr_gl.gl.context import current, idle_framebuffer
from dvr_gl.gl.programs import build_source
from dvr_gl.techniques import proxy

U32 = 2.0 ** -24
SHADER = "slice3d/proxy_vertex.vert"
SETTINGS = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])

AXES = [s * np.eye(3)[a] for a in range(3) for s in (1.0, -1.0)]
DIAGONALS_45 = [np.array(v, float) / math.sqrt(2) for v in itertools.product((-1, 0, 1), repeat=3)
                if sum(abs(c) for c in v) == 2]
DIAGONALS_3D = [np.array(v, float) / math.sqrt(3) for v in itertools.product((-1, 1), repeat=3)]
SPECIAL_NORMALS = AXES + DIAGONALS_45 + DIAGONALS_3D


# -- independent references --------------------------------------------------------------

def polygon_area(points, normal):
    """Signed area of a closed polygon in a plane, positive when counter-clockwise as seen
    looking along +normal (the proxy module's convention)."""
    p = np.asarray(points, float)
    if len(p) < 3:
        return 0.0
    q = p - p[0]
    total = np.cross(q[:-1], q[1:]).sum(axis=0)
    return 0.5 * float(total @ -np.asarray(normal, float))


def clipped_area(lo, hi, normal, offset):
    """Area of the plane's cut through the box, by Sutherland-Hodgman: a square much
    larger than the box, in the plane, clipped by the six closed half-spaces. Shares no
    code with the module."""
    n = np.asarray(normal, float)
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    a = helper - (helper @ n) * n
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    centre = 0.5 * (np.asarray(lo) + np.asarray(hi))
    origin = offset * n + (centre - (centre @ n) * n)   # exact on the plane for axis normals
    r = 2.0 * float(np.linalg.norm(np.asarray(hi) - np.asarray(lo)))
    poly = [origin + r * (sa * a + sb * b) for sa, sb in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    for axis in range(3):
        for bound, side in ((lo[axis], 1.0), (hi[axis], -1.0)):
            def inside(p):
                return side * (p[axis] - bound) >= 0
            out = []
            for i, cur in enumerate(poly):
                prev = poly[i - 1]
                if inside(cur):
                    if not inside(prev):
                        out.append(_cut(prev, cur, axis, bound))
                    out.append(cur)
                elif inside(prev):
                    out.append(_cut(prev, cur, axis, bound))
            poly = out
            if not poly:
                return 0.0
    return abs(polygon_area(poly, n))


def _cut(p, q, axis, bound):
    t = (bound - p[axis]) / (q[axis] - p[axis])
    return p + t * (q - p)


def fan_area(slots, normal):
    """Signed area of the four fan triangles over six slots (repeated slots add zero)."""
    return sum(polygon_area(slots[[0, i, i + 1]], normal) for i in range(1, 5))


# -- hypothesis strategies -----------------------------------------------------------------

@st.composite
def boxes(draw):
    """(lo, hi): sizes 1e-3 .. 1e3 per axis, sometimes one axis only 2 samples thick."""
    sizes = 10.0 ** np.array(draw(st.lists(st.floats(-3, 3), min_size=3, max_size=3)))
    thin = draw(st.sampled_from([None, None, 0, 1, 2]))
    if thin is not None:
        sizes[thin] = 2 * sizes.max() / 512
    lo = sizes * np.array(draw(st.lists(st.floats(-1, 1), min_size=3, max_size=3)))
    return lo, lo + sizes


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


random_normals = st.lists(st.floats(-1, 1), min_size=3, max_size=3).filter(
    lambda v: np.linalg.norm(v) > 0.1).map(_unit)
normals = st.one_of(st.sampled_from(SPECIAL_NORMALS), random_normals)


@st.composite
def cuts(draw, normal_strategy=normals):
    """A box, a normal, and offsets: random within the box's range, exactly at corner
    depths, at the ends of the range, and beyond them."""
    lo, hi = draw(boxes())
    n = draw(normal_strategy)
    corners = proxy.box_corners(lo, hi)
    depth = corners @ n
    fractions = draw(st.lists(st.one_of(st.floats(0, 1), st.sampled_from([0.0, 0.5, 1.0]),
                                        st.floats(-0.2, 1.2)), min_size=1, max_size=6))
    offsets = [depth.min() + f * (depth.max() - depth.min()) for f in fractions]
    offsets += [depth[i] for i in draw(st.lists(st.integers(0, 7), max_size=3))]
    return lo, hi, corners, n, np.array(offsets)


def _area_tolerance(corners, n):
    """Allowed area difference between two computations of one cut: the merging
    tolerance times the perimeter (<= 4 diagonals), plus rounding. Rounding of a point's
    distance from the plane (~64 eps of the coordinates) moves the point along an edge
    by that over the edge's slope to the plane, the smallest non-zero |normal
    component|: nearly axis-aligned normals are ill-conditioned and get a wider bound."""
    diag = _scale(corners)
    slope = np.min(np.abs(n[n != 0]))
    rounding = 64 * np.finfo(float).eps * (np.abs(corners).max() + diag)
    with np.errstate(over="ignore"):
        return 16 * proxy.box_tolerance(corners) * diag + 4 * diag * rounding / slope + 1e-13 * diag ** 2


def _scale(corners):
    return float(np.linalg.norm(np.ptp(corners, axis=0)))


# -- box_corners, fan_triangles ------------------------------------------------------------

def test_box_corner_numbering():
    c = proxy.box_corners([1, 2, 3], [4, 6, 8])
    for i in range(8):
        assert tuple(c[i]) == (4 if i & 1 else 1, 6 if i & 2 else 2, 8 if i & 4 else 3)
    assert len({tuple(sorted(e)) for e in proxy.EDGES.tolist()}) == 12
    for a, b in proxy.EDGES:  # every edge joins corners differing on one axis
        assert np.count_nonzero(c[a] != c[b]) == 1


def test_fan_triangles_order_and_slices():
    verts = np.zeros((3, 6, 3))
    verts[:, :, 0] = np.arange(6)
    verts[:, :, 1] = np.arange(3)[:, None]
    counts = np.array([5, 0, 3])
    pos, slices = proxy.fan_triangles(verts, counts)
    assert pos.dtype == np.float32 and slices.dtype == np.int32
    assert pos.shape == (3 * 4, 3) and slices.tolist() == [0] * 9 + [2] * 3
    assert pos[:, 0].tolist() == [0, 1, 2, 0, 2, 3, 0, 3, 4, 0, 1, 2]
    assert pos[:9, 1].tolist() == [0] * 9 and pos[9:, 1].tolist() == [2] * 3
    empty, none = proxy.fan_triangles(verts[:0], counts[:0])
    assert empty.shape == (0, 3) and none.shape == (0,)


# -- plane_polygons: properties -------------------------------------------------------------

@SETTINGS
@given(cuts())
def test_plane_polygons_properties(cut):
    lo, hi, corners, n, offsets = cut
    verts, counts = proxy.plane_polygons(corners, n, offsets)
    assert verts.shape == (len(offsets), 6, 3) and counts.shape == (len(offsets),)
    tol = proxy.box_tolerance(corners)
    for k, off in enumerate(offsets):
        c = counts[k]
        reference = clipped_area(lo, hi, n, off)
        area_tol = _area_tolerance(corners, n)
        if c == 0:
            assert reference <= area_tol
            continue
        assert 3 <= c <= 6
        p = verts[k, :c]
        assert np.all(verts[k, c:] == p[-1])                     # padding repeats the last
        assert np.all(np.abs(p @ n - off) <= 2 * tol)            # on the plane
        assert np.all(p >= lo - 2 * tol) and np.all(p <= hi + 2 * tol)
        gap = np.minimum(np.abs(p - lo), np.abs(p - hi)).min(axis=1)
        assert np.all(gap <= 2 * tol)                            # on the box surface
        # convex and counter-clockwise seen from the eye: every turn is about -normal
        edges = np.roll(p, -1, axis=0) - p
        turns = np.cross(edges, np.roll(edges, -1, axis=0)) @ n
        assert np.all(turns < 0), turns
        area = polygon_area(p, n)
        assert area > 0
        assert abs(area - reference) <= area_tol, (area, reference)


# -- plane_polygons: hard cases -------------------------------------------------------------

def _area_of(corners, n, off):
    v, c = proxy.plane_polygons(corners, n, [off])
    return c[0], polygon_area(v[0, :c[0]], n)


@pytest.mark.parametrize("n", AXES, ids=lambda n: "axis" + "".join(f"{c:+.0f}" for c in n))
def test_axis_normals_give_rectangles_including_on_faces(n):
    lo, hi = np.array([-1.0, 0.5, 2.0]), np.array([2.0, 1.0, 6.0])
    corners = proxy.box_corners(lo, hi)
    axis = int(np.argmax(np.abs(n)))
    face_area = np.prod(np.delete(hi - lo, axis))
    for coordinate in (lo[axis], hi[axis], 0.5 * (lo[axis] + hi[axis]), lo[axis] + 1e-3):
        off = float(n @ np.where(np.arange(3) == axis, coordinate, 0.0))
        count, area = _area_of(corners, n, off)
        assert count == 4 and area == pytest.approx(face_area, rel=1e-12)
    for coordinate in (lo[axis] - 1e-3, hi[axis] + 1e-3):
        off = float(n @ np.where(np.arange(3) == axis, coordinate, 0.0))
        assert _area_of(corners, n, off)[0] == 0


def test_regular_hexagon_through_the_centre():
    side = 3.0
    corners = proxy.box_corners([0, 0, 0], [side] * 3)
    for n in DIAGONALS_3D:
        off = float(n @ np.full(3, side / 2))
        verts, counts = proxy.plane_polygons(corners, n, [off])
        assert counts[0] == 6
        p = verts[0]
        # a regular hexagon of side side/sqrt(2): area 3 sqrt(3)/2 (side^2 / 2)
        assert polygon_area(p, n) == pytest.approx(3 * math.sqrt(3) / 4 * side ** 2, rel=1e-12)
        lengths = np.linalg.norm(np.roll(p, -1, axis=0) - p, axis=1)
        np.testing.assert_allclose(lengths, side / math.sqrt(2), rtol=1e-12)


def test_planes_through_corners_and_edges():
    lo, hi = np.zeros(3), np.array([1.0, 2.0, 3.0])
    corners = proxy.box_corners(lo, hi)
    for n in DIAGONALS_3D:
        depth = corners @ n
        near, far = np.argmin(depth), np.argmax(depth)
        # touching the nearest or farthest corner only: degenerate
        assert proxy.plane_polygons(corners, n, depth[[near, far]])[1].tolist() == [0, 0]
        # through the three neighbours of the nearest corner: a triangle with them as vertices
        neighbours = [near ^ b for b in (1, 2, 4)]
        for i in neighbours:
            verts, counts = proxy.plane_polygons(corners, n, [depth[i]])
            assert counts[0] >= 3
            assert any(np.allclose(v, corners[i], atol=1e-12) for v in verts[0, :counts[0]])
    cube = proxy.box_corners(lo, [2.0, 2.0, 2.0])
    n = _unit([1, 1, 1])
    verts, counts = proxy.plane_polygons(cube, n, [n @ [2, 0, 0]])   # through corners 1, 2, 4
    assert counts[0] == 3
    assert {tuple(v) for v in np.round(verts[0, :3], 12)} == {(2, 0, 0), (0, 2, 0), (0, 0, 2)}
    for n in DIAGONALS_45:
        depth = corners @ n
        # touching an edge of the box (the nearest or farthest pair of corners): degenerate
        assert proxy.plane_polygons(corners, n, [depth.min(), depth.max()])[1].tolist() == [0, 0]
        # the diagonal plane through a cube's centre holds two opposite edges: a
        # rectangle 2 sqrt(2) x 2 on four corners
        c_depth = cube @ n
        verts, counts = proxy.plane_polygons(cube, n, [n @ np.ones(3)])
        assert counts[0] == 4
        assert polygon_area(verts[0, :4], n) == pytest.approx(4 * math.sqrt(2), rel=1e-12)
        on_plane = np.flatnonzero(np.abs(c_depth - n @ np.ones(3)) < 1e-12)
        assert len(on_plane) == 4
        for v in verts[0, :4]:
            assert np.min(np.linalg.norm(cube[on_plane] - v, axis=1)) < 1e-12


def test_planes_outside_the_box_are_empty():
    corners = proxy.box_corners([0, 0, 0], [1, 1, 1])
    n = _unit([0.3, -0.5, 0.8])
    depth = corners @ n
    verts, counts = proxy.plane_polygons(corners, n, [depth.min() - 1e-6, depth.max() + 1e-6, -1e9, 1e9])
    assert counts.tolist() == [0, 0, 0, 0]
    assert proxy.fan_triangles(verts, counts)[0].shape == (0, 3)


def test_tolerance_merges_points_at_a_corner():
    corners = proxy.box_corners([0, 0, 0], [1, 1, 1])
    n = _unit([1, 2, 3])
    tol = proxy.box_tolerance(corners)
    exact = proxy.plane_polygons(corners, n, [n @ corners[1]])
    assert exact[1][0] == 3    # corner 1, and points on edges 0-2 and 0-4
    # planes through corner 1 or passing it on either side closely enough that the
    # points on its edges lie within the tolerance of it (a shift s moves the point on
    # an edge by s / |n . edge direction| <= s * sqrt(14)): they merge into the corner
    for shift in (0.0, 0.1 * tol, -0.1 * tol, 0.25 * tol, -0.25 * tol):
        verts, counts = proxy.plane_polygons(corners, n, [n @ corners[1] + shift])
        assert counts[0] == 3
        p = verts[0, :3]
        assert np.sum(np.all(p == corners[1], axis=1)) == 1
        np.testing.assert_allclose(p, exact[0][0, :3], rtol=0, atol=2 * tol)
    # the nearest corner (0) touched within the tolerance: one point, degenerate
    assert proxy.plane_polygons(corners, n, [0.5 * tol, -0.5 * tol])[1].tolist() == [0, 0]


def test_tolerance_is_a_distance_along_edges():
    """A plane tilted 1e-6 from a face, passing 1e-9 from two corners, is a sliver 1e-3
    wide: a point-to-plane tolerance would turn it into the box edge and lose it."""
    lo, hi = np.zeros(3), np.array([1e-3, 1.0, 10.0])
    corners = proxy.box_corners(lo, hi)
    n = _unit([1.0, 0.0, 1e-6])
    off = 1.01e-9
    verts, counts = proxy.plane_polygons(corners, n, [off])
    area = polygon_area(verts[0, :counts[0]], n)
    assert counts[0] == 4 and area == pytest.approx(clipped_area(lo, hi, n, off), rel=1e-6)
    assert area == pytest.approx(1.01e-3, rel=1e-3)
    assert proxy.polygons_by_paths(corners, n, [off])[1][0] == 4


def test_plane_hugging_an_edge_leaves_no_flat_vertex():
    """Tilted 1e-10 about the x-z diagonal of a unit cube, the plane through its middle
    runs within the tolerance of edges (1,0,0)-(1,1,0) and (0,0,1)-(0,1,1), crossing
    them halfway: the result is the 4-corner rectangle, without those middle points."""
    corners = proxy.box_corners([0, 0, 0], [1, 1, 1])
    n = _unit([1.0, 1e-10, 1.0])
    depth = corners @ n
    off = 0.5 * (depth.min() + depth.max())
    for verts, counts in (proxy.plane_polygons(corners, n, [off]), proxy.polygons_by_paths(corners, n, [off])):
        assert counts[0] == 4
        expected = corners[[1, 4, 6, 3]]   # (1,0,0), (0,0,1), (0,1,1), (1,1,0)
        assert _same_polygon(expected, verts[0, :4], 1e-9)


def test_close_slot_points_at_one_corner_merge():
    """Two slot points each within the tolerance of one corner, but farther than it from
    each other, are that corner once (not two flat vertices dropped together)."""
    lo, hi = [0.0, 0.0, 0.0], [1.0000000002302585, 1.0, 1.1547819846894583]
    corners = proxy.box_corners(lo, hi)
    n = _unit([1.0, 1.0, 1.0])
    off = 0.5773502693225656
    v_cpu, c_cpu = proxy.plane_polygons(corners, n, [off])
    v_path, c_path = proxy.polygons_by_paths(corners, n, [off])
    assert c_cpu[0] == c_path[0] == 3
    assert _same_polygon(v_cpu[0, :3], v_path[0, :3], 1e-12)


# -- polygons_by_paths -----------------------------------------------------------------------

def test_vertex_path_tables_cover_the_box():
    for n in SPECIAL_NORMALS + [_unit(v) for v in np.random.default_rng(1).normal(size=(20, 3))]:
        edges = proxy.vertex_path_tables(n)["u_edges"]
        assert edges.shape == (12, 2) and edges.dtype == np.int32
        assert {tuple(sorted(e)) for e in edges.tolist()} == {tuple(e) for e in proxy.EDGES.tolist()}
        corners = proxy.box_corners([0, 0, 0], [1, 1, 1])
        depth = corners @ n
        near, far = edges[0, 0], edges[2, 1]
        assert depth[near] == depth.min() and depth[far] == depth.max()
        for p in range(3):  # each path runs near -> far, end to end, depths not decreasing
            path = edges[3 * p:3 * p + 3]
            assert path[0, 0] == near and path[2, 1] == far
            assert np.all(path[:-1, 1] == path[1:, 0])
            assert np.all(depth[path[:, 1]] >= depth[path[:, 0]])
        inner = [set(edges[3 * p:3 * p + 3, 1][:2].tolist()) for p in range(3)]
        assert not (inner[0] & inner[1] or inner[1] & inner[2] or inner[0] & inner[2])
        for p in range(3):  # cross edge p joins path p+1's first and path p's second corner
            assert edges[9 + p, 0] == edges[3 * ((p + 1) % 3), 1]
            assert edges[9 + p, 1] == edges[3 * p + 1, 1]


def _same_polygon(a, b, tol):
    """Same vertices in the same cyclic order, possibly starting elsewhere."""
    if len(a) != len(b):
        return False
    if len(a) == 0:
        return True
    start = int(np.argmin(np.linalg.norm(b - a[0], axis=1)))
    return np.allclose(np.roll(b, -start, axis=0), a, rtol=0, atol=tol)


@SETTINGS
@given(cuts())
def test_paths_equal_plane_polygons(cut):
    lo, hi, corners, n, offsets = cut
    v_cpu, c_cpu = proxy.plane_polygons(corners, n, offsets)
    v_path, c_path = proxy.polygons_by_paths(corners, n, offsets)
    tol = proxy.box_tolerance(corners)
    for k in range(len(offsets)):
        a_cpu = polygon_area(v_cpu[k, :c_cpu[k]], n)
        a_path = polygon_area(v_path[k, :c_path[k]], n)
        assert abs(a_cpu - a_path) <= _area_tolerance(corners, n), _inputs(cut)
        if c_path[k]:
            assert a_path > 0  # the slots run counter-clockwise seen from the eye too
        # same vertices in the same order, unless two vertices, or a vertex and its
        # neighbours' chord, are within a few tolerances: there merging may go either way
        if _clear(v_cpu[k, :c_cpu[k]], 8 * tol) and _clear(v_path[k, :c_path[k]], 8 * tol):
            assert c_cpu[k] == c_path[k]
            assert _same_polygon(v_cpu[k, :c_cpu[k]], v_path[k, :c_path[k]], 4 * tol)


def _inputs(cut):
    """The example's numbers at full precision, for a failure message."""
    lo, hi, _, n, offsets = cut
    return f"lo={lo.tolist()} hi={hi.tolist()} normal={n.tolist()} offsets={offsets.tolist()}"


def _clear(p, gap):
    """No two vertices within ``gap``, and none within ``gap`` of its neighbours' chord."""
    if len(p) < 3:
        return True
    distances = np.linalg.norm(p[:, None] - p[None, :], axis=-1)
    prev, nxt = np.roll(p, 1, axis=0), np.roll(p, -1, axis=0)
    chord = nxt - prev
    height = np.linalg.norm(np.cross(chord, p - prev), axis=1) / np.linalg.norm(chord, axis=1)
    return distances[~np.eye(len(p), dtype=bool)].min() > gap and height.min() > gap


def test_paths_on_hard_cases():
    lo, hi = np.array([0.0, 0.0, 0.0]), np.array([1.0, 2.0, 4.0])
    corners = proxy.box_corners(lo, hi)
    for n in SPECIAL_NORMALS:
        depth = corners @ n
        offsets = np.concatenate([depth, np.linspace(depth.min(), depth.max(), 13),
                                  [depth.min() - 1, depth.max() + 1]])
        v_cpu, c_cpu = proxy.plane_polygons(corners, n, offsets)
        v_path, c_path = proxy.polygons_by_paths(corners, n, offsets)
        assert c_cpu.tolist() == c_path.tolist(), n
        for k in range(len(offsets)):
            assert _same_polygon(v_cpu[k, :c_cpu[k]], v_path[k, :c_path[k]], 1e-9)


# -- slice_depths --------------------------------------------------------------------------

@SETTINGS
@given(boxes(), normals, st.lists(st.floats(-3, 3), min_size=3, max_size=3), st.floats(1e-3, 0.5))
def test_slice_depths_cover_every_plane_meeting_the_box(box, n, eye_f, step_f):
    lo, hi = box
    corners = proxy.box_corners(lo, hi)
    eye = lo + np.array(eye_f) * (hi - lo)   # inside, beside or far from the box
    step = step_f * _scale(corners)
    far_depth, count = proxy.slice_depths(corners, n, eye, step)
    depth = (corners - eye) @ n
    j = np.arange(0, math.floor(depth.max() / step) + 2)
    planes = (j + 0.5) * step
    meeting = planes[(planes >= depth.min()) & (planes <= depth.max())]
    listed = far_depth - np.arange(count) * step
    assert np.all(listed > 0)
    assert np.all(np.diff(listed) < 0)
    for d in meeting:
        assert np.any(np.abs(listed - d) <= 1e-9 * step), (d, listed)
    # at most one extra plane at each end, missing the box by less than 1e-6 step
    extra = listed[(listed < depth.min()) | (listed > depth.max())]
    assert len(extra) <= 2
    assert np.all((extra > depth.min() - 1e-6 * step - 1e-12) & (extra < depth.max() + 1e-6 * step + 1e-12))


def test_slice_depths_edge_cases():
    corners = proxy.box_corners([0, 0, 0], [1, 1, 1])
    n = np.array([0.0, 0.0, 1.0])
    # box depth range [2, 3] from this eye; planes at (j + 0.5) * 0.5: 2.25, 2.75 ...
    assert proxy.slice_depths(corners, n, [0.5, 0.5, -2.0], 0.5) == (2.75, 2)
    # planes exactly on the faces (depth 2.5 and 3.5 with step 1): both included
    assert proxy.slice_depths(corners, n, [0.5, 0.5, -2.5], 1.0) == (3.5, 2)
    # eye inside: only planes in front of it
    far, count = proxy.slice_depths(corners, n, [0.5, 0.5, 0.3], 0.1)
    assert far == pytest.approx(0.65) and count == 7
    assert far - (count - 1) * 0.1 > 0
    # box behind the eye
    assert proxy.slice_depths(corners, n, [0.5, 0.5, 2.0], 0.1) == (0.0, 0)
    with pytest.raises(ValueError):
        proxy.slice_depths(corners, n, [0, 0, 0], 0.0)


def test_plane_offsets_match_depths():
    n = _unit([1, 2, -2])
    eye = np.array([3.0, -1.0, 2.0])
    off = proxy.plane_offsets(n, eye, 5.0, 0.5, 4)
    np.testing.assert_allclose(off - n @ eye, [5.0, 4.5, 4.0, 3.5])


# -- the GLSL vertex shader -----------------------------------------------------------------

@pytest.fixture(scope="module")
def proxy_program(renderer):
    with current(renderer.ctx) as ctx:
        prog = ctx.program(vertex_shader=build_source(SHADER), varyings=["v_point", "v_slice"])
    yield prog
    with current(renderer.ctx):
        prog.release()


def run_shader(ctx, prog, corners, n, eye, far_depth, step, count):
    """Every vertex of ``count`` instances, captured by transform feedback: points
    (count, 6, 3) by slot (checking that vertices sharing a slot agree) and slices."""
    c32 = np.asarray(corners, np.float32)
    uniforms = {"u_corners": c32, "u_normal": np.asarray(n, np.float32),
                "u_eye": np.asarray(eye, np.float32), "u_far_depth": np.float32(far_depth),
                "u_step": np.float32(step), "u_view_proj": np.eye(4, dtype=np.float32)}
    uniforms.update(proxy.vertex_path_tables(n))
    record = np.dtype([("point", np.float32, 3), ("slice", np.int32)])
    with current(ctx):
        for name, value in uniforms.items():
            prog[name].write(np.ascontiguousarray(value).tobytes())
        vao = ctx.vertex_array(prog, [])
        out = ctx.buffer(reserve=count * 12 * record.itemsize)
        idle_framebuffer(ctx).use()
        vao.transform(out, mode=ctx.POINTS, vertices=12, instances=count)
        data = np.frombuffer(out.read(), record).reshape(count, 12)
        out.release()
        vao.release()
    assert np.all(data["slice"] == np.arange(count)[:, None])
    points = data["point"].astype(np.float64)
    slots = np.empty((count, 6, 3))
    for vertex, slot in enumerate(proxy.FAN_SLOTS):
        slots[:, slot] = points[:, vertex]
    for vertex, slot in enumerate(proxy.FAN_SLOTS):
        assert np.array_equal(points[:, vertex], slots[:, slot])
    return slots


def _twin(corners, n, eye, far_depth, step, count):
    """path_slots on the float32 inputs the shader sees, in the shader's depth terms."""
    depths = np.float32(far_depth) - np.arange(count, dtype=np.float32) * np.float32(step)
    c = np.asarray(corners, np.float32).astype(np.float64)
    n32 = np.asarray(n, np.float32).astype(np.float64)
    e32 = np.asarray(eye, np.float32).astype(np.float64)
    slots, inside = proxy.path_slots(c, n32, depths.astype(np.float64), depth_origin=e32)
    return slots, inside, depths.astype(np.float64), (c - e32) @ n32


def test_shader_equals_twin_on_random_views(ctx, proxy_program):
    rng = np.random.default_rng(7)
    compared = 0
    for trial in range(40):
        n = _unit(rng.normal(size=3))
        if np.min(np.abs(n)) < 0.1:
            continue   # nearly parallel edges amplify rounding; see test_shader_hard_cases
        sizes = 10.0 ** rng.uniform(-2, 2, 3)
        corners = proxy.box_corners(np.zeros(3), sizes)
        diag = _scale(corners)
        aside = rng.normal(size=3) * 0.2 * diag
        eye = 0.5 * sizes - n * diag * rng.uniform(0.6, 3.0) + aside - (aside @ n) * n
        if trial % 5 == 0:
            eye = rng.uniform(0, 1, 3) * sizes      # eye inside the box
        step = diag / rng.uniform(5, 60)
        far_depth, count = proxy.slice_depths(corners, n, eye, step)
        if count == 0:  # an eye inside, closer than half a step to the box's far side
            assert np.max((corners - eye) @ n) < 0.5 * step
            continue
        far_depth += 2 * step                       # two planes beyond the box
        count += 2
        gl = run_shader(ctx, proxy_program, corners, n, eye, far_depth, step, count)
        ref, inside, depths, corner_depths = _twin(corners, n, eye, far_depth, step, count)
        assert not inside[0] and not inside[1]
        radius = float(np.max(np.linalg.norm(corners - eye, axis=1)) + np.max(np.abs(corners)))
        bound = 128 * U32 * radius
        clear = np.min(np.abs(depths[:, None] - corner_depths[None, :]), axis=1) > 1e-4 * radius
        np.testing.assert_allclose(gl[clear], ref[clear], rtol=0, atol=bound)
        compared += clear.sum()
        # every plane, near corner depths too: same polygon area
        for k in range(count):
            assert fan_area(gl[k], n) == pytest.approx(fan_area(ref[k], n), abs=bound * 8 * diag)
    assert compared > 200


@pytest.mark.parametrize("n", SPECIAL_NORMALS, ids=lambda n: "n" + "".join(f"{c:+.1f}" for c in n))
def test_shader_hard_cases(ctx, proxy_program, n):
    """Axis-aligned, 45-degree and body-diagonal views of a box with dyadic sizes, with
    planes on the nearest and farthest corners, edges or faces and one beyond each. For
    axis normals every quantity is exact in float32, planes exactly on faces included;
    for the others planes land within rounding of corners and edges."""
    lo, hi = np.zeros(3), np.array([1.0, 2.0, 4.0])
    corners = proxy.box_corners(lo, hi)
    centre = 0.5 * (lo + hi)
    eye = centre - 8.0 * n
    depth = (corners - eye) @ n
    step = 0.25 if np.count_nonzero(n) == 1 else (depth.max() - depth.min()) / 16
    far_depth = float(depth.max()) + step      # one plane beyond, then onto the far corner
    count = int(round((far_depth - depth.min()) / step)) + 2
    gl = run_shader(ctx, proxy_program, corners, n, eye, far_depth, step, count)
    ref, inside, depths, _ = _twin(corners, n, eye, far_depth, step, count)
    assert not inside[0] and not inside[-1]
    radius = 16.0
    if np.count_nonzero(n) == 1:
        assert np.array_equal(gl, ref)
    else:
        for k in range(count):
            assert fan_area(gl[k], n) == pytest.approx(fan_area(ref[k], n), abs=128 * U32 * radius * 20)
    # and the areas are the cuts' areas
    offsets = depths + float(n @ eye)
    v_cpu, c_cpu = proxy.plane_polygons(corners, n, offsets)
    for k in range(count):
        expected = polygon_area(v_cpu[k, :c_cpu[k]], n)
        assert fan_area(gl[k], n) == pytest.approx(expected, abs=128 * U32 * radius * 20)


def test_shader_draws_front_facing_slices(ctx, renderer):
    """Rasterised with back faces culled and additive blending, the slices' coverage
    (weighted by slice index + 1, read from the flat v_slice) matches their areas: the
    instanced draw works, every polygon faces the viewer, none is drawn twice."""
    fs = """#version 330 core
    flat in int v_slice;
    out vec4 f_color;
    void main() { f_color = vec4(1.0, float(v_slice + 1), 0.0, 1.0); }
    """
    size = 96
    corners = proxy.box_corners([0, 0, 0], [1.0, 1.5, 0.75])
    n = _unit([0.4, -0.7, 0.55])
    centre = corners.mean(axis=0)
    eye = centre - 4.0 * n
    step = 0.1
    far_depth, count = proxy.slice_depths(corners, n, eye, step)
    # orthographic view along n: screen x = u, y = v (u x v = -n), depth grows along n
    u, v = proxy.plane_basis(n)
    half = 1.2
    m = np.zeros((4, 4))
    m[0, :3], m[0, 3] = u / half, -(u @ centre) / half
    m[1, :3], m[1, 3] = v / half, -(v @ centre) / half
    m[2, :3], m[2, 3] = n / 4.0, -(n @ centre) / 4.0
    m[3, 3] = 1.0
    with current(ctx):
        prog = ctx.program(vertex_shader=build_source(SHADER), fragment_shader=fs)
        uniforms = {"u_corners": corners.astype(np.float32), "u_normal": n.astype(np.float32),
                    "u_eye": eye.astype(np.float32), "u_far_depth": np.float32(far_depth),
                    "u_step": np.float32(step), "u_view_proj": m.T.astype(np.float32)}
        uniforms.update(proxy.vertex_path_tables(n))
        for name, value in uniforms.items():
            prog[name].write(np.ascontiguousarray(value).tobytes())
        tex = ctx.texture((size, size), 4, dtype="f4")
        fbo = ctx.framebuffer([tex])
        vao = ctx.vertex_array(prog, [])
        try:
            fbo.use()
            fbo.clear(0.0, 0.0, 0.0, 0.0)
            ctx.disable(ctx.DEPTH_TEST)
            ctx.enable(ctx.BLEND | ctx.CULL_FACE)
            ctx.blend_func = ctx.ONE, ctx.ONE
            ctx.front_face = "ccw"
            ctx.cull_face = "back"
            vao.render(ctx.TRIANGLES, vertices=12, instances=count)
            image = np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32).reshape(size, size, 4)
        finally:
            ctx.disable(ctx.BLEND | ctx.CULL_FACE)
            ctx.blend_func = ctx.SRC_ALPHA, ctx.ONE_MINUS_SRC_ALPHA
            idle_framebuffer(ctx).use()
            for obj in (vao, fbo, tex, prog):
                obj.release()
    offsets = proxy.plane_offsets(n, eye, far_depth, step, count)
    verts, counts = proxy.plane_polygons(corners, n, offsets)
    assert np.count_nonzero(counts) >= 5
    pixel = (2 * half / size) ** 2
    areas = np.array([polygon_area(verts[k, :counts[k]], n) for k in range(count)])
    perimeters = np.array([np.linalg.norm(np.diff(verts[k, :counts[k]], axis=0, append=verts[k, :1]), axis=1).sum()
                           if counts[k] else 0.0 for k in range(count)])
    # each polygon's pixel count is its area in pixels within about its perimeter in pixels
    slack = perimeters / math.sqrt(pixel)
    np.testing.assert_allclose(image[..., 0].sum(), areas.sum() / pixel, atol=slack.sum())
    weights = np.arange(1, count + 1)
    np.testing.assert_allclose(image[..., 1].sum(), (weights * areas).sum() / pixel, atol=(weights * slack).sum())
