"""Splatting (technique "splat"): GL against its NumPy reference, the kernel's
normalisation, a closed form, and the trade-offs it exists to show (holes against blur,
density).

Tolerance against the reference. Both composite the same splats in the same order; GL
works in float32. The kernel's exponent comes from the ray's offset at its closest
approach, whose float32 error is about eps * |q| (|q| the eye's distance from the
splat), so the exponent m^2 (at most cutoff^2) is off by about 2 cutoff eps |q| / sigma
and each splat's opacity relatively by as much; over the splats that reach a pixel
(opacity adds up to at most 1) that bounds the pixel's error, and every blend adds a
float32 rounding: bound(scene) = 2 cutoff eps |q|max / sigma_min + 1e-5.
"""

import math

import numpy as np
import pytest

import dvr_gl
from dvr_gl import Camera, Scene, TransferFunction, Volume
from dvr_gl import data as bundled
from dvr_gl.techniques import splat

EPS32 = 2.0 ** -23


def bound(scene, plan):
    lo, hi = scene.volume.bounds
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    far = float(np.linalg.norm(corners - scene.camera.eye, axis=1).max())
    return 2 * plan.cutoff * EPS32 * far / float(plan.sigma.min()) + 1e-5


def assert_matches_reference(renderer, scene, **options):
    img = renderer.render(scene, technique="splat", **options)
    ref = dvr_gl.reference.render(scene, technique="splat", **options)
    plan = splat.make_plan(scene, **options)
    assert plan.splats.count > 0 and ref[..., 3].max() > 0.1
    assert np.abs(img - ref).max() < bound(scene, plan), (np.abs(img - ref).max(), bound(scene, plan))
    return img


def test_gl_matches_reference(renderer):
    head = bundled.ct_head()
    lo, hi = head.bounds
    c = (lo + hi) / 2
    tf = bundled.ct_head_tf()
    for cam, options in ((dvr_gl.default_camera(head, azimuth=30, elevation=15), {}),
                         (Camera(c + np.array([0, 40, 300.0]), c, ortho_height=220), {"radius": 0.7}),
                         (Camera(c + np.array([10, 5, 20.0]), c + np.array([30, 0, -60.0]), fov=70), {})):
        assert_matches_reference(renderer, Scene(head, tf, cam, 64, 56), **options)
    field = bundled.synthetic(24)        # anisotropic resampling at density 2
    field = Volume(field.data, spacing=(1.0, 0.6, 1.8))
    cam = dvr_gl.default_camera(field, azimuth=35, elevation=25)
    assert_matches_reference(renderer, Scene(field, bundled.synthetic_tf(), cam, 48, 48), density=2)


def one_sample(radius, spacing=(1.0, 1.0, 1.0), alpha=0.2):
    v = np.zeros((9, 9, 9))
    v[4, 4, 4] = 1.0
    vol = Volume(v, spacing=spacing)
    tf = TransferFunction([(0, 1, 1, 1), (1, 1, 1, 1)], [(0, 0.0), (1, alpha)], unit_distance=2.0)
    return vol, tf


@pytest.mark.parametrize("spacing", [(1.0, 1.0, 1.0), (1.5, 0.7, 2.5)])
def test_footprint_integrates_to_the_kernel(renderer, spacing):
    """One sample, seen orthographically: the optical depth summed over the image times the
    pixel area is the sample's extinction times its cell volume (the kernel has unit
    integral once renormalised for its truncation), from any direction."""
    vol, tf = one_sample(0.7, spacing)
    c = (vol.bounds[0] + vol.bounds[1]) / 2
    tau_v = -math.log1p(-0.2) / 2.0 * float(np.prod(spacing))
    for direction in ((0, 0, 1.0), (1.0, 0.6, 0.3), (0.2, -1.0, 0.5)):
        d = np.array(direction) / np.linalg.norm(direction)
        up = (0, 1, 0) if abs(d[1]) < 0.9 else (1, 0, 0)
        cam = Camera(c + 30 * d, c, up=up, ortho_height=14.0)
        scene = Scene(vol, tf, cam, 160, 160)
        pixel_area = (14.0 / 160) ** 2
        for image in (renderer.render(scene, technique="splat", radius=0.7),
                      dvr_gl.reference.render(scene, technique="splat", radius=0.7)):
            od = -np.log1p(-np.asarray(image[..., 3], np.float64))
            assert od.sum() * pixel_area == pytest.approx(tau_v, rel=2e-3)


def test_constant_box_closed_form(renderer):
    """A constant field: at radius 0.7 the kernels' sum is flat to 1e-4 inside the box, so
    a ray through the middle sees the closed form 1 - (1 - alpha)^(L / u)."""
    n = 17
    vol = Volume(np.full((n, n, n), 0.5))
    tf = TransferFunction([(0, 0.9, 0.6, 0.2), (1, 0.9, 0.6, 0.2)], [(0, 0.2), (1, 0.2)], unit_distance=4.0)
    scene = Scene(vol, tf, Camera((8.0, 8.0, 40.0), (8.0, 8.0, 8.0), ortho_height=24.0), 48, 48)
    img = renderer.render(scene, technique="splat", radius=0.7)
    # the samples' trapezoid weights carry exactly the box's depth; the kernels reach past
    # it, and the ray through the middle collects all of it
    want = 1 - (1 - 0.2) ** (16.0 / 4.0)
    assert img[24, 24, 3] == pytest.approx(want, abs=2e-3)
    assert np.allclose(img[..., :3], img[..., 3:] * np.array([0.9, 0.6, 0.2]), atol=1e-6)


