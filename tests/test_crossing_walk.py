"""The walk by crossings (``refine_walk="crossings"``): cell to cell, empty cells passed
over many at a time, the field's cubic in each other cell cut where it turns and where it
enters or leaves the values with opacity, each piece read from the pre-integrated table
along its straight line moved to the cubic's mean."""

import types

import numpy as np
import pytest

import dvr_gl
from dvr_gl import metrics, reference
from dvr_gl.reference import crossing_walk as twin
from dvr_gl.rendering import tolerance
from dvr_gl.techniques import crossing_walk, raycast

from test_raycast import TF
from test_refine import _scene
from test_reach_walk import ml_spike
from test_slicing import SPIKE, preintegrated_tolerance


def walk_tolerance(plan):
    """The pre-integrated bound per lookup (test_slicing, for the fine table and pieces up
    to the longest piece) times the most pieces the reference reads on one ray (the last
    ``twin.render_plan`` call). GL and reference pass over the same cells (the same
    empty cubes) and make the same cubics from the same corners; float32 moves a
    crossing found by Halley's method by a few ulps of the stretch, which changes the
    piece's end values by the field's rounding already in that bound; a cubic that only
    grazes a knot within ``plan.crossings.tol`` may be cut in one and not the other, which
    changes that piece by the straight line's error over a stretch the cubic hardly leaves
    the knot: within the same bound here."""
    fine = types.SimpleNamespace(preint=plan.preint_fine, scene=plan.scene, step=plan.crossings.part)
    return preintegrated_tolerance(fine, 1) * max(twin.render_plan.counts["max_pieces"], 1)


def ml_scene(width=40, height=32):
    volume, tf = ml_spike()
    return dvr_gl.Scene(volume, tf, dvr_gl.default_camera(volume, azimuth=30, elevation=20), width, height)


@pytest.mark.parametrize("case", ["ml", "spike-perspective", "spike-ortho-lit", "spike-eye-inside", "smooth"])
def test_crossing_walk_gl_matches_reference(renderer, case):
    if case == "ml":
        scene = ml_scene()
        step = 4.0 * scene.volume.min_spacing
    else:
        tf = TF if case == "smooth" else SPIKE
        camera = {"spike-ortho-lit": "ortho", "spike-eye-inside": "eye_inside"}.get(case, "perspective")
        scene = _scene(tf, camera, shading=case == "spike-ortho-lit")
        step = 2.0
    opts = dict(step=step, preintegrate=True, refine=2, refine_walk="crossings", ert_transmittance=0.0)
    plan = raycast.make_plan(scene, **opts)
    assert plan.defines["CROSSING_WALK"] == 1
    gl = renderer.render(scene, **opts)
    ref = reference.render(scene, technique="raycast", **opts)
    assert ref[..., 3].max() > 0.05
    assert metrics.max_abs_error(gl, ref) <= walk_tolerance(plan)


def test_crossing_walk_moves_on_far_from_the_eye(renderer):
    """Seen from far away (a 1-degree view: the eye about 100 volume radii out), a
    hundred-thousandth of a cell is below float32's resolution of the ray's t, and a walk
    nudged on by that alone stood still at a face until its round limit, dropping what
    lay beyond (found on the chest CT's spike, 0.46 of opacity in some pixels): the nudge
    is at least four float32 steps of t, as in the twin."""
    volume, tf = ml_spike()
    scene = dvr_gl.Scene(volume, tf, dvr_gl.default_camera(volume, azimuth=30, elevation=20, fov=1.0), 40, 32)
    opts = dict(step=2.0 * volume.min_spacing, preintegrate=True, refine=2, refine_walk="crossings",
                ert_transmittance=0.0)
    plan = raycast.make_plan(scene, **opts)
    gl = renderer.render(scene, **opts)
    ref = reference.render(scene, technique="raycast", **opts)
    assert ref[..., 3].max() > 0.5
    assert metrics.max_abs_error(gl, ref) <= walk_tolerance(plan)


def test_crossing_walk_error_shrinks_with_its_pieces(renderer):
    """Against the exact image of the Marschner-Lobb spike, at a 4-voxel step: the error
    falls as the longest piece (step / refine) goes from 1 to 1/4 to 1/16 voxel (4.6x and
    17x here; asserted 3x: the straight line's error over a piece is second order in its
    length, and a 1-voxel cap binds only where the field lingers in the band), and at
    equal parts it is under a third of the walk by reach's (8.4x and 3.8x here)."""
    scene = ml_scene(48, 40)
    exact = reference.exact(scene)
    step = 4.0 * scene.volume.min_spacing
    parts = (4, 16, 64)
    errors = [metrics.rmse(renderer.render(scene, step=step, preintegrate=True, refine=k, refine_walk="crossings"),
                           exact) for k in parts]
    assert all(coarse > 3 * fine for coarse, fine in zip(errors, errors[1:])), errors
    reach = [metrics.rmse(renderer.render(scene, step=step, preintegrate=True, refine=k, refine_walk="reach"), exact)
             for k in parts[:2]]
    assert all(3 * c < r for c, r in zip(errors, reach)), (errors, reach)


