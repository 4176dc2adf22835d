"""Opaque geometry (``Scene.geometry``) in projected tetrahedra ("tetra") and its NumPy twin.

Each fragment's cell segment is cut at its pixel's first surface (t_hit), its end value
interpolated along the cell's linear field, as the clip cuts it; the surface's lit colour
is the backmost layer (composite), or goes behind the shortened ray's classified value
(mip, minip, average).

Closed forms. The unit cube of six tets with the linear field ``s = z + 0.2 x`` of
test_clip_tetra.py, seen orthographically along -z, with a square at z = 0.4 (normal
+-z) that reaches beyond the cube in y. A ray through the square inside the cube keeps
the chord from z = 1 down to 0.4: composite is test_clip_tetra's quadrature over the box
z >= 0.4 with the surface behind (``C + T lit``, ``A = 1``); mip, minip and average are
the field's values 1 + 0.2x, 0.4 + 0.2x and their mean, classified, with the surface
behind (``C + (1 - a) lit``). With the headlight ``|N.L| = 1``, so ``lit = colour (ka + kd)
+ ks``. A ray through the square beyond the cube sees the square alone; one missing it
sees the whole cube.

Tolerances. Against the closed form: ``GL_TOL`` of test_tetra.py (the float32 chord
arithmetic; the cut at t_hit is one more float32 distance, of the same relative error)
plus the term of the rasterised t_hit below. GL against its twin on the Delaunay ball with
an icosphere inside: per pixel ``GL_TOL`` plus the term test_geometry.py derives for the
ray caster's t_hit (``surface_tolerance``), with this technique's sensitivity to it. The
rasterised t differs from the twin's float64 hit by the window position's rounding
(``spread`` over ``REACH`` px scaled to 16 u of the image size) and the box-relative
position's (8 u (t + |eye| + diagonal)); moving a segment's end by dt changes a composite
pixel by at most ``(1 + lit) tau_max dt`` (the segment integral is exact, so only the
piece gained or lost counts: its opacity is at most tau_max dt, and the surface's weight
T moves by as much), and a reduction by ``(1 + lit) (max|alpha'| + max|c'|) G dt`` (the
end value moves by G dt, G the largest cell gradient; the mean of a segment as much at
most, the field being G-Lipschitz along a ray of the convex ball); the lit colour adds
64 u (lit + ks n). Pixels whose coverage the rasteriser's snapping may decide otherwise
(``coverage_and_reach``) are left out, as in test_geometry.py; measured, none differs.
"""

import numpy as np
import pytest

import dvr_gl
from dvr_gl import Scene, metrics, reference
from dvr_gl.data import delaunay_ball
from dvr_gl.model.mesh import cell_fields
from dvr_gl.techniques import tetra

from test_clip_tetra import ALONG_Z, RAMP_CUBE, RAMP_TF, ball_scene, quadrature
from test_geometry import REACH, U32, coverage_and_reach, headlight_lit, icosphere, inside, pixel_xy, square
from test_tetra import GL_TOL

SQUARE = square(0.2, 0.8, 0.1, 1.4, 0.4)


def tetra_surface_tolerance(scene, spread, t):
    """Per pixel: GL_TOL plus what the rasterised t_hit moves a pixel by (module docstring)."""
    tf, mesh = scene.tf, scene.volume
    ka, kd, ks, n = scene.phong
    lit = max(float(np.max(s.color)) for s in scene.geometry) * (ka + kd) + ks
    knots = tf.knots
    slope_a = float(np.abs(np.diff(tf.opacity(knots)) / np.diff(knots)).max())
    slope_c = float(np.abs(np.diff(tf.color(knots), axis=0) / np.diff(knots)[:, None]).max())
    a_max = float(tf.opacity(knots).max())
    if scene.mode == "composite":
        rate = (1 + lit) * -np.log1p(-a_max) / tf.unit_distance
    else:
        G = float(np.linalg.norm(cell_fields(mesh)[:, 0, :3], axis=1).max())
        rate = (1 + lit) * (slope_a + slope_c) * G
    lo = mesh.bounds[0]
    eye = float(np.linalg.norm(scene.camera.eye - lo))
    window = 16 * U32 * max(scene.width, scene.height)
    dt = spread * window / REACH + 8 * U32 * (np.where(np.isfinite(t), t, 0.0) + eye
                                             + float(np.linalg.norm(mesh.extent)))
    return GL_TOL + rate * dt + 64 * U32 * (lit + ks * n)