def test_holes_against_blur_and_density():
    """Against exact: too small a kernel leaves holes (stripes between sample planes), too
    large a kernel blurs; the default lies between, and density=2 lowers the error."""
    vol = bundled.synthetic(32)
    scene = Scene(vol, bundled.synthetic_tf(), dvr_gl.default_camera(vol, azimuth=25, elevation=20), 64, 64)
    exact = dvr_gl.reference.exact(scene)
    with dvr_gl.Renderer() as r:
        rmse = {k: math.sqrt(np.mean((r.render(scene, technique="splat", radius=k) - exact) ** 2))
                for k in (0.2, splat.DEFAULT_RADIUS, 1.0)}
        dense = math.sqrt(np.mean((r.render(scene, technique="splat", density=2) - exact) ** 2))
    assert rmse[splat.DEFAULT_RADIUS] < rmse[0.2] and rmse[splat.DEFAULT_RADIUS] < rmse[1.0], rmse
    assert dense < 0.7 * rmse[splat.DEFAULT_RADIUS], (dense, rmse)


def test_only_samples_with_opacity_are_drawn_in_depth_order(renderer):
    vol = bundled.ct_head()
    tf = bundled.ct_head_tf()
    scene = Scene(vol, tf, dvr_gl.default_camera(vol, azimuth=30, elevation=15), 32, 32)
    plan = splat.make_plan(scene)
    assert plan.splats.count == int((tf.opacity(vol.values()) > 0).sum())
    eye = scene.camera.eye - vol.bounds[0]
    dist = np.linalg.norm(plan.splats.points[plan.order] - eye, axis=1)
    assert np.all(np.diff(dist) <= 1e-3)                      # farthest first
    empty = TransferFunction([(0, 1, 1, 1), (4000, 1, 1, 1)], [(0, 0.0), (4000, 0.0)])
    blank = scene.replace(tf=empty)
    assert splat.make_plan(blank).splats.count == 0
    assert renderer.render(blank, technique="splat").max() == 0.0


def test_order_is_made_once_per_view(renderer):
    vol = bundled.ct_head()
    scene = Scene(vol, bundled.ct_head_tf(), dvr_gl.default_camera(vol), 16, 16)
    first = splat.make_plan(scene, tables=renderer.tables)
    again = splat.make_plan(scene, tables=renderer.tables)
    assert again.splats is first.splats and again.order is first.order
    turned = splat.make_plan(scene.replace(camera=dvr_gl.default_camera(vol, azimuth=40)), tables=renderer.tables)
    assert turned.splats is first.splats and turned.order is not first.order


def test_options_are_checked():
    vol = bundled.ct_head()
    scene = Scene(vol, bundled.ct_head_tf(), dvr_gl.default_camera(vol), 16, 16)
    for kwargs, words in (({"density": 0}, "density"), ({"density": 2.5}, "density"), ({"radius": 0}, "radius"),
                          ({"cutoff": float("inf")}, "cutoff"), ({"step": 1.0}, "step"), ({"target": "x"}, "target")):
        with pytest.raises(ValueError, match=words):
            splat.make_plan(scene, **kwargs)
    with pytest.raises(ValueError, match="composite"):
        splat.make_plan(scene.replace(mode="mip"))
    with pytest.raises(ValueError, match="density applies to grids"):
        splat.make_plan(Scene(bundled.delaunay_ball(), bundled.synthetic_tf(), scene.camera, 16, 16), density=2)


def test_mesh_points_are_splatted(renderer):
    """A tetrahedral mesh is splatted at its points: each kernel carries the point's lumped
    volume (the integral of its basis function) and is as wide as its edges on average,
    so over a far orthographic image the optical depth adds up to the integral of the
    extinction (a constant field: tau times the volume); GL matches the reference on the
    Delaunay ball."""
    from dvr_gl import TetMesh
    cube = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], float) * 2.0
    six = np.array([[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]])
    mesh = TetMesh(cube, six, np.full(8, 0.5))
    tf = TransferFunction([(0, 1, 1, 1), (1, 1, 1, 1)], [(0, 0.05), (1, 0.05)], unit_distance=1.0)
    scene = Scene(mesh, tf, Camera((1.0, 1.3, 30.0), (1.0, 1.0, 1.0), ortho_height=9.0), 180, 180)
    plan = splat.make_plan(scene)
    assert plan.splats.count == 8
    assert plan.splats.samples[:, 3].sum() == pytest.approx(-math.log1p(-0.05) * 8.0, rel=1e-6)
    for image in (renderer.render(scene, technique="splat"), dvr_gl.reference.render(scene, technique="splat")):
        od = -np.log1p(-np.asarray(image[..., 3], np.float64))
        assert od.sum() * (9.0 / 180) ** 2 == pytest.approx(-math.log1p(-0.05) * 8.0, rel=2e-3)
    ball = bundled.delaunay_ball()
    scene = Scene(ball, bundled.synthetic_tf(), dvr_gl.default_camera(ball, azimuth=20, elevation=10), 56, 56)
    img = assert_matches_reference(renderer, scene)
    exact = dvr_gl.reference.exact(scene)
    # the right picture (measured 0.068: Gaussian kernels on 4000 scattered points blur
    # the linear field; a black or noisy image is above 0.15)
    assert math.sqrt(np.mean((img - exact) ** 2)) < 0.1 and img[..., 3].max() > 0.3

