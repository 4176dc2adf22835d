"""The VTK peer (``dvr_gl.bench.vtk_peer``) against closed forms.

VTK is an optional extra ("bench"): these tests skip only when ``vtk`` cannot be
imported. If VTK imports but cannot render headless, they fail.
"""

import numpy as np
import pytest

pytest.importorskip("vtk", reason="VTK is an optional extra (pip install 'dvr-gl[bench]')")

from dvr_gl import Camera, Scene, TransferFunction, Volume, default_camera  # noqa: E402
from dvr_gl.reference.common import ray_box  # noqa: E402
from dvr_gl.bench.vtk_peer import VTKPeer  # noqa: E402

COLOUR = np.array([1.0, 0.5, 0.25])


@pytest.fixture(scope="module")
def peer():
    p = VTKPeer()
    yield p
    p.close()


def constant_box(value=100, dtype=np.float32, n=16, spacing=(1.0, 1.5, 0.8), a=0.1, u=2.0):
    vol = Volume(np.full((n, n, n), value, dtype), spacing=spacing, origin=(-3.0, 1.0, 2.0))
    tf = TransferFunction([(0, *COLOUR), (255, *COLOUR)], [(0, a), (255, a)], unit_distance=u)
    return vol, tf


def test_renders_headless(peer):
    assert peer.renderer_string() not in ("", "unknown")


@pytest.mark.parametrize("ortho", [False, True])
@pytest.mark.parametrize("step", [1.0, 0.25])
def test_constant_box_alpha_matches_closed_form(peer, ortho, step):
    # A constant box of opacity a per unit distance u has A = 1 - (1 - a)^(L/u) on a ray
    # whose chord through the box is L. VTK takes a whole number of steps, first one step
    # past the entry, so it absorbs over a length within one step of L (measured: from
    # about -0.96 to +1.0 steps; half a step short on average). Its alpha is therefore
    # within (1 - A) * ((1 - a)^(-step/u) - 1) of the closed form -- one step's extra
    # absorption. Observed worst case: that bound to within 0.1 %; allow 1 % plus 1e-5
    # for float32 arithmetic in the shader and for pixels whose chord is a grazing sliver.
    a, u = 0.1, 2.0
    vol, tf = constant_box(a=a, u=u)
    camera = (default_camera(vol, azimuth=-50, elevation=35, ortho=True) if ortho
              else default_camera(vol, azimuth=30, elevation=20))
    scene = Scene(vol, tf, camera, width=48, height=40)
    image, seconds = peer.render(scene, step, repeats=1, warmup=0)
    assert image.shape == (40, 48, 4) and image.dtype == np.float32
    assert seconds > 0

    origins, dirs = camera.rays(scene.width, scene.height)
    t0, t1 = ray_box(origins, dirs, *vol.bounds)
    length = np.maximum(t1 - t0, 0.0)
    alpha = 1 - (1 - a) ** (length / u)
    bound = (1 - alpha) * ((1 - a) ** (-step / u) - 1)
    signed = image[..., 3] - alpha
    err = np.abs(signed)
    assert np.all(err <= 1.01 * bound + 1e-5), float((err / (bound + 1e-12)).max())
    # VTK falls short on average.
    assert signed[length > 0].mean() < 0
    # Rays that miss the box are transparent black; every ray that hits it sees it.
    assert np.all(image[length == 0] == 0)
    assert np.all(image[length > 0.5][..., 3] > 0)


def test_constant_box_error_is_first_order_in_the_step(peer):
    # Whole steps: the alpha error falls like the step (second-order methods fall 16x
    # from step 1 to 1/4; this falls about 4x: observed 3.9 here, 4.25 with an orthographic camera).
    a, u = 0.1, 2.0
    vol, tf = constant_box(a=a, u=u)
    camera = default_camera(vol, azimuth=30, elevation=20)
    scene = Scene(vol, tf, camera, width=48, height=40)
    origins, dirs = camera.rays(scene.width, scene.height)
    t0, t1 = ray_box(origins, dirs, *vol.bounds)
    alpha = 1 - (1 - a) ** (np.maximum(t1 - t0, 0.0) / u)
    rmse = [np.sqrt(np.mean((peer.render(scene, step, repeats=1, warmup=0)[0][..., 3] - alpha) ** 2))
            for step in (1.0, 0.25)]
    assert 2.5 < rmse[0] / rmse[1] < 6, rmse


