"""Opaque geometry (``Scene.geometry``) in 2D and 3D texture slicing: GL against the NumPy
twin with the surfaces in Marschner-Lobb and in the CT head (perspective and
orthographic, pre-integration on and off), the constant box's closed form, and the error
against the exact image with the surfaces within the error without them.

The rule (docs/contract.md, "Opaque geometry"): each ray's kept interval ends at its first
surface, ``range.y = min(range.y, t_hit)``, exactly as a clip cuts it (a slice behind the
surface is no slice for that ray, the slab that straddles it runs to it, a shortened chord
with no slice is the gap pass's), and the surface's lit colour, opacity 1, is the target's
content before the first slice is blended over it (the backmost layer)."""

import numpy as np
import pytest

import dvr_gl
from dvr_gl import metrics, reference
from dvr_gl.data import ct_head, ct_head_tf
from dvr_gl.reference.exact_geometry import surface_hits
from dvr_gl.techniques import get_technique, raycast
from test_geometry import (band_area, constant_scene, coverage_and_reach, icosphere, square, surface_tolerance,
                           _head_scenes, _ml_scenes)
from test_raycast import derived_tolerance
from test_slicing import preintegrated_tolerance, slice_tolerance

SIZE = 64
VARIANTS = [("slice2d", {}), ("slice2d", {"preintegrate": True}),
            ("slice3d", {}), ("slice3d", {"preintegrate": True})]


def _scenes():
    ml = _ml_scenes(SIZE)
    head = _head_scenes(SIZE)["head"]
    vol = head.volume
    return {
        "marschner-lobb, perspective": ml["perspective"],
        "marschner-lobb, ortho": ml["ortho"],
        "ct head, perspective": head,
        "ct head, ortho": head.replace(camera=dvr_gl.default_camera(vol, azimuth=-50, elevation=15, ortho=True)),
    }


def longest_segment(plan):
    """The longest piece of a ray one fragment stands for: the distance between slices
    along the ray (``step / cos`` for planes, ``step`` for shells, ``slice_distance / |d_w|``
    for a 2D stack) over every pixel's ray; the gap pass's pieces are no longer."""
    scene = plan.scene
    _, d = scene.camera.rays(scene.width, scene.height)
    d = d.reshape(-1, 3)
    if hasattr(plan, "axis"):
        return plan.slice_distance / float(np.abs(d[:, plan.axis]).min())
    if plan.shells:
        return plan.step
    return plan.step / float((d @ scene.camera.forward).min())


def geometry_tolerance(plan, spread, t):
    """A bound per pixel on |GL - twin|: the slicing bound without geometry
    (``test_slicing.slice_tolerance``, or ``preintegrated_tolerance`` over two table
    lookups per slice), plus the term ``test_geometry.surface_tolerance`` adds to the ray
    caster's for the rasterised ray end and the float32 lit colour. That term is the one
    of a ray caster whose last segment is as long as the longest slab here (the end
    moves the last segment's length and its midpoint alike): taken as ``surface_tolerance``
    of that ray caster's plan less its own ``derived_tolerance``."""
    base = slice_tolerance(plan) if plan.preint is None else preintegrated_tolerance(plan, 2 * plan.count)
    ray = raycast.make_plan(plan.scene, step=longest_segment(plan), ert_transmittance=0.0)
    return base + surface_tolerance(ray, spread, t) - derived_tolerance(ray)


def check_against_twin(renderer, scene, technique, opts):
    gl = renderer.render(scene, technique=technique, **opts)
    twin = reference.render(scene, technique, **opts)
    plan = get_technique(technique).make_plan(scene, **opts)
    ambiguous, hit, spread, t = coverage_and_reach(scene)
    tol = geometry_tolerance(plan, spread, t)
    error = np.abs(gl - twin).max(axis=-1)
    edge = np.zeros_like(hit)           # silhouettes: surface pixels beside one that misses
    for axis in (0, 1):
        change = np.diff(hit, axis=axis)
        lead = [slice(None)] * 2
        lead[axis] = slice(0, -1)
        trail = [slice(None)] * 2
        trail[axis] = slice(1, None)
        edge[tuple(lead)] |= change
        edge[tuple(trail)] |= change
    compared = ~ambiguous
    assert hit.sum() > 0.03 * hit.size
    assert (edge & compared).sum() >= 20
    assert ambiguous.sum() <= 2 * band_area(scene) + 5, (ambiguous.sum(), band_area(scene))
    return error, tol, compared, gl


@pytest.mark.parametrize("technique,opts", VARIANTS, ids=lambda v: str(v))
@pytest.mark.parametrize("name", list(_scenes()))
def test_slicing_with_geometry_matches_its_twin(renderer, name, technique, opts):
    scene = _scenes()[name]
    error, tol, compared, gl = check_against_twin(renderer, scene, technique, opts)
    assert np.all(error[compared] <= tol[compared]), (error[compared] / tol[compared]).max()
    plain = renderer.render(scene.replace(geometry=()), technique=technique, **opts)
    assert metrics.max_abs_error(gl, plain) > 0.3                  # the surfaces are there


@pytest.mark.parametrize("technique,opts", [("slice3d", {"proxy": "vertex"}), ("slice3d", {"shells": True}),
                                            ("slice2d", {"interpolate": 2})], ids=lambda v: str(v))
def test_slicing_options_with_geometry_match_the_twin(renderer, technique, opts):
    """The other proxies and the intermediate 2D slices end at the surface alike."""
    scene = _ml_scenes(48)["perspective"]
    error, tol, compared, _ = check_against_twin(renderer, scene, technique, opts)
    assert np.all(error[compared] <= tol[compared]), (error[compared] / tol[compared]).max()