# ---------------------------------------------------------------------------- closed forms

def _cube_scene(mode="composite"):
    return Scene(RAMP_CUBE, RAMP_TF, ALONG_Z, 32, 32, mode=mode, geometry=[SQUARE])


def test_the_closed_form_scene_has_every_kind_of_pixel():
    x, y = pixel_xy(_cube_scene())
    data = inside(x, y, 0, 1, 0, 1)
    on = inside(x, y, 0.2, 0.8, 0.1, 1.4)
    assert (on & data).any() and (on & ~data).any() and (data & ~on).any() and (~on & ~data).any()


def test_a_linear_cube_with_a_square_inside_is_the_closed_form(renderer):
    scene = _cube_scene()
    x, y = pixel_xy(scene)
    on = inside(x, y, 0.2, 0.8, 0.1, 1.4)
    cut = quadrature(scene, ((0, 0, 0.4), (1, 1, 1)))
    whole = quadrature(scene, ((0, 0, 0), (1, 1, 1)))
    lit = headlight_lit(scene, SQUARE)
    C = np.where(on[..., None], cut[..., :3] + (1 - cut[..., 3:4]) * lit, whole[..., :3])
    A = np.where(on, 1.0, whole[..., 3])
    want = np.concatenate([C, A[..., None]], axis=-1)
    assert np.abs(reference.exact(scene, cache=False) - want).max() < 1e-9
    assert np.abs(reference.render(scene, technique="tetra") - want).max() < 2e-8
    _, _, spread, t = coverage_and_reach(scene)
    tol = tetra_surface_tolerance(scene, spread, t)
    gl = renderer.render(scene, technique="tetra")
    assert np.all(np.abs(gl - want).max(axis=-1) <= tol)
    # the surface is seen: without it the picture is the whole cube
    assert np.abs(renderer.render(scene.replace(geometry=()), technique="tetra") - want).max() > 0.2


@pytest.mark.parametrize("mode", ["mip", "minip", "average"])
def test_reductions_of_the_shortened_ray_with_the_surface_behind(renderer, mode):
    scene = _cube_scene(mode)
    x, y = pixel_xy(scene)
    data = inside(x, y, 0, 1, 0, 1)
    on = inside(x, y, 0.2, 0.8, 0.1, 1.4)
    # the field's values on the kept chord: z from 1 down to 0.4 on the square, to 0 off it
    low = np.where(on, 0.4, 0.0)
    s = 0.2 * x + {"mip": 1.0, "minip": low, "average": (1.0 + low) / 2}[mode]
    a = np.where(data, RAMP_TF.opacity(s), 0.0)
    C = RAMP_TF.color(s) * a[..., None]
    lit = headlight_lit(scene, SQUARE)
    C = np.where(on[..., None], C + (1 - a[..., None]) * lit, C)
    A = np.where(on, 1.0, a)
    want = np.concatenate([C, A[..., None]], axis=-1)
    assert np.abs(reference.exact(scene, cache=False) - want).max() < 1e-12
    assert np.abs(reference.render(scene, technique="tetra") - want).max() < 1e-12
    _, _, spread, t = coverage_and_reach(scene)
    tol = tetra_surface_tolerance(scene, spread, t)
    gl = renderer.render(scene, technique="tetra")
    assert np.all(np.abs(gl - want).max(axis=-1) <= tol)


def test_a_surface_in_front_of_every_cell_hides_them(renderer):
    """A square between the eye and the whole cube: every segment is cut away, the image
    is the square alone (and the empty background)."""
    sq = square(-0.5, 1.5, -0.5, 1.5, 2.0)
    scene = Scene(RAMP_CUBE, RAMP_TF, ALONG_Z, 16, 16, geometry=[sq])
    x, y = pixel_xy(scene)
    on = inside(x, y, -0.5, 1.5, -0.5, 1.5)
    want = np.where(on[..., None], np.append(headlight_lit(scene, sq), 1.0), 0.0)
    assert np.abs(reference.render(scene, technique="tetra") - want).max() < 1e-12
    assert np.abs(renderer.render(scene, technique="tetra") - want).max() < 1e-6


# ------------------------------------------------------------------------ the Delaunay ball