def test_output_is_premultiplied(peer):
    # rgb = c * A for a constant colour c: VTK's target holds premultiplied colour.
    vol, tf = constant_box()
    scene = Scene(vol, tf, default_camera(vol, azimuth=30, elevation=20), width=32, height=32)
    image, _ = peer.render(scene, 0.5, repeats=1, warmup=0)
    np.testing.assert_allclose(image[..., :3], COLOUR * image[..., 3:4], atol=2e-6)
    assert image[..., 3].max() > 0.5


def test_exact_when_chord_is_a_whole_number_of_steps(peer):
    # A box 20 units thick seen square-on with step 0.5 (perspective, central ray):
    # 40 whole steps, so VTK's alpha is the closed form to float precision.
    a, u = 0.1, 1.0
    vol = Volume(np.full((21, 21, 21), 100, np.float32))
    tf = TransferFunction([(0, *COLOUR), (255, *COLOUR)], [(0, a), (255, a)], unit_distance=u)
    scene = Scene(vol, tf, Camera((10, 10, 60), (10, 10, 10), fov=30), width=32, height=32)
    image, _ = peer.render(scene, 0.5, repeats=1, warmup=0)
    centre = image[15:17, 15:17, 3]
    # The four pixels round the centre are a hair off axis; their chords are 20.0003.
    np.testing.assert_allclose(centre, 1 - (1 - a) ** 20, atol=2e-5)


@pytest.mark.parametrize("dtype", [np.float32, np.int16])
@pytest.mark.parametrize("mode", ["mip", "minip", "average"])
def test_extremes_and_average_of_a_ramp(peer, mode, dtype):
    # A field that varies along x only, seen down z orthographically: every ray sees one
    # value s(x), so MIP, MinIP and the average are all c(s) * alpha(s), alpha(s) at the
    # pixel centre's x. This pins the sample positions (texel centres) and the
    # classification. Tolerance 2e-3: VTK's colour and opacity tables (~5e-4 here) on
    # values from float32 texture filtering.
    n = 21
    x = (np.arange(n) * 10).astype(dtype)
    vol = Volume(np.broadcast_to(x[None, None, :], (n, n, n)).copy(), spacing=(0.5, 1, 1), origin=(1, 2, 3))
    tf = TransferFunction([(0, 0, 0, 1), (200, 1, 1, 0)], [(0, 0.1), (200, 0.9)], unit_distance=1)
    lo, hi = vol.bounds
    c = (lo + hi) / 2
    camera = Camera(c + [0, 0, 50], c, (0, 1, 0), ortho_height=12)
    scene = Scene(vol, tf, camera, width=64, height=64, mode=mode)
    image, _ = peer.render(scene, 0.5, repeats=1, warmup=0)
    origins, _ = camera.rays(64, 64)
    xs = origins[32, :, 0]
    inside = (xs > lo[0] + 0.05) & (xs < hi[0] - 0.05)
    s = (xs[inside] - lo[0]) / 0.5 * 10
    alpha = tf.opacity(s)
    expected = np.concatenate([tf.color(s) * alpha[:, None], alpha[:, None]], axis=1)
    np.testing.assert_allclose(image[32, inside], expected, atol=2e-3)
    assert np.all(image[32, ~((xs > lo[0] - 0.05) & (xs < hi[0] + 0.05))] == 0)


