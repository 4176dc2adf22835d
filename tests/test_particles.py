"""Particle-based volume rendering (technique "particles"): GL against its NumPy
reference, the density derivation on a closed form, convergence like 1/sqrt(R), and
what is generated when.

Tolerance against the reference. Both draw the same particles; a pixel's colour is the
TF's at the first sphere its ray enters, computed in float32 by GL (a few 1e-7) and in
float64 here. A pixel can pick another particle only where its ray grazes a sphere or two
entries tie within float32 rounding; we allow 0.2 % of the covered pixels that (0 seen).
"""

import math

import numpy as np
import pytest

import dvr_gl
from dvr_gl import Camera, Scene, TransferFunction, Volume
from dvr_gl.techniques import particle_sets as pbvr
from dvr_gl import data as bundled
from dvr_gl.techniques import particles as technique

REF_TOL = 1e-6


def head_scene(cam=None, w=64, h=64):
    vol = bundled.ct_head()
    return Scene(vol, bundled.ct_head_tf(), cam or dvr_gl.default_camera(vol, azimuth=30, elevation=15), w, h)


def assert_matches_reference(renderer, scene, **options):
    img = renderer.render(scene, technique="particles", **options)
    ref = dvr_gl.reference.render(scene, technique="particles", **options)
    differ = (np.abs(img - ref).max(-1) > REF_TOL).sum()
    covered = (ref[..., 3] > 0).sum()
    assert covered > 50
    assert differ <= 0.002 * covered, (differ, covered)
    return img, ref


def test_gl_matches_reference_on_grids(renderer):
    vol = bundled.ct_head()
    lo, hi = vol.bounds
    c = (lo + hi) / 2
    for cam in (dvr_gl.default_camera(vol, azimuth=30, elevation=15),
                Camera(c + np.array([60, 40, 220.0]), c, fov=30),                  # data beyond the image
                Camera(c + np.array([0, 0, 300.0]), c, ortho_height=150),
                Camera(c + np.array([10, 5, 20.0]), c + np.array([30, 0, -60.0]), fov=70)):   # eye inside
        assert_matches_reference(renderer, Scene(vol, bundled.ct_head_tf(), cam, 72, 56), repetitions=2)


def test_gl_matches_reference_on_a_mesh(renderer):
    mesh = bundled.delaunay_ball()
    scene = Scene(mesh, bundled.synthetic_tf(), dvr_gl.default_camera(mesh, azimuth=20, elevation=10), 64, 64)
    assert_matches_reference(renderer, scene, repetitions=2, seed=3)


def constant_box(alpha=0.3, n=17):
    vol = Volume(np.full((n, n, n), 0.5), spacing=(1.0, 1.0, 1.0))
    tf = TransferFunction([(0, 0.9, 0.6, 0.2), (1, 0.9, 0.6, 0.2)], [(0, alpha), (1, alpha)], unit_distance=4.0)
    return vol, tf


def test_constant_box_closed_form(renderer):
    """Density tau / (pi r^2) makes the expected image the emission-absorption one: the
    mean alpha over the image (averaged over 8 seeds, 8 repetitions each) equals the
    closed form 1 - (1 - alpha)^(L / u) within 4 standard errors of the seeds' spread
    plus the silhouette's share (discs reach r beyond the box outline: well below 1 %)."""
    vol, tf = constant_box()
    cam = Camera((30.0, 22.0, 40.0), (8.0, 8.0, 8.0), fov=35)
    scene = Scene(vol, tf, cam, 64, 64)
    exact = dvr_gl.reference.exact(scene)
    means = [renderer.render(scene, technique="particles", repetitions=8, seed=k)[..., 3].mean() for k in range(8)]
    spread = np.std(means, ddof=1) / math.sqrt(len(means))
    want = exact[..., 3].mean()
    assert abs(np.mean(means) - want) < 4 * spread + 0.005 * want, (np.mean(means), want, spread)
    # colour is the TF's, so C = c A exactly per pixel
    img = renderer.render(scene, technique="particles", repetitions=8)
    assert np.allclose(img[..., :3], img[..., 3:] * np.array([0.9, 0.6, 0.2]), atol=1e-6)


def test_error_falls_like_one_over_sqrt_repetitions(renderer):
    scene = head_scene()
    exact = dvr_gl.reference.exact(scene)
    reps = [1, 4, 16, 64]
    rmse = [math.sqrt(np.mean((renderer.render(scene, technique="particles", repetitions=R) - exact) ** 2))
            for R in reps]
    slope = np.polyfit(np.log(reps), np.log(rmse), 1)[0]
    assert -0.6 < slope < -0.4, (slope, rmse)
    assert rmse[-1] <= rmse[0] / 5, rmse


