"""Opaque geometry (``Scene.geometry``) in splatting ("splat"), both kernels, and its
NumPy twin.

The rule (docs/contract.md, "Opaque geometry") is the clip rule with the first surface's
t_hit as the kept range's end:

- tent: each sheet's piece of a ray is cut at t_hit (a sheet behind it is no sheet for
  that ray, the piece straddling it runs to it and is classified at its middle; a
  shortened chord that crosses no sheet is the gap pass's), and the surface's lit colour,
  opacity 1, is blended under everything last (front to back: ``C + (1 - A) lit``,
  ``A = 1``);
- Gaussian: each kernel counts by its erf share of the ray up to t_hit (from the clip's
  start, or unclipped from minus infinity), and the surface is the backmost layer the
  splats are composited over.

Tolerances, GL against its twin. Pixels whose coverage the rasteriser's snapping may
decide otherwise (test_geometry's ``coverage_and_reach``: a ray 2^-7 px off the centre
meets another face, or none) are left out and counted (at most twice the area of those
bands, as test_geometry.py asserts); silhouette pixels outside the bands are compared.
Elsewhere the bound is the kernel's own, plus the terms test_geometry.py derives for a
rasterised t_hit (off the float64 hit by ``dt = spread * window / REACH + 8 u (t + |eye| +
diagonal)``, ``window`` 16 u max(W, H) px on llvmpipe, which interpolates from the float
positions, and where a rasteriser may interpolate from vertices snapped to its sub-pixel
grid twice half its step: ``window_rounding``; the tent's far larger terms take
test_geometry's llvmpipe figure) and the float32 lit colour (``64 u (lit + ks n)``):

- tent: tests/test_splat.py's ``tent_tolerance`` over the shortened rays (the sheets the
  twin draws, the straddling piece's length), plus two of 3D slicing's per-sample bounds
  (``test_slicing.per_slice_tolerance``) for the pieces that sample the volume's texture
  at their middle (at a cut or the surface), plus what moving the end by dt changes, as
  for 3D slicing (tests/test_geometry_slicing.py): the ray caster's term with a last
  segment as long as the longest piece (its midpoint term over-counts here: the sheet's
  value does not move with t_hit);
- Gaussian: tests/test_splat.py's ``gaussian_tolerance`` (and with clips
  ``reference.splat.clip_rounding``, tests/test_clip_points.py), plus the share's
  sensitivity to the end moved by dt (``reference.splat.surface_rounding``), times
  ``1 + lit``: a splat's opacity change moves its colour by as much and the surface's
  weight behind it by as much again, times the lit colour.

Against the exact image (48 x 48): RMSE with the surfaces / without them over the pixels
outside the coverage bands, tent at density 1 and 2: 0.79, 0.78 (Marschner-Lobb), 0.89,
0.92 (CT head); Gaussian 0.95 and 0.88. Over every pixel the same at density 1 (0.79,
0.96; Gaussian 0.95, 0.87), but on the head at density 2 1.68: its 11 pixels in the bands,
where GL's rasteriser and the float64 test disagree on coverage (a surface pixel against
a data pixel), outweigh the smaller error there. The last piece before the surface ends
up to half a step beyond its sheet, so it takes the field at its middle, as the first
piece behind a clip's cut does (tests/test_clip_points.py).
"""

import numpy as np
import pytest

import dvr_gl
from dvr_gl import metrics, reference
from dvr_gl.reference.common import box_rays
from dvr_gl.reference.exact_geometry import surface_hits
from dvr_gl.reference.splat import clip_rounding, surface_rounding
from dvr_gl.gl.context import current
from dvr_gl.techniques import raycast, splat

import test_splat
from test_geometry import (REACH, U32, _head_scenes, _ml_scenes, band_area, constant_scene, coverage_and_reach,
                           headlight_lit, inside, pixel_xy, square, surface_tolerance)
from test_raycast import derived_tolerance
from test_slicing import per_slice_tolerance
from test_splat import gaussian_tolerance, tent_tolerance


def _lit(scene):
    ka, kd, ks, n = scene.phong
    return max(float(np.max(s.color)) for s in scene.geometry) * (ka + kd) + ks