@pytest.mark.parametrize("technique", ["slice2d", "slice3d"])
def test_slicing_gives_the_closed_form_to_its_float32_rounding(renderer, technique):
    """A constant box (test_geometry's closed form, a square inside the data and beyond
    its edge): every slab has the same value, so the slabs' opacities multiply to the
    closed form's ``(1 - a)^(L / u)`` whatever the slices, and GL matches it to the float32
    rounding of its blended slabs (``slice_tolerance``), as the ray caster does."""
    sq = square(4.0, 30.0, 2.0, 9.0, 6.5)
    scene = constant_scene(geometry=[sq])
    gl = renderer.render(scene, technique=technique)
    exact = reference.exact(scene, cache=False)
    plan = get_technique(technique).make_plan(scene)
    assert metrics.max_abs_error(gl, exact) <= max(slice_tolerance(plan), 1e-5)


#: RMSE against exact with the surfaces / without, Marschner-Lobb in perspective at 48 x 48
#: (measured: slice3d step 0.05 0.83, 0.025 0.79; slice2d 0.82, interpolate=1 0.74;
#: pre-integrated slice3d 0.87, slice2d 0.86): the surfaces hide data behind them and
#: bring no error of their own where GL and the exact image meet the same face
ACCURACY = [("slice3d", {"step": 0.05}), ("slice3d", {"step": 0.025}), ("slice2d", {}),
            ("slice2d", {"interpolate": 1}), ("slice3d", {"step": 0.05, "preintegrate": True}),
            ("slice2d", {"preintegrate": True})]


@pytest.mark.parametrize("technique,opts", ACCURACY, ids=lambda v: str(v))
def test_error_against_exact_is_within_the_error_without_geometry(renderer, technique, opts, tmp_path):
    scene = _ml_scenes(48)["perspective"]
    plain = scene.replace(geometry=())
    with_surfaces = metrics.rmse(renderer.render(scene, technique=technique, **opts),
                                 reference.exact(scene, cache_dir=tmp_path))
    without = metrics.rmse(renderer.render(plain, technique=technique, **opts),
                           reference.exact(plain, cache_dir=tmp_path))
    assert with_surfaces <= without, (with_surfaces, without)


def test_slice3d_error_with_geometry_falls_at_second_order(renderer, tmp_path):
    """Midpoint slabs with the last one ending at the surface: second order, as without
    geometry (test_slicing)."""
    scene = _ml_scenes(48)["perspective"]
    exact = reference.exact(scene, cache_dir=tmp_path)
    steps = np.array([0.1, 0.05, 0.025])
    errors = np.array([metrics.rmse(renderer.render(scene, technique="slice3d", step=d), exact) for d in steps])
    order = np.polyfit(np.log(steps), np.log(errors), 1)[0]
    assert 1.7 < order < 2.6, (errors, order)


def test_tiles_match_the_twin_as_the_whole_image_does():
    """The surface pass is drawn per tile, the slices too: the same bound holds."""
    scene = _ml_scenes(40)["perspective"]
    with dvr_gl.Renderer(max_tile=16) as tiled:
        for technique in ("slice2d", "slice3d"):
            error, tol, compared, _ = check_against_twin(tiled, scene, technique, {})
            assert np.all(error[compared] <= tol[compared]), (technique, (error[compared] / tol[compared]).max())


@pytest.mark.parametrize("technique", ["slice2d", "slice3d"])
def test_nothing_is_made_again_per_frame(renderer, technique):
    scene = _ml_scenes(32)["perspective"]
    renderer.render(scene, technique=technique)
    made = len(renderer.created)
    renderer.render(scene, technique=technique)
    renderer.render(scene.replace(camera=dvr_gl.default_camera(scene.volume, azimuth=40)), technique=technique)
    assert len(renderer.created) == made


def test_a_surface_in_front_of_the_data_hides_it_and_one_outside_shows(renderer):
    """A square in front of the whole box (every slice and the gap pass behind it) shows
    alone; a sphere beside the box, where no slice is drawn, shows too."""
    vol = ct_head()
    lo, hi = vol.bounds
    centre = (lo + hi) / 2
    cam = dvr_gl.default_camera(vol, azimuth=0, elevation=0)
    near = centre + 0.6 * (cam.eye - centre)
    span = float(np.linalg.norm(hi - lo))
    wall = dvr_gl.Surface([near + span * (a * cam.right + b * cam.true_up) for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))],
                          [(0, 1, 2), (0, 2, 3)], color=(0.2, 0.6, 0.4))
    width = float(hi[0] - lo[0])       # the view is along -z: x is across it
    beside = icosphere(centre + 0.67 * width * cam.right, 0.1 * width)    # in view, off the box
    for in_front, surface in ((True, wall), (False, beside)):
        scene = dvr_gl.Scene(vol, ct_head_tf(), cam, 32, 32, geometry=[surface])
        ambiguous, hit, _, _ = coverage_and_reach(scene)
        _, lit = surface_hits(scene)
        lit = lit.reshape(32, 32, 3)
        assert hit.sum() > 8
        for technique in ("slice2d", "slice3d"):
            gl = renderer.render(scene, technique=technique)
            twin = reference.render(scene, technique)
            assert np.abs(gl - twin)[~ambiguous].max() < 1e-5, technique
            shown = hit & ~ambiguous
            np.testing.assert_array_equal(gl[shown, 3], 1.0)
            if in_front:            # the surface alone: no data in front of it
                np.testing.assert_allclose(gl[shown, :3], lit[shown], rtol=0, atol=1e-5)
            else:
                assert (gl[~hit, 3] > 0.3).any()     # the data beside it