def test_passing_over_empty_cells_changes_no_pixel(renderer, monkeypatch):
    """A cell passed over has no value within a table cell of its corners' range with
    opacity: walked, its pieces would read exactly zero from the table. With every cell
    counted as one that may show something (no empty cube: every cell walked) the image
    is the same bit for bit."""
    scene = ml_scene()
    opts = dict(step=4.0 * scene.volume.min_spacing, preintegrate=True, refine=2, refine_walk="crossings")
    plan = raycast.make_plan(scene, **opts)
    assert 0.5 < (plan.crossings.empty_cubes[0] > 0).mean() < 1.0      # most cells are passed over
    skipped = renderer.render(scene, **opts)
    # every cell walked: each one counted as one that may show something
    walk_cells = crossing_walk.walk_cells
    monkeypatch.setattr(crossing_walk, "walk_cells", lambda volume, tf, table, occupancy: walk_cells(
        volume, tf, table, lambda ranges, tf, table: np.ones(ranges[0].shape)))
    walked_all = dvr_gl.Renderer()
    try:
        every = walked_all.render(scene, **opts)
    finally:
        walked_all.release()
    assert skipped[..., 3].max() > 0.5
    np.testing.assert_array_equal(skipped, every)


def test_empty_cubes_are_the_largest_towards_each_octant():
    """One visible block of cells among empty ones: each cell's cube towards an octant is
    the largest of the codes' sides that keeps clear of it, where its centre lies in the
    volume (cells beyond count as clear), or at least the side of the Chebyshev distance
    (the cube within the empty one centred on the cell): against a brute-force search.
    The walk map packs the eight codes, and numbers the visible cells."""
    volume = dvr_gl.Volume(np.zeros((12, 13, 14), np.float32))
    values = volume.values(np.float32).copy()
    values[3, 4, 5] = 100.0                  # the eight cells around this sample see it
    volume = dvr_gl.Volume(values)
    tf = dvr_gl.TransferFunction(color=[(0, 1, 1, 1), (100, 1, 1, 1)], opacity=[(0, 0.0), (50, 0.0), (100, 1.0)])
    plan = raycast.make_plan(dvr_gl.Scene(volume, tf, dvr_gl.default_camera(volume), 8, 8), preintegrate=True,
                             refine=2, refine_walk="crossings")
    cw = plan.crossings
    assert cw.empty_cubes.shape == (8, 11, 12, 13)
    shows = np.zeros((11, 12, 13), bool)
    shows[2:4, 3:5, 4:6] = True
    sides = [int(crossing_walk.cube_reach(c)) + 1 for c in range(1, 16)]
    assert sides == [1, 3, 5, 7, 9, 13, 17, 25, 33, 49, 65, 97, 129, 193, 257]
    size = np.array(shows.shape)
    grid = np.stack(np.indices(shows.shape), axis=-1)
    seen = grid[shows]
    for octant in range(8):
        step = np.array([-1 if octant & 4 else 1, -1 if octant & 2 else 1, -1 if octant & 1 else 1])  # z, y, x
        for cell in np.ndindex(shows.shape):
            here = np.array(cell)
            distance = np.abs(seen - here).max(axis=1).min()     # Chebyshev, to the nearest visible cell

            def clear(k):
                ends = here + step * (k - 1)
                lo, hi = np.maximum(np.minimum(here, ends), 0), np.minimum(np.maximum(here, ends), size - 1)
                centre = here + step * (k // 2)
                inside = ((centre >= 0) & (centre < size)).all()
                return k <= distance or (inside and not shows[lo[0]:hi[0] + 1, lo[1]:hi[1] + 1, lo[2]:hi[2] + 1].any())
            expected = max((c for c, k in enumerate(sides, start=1) if clear(k)), default=0)
            assert cw.empty_cubes[(octant,) + cell] == expected, (octant, cell)
    # next to the visible block: away from it a cube 13 cells a side, towards it one cell
    assert (cw.empty_cubes[0, 4, 4, 4], cw.empty_cubes[7, 4, 4, 4]) == (6, 1)
    word = cw.walk_map[0, 0, 0]
    assert [(int(word) >> (4 * o)) & 15 for o in range(8)] == list(cw.empty_cubes[:, 0, 0, 0])
    assert cw.walk_map[shows].tolist() == [n << 4 for n in range(8)]


def test_knots_and_support():
    tf = dvr_gl.TransferFunction(color=[(0, 1, 1, 1), (10, 1, 1, 1)],
                                 opacity=[(0, 0.0), (4, 0.0), (5, 0.9), (6, 0.0), (10, 0.0)])
    np.testing.assert_array_equal(crossing_walk.knot_values(tf), [4.0, 6.0])
    assert crossing_walk.support(tf) == (4.0, 6.0)
    assert crossing_walk.support(TF)[1] == np.inf           # opacity up to the last knot and beyond


def test_crossing_walk_errors():
    scene = _scene(SPIKE)
    with pytest.raises(ValueError, match="refine_walk must be one of even, reach, crossings"):
        raycast.make_plan(scene, preintegrate=True, refine=4, refine_walk="cells")
    values = scene.volume.values(np.float32).copy()
    values[0, 0, 0] = np.nan
    masked = scene.replace(volume=dvr_gl.Volume(values, spacing=scene.volume.spacing, mask_nonfinite=True))
    with pytest.raises(ValueError, match="refine_walk='crossings' does not yet take volumes with non-finite"):
        raycast.make_plan(masked, preintegrate=True, refine=4, refine_walk="crossings")


def test_tolerance_weighs_the_crossing_walk_where_opacity_is_narrow(renderer):
    """The pilot measures the walk by crossings as one more way only where the values
    with opacity are a narrow share of the data's; asked for, a request is kept."""
    scene = ml_scene(48, 40)
    assert {"preintegrate": True, "refine": tolerance.REFINE_PARTS, "refine_walk": "crossings"} \
        in tolerance.samplings(scene)
    assert not any(w.get("refine_walk") == "crossings" for w in tolerance.samplings(_scene(TF)))
    opts = dict(preintegrate=True, refine=4, refine_walk="crossings")
    image = renderer.render(scene, tolerance=1e-2, **opts)
    assert renderer.last_choice.refine_walk == "crossings"
    assert metrics.rmse(image, reference.exact(scene)) <= 1e-2


def test_stored_coefficients_give_the_trilinear_field():
    """The walk map numbers the cells that may show something in order (n << 4 in the n-th);
    the coefficient texture holds each one's trilinear field: checked against the
    trilinear interpolation of its eight corners at random points in it."""
    scene = ml_scene()
    plan = raycast.make_plan(scene, step=4.0 * scene.volume.min_spacing, preintegrate=True, refine=2,
                             refine_walk="crossings")
    cw = plan.crossings
    visible = np.flatnonzero(cw.empty_cubes[0].ravel() == 0)
    np.testing.assert_array_equal(cw.walk_map.ravel()[visible] >> 4, np.arange(visible.size))
    assert (cw.walk_map.ravel()[visible] & 15 == 0).all() and (cw.walk_map[cw.empty_cubes[0] > 0] & 15 > 0).all()
    rng = np.random.default_rng(3)
    pick = rng.choice(visible.size, 50, replace=False)
    row, col = pick // crossing_walk.COEFFICIENT_ROW, 2 * (pick % crossing_walk.COEFFICIENT_ROW)
    c = np.concatenate([cw.coefficients[row, col], cw.coefficients[row, col + 1]], axis=1).astype(np.float64)
    k, j, i = np.unravel_index(visible[pick], cw.empty_cubes.shape[1:])
    x, y, z = rng.random((3, pick.size))
    v = scene.volume.values(np.float64)
    corners = {(a, b, e): v[k + e, j + b, i + a] for a in (0, 1) for b in (0, 1) for e in (0, 1)}
    trilinear = sum(corners[a, b, e] * (x if a else 1 - x) * (y if b else 1 - y) * (z if e else 1 - z)
                    for (a, b, e) in corners)
    field = (c[:, 0] + c[:, 1] * x + c[:, 2] * y + c[:, 3] * z + c[:, 4] * x * y + c[:, 5] * x * z
             + c[:, 6] * y * z + c[:, 7] * x * y * z)
    # each coefficient rounded to float32 (half an ulp, 2^-24 of its size): sizes at most
    # 1, 2 (three), 4 (three) and 8 times the largest value, weights at most 1: 27 in all
    np.testing.assert_allclose(field, trilinear, rtol=0, atol=27 * 2.0 ** -24 * np.abs(v).max())