def window_rounding(renderer, scene):
    """How far, in pixels, the point a rasterised surface's position is interpolated at
    may lie from the pixel centre, to be scaled by ``spread / REACH`` (t's change over
    ``REACH`` px along x or y). llvmpipe interpolates from the float positions: 16 u of
    the image's size (measured, ``test_geometry.surface_tolerance``). GL lets a rasteriser
    interpolate from the vertices snapped to its sub-pixel grid (GL_SUBPIXEL_BITS), each
    moved by up to half a grid step per axis: the point moves by as much per axis (a convex
    combination of the moves), t by that times its slope along x plus along y, so twice
    the step's half (an NVIDIA GPU, 8 bits: t off the float64 hit by up to 0.64 of it)."""
    with current(renderer.ctx):
        info = renderer.ctx.info
    if "llvmpipe" in (info.get("GL_RENDERER") or ""):
        return 16 * U32 * max(scene.width, scene.height)
    return 2 * 2.0 ** -(int(info.get("GL_SUBPIXEL_BITS") or 4) + 1)


def _surface_dt(scene, spread, t, window):
    """How far GL's rasterised t_hit may be from the float64 hit (test_geometry), the
    window position's rounding ``window`` px (``window_rounding``)."""
    lo = scene.volume.bounds[0]
    eye = float(np.linalg.norm(scene.camera.eye - lo))
    return spread * window / REACH + 8 * U32 * (np.where(np.isfinite(t), t, 0.0) + eye
                                                + float(np.linalg.norm(scene.volume.extent)))


def tent_bound(plan, spread, t):
    """(H, W): tent_tolerance over the rays shortened at the twin's hits, plus the
    surface's terms (module docstring)."""
    scene = plan.scene
    o, d, t0, t1 = box_rays(scene)
    t1 = np.minimum(t1, surface_hits(scene)[0])
    with pytest.MonkeyPatch.context() as patch:          # tent_tolerance follows these rays
        patch.setattr(test_splat, "box_rays", lambda s: (o, d, t0, t1))
        base = tent_tolerance(plan)[..., 0]
    _, dirs = scene.camera.rays(scene.width, scene.height)
    longest = plan.step / float((dirs.reshape(-1, 3) @ scene.camera.forward).min())
    ray = raycast.make_plan(scene, step=1.5 * longest, ert_transmittance=0.0)   # the straddling piece
    # a piece with an end at a cut or the surface samples the volume's texture at its
    # middle: at most two per ray, each bounded as one of 3D slicing's samples
    ends = 2 * per_slice_tolerance(plan.gap) * max(1.0, 1.5 * longest / scene.tf.unit_distance)
    return base + ends + surface_tolerance(ray, spread, t) - derived_tolerance(ray)


def gaussian_bound(plan, spread, t, window):
    """(H, W): the Gaussian kernel's bound plus the surface's terms (module docstring)."""
    scene = plan.scene
    ka, kd, ks, n = scene.phong
    lit = _lit(scene)
    moved = surface_rounding(plan, _surface_dt(scene, spread, t, window))
    return (gaussian_tolerance(scene, plan)[..., 0] + clip_rounding(plan) + (1 + lit) * moved
            + 64 * U32 * (lit + ks * n))


def _silhouette(hit):
    """Surface pixels with a 4-neighbour that misses every surface, and back."""
    edge = np.zeros_like(hit)
    for axis in (0, 1):
        change = np.diff(hit, axis=axis)
        lead = [slice(None)] * 2
        lead[axis] = slice(0, -1)
        trail = [slice(None)] * 2
        trail[axis] = slice(1, None)
        edge[tuple(lead)] |= change
        edge[tuple(trail)] |= change
    return edge


_COVERAGE = {}


def _coverage(scene):
    """test_geometry's ``coverage_and_reach``, once per scene (five ray sets against
    every face: the slow part of a check)."""
    key = scene.digest()
    if key not in _COVERAGE:
        _COVERAGE[key] = coverage_and_reach(scene)
    return _COVERAGE[key]


def check_against_twin(renderer, scene, min_share=0.03, **options):
    gl = renderer.render(scene, technique="splat", **options)
    twin = reference.render(scene, "splat", **options)
    plan = splat.make_plan(scene, **options)
    ambiguous, hit, spread, t = _coverage(scene)
    tol = (tent_bound(plan, spread, t) if plan.kernel == "tent"
           else gaussian_bound(plan, spread, t, window_rounding(renderer, scene)))
    error = np.abs(gl - twin).max(axis=-1)
    compared = ~ambiguous
    assert hit.sum() > min_share * hit.size                          # the surface is in the picture
    assert (_silhouette(hit) & compared).sum() >= 20                 # silhouette pixels are compared
    assert ambiguous.sum() <= 2 * band_area(scene) + 5, (ambiguous.sum(), band_area(scene))
    assert np.all(error[compared] <= tol[compared]), (error[compared] / tol[compared]).max()
    return gl, twin


