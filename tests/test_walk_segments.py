"""Table-integrated segments of the cell walk (``tetra``, ``sort="walk", segments="table"``;
``dvr_gl.model.segment_table``), the mesh pilot's cheap approximate way.

Tolerances. The NumPy twin (``table_segment``, used by ``reference.render``) and the
exact integral (``reference.linear_segment``) differ by the approximation itself, which
is the point of the convergence test: it leaves out the attenuation inside a segment, so
its error falls as the segment gets shorter (it goes with the segment's optical depth
times its change of colour, both in proportion to its length at a fixed field gradient:
measured 4x to 7x a halving here, the test asks for 1.7x). GL
against the twin: the walk's own ``GL_TOL`` (1e-4, test_tetra_walk.py) plus the table's
float32 sums, whose difference over at least one entry keeps a relative rounding of
2^-23 times the largest sum over that entry's step: at most a few 1e-5 on these TFs
(measured 2e-5 on the ball), inside GL_TOL.
"""

import numpy as np
import pytest

from dvr_gl import Scene, TransferFunction, reference
from dvr_gl.data import delaunay_ball, synthetic_tf
from dvr_gl.model.camera import default_camera
from dvr_gl.model.segment_table import SegmentTable, table_segment
from dvr_gl.model.transfer import SegmentKnots
from dvr_gl.reference.linear_segment import linear_segment
from dvr_gl.rendering import mesh_tolerance as mt
from dvr_gl.techniques import tetra

from test_tetra import GL_TOL

RAMP = TransferFunction([(0.0, 0.1, 0.2, 0.9), (0.5, 0.2, 0.9, 0.3), (1.0, 0.9, 0.2, 0.1)],
                        [(0.0, 0.0), (0.4, 0.2), (0.6, 0.7), (1.0, 0.3)], unit_distance=0.25)


def test_constant_value_segment_is_exact():
    """A segment of one value: c A with A = 1 - (1 - alpha)^(L / u), as exact's."""
    table = SegmentTable(RAMP)
    s = np.array([0.1, 0.45, 0.6, 0.93, -0.5, 1.5])       # beyond the knots too
    length = np.array([0.01, 0.1, 0.3, 1.0, 0.2, 0.2])
    got = table_segment(table, s, s, length)
    want = linear_segment(SegmentKnots(RAMP), s, s, length)
    assert np.abs(got - want).max() < 1e-5


def test_error_falls_with_the_segment():
    """At a fixed field gradient (value change per length), halving the segments lowers
    the largest error against the exact integral at least 1.7x (measured 4x to 7x)."""
    table = SegmentTable(RAMP)
    rng = np.random.default_rng(3)
    start = rng.uniform(-0.1, 1.1, 2000)
    gradient = rng.uniform(-2.0, 2.0, 2000)       # value units per unit length
    errors = []
    for length in (0.2, 0.1, 0.05, 0.025):
        back = start + gradient * length
        got = table_segment(table, start, back, np.full(2000, length))
        want = linear_segment(SegmentKnots(RAMP), start, back, np.full(2000, length))
        errors.append(np.abs(got - want).max())
    assert errors[0] > 1e-4                       # the approximation is not exact
    assert all(a > 1.7 * b for a, b in zip(errors, errors[1:])), errors


def test_beyond_the_knots_the_sum_goes_on_linearly():
    table = SegmentTable(RAMP)
    s = np.array([-2.0, -1.0, 2.0, 3.0])
    c = table.cumulative(s)
    tau_hi = -np.log(1.0 - 0.3)                  # opacity 0.3 above the last knot, 0 below the first
    assert np.allclose(c[3, 3] - c[2, 3], tau_hi, rtol=1e-5)
    assert np.allclose(c[1, 3] - c[0, 3], 0.0, atol=1e-7)


@pytest.mark.parametrize("azimuth", [30.0, 200.0])
def test_gl_matches_its_twin(renderer, azimuth):
    mesh = delaunay_ball()
    scene = Scene(mesh, synthetic_tf(), default_camera(mesh, azimuth=azimuth, elevation=20.0), 32, 32)
    img = renderer.render(scene, technique="tetra", sort="walk", segments="table")
    twin = reference.render(scene, technique="tetra", sort="walk", segments="table")
    exact_twin = reference.render(scene, technique="tetra", sort="walk")
    assert np.abs(img - twin).max() < GL_TOL
    assert np.abs(twin - exact_twin).max() > 1e-3      # a different integral: the test can tell


def test_bad_segments_are_named(renderer):
    mesh = delaunay_ball()
    scene = Scene(mesh, synthetic_tf(), default_camera(mesh), 8, 8)
    with pytest.raises(ValueError, match="segments must be one of exact, table, got 'fast'"):
        tetra.make_plan(scene, sort="walk", segments="fast")
    with pytest.raises(ValueError, match="sort='walk'.*sort='mpvo'"):
        tetra.make_plan(scene, sort="mpvo", segments="table")
    with pytest.raises(ValueError, match="mode='mip'"):
        tetra.make_plan(scene.replace(mode="mip"), sort="walk", segments="table")


def test_the_pilot_measures_the_table_way():
    assert any(dict(w.options).get("segments") == "table" for w in mt.available_ways())