def test_isosurface_facing_the_camera(peer):
    # A plane z = const seen head-on: colour c(v) * (ka + kd) + ks, opacity 1, where the
    # normal is along the ray. Only the central pixels are compared: VTK lights from a
    # point at the camera position and uses Phong's (R.V)^n, so off-axis pixels differ
    # from the contract's headlight Blinn-Phong (see dvr_gl.bench.vtk_peer).
    n = 21
    z = (np.arange(n) * 10).astype(np.float32)
    vol = Volume(np.broadcast_to(z[::-1, None, None], (n, n, n)).copy())
    tf = TransferFunction([(0, 0, 0.5, 1), (200, 1, 0.5, 0)], [(0, 0.5), (200, 0.5)])
    camera = Camera((10, 10, 80), (10, 10, 10), ortho_height=10)
    scene = Scene(vol, tf, camera, width=32, height=32, mode="isosurface", iso_value=50)
    image, _ = peer.render(scene, 0.25, repeats=1, warmup=0)
    ka, kd, ks, _ = scene.phong
    expected = np.append(tf.color(50) * (ka + kd) + ks, 1.0)
    np.testing.assert_allclose(image[15:17, 15:17].reshape(-1, 4), np.tile(expected, (4, 1)), atol=2e-3)


def test_chest_like_image_is_close_to_float_upload(peer):
    # The same small scene with native uint8 data and with float32 data: the only
    # difference is the texture filter's precision (8-bit weights for 8-bit textures on
    # llvmpipe), which stays small.
    rng = np.random.default_rng(1)
    data = np.clip(rng.normal(100, 40, (12, 14, 16)), 0, 255).astype(np.uint8)
    vol = Volume(data, spacing=(1.4, 1.4, 2.5))
    tf = TransferFunction([(0, 0, 0, 0), (255, 1, 0.8, 0.6)], [(50, 0), (200, 0.3)], unit_distance=1.4)
    scene = Scene(vol, tf, default_camera(vol, azimuth=30, elevation=20), width=40, height=40)
    native, _ = peer.render(scene, 0.7, repeats=1, warmup=0)
    with VTKPeer(data_as_float=True) as fpeer:
        floated, _ = fpeer.render(scene, 0.7, repeats=1, warmup=0)
    assert np.abs(native - floated).max() < 0.03
    assert native[..., 3].max() > 0.3