def _scenes(size):
    ml, head = _ml_scenes(size), _head_scenes(size)
    return {"marschner-lobb, perspective": ml["perspective"], "marschner-lobb, ortho": ml["ortho"],
            "marschner-lobb, clipped": ml["clipped"], "marschner-lobb, eye inside, lit": ml["eye inside, lit"],
            "ct head": head["head"], "ct head, lit from behind": head["head, lit from behind"]}


#: the Gaussian twin integrates every (pixel, kernel) pair: fewer scenes keep it quick
TWIN_CASES = [(name, "tent", 32 if name.startswith("ct") else 40) for name in _scenes(8) if name != "ct head"] + [
    ("marschner-lobb, perspective", "gaussian", 40), ("marschner-lobb, clipped", "gaussian", 40),
    ("ct head", "gaussian", 24)]


@pytest.mark.parametrize("name, kernel, size", TWIN_CASES)
def test_splat_with_geometry_matches_its_twin(renderer, name, kernel, size):
    scene = _scenes(size)[name]
    gl, _ = check_against_twin(renderer, scene, kernel=kernel)
    plain = renderer.render(scene.replace(geometry=()), technique="splat", kernel=kernel)
    assert metrics.max_abs_error(gl, plain) > 0.3                  # the surfaces are there


def test_tent_at_density_2_with_geometry_matches_its_twin(renderer):
    check_against_twin(renderer, _scenes(40)["marschner-lobb, perspective"], density=2)


@pytest.mark.parametrize("kernel", ["tent", "gaussian"])
def test_tiles_match_the_twin_as_the_whole_image_does(kernel):
    """Each tile (with the sprites' margin, 129 px a side) draws its own surface pass:
    the same bound as the whole image. A wide, short image makes several tiles."""
    scene = _scenes(8)["marschner-lobb, perspective"].replace(width=160, height=32)
    with dvr_gl.Renderer(max_tile=300) as tiled:
        check_against_twin(tiled, scene, kernel=kernel)


def test_a_constant_box_with_a_square_inside_is_the_closed_form(renderer):
    """tests/test_geometry.py's closed form (a square inside the constant box and beyond its
    edge): every sheet has the value and the pieces tile each ray's interval up to the
    square, so the tent renders ``c (1 - T) + T lit`` to tests/test_clip_points.py's
    constant-box bound, plus the rasterised end's ``(1 + lit) tau dt`` and the lit colour's
    rounding."""
    sq = square(4.0, 30.0, 2.0, 9.0, 6.5)
    scene = constant_scene(48, geometry=[sq])
    exact = reference.exact(scene, cache=False)
    gl = renderer.render(scene, technique="splat")
    plan = splat.make_plan(scene)
    _, _, t0, t1 = box_rays(scene)
    chord = np.maximum(t1 - t0, 0.0)
    tau = -np.log1p(-0.2) / 2.0
    ambiguous, hit, spread, t = coverage_and_reach(scene)
    lit = _lit(scene)
    ka, kd, ks, n = scene.phong
    tol = (64 * U32 * (float(chord.max()) / plan.step + 3) + tau * 8 * U32 * float(t1[chord > 0].max())
           + (1 + lit) * tau * _surface_dt(scene, spread, t, window_rounding(renderer, scene))
           + 64 * U32 * (lit + ks * n))
    x, y = pixel_xy(scene)
    assert (hit & inside(x, y, 0, 15, 0, 11)).sum() > 50 and (hit & ~inside(x, y, 0, 15, 0, 11)).sum() > 20
    error = np.abs(gl - exact).max(axis=-1)
    assert np.all(error[~ambiguous] <= tol[~ambiguous]), (error[~ambiguous] / tol[~ambiguous]).max()