def test_same_seed_same_image_and_turning_generates_nothing(renderer, monkeypatch):
    scene = head_scene()
    calls = []
    real = pbvr.generate
    monkeypatch.setattr(pbvr, "generate", lambda *a, **k: calls.append(a) or real(*a, **k))
    first = renderer.render(scene, technique="particles", repetitions=3, seed=5)
    assert len(calls) == 3
    for azimuth in (40, 75, 160):
        turned = scene.replace(camera=dvr_gl.default_camera(scene.volume, azimuth=azimuth, elevation=15))
        plan = technique.make_plan(turned, repetitions=3, seed=5, tables=renderer.tables)
        assert plan.generate_seconds == 0.0 and plan.radius == pbvr.default_radius(scene)
        renderer.render(turned, technique="particles", repetitions=3, seed=5)
    assert len(calls) == 3
    again = renderer.render(scene, technique="particles", repetitions=3, seed=5)
    assert np.array_equal(first, again)
    other = renderer.render(scene, technique="particles", repetitions=3, seed=6)
    assert not np.array_equal(first, other)
    assert len(calls) == 6
    more = technique.make_plan(scene, repetitions=5, seed=5, tables=renderer.tables)   # sets 0-2 reused
    assert len(calls) == 8 and more.sets[:3] == technique.make_plan(scene, repetitions=3, seed=5,
                                                                    tables=renderer.tables).sets


def test_only_cells_with_opacity_make_particles(renderer):
    vol = bundled.ct_head()
    empty = TransferFunction([(0, 1, 1, 1), (4000, 1, 1, 1)], [(0, 0.0), (4000, 0.0)])
    scene = Scene(vol, empty, dvr_gl.default_camera(vol), 32, 32)
    plan = technique.make_plan(scene, repetitions=2)
    assert plan.count == 0 and all(s.candidates == 0 and s.cells == 0 for s in plan.sets)
    assert renderer.render(scene, technique="particles").max() == 0.0
    # a band of the range: only cells whose range meets it emit
    band = TransferFunction([(0, 1, 1, 1), (4000, 1, 1, 1)], [(0, 0.0), (1500, 0.0), (1600, 0.4), (1700, 0.0)])
    s = pbvr.generate(vol, band, 1.0)
    v = vol.values()
    cells_lo = np.minimum.reduce([v[z:z + v.shape[0] - 1, y:y + v.shape[1] - 1, x:x + v.shape[2] - 1]
                                  for z in (0, 1) for y in (0, 1) for x in (0, 1)])
    cells_hi = np.maximum.reduce([v[z:z + v.shape[0] - 1, y:y + v.shape[1] - 1, x:x + v.shape[2] - 1]
                                  for z in (0, 1) for y in (0, 1) for x in (0, 1)])
    assert s.cells == int(((cells_hi > 1500) & (cells_lo < 1700)).sum())
    assert s.count > 0 and ((s.scalars > 1500) & (s.scalars < 1700)).all()


def test_thinning_gives_the_density():
    """The particle count per set is Poisson with mean integral(tau) / (pi r^2): on a
    linear ramp through a linear opacity the integral has a closed form."""
    n = 9
    ramp = np.broadcast_to(np.linspace(0, 1, n), (n, n, n)).copy()
    vol = Volume(ramp, spacing=(1.0, 1.0, 1.0))
    tf = TransferFunction([(0, 1, 1, 1), (1, 1, 1, 1)], [(0, 0.0), (1, 0.5)], unit_distance=2.0)
    # tau(s) = -ln(1 - s / 2) / 2 along x in [0, 8] (s = x / 8), the same over y, z (8 x 8)
    x = np.linspace(0, 8, 200001)
    integral = 64 * np.trapezoid(-np.log1p(-(x / 8) / 2) / 2, x)
    radius = 0.05
    counts = [pbvr.generate(vol, tf, radius, seed=0, repetition=k).count for k in range(6)]
    mean = integral / (math.pi * radius ** 2)
    assert abs(np.mean(counts) - mean) < 4 * math.sqrt(mean / len(counts)), (np.mean(counts), mean)


def test_grid_and_its_tetrahedralisation_agree_within_noise(renderer):
    """A linear field is the same function on the grid and on its Kuhn tetrahedra, so both
    particle images estimate the same exact image: they differ by their two noises."""
    from dvr_gl.model.cell_split import grid_to_tets
    n = 9
    z, y, x = np.meshgrid(*(np.linspace(0, 1, n),) * 3, indexing="ij")
    vol = Volume(0.2 + 0.5 * x + 0.3 * z, spacing=(1.0, 1.0, 1.0))
    tf = TransferFunction([(0, 0.1, 0.3, 0.9), (1, 0.9, 0.3, 0.1)], [(0, 0.05), (1, 0.5)], unit_distance=3.0)
    cam = Camera((14.0, 10.0, 18.0), (4.0, 4.0, 4.0), fov=40)
    grid = Scene(vol, tf, cam, 48, 48)
    mesh = grid.replace(volume=grid_to_tets(vol))
    exact = dvr_gl.reference.exact(grid)
    g = renderer.render(grid, technique="particles", repetitions=16, radius=0.1)
    m = renderer.render(mesh, technique="particles", repetitions=16, radius=0.1, seed=1)
    eg, em = (math.sqrt(np.mean((i - exact) ** 2)) for i in (g, m))
    assert 0.5 < eg / em < 2.0, (eg, em)
    assert math.sqrt(np.mean((g - m) ** 2)) < 1.25 * math.hypot(eg, em)
    assert abs(g[..., 3].mean() - m[..., 3].mean()) < 0.05 * exact[..., 3].mean()