def test_bench_quick_smoke(renderer, tmp_path, monkeypatch, capsys):
    # `dvr-gl bench` end to end on a tiny image: table, CSV, JSON and figure, with VTK
    # rows and ratio columns. (`renderer` only makes a missing GL backend skip.)
    import argparse
    import json

    from dvr_gl.bench import cli, raycast as bench

    monkeypatch.setenv("DVR_GL_CACHE", str(tmp_path / "cache"))
    parser = cli.add_arguments(argparse.ArgumentParser())
    args = parser.parse_args(["--quick", "--size", "24", "--repeats", "1", "--datasets", "head",
                              "--steps", "1", "--out", str(tmp_path / "b")])
    assert cli.run_bench(args) == 0
    table = capsys.readouterr().out
    assert "VTK GPU raycast" in table and "dvr_gl raycast+skip" in table
    rows = json.loads((tmp_path / "b.json").read_text())["rows"]
    assert {r["renderer"] for r in rows} == ({label for label, _, _ in bench.RENDERERS}
                                             | {bench.TOLERANCE_LABEL, bench.ADAPTIVE_LABEL})
    asked = next(r for r in rows if r["renderer"] == bench.TOLERANCE_LABEL)    # VTK's error, asked for
    assert asked["chosen_step_voxels"] > 0 and asked["rmse"] <= next(
        r for r in rows if r["kind"] == "vtk")["rmse"]
    assert all(r["rmse"] > 0 and r["ms_median"] > 0 for r in rows)
    vtk = next(r for r in rows if r["kind"] == "vtk")
    assert vtk["time_vs_vtk"] == 1.0 and vtk["rmse_vs_vtk"] == 1.0
    assert (tmp_path / "b.csv").read_text().startswith("dataset,")
    assert (tmp_path / "b.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_bench_error_size_measures_the_same_view_smaller(renderer, tmp_path, monkeypatch, capsys):
    # --error-size: frames timed at --size, the error of each way measured at the smaller
    # size on the same view, so the errors equal those of a run whose frames are that size
    import argparse
    import json

    from dvr_gl.bench import cli, raycast as bench

    monkeypatch.setenv("DVR_GL_CACHE", str(tmp_path / "cache"))
    parser = cli.add_arguments(argparse.ArgumentParser())
    rows = {}
    for stem, extra in (("big", ["--size", "32", "--error-size", "16"]), ("small", ["--size", "16"])):
        args = parser.parse_args(["--quick", "--repeats", "1", "--datasets", "head", "--steps", "1",
                                  "--out", str(tmp_path / stem)] + extra)
        assert cli.run_bench(args) == 0
        rows[stem] = {r["renderer"]: r for r in json.loads((tmp_path / f"{stem}.json").read_text())["rows"]}
    capsys.readouterr()
    assert {r["width"] for r in rows["big"].values()} == {32}
    for label, _, _ in bench.RENDERERS:       # the same ways at the same step: the same error
        assert rows["big"][label]["rmse"] == pytest.approx(rows["small"][label]["rmse"], rel=1e-6, abs=1e-9)
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


# -- meshes: VTK's projected tetrahedra (vtkProjectedTetrahedraMapper) ----------------

from dvr_gl import TetMesh  # noqa: E402
from dvr_gl.bench.vtk_peer import render_vtk_mesh  # noqa: E402

# The unit cube's corners, index = x + 2y + 4z, split into 6 tetrahedra round the main
# diagonal 0-7 (one per order in which a path from 0 to 7 steps along x, y and z).
CUBE_TETS = np.array([[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]])
# Colours k/255: VTK's PT mapper keeps colour and opacity in 8 bits, floor(v * 255.9999)
# / 255, which leaves these exact.
MESH_COLOUR = np.array([1.0, 0.6, 0.2])


def cube_mesh(lo=(0, 0, 0), hi=(1, 1, 1), value=100.0):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    i = np.arange(8)
    bits = np.stack([i & 1, (i >> 1) & 1, (i >> 2) & 1], axis=1)
    return TetMesh(lo + bits * (hi - lo), CUBE_TETS, np.full(8, value))


def box_mesh(lo, hi, n, field=None):
    """The box [lo, hi] cut into n^3 cubes of 6 tets each (the same split in every cube,
    so faces match)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    axes = [np.linspace(lo[k], hi[k], n + 1) for k in range(3)]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    idx = np.arange((n + 1) ** 3).reshape(n + 1, n + 1, n + 1)
    i, j, k = np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing="ij")
    corners = np.stack([idx[i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1)] for c in range(8)], -1)
    tets = corners.reshape(-1, 8)[:, CUBE_TETS].reshape(-1, 4)
    return TetMesh(pts, tets, np.full(len(pts), 100.0) if field is None else field(pts))


def constant_tf(a, u):
    return TransferFunction([(0, *MESH_COLOUR), (255, *MESH_COLOUR)], [(0, a), (255, a)], unit_distance=u)


def axis_camera(axis, centre=(0.5, 0.5, 0.5), height=2.0):
    """Orthographic, looking down -axis at the centre (up: the next axis)."""
    c = np.asarray(centre, float)
    e = np.eye(3)
    return Camera(c + 5 * e[axis], c, e[(axis + 1) % 3], ortho_height=height)


@pytest.mark.parametrize("axis", [0, 1, 2])
@pytest.mark.parametrize("a,u", [(0.1, 2.0), (0.5, 1.0), (0.9, 0.5), (0.02, 0.3)])
def test_mesh_constant_cube_matches_closed_form(peer, axis, a, u):
    # Orthographic along an axis every ray through the unit cube has chord L = 1, so
    # A = 1 - (1 - a)^(L/u). VTK's PT mapper computes, per tet, the thickness at the
    # projected "thick" vertex exactly (orthographic: a linear depth correction) and
    # interpolates it linearly over the projected triangles, which is exact for a
    # planar-faced cell under an orthographic projection; it absorbs
    # 1 - exp(-att * L / unit) with the peer's att = 1.0 (exact in 8 bits) and unit =
    # 1 / tau. Measured: |error| <= 4e-7 (float32 in the shader and the blending of the
    # overlapping cells); allowed 2e-6.
    mesh = cube_mesh()
    scene = Scene(mesh, constant_tf(a, u), axis_camera(axis), width=40, height=40)
    image, seconds = peer.render(scene, repeats=1, warmup=0)
    assert image.shape == (40, 40, 4) and image.dtype == np.float32 and seconds > 0
    origins, _ = scene.camera.rays(40, 40)
    p = origins - 0.5
    q = (axis + 1) % 3, (axis + 2) % 3            # the two screen axes
    inside = (np.abs(p[..., q[0]]) < 0.5 - 0.03) & (np.abs(p[..., q[1]]) < 0.5 - 0.03)
    outside = (np.abs(p[..., q[0]]) > 0.5 + 0.03) | (np.abs(p[..., q[1]]) > 0.5 + 0.03)
    closed = 1 - (1 - a) ** (1.0 / u)
    np.testing.assert_allclose(image[inside][:, 3], closed, atol=2e-6)
    assert np.all(image[outside] == 0)
    assert inside.sum() == 18 * 18          # the cube is 20 pixels wide


def test_mesh_native_opacity_is_read_as_extinction(peer):
    # Given the opacity points unchanged (native_opacity=True, as a VTK user would set
    # them up), VTK's PT mapper reads alpha as an extinction per unit distance,
    # truncated to 8 bits: A = 1 - exp(-q L / u) with q = floor(alpha * 255.9999) / 255,
    # not the contract's 1 - (1 - alpha)^(L/u): 18 % less alpha for a = 0.5, L = u.
    a, u = 0.5, 1.0
    scene = Scene(cube_mesh(), constant_tf(a, u), axis_camera(2), width=32, height=32)
    image, _ = peer.render_mesh(scene, repeats=1, warmup=0, native_opacity=True)
    q = np.floor(a * 255.9999) / 255
    centre = image[12:20, 12:20, 3]
    np.testing.assert_allclose(centre, 1 - np.exp(-q / u), atol=2e-6)
    assert centre.max() < 0.83 * (1 - (1 - a) ** (1 / u))
    # and the contract's mapping (the default) restores it
    image, _ = peer.render_mesh(scene, repeats=1, warmup=0)
    np.testing.assert_allclose(image[12:20, 12:20, 3], 1 - (1 - a) ** (1 / u), atol=2e-6)


def test_mesh_perspective_error_falls_with_cell_size(peer):
    # In perspective VTK still interpolates each tet's thickness linearly in screen space
    # from its thick vertex (and takes that thickness from a 2048-entry square-root
    # table), while the true chord is not linear there. The alpha error of a constant box
    # therefore depends on the cells' size against their distance. Measured (box 2 x 3 x
    # 1.6, a = 0.5, u = 1, 96 x 80, azimuth 30, elevation 20; pixels away from the
    # silhouette): max error 7.0e-2 with 6 tets, 2.1e-2 with 48, 5.8e-3 with 384, 1.6e-3
    # with 3072 (~4x less per halving of the cell: second order).
    a, u = 0.5, 1.0
    errors = []
    for n in (1, 4):
        mesh = box_mesh((-1, -1.5, -0.8), (1, 1.5, 0.8), n)
        camera = default_camera(mesh, azimuth=30, elevation=20)
        scene = Scene(mesh, constant_tf(a, u), camera, width=96, height=80)
        image, _ = peer.render_mesh(scene, repeats=1, warmup=0)
        origins, dirs = camera.rays(96, 80)
        t0, t1 = ray_box(origins, dirs, *mesh.bounds)
        closed = 1 - (1 - a) ** (np.maximum(t1 - t0, 0.0) / u)
        hit = t1 > t0
        core = hit.copy()
        core[1:] &= hit[:-1]
        core[:-1] &= hit[1:]
        core[:, 1:] &= hit[:, :-1]
        core[:, :-1] &= hit[:, 1:]
        errors.append(np.abs(image[..., 3] - closed)[core].max())
        assert np.all(image[~hit] == 0)
    assert errors[0] < 0.1 and errors[1] < 0.01 and errors[1] < errors[0] / 6, errors


def test_mesh_orientation_shape_and_premultiplication(peer):
    # A box in the upper right of an orthographic view down -z (x right, y up): its
    # pixels are at the top (row 0 is the top row) and on the right. Non-square image.
    mesh = box_mesh((0.2, 0.5, -0.5), (0.9, 0.9, 0.5), 2)
    camera = Camera((0, 0, 5), (0, 0, 0), (0, 1, 0), ortho_height=2)
    scene = Scene(mesh, constant_tf(0.3, 1.0), camera, width=48, height=32)
    image, _ = peer.render_mesh(scene, repeats=1, warmup=0)
    assert image.shape == (32, 48, 4) and image.dtype == np.float32
    origins, _ = camera.rays(48, 32)
    x, y = origins[..., 0], origins[..., 1]
    inside = (x > 0.2 + 0.03) & (x < 0.9 - 0.03) & (y > 0.5 + 0.03) & (y < 0.9 - 0.03)
    outside = (x < 0.2 - 0.03) | (x > 0.9 + 0.03) | (y < 0.5 - 0.03) | (y > 0.9 + 0.03)
    assert inside[:8].any() and not inside[16:].any() and not inside[:, :24].any()
    np.testing.assert_allclose(image[inside][:, 3], 1 - 0.7, atol=2e-6)
    assert np.all(image[outside] == 0)
    # premultiplied: rgb = c * A for a constant colour
    np.testing.assert_allclose(image[..., :3], MESH_COLOUR * image[..., 3:4], atol=1e-6)


def test_mesh_varying_field_is_premultiplied_and_bounded(peer):
    # A field varying through the box, colours and opacities from a ramp: every pixel
    # has rgb <= A (premultiplied colours in [0, 1]) and 0 <= A <= 1.
    mesh = box_mesh((0, 0, 0), (1, 2, 1), 4, field=lambda p: 100 * p[:, 0] + 50 * p[:, 1] * p[:, 2])
    tf = TransferFunction([(0, 0, 0.2, 1), (200, 1, 0.6, 0)], [(0, 0.05), (200, 0.8)], unit_distance=0.5)
    scene = Scene(mesh, tf, default_camera(mesh, azimuth=30, elevation=20), width=40, height=40)
    image, _ = peer.render_mesh(scene, repeats=1, warmup=0)
    a = image[..., 3]
    assert a.max() > 0.3 and a.min() >= 0 and a.max() <= 1
    assert np.all(image[..., :3] <= a[..., None] + 1e-6)


def test_mesh_and_grid_share_the_window(peer):
    # Grid and mesh scenes alternate in one peer (one window per process): each hides
    # the other's actor, and the grid image is unchanged by a mesh frame in between.
    vol = Volume(np.full((8, 8, 8), 100, np.float32))
    tf = constant_tf(0.2, 2.0)
    grid_scene = Scene(vol, tf, default_camera(vol, azimuth=30, elevation=20), width=32, height=32)
    mesh_scene = Scene(cube_mesh((10, 0, 0), (11, 1, 1)), tf, axis_camera(2, (10.5, 0.5, 0.5)), width=32, height=32)
    first, _ = peer.render(grid_scene, 0.5, repeats=1, warmup=0)
    mesh_image, _ = peer.render(mesh_scene, repeats=1, warmup=0)
    again, _ = peer.render(grid_scene, 0.5, repeats=1, warmup=0)
    np.testing.assert_array_equal(first, again)
    assert mesh_image[16, 16, 3] == pytest.approx(1 - 0.8 ** 0.5, abs=2e-6)
    with pytest.raises(TypeError):
        peer.render(grid_scene)                                # a grid needs its step
    with pytest.raises(NotImplementedError):
        peer.render_mesh(mesh_scene.replace(mode="mip"), repeats=1, warmup=0)


def test_render_vtk_mesh_times_each_frame_and_turns():
    # The module-level entry point (one shared window): a list of per-frame seconds,
    # a new view per timed frame with `turn`, and the first frame already complete
    # (VTK's PT mapper drops its first batch of cells in its very first frame; the
    # peer renders that one untimed).
    mesh = box_mesh((0, 0, 0), (1, 1, 1), 7)                     # 2058 tets > one batch of 1000
    scene = Scene(mesh, constant_tf(0.3, 0.5), axis_camera(2), width=32, height=32)
    image, times = render_vtk_mesh(scene, repeats=3, warmup=0)
    assert len(times) == 3 and all(t > 0 for t in times)
    np.testing.assert_allclose(image[10:22, 10:22, 3], 1 - 0.7 ** 2, atol=2e-6)
    cams = []
    turned, times = render_vtk_mesh(scene, repeats=2, warmup=1,
                                    turn=lambda i: cams.append(i) or default_camera(mesh, azimuth=40 + 10 * i))
    assert cams == [0, 1] and len(times) == 2
    assert not np.allclose(turned, image)


def test_mesh_linear_field_error_falls_with_cell_size(peer):
    # A field linear along the view (s = 100 z on the unit cube, orthographic down -z)
    # with opacity and colour ramps: every ray sees s go from 100 to 0, so the exact
    # (C, A) is one number, here by a 2e5-point midpoint rule (error ~1e-10). VTK's PT
    # mapper classifies at the vertices only (8-bit colour and extinction), interpolates
    # them linearly over each cell and gives a cell the mean of its front and back
    # colour: pre-classification, whose error falls with the cell size. Measured max
    # |error| over the central pixels, (r, g, b, A): 2 cells across (48 tets) 0.075,
    # 0.028, 0.092, 0.071; 8 across (3072 tets) 0.0096, 0.0048, 0.0027, 0.0098; 16 across
    # 0.0005, 0.0002, 0.0026 (the 8-bit colour), 0.0001. Allowed: 1.3x those.
    tf = TransferFunction([(0, 0, 0.2, 1), (100, 1, 0.6, 0)], [(0, 0.0), (100, 0.8)], unit_distance=0.25)
    n_t = 200_000
    t = (np.arange(n_t) + 0.5) / n_t
    s = 100 * (1 - t)
    tau = tf.extinction(s)
    od = np.cumsum(tau) / n_t
    trans = np.exp(-(od - tau / (2 * n_t)))
    exact = np.append((tf.color(s) * (tau * trans)[:, None]).sum(0) / n_t, 1 - np.exp(-od[-1]))
    for n, bound in ((2, [0.098, 0.037, 0.12, 0.092]), (8, [0.0125, 0.0063, 0.0036, 0.0128])):
        mesh = box_mesh((0, 0, 0), (1, 1, 1), n, field=lambda p: 100 * p[:, 2])
        image, _ = peer.render_mesh(Scene(mesh, tf, axis_camera(2), 32, 32), repeats=1, warmup=0)
        err = np.abs(image[8:24, 8:24].reshape(-1, 4) - exact).max(axis=0)
        assert np.all(err <= bound), (n, err)


def test_equal_error_and_time_reads_the_skipping_ray_caster_only():
    """The interpolation runs along dvr_gl raycast+skip's steps; other dvr_gl rows (the
    tolerance points, the adaptive curve) do not bend it."""
    from dvr_gl.bench import raycast as bench

    def row(renderer, kind, step, ms, rmse):
        return {"dataset": "d", "renderer": renderer, "kind": kind, "skip_empty": kind != "vtk",
                "step_voxels": step, "ms_median": ms, "rmse": rmse}
    rows = [row("VTK GPU raycast", "vtk", 1, 100.0, 1e-2),
            row("dvr_gl raycast+skip", "dvr_gl", 1, 50.0, 2e-2), row("dvr_gl raycast+skip", "dvr_gl", 0.5, 100.0, 5e-3),
            row(bench.ADAPTIVE_LABEL, "dvr_gl", 1, 500.0, 1e-4), row(bench.TOLERANCE_LABEL, "dvr_gl", 1, 10.0, 1e-2)]
    (r,) = bench.equal_error_and_time(rows)
    # log-log halfway in error between the two steps: sqrt(50 * 100) ms
    assert r["time_ratio_at_equal_error"] == pytest.approx((50.0 * 100.0) ** 0.5 / 100.0)
    assert r["error_ratio_at_equal_time"] == pytest.approx(0.5)