@pytest.mark.parametrize("kernel", ["tent", "gaussian"])
def test_a_surface_in_front_of_all_data_shows_exactly_the_lit_surface(renderer, kernel):
    """A square well in front of the constant box (11 units above its top: 27 kernel
    standard deviations, so every Gaussian's share in front of it rounds to exactly 0),
    over part of the image: its pixels are exactly the surface alone (the image with a
    transparent transfer function), opaque, its lit colour to the float32 rounding; the
    rest shows the data."""
    sq = square(-2.0, 8.0, -4.0, 6.0, 30.0)
    scene = constant_scene(32, geometry=[sq])
    clear = dvr_gl.TransferFunction([(0.0, 0.0, 0.0, 0.0)], [(0.0, 0.0)])
    gl = renderer.render(scene, technique="splat", kernel=kernel)
    alone = renderer.render(scene.replace(tf=clear), technique="splat", kernel=kernel)
    ambiguous, hit, _, _ = coverage_and_reach(scene)
    shown = hit & ~ambiguous
    assert shown.sum() > 50 and (~hit & (gl[..., 3] > 0.3)).sum() > 50
    np.testing.assert_array_equal(gl[shown], alone[shown])
    np.testing.assert_array_equal(gl[shown, 3], 1.0)
    ka, kd, ks, n = scene.phong
    lit = headlight_lit(scene, sq)
    assert np.abs(gl[shown, :3] - lit).max() <= 64 * U32 * (_lit(scene) + ks * n)
    twin = reference.render(scene, "splat", kernel=kernel)
    np.testing.assert_array_equal(twin[shown, :3], np.broadcast_to(lit, twin[shown, :3].shape))


#: (scene, kernel, density) against the exact image at 48 x 48 (module docstring)
ACCURACY = [("marschner-lobb, perspective", "tent", 1), ("marschner-lobb, perspective", "tent", 2),
            ("ct head", "tent", 1), ("ct head", "tent", 2), ("marschner-lobb, perspective", "gaussian", 1),
            ("ct head", "gaussian", 1)]


@pytest.mark.parametrize("name, kernel, density", ACCURACY)
def test_error_against_exact_stays_within_the_error_without_the_surface(renderer, name, kernel, density):
    """Over the pixels outside the coverage bands (those the rasteriser may cover
    otherwise, counted in ``check_against_twin``) always, and over every pixel at
    density 1; measured ratios in the module docstring."""
    scene = _scenes(48)[name]
    plain = scene.replace(geometry=())
    compared = ~_coverage(scene)[0]
    image = renderer.render(scene, technique="splat", kernel=kernel, density=density)
    alone = renderer.render(plain, technique="splat", kernel=kernel, density=density)
    exact, exact_plain = reference.exact(scene), reference.exact(plain)
    err, err_plain = metrics.rmse(image[compared], exact[compared]), metrics.rmse(alone[compared], exact_plain[compared])
    assert err <= err_plain, (err, err_plain)
    if density == 1:
        assert metrics.rmse(image, exact) <= metrics.rmse(alone, exact_plain)
    assert metrics.rmse(image, exact_plain) > 3 * err        # the judge sees the surface


def test_images_without_geometry_compile_no_geometry_code():
    scene = _scenes(16)["marschner-lobb, perspective"]
    for kernel in ("tent", "gaussian"):
        assert "GEOMETRY" not in splat.make_plan(scene.replace(geometry=()), kernel=kernel).defines
        assert splat.make_plan(scene, kernel=kernel).defines["GEOMETRY"] == 1
    assert "GEOMETRY" not in splat.make_plan(scene).splat_defines      # the splat pass has no ray end


@pytest.mark.parametrize("kernel", ["tent", "gaussian"])
def test_nothing_is_made_again_per_frame(renderer, kernel):
    scene = _scenes(32)["marschner-lobb, perspective"]
    renderer.render(scene, technique="splat", kernel=kernel)
    made = len(renderer.created)
    renderer.render(scene, technique="splat", kernel=kernel)
    renderer.render(scene.replace(camera=dvr_gl.default_camera(scene.volume, azimuth=80)), technique="splat",
                    kernel=kernel)
    assert len(renderer.created) == made


@pytest.mark.parametrize("kernel", ["tent", "gaussian"])
def test_with_nothing_to_splat_the_surface_shows_alone(renderer, kernel):
    """A transfer function with no opacity: no sample is splatted, the image is the
    surfaces alone, as the twin's."""
    scene = _scenes(32)["ct head"].replace(tf=dvr_gl.TransferFunction([(0.0, 0.0, 0.0, 0.0)], [(0.0, 0.0)]))
    gl = renderer.render(scene, technique="splat", kernel=kernel)
    twin = reference.render(scene, "splat", kernel=kernel)
    ambiguous, hit, _, _ = coverage_and_reach(scene)
    ka, kd, ks, n = scene.phong
    assert hit.sum() > 20 and np.all(gl[hit & ~ambiguous, 3] == 1.0)
    assert np.abs(gl - twin).max(-1)[~ambiguous].max() <= 64 * U32 * (_lit(scene) + ks * n)