def test_options_are_checked(renderer):
    scene = head_scene(w=16, h=16)
    for kwargs, words in (({"repetitions": 0}, "repetitions"), ({"seed": -1}, "seed"),
                          ({"radius": -1.0}, "radius"), ({"radius": float("nan")}, "radius"),
                          ({"sampler": "metropolis?"}, "sampler"), ({"step": 1.0}, "step")):
        with pytest.raises(ValueError, match=words):
            technique.make_plan(scene, **kwargs)
    with pytest.raises(ValueError, match="composite"):
        technique.make_plan(scene.replace(mode="mip"))
    with pytest.raises(ValueError, match="radius"):
        technique.make_plan(scene, radius=1e-4)          # far too many particles


def test_samplers_on_a_feature_inside_one_cell():
    """A narrow opacity spike in the middle of one cell's range: the corners see no
    opacity, so the classic samplers (count from the corners' average) make no particles,
    while thinning finds the right count; with a linear opacity all three agree."""
    vol = Volume(np.broadcast_to(np.array([0.0, 1.0]), (2, 2, 2)).copy(), spacing=(4.0, 4.0, 4.0))
    spike = TransferFunction([(0, 1, 1, 1), (1, 1, 1, 1)], [(0, 0.0), (0.45, 0.0), (0.5, 0.6), (0.55, 0.0), (1, 0.0)],
                             unit_distance=1.0)
    radius = 0.05
    x = np.linspace(0, 1, 400001)
    integral = 16 * 4 * np.trapezoid(pbvr.extinction(spike, x), x)   # cross-section 4 x 4, length 4
    mean = integral / (math.pi * radius ** 2)
    counts = [pbvr.generate(vol, spike, radius, repetition=k).count for k in range(4)]
    assert abs(np.mean(counts) - mean) < 4 * math.sqrt(mean / 4)
    for sampler in ("uniform", "metropolis"):
        assert pbvr.generate(vol, spike, radius, sampler=sampler).count == 0
    ramp = TransferFunction([(0, 1, 1, 1), (1, 1, 1, 1)], [(0, 0.1), (1, 0.1)], unit_distance=1.0)
    counts = {s: np.mean([pbvr.generate(vol, ramp, 0.2, repetition=k, sampler=s).count for k in range(4)])
              for s in pbvr.SAMPLERS}
    want = float(pbvr.extinction(ramp, 0.5)) * 64 / (math.pi * 0.04)
    for s, c in counts.items():
        assert abs(c - want) < 4 * math.sqrt(want / 4), (s, c, want)
    # metropolis moves particles towards the opacity: on a ramp of opacity its mean scalar rises
    rising = TransferFunction([(0, 1, 1, 1), (1, 1, 1, 1)], [(0, 0.0), (1, 0.8)], unit_distance=1.0)
    uniform = pbvr.generate(vol, rising, 0.2, sampler="uniform").scalars.mean()
    moved = pbvr.generate(vol, rising, 0.2, sampler="metropolis").scalars.mean()
    assert 0.45 < uniform < 0.55 and moved > 0.6


def test_long_generation_shows_progress(monkeypatch, capsys):
    monkeypatch.setattr(technique, "PROGRESS_CANDIDATES", 0)
    plan = technique.make_plan(head_scene(w=32, h=32), repetitions=3)
    err = capsys.readouterr().err
    assert plan.count > 0 and "particles: set 3 of 3" in err and "3/3" in err


def test_default_radius_with_the_eye_inside_the_data():
    """Half a pixel at the data's centre, but at least at a quarter of its diagonal: an eye
    at the centre does not ask for infinitely small particles."""
    vol = bundled.ct_head()
    lo, hi = vol.bounds
    c = (lo + hi) / 2
    inside = Scene(vol, bundled.ct_head_tf(), Camera(c, c + np.array([0, 0, -1.0]), fov=60), 64, 64)
    outside = head_scene()
    r_in, r_out = pbvr.default_radius(inside), pbvr.default_radius(outside)
    assert 0 < r_in <= r_out and r_in > 0.05 * r_out
    assert r_out <= 0.5 * vol.min_spacing                       # never wider than half a cell
    far = outside.replace(width=16, height=16)
    assert pbvr.default_radius(far) == 0.5 * vol.min_spacing
    assert technique.make_plan(inside).count > 0