def _ball_surfaces():
    lo, hi = delaunay_ball().bounds
    centre = (lo + hi) / 2
    sphere = icosphere(centre + [-12.0, 10.0, -2.0], 12.0)
    # a tilted square through the ball and out of it
    tilted = dvr_gl.Surface([centre + [-45.0, -40.0, 10.0], centre + [5.0, -40.0, 20.0],
                             centre + [5.0, -10.0, 25.0], centre + [-45.0, -10.0, 15.0]],
                            [(0, 1, 2), (0, 2, 3)], color=(0.3, 0.8, 0.4))
    return [sphere, tilted]


def _check_against_twin(renderer, scene):
    gl = renderer.render(scene, technique="tetra")
    twin = reference.render(scene, technique="tetra")
    ambiguous, hit, spread, t = coverage_and_reach(scene)
    tol = tetra_surface_tolerance(scene, spread, t)
    error = np.abs(gl - twin).max(axis=-1)
    compared = ~ambiguous
    assert hit.sum() > 0.03 * hit.size
    assert np.all(error[compared] <= tol[compared]), (error[compared] / tol[compared]).max()
    return gl, twin, compared


@pytest.mark.parametrize("view", ["perspective", "orthographic", "along an axis", "45 degrees", "eye inside"])
def test_gl_matches_its_twin_on_the_delaunay_ball(renderer, view):
    scene = ball_scene(view).replace(geometry=_ball_surfaces())
    gl, _, _ = _check_against_twin(renderer, scene)
    plain = renderer.render(scene.replace(geometry=()), technique="tetra")
    assert metrics.max_abs_error(gl, plain) > 0.3                  # the surfaces are there


@pytest.mark.parametrize("mode", ["mip", "minip", "average"])
def test_gl_reductions_match_the_twin_on_the_delaunay_ball(renderer, mode):
    _check_against_twin(renderer, ball_scene("perspective", mode=mode).replace(geometry=_ball_surfaces()))


def test_lit_clipped_cells_with_a_surface_match_the_twin(renderer):
    lo, hi = delaunay_ball().bounds
    scene = ball_scene("perspective", clip_planes=[((lo + hi) / 2, (1.0, 0.3, 0.2))])
    _check_against_twin(renderer, scene.replace(geometry=_ball_surfaces(), shading=True))


@pytest.mark.parametrize("mode", ["composite", "mip"])
def test_error_against_exact_with_the_surface_stays_within_the_error_without_it(renderer, mode):
    """Tetra integrates each cell exactly: its error against the exact image is float32
    rounding, and cutting the segments at the surface adds none of its own (measured,
    perspective composite: RMSE 8.5e-7 with the surfaces, 9.6e-7 without; mip 1.3e-6, 1.6e-6)."""
    base = ball_scene("perspective", mode=mode)
    scene = base.replace(geometry=_ball_surfaces())
    err = metrics.rmse(renderer.render(scene, technique="tetra"), reference.exact(scene, cache=False))
    err_plain = metrics.rmse(renderer.render(base, technique="tetra"), reference.exact(base, cache=False))
    assert err <= err_plain, (err, err_plain)
    # against the exact image without the surfaces it is plainly wrong: the judge sees them
    assert metrics.rmse(renderer.render(scene, technique="tetra"), reference.exact(base, cache=False)) > 100 * err


def test_images_without_geometry_compile_no_geometry_code():
    scene = ball_scene("perspective")
    assert "GEOMETRY" not in tetra.make_plan(scene).defines
    assert tetra.make_plan(scene.replace(geometry=_ball_surfaces())).defines["GEOMETRY"] == 1
    mip = scene.replace(mode="mip")
    assert "GEOMETRY" not in tetra.make_plan(mip).defines
    assert tetra.make_plan(mip.replace(geometry=_ball_surfaces())).defines["GEOMETRY"] == 1


def test_nothing_is_made_again_per_frame(renderer):
    scene = ball_scene("perspective", size=24).replace(geometry=_ball_surfaces())
    renderer.render(scene, technique="tetra")
    made = len(renderer.created)
    renderer.render(scene, technique="tetra")
    renderer.render(scene.replace(camera=dvr_gl.default_camera(scene.volume, azimuth=80)), technique="tetra")
    assert len(renderer.created) == made


@pytest.mark.parametrize("mode", ["composite", "mip"])
def test_tiles_match_the_twin_as_the_whole_image_does(mode):
    """The surface pass is drawn per tile, as the cells are: the same bound holds."""
    scene = ball_scene("perspective", size=40, mode=mode).replace(geometry=_ball_surfaces())
    with dvr_gl.Renderer(max_tile=16) as tiled:
        _check_against_twin(tiled, scene)
