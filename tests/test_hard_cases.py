"""The hard-case suite: one test per case and technique, each asserting a bound derived
from the image contract (never a snapshot) and recording (case, technique, bound,
measured) in one table. ``DVR_GL_HARD_CASES=table.md pytest tests/test_hard_cases.py``
writes that table as Markdown.

Regression tests of the defects found by trying dvr_gl as a new user would are here too:
slicing that lost rays grazing the box, a renderer killed by another library's EGL
teardown, large images, and a closed output pipe."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

import dvr_gl
from dvr_gl import metrics, reference
from dvr_gl.data import phantoms

TABLE = []
U32 = 2.0 ** -24


def record(case, technique, bound, measured):
    """Add a row to the table and assert the bound."""
    TABLE.append((case, technique, bound, measured))
    assert measured <= bound, f"{case} / {technique}: {measured:.3g} > bound {bound:.3g}"


@pytest.fixture(scope="module", autouse=True)
def _write_table():
    yield
    path = os.environ.get("DVR_GL_HARD_CASES")
    if path and TABLE:
        lines = ["# The hard cases: bound and measured error", "",
                 "| case | technique | bound | measured |", "|---|---|---|---|"]
        lines += [f"| {c} | {t} | {b:.3g} | {m:.3g} |" for c, t, b, m in TABLE]
        with open(path, "w") as f:
            f.write("\n".join(lines) + "\n")


# -- 1. slicing and rays that graze the box ---------------------------------------------------

def opaque_box():
    vol = dvr_gl.Volume(np.full((16, 16, 16), 5.0, np.float32))
    tf = dvr_gl.TransferFunction(color=[(0, 1, 1, 1)], opacity=[(0, 1.0)], unit_distance=1e-3)
    return vol, tf


VIEWS = {"ortho 30/20": (30, 20, True), "perspective 30/20": (30, 20, False),
         "perspective diagonal": (45, 35.26, False), "ortho diagonal": (45, 35.26, True)}
SLICINGS = [("slice3d", {}), ("slice3d", {"proxy": "vertex"}), ("slice3d", {"shells": True}),
            ("slice2d", {"interpolate": 3}), ("slice2d", {})]


def _slicing_options(technique, opts, volume):
    return {"step": 0.25 * volume.min_spacing, **opts} if technique == "slice3d" else opts


@pytest.mark.parametrize("technique,opts", SLICINGS, ids=str)
@pytest.mark.parametrize("view", list(VIEWS))
def test_slicing_integrates_rays_that_graze_an_opaque_box(renderer, technique, opts, view):
    """Every ray through the box is fully opaque, whatever its chord: the float64 marcher
    is exact (0), so the bound is float32's: a handful of opaque segments composited."""
    vol, tf = opaque_box()
    az, el, ortho = VIEWS[view]
    scene = dvr_gl.Scene(vol, tf, dvr_gl.default_camera(vol, azimuth=az, elevation=el, ortho=ortho),
                         width=128, height=128)
    exact = reference.exact(scene)
    ideal = metrics.rmse(reference.render(scene, technique="raycast", step=0.25, lut_exact=True), exact)
    gl = renderer.render(scene, technique=technique, **_slicing_options(technique, opts, vol))
    assert (exact[..., 3] > 0.5).sum() > 3000
    record(f"opaque box, grazing rays, {view}", f"{technique} {opts}", 1.5 * ideal + 1e-6, metrics.rmse(gl, exact))


@pytest.mark.parametrize("technique,opts", SLICINGS[:4], ids=str)
@pytest.mark.parametrize("view", ["ortho 30/20", "perspective 30/20", "perspective diagonal"])
def test_slicing_at_quarter_voxel_is_as_accurate_as_a_marcher_on_marschner_lobb(renderer, technique, opts, view):
    """Within 1.5x the float64 midpoint marcher (exact TF) at the same sample distance
    along the rays: 0.25 voxel for 3D slices; for 2D slices the stack's 0.25 voxel along
    its axis is 0.25 / |cos| along a ray at angle theta to it, and the marcher takes that
    (the central ray's) distance."""
    vol, tf = phantoms.marschner_lobb(), phantoms.marschner_lobb_tf()
    az, el, ortho = VIEWS[view]
    cam = dvr_gl.default_camera(vol, azimuth=az, elevation=el, ortho=ortho)
    scene = dvr_gl.Scene(vol, tf, cam, width=128, height=128)
    step = 0.25 * vol.min_spacing
    if technique == "slice2d":
        step /= float(np.abs(cam.forward).max())
    exact = reference.exact(scene)
    ideal = metrics.rmse(reference.render(scene, technique="raycast", step=step, lut_exact=True), exact)
    gl = renderer.render(scene, technique=technique, **_slicing_options(technique, opts, vol))
    record(f"Marschner-Lobb, 0.25 voxel, {view}", f"{technique} {opts}", 1.5 * ideal, metrics.rmse(gl, exact))


@pytest.mark.parametrize("technique,opts", [("slice3d", {"step": 0.25, "preintegrate": True}),
                                            ("slice2d", {"interpolate": 3, "preintegrate": True}),
                                            ("slice3d", {"step": 0.25, "shells": True, "preintegrate": True})], ids=str)
def test_gap_pass_matches_its_reference_and_exact(renderer, technique, opts):
    """The gap pass is in the NumPy references too: with pre-integration on the constant
    box every segment is exact, so GL, reference and exact differ by float32 rounding
    alone: ~64u per segment (table lookup, exponential, blending), added over the longest
    ray's segments (diagonal / step + 2)."""
    vol, tf = opaque_box()
    tf = dvr_gl.TransferFunction(color=[(0, 0.3, 0.6, 0.9)], opacity=[(0, 0.9)], unit_distance=2.0)
    scene = dvr_gl.Scene(vol, tf, dvr_gl.default_camera(vol, azimuth=30, elevation=20), width=96, height=96)
    gl = renderer.render(scene, technique=technique, **opts)
    ref = reference.render(scene, technique=technique, **opts)
    exact = reference.exact(scene)
    bound = 64 * U32 * (float(np.linalg.norm(vol.extent)) / 0.25 + 2)
    record("constant box, pre-integrated, silhouettes", f"{technique} {opts} vs reference", bound,
           metrics.max_abs_error(gl, ref))
    record("constant box, pre-integrated, silhouettes", f"{technique} {opts} vs exact", bound,
           metrics.max_abs_error(gl, exact))


# -- the contract's closed form on hard geometry and numbers --------------------------------------

def _box_case(case):
    """(volume, tf, camera, step) of a constant box case: the exact image is the closed
    form A = 1 - (1 - alpha)^(L / u) along each pixel's chord L."""
    value, alpha, unit = 10.0, 0.6, 1.0
    shape, spacing = (9, 7, 8), (1.0, 1.0, 1.0)
    view = dict(azimuth=30, elevation=20)
    eye = None
    step = 0.5
    if case == "alpha 1":
        alpha = 1.0
    elif case == "alpha 1 - 1e-7":
        alpha = 1 - 1e-7
    elif case == "unit distance 1e-4":
        unit, alpha = 1e-4, 1e-5
    elif case == "unit distance 1e4":
        unit, alpha = 1e4, 0.9
    elif case == "step longer than the volume":
        step = 50.0
    elif case == "view along an axis":
        view = dict(azimuth=0, elevation=0)
    elif case == "view along the diagonal":
        view = dict(azimuth=45, elevation=35.26438968)
    elif case == "view at 45 degrees":
        view = dict(azimuth=45, elevation=0)
    elif case == "eye inside":
        eye = ((2.0, 3.0, 4.0), (7.0, 1.0, 0.0))
    elif case == "eye on a face plane":
        eye = ((0.0, 3.0, 20.0), (4.0, 3.0, 0.0))
    elif case == "eye at a corner":
        eye = ((0.0, 0.0, 0.0), (7.0, 6.0, 8.0))
    elif case == "spacing 100:1":
        spacing, step = (1.0, 1.0, 100.0), 0.5
    elif case == "two samples thick":
        shape = (2, 7, 8)
    elif case == "1024 samples long":
        shape, step = (4, 4, 1024), 4.0
    elif case == "values 1e-30":
        value = 1e-30
    elif case == "values 1e30":
        value = 1e30
    elif case == "uint16 65535":
        value = 65535.0
    dtype = np.uint16 if case.startswith("uint16") else np.float64 if abs(np.log10(value)) > 20 else np.float32
    data = np.full(shape, value, dtype)
    vol = dvr_gl.Volume(data, spacing=spacing)
    tf = dvr_gl.TransferFunction(color=[(0.5 * value, 0.2, 0.6, 1.0), (2 * value, 0.2, 0.6, 1.0)],
                                 opacity=[(0.5 * value, alpha), (2 * value, alpha)], unit_distance=unit)
    if eye is not None:
        cam = dvr_gl.Camera(*eye, fov=70)
    else:
        cam = dvr_gl.default_camera(vol, **view)
    return vol, tf, cam, step * vol.min_spacing


BOX_CASES = ["alpha 1", "alpha 1 - 1e-7", "unit distance 1e-4", "unit distance 1e4", "step longer than the volume",
             "view along an axis", "view along the diagonal", "view at 45 degrees", "eye inside",
             "eye on a face plane", "eye at a corner", "spacing 100:1", "two samples thick", "1024 samples long",
             "values 1e-30", "values 1e30", "uint16 65535"]
BOX_TECHNIQUES = [("raycast", {"ert_transmittance": 0.0}), ("slice3d", {}), ("slice3d", {"shells": True}),
                  ("slice2d", {})]


@pytest.mark.parametrize("technique,opts", BOX_TECHNIQUES, ids=str)
@pytest.mark.parametrize("case", BOX_CASES)
def test_constant_box_closed_form_in_hard_cases(renderer, case, technique, opts):
    """Every technique that integrates chords reproduces the closed form to float32:
    each segment's opacity is exact for a constant field up to ~64u (correctOpacity's
    series and exponent), and the errors add over the segments of the longest chord;
    the chord itself carries float32 rounding of the distances to its ends (~8u of the
    farthest exit distance), which changes A by at most tau times that."""
    vol, tf, cam, step = _box_case(case)
    scene = dvr_gl.Scene(vol, tf, cam, width=32, height=32)
    o, d = cam.rays(32, 32)
    lo, hi = vol.bounds
    from dvr_gl.reference.common import ray_box
    t0, t1 = ray_box(o.reshape(-1, 3), d.reshape(-1, 3), lo, hi)
    chord = np.maximum(t1 - t0, 0).reshape(32, 32)
    alpha = float(tf.opacity(np.array([float(vol.data.flat[0])]))[0])
    with np.errstate(divide="ignore"):
        want_a = np.where(chord > 0, -np.expm1(chord / tf.unit_distance * np.log1p(-alpha)) if alpha < 1
                          else 1.0, 0.0)
    want = np.concatenate([want_a[..., None] * np.array([0.2, 0.6, 1.0]), want_a[..., None]], axis=-1)
    if technique == "slice2d":
        segment = vol.spacing[int(np.argmax(np.abs(cam.forward)))] / float(np.abs(cam.forward).max())
        gl = renderer.render(scene, technique=technique, **opts)
    else:
        segment = step
        gl = renderer.render(scene, technique=technique, step=step, **opts)
    segments = float(chord.max()) / min(segment, float(chord.max()) or 1.0) + 2
    tau = -np.log1p(-alpha) / tf.unit_distance if alpha < 1 else 0.0   # alpha = 1: any chord gives 1
    bound = 64 * U32 * segments + tau * 8 * U32 * float(t1[t1 > t0].max()) + 1e-7
    assert want_a.max() > 1e-4
    record(f"constant box: {case}", f"{technique} {opts}", bound, float(np.abs(gl - want).max()))


@pytest.mark.parametrize("technique,opts", BOX_TECHNIQUES, ids=str)
def test_nan_masking_removes_exactly_the_cells_with_a_nan_corner(renderer, technique, opts):
    """Samples of z-layers 5.. are NaN: with masking the domain is the box z <= 4 (cells
    with a NaN corner removed), whose chord gives the closed form. Samples are masked by
    the cell they fall in, so the segment that crosses z = 4 may be taken whole or not:
    beyond float32 rounding the bound adds tau times the longest segment."""
    data = np.full((9, 7, 8), 10.0, np.float32)
    data[5:] = np.nan
    vol = dvr_gl.Volume(data, mask_nonfinite=True)
    tf = dvr_gl.TransferFunction(color=[(0, 0.2, 0.6, 1.0)], opacity=[(0, 0.3)], unit_distance=1.0)
    cam = dvr_gl.default_camera(vol, azimuth=30, elevation=20)
    scene = dvr_gl.Scene(vol, tf, cam, width=32, height=32)
    from dvr_gl.reference.common import ray_box
    o, d = cam.rays(32, 32)
    t0, t1 = ray_box(o.reshape(-1, 3), d.reshape(-1, 3), np.zeros(3), np.array([7.0, 6.0, 4.0]))
    chord = np.maximum(t1 - t0, 0).reshape(32, 32)
    want_a = -np.expm1(chord * np.log1p(-0.3))
    step = 0.5
    if technique == "slice2d":
        gl = renderer.render(scene, technique=technique, **opts)
        step = 1.0 / float(np.abs(cam.forward).max())
    else:
        gl = renderer.render(scene, technique=technique, step=step, **opts)
    tau = -np.log1p(-0.3)
    bound = 64 * U32 * (float(chord.max()) / step + 2) + tau * step
    assert want_a.max() > 0.5 and np.isfinite(gl).all()
    record("NaN samples masked (half the box)", f"{technique} {opts}", bound, float(np.abs(gl[..., 3] - want_a).max()))


def test_a_thousand_frames_keep_memory_flat_and_raise_no_gl_error(renderer):
    """Soak: 1000 frames, alternating techniques and views; after the first frames no new
    GPU object is made, the process's resident memory grows by less than 16 MB between
    frame 100 and frame 1000, and GL reports no error."""
    vol = phantoms.marschner_lobb(17)
    tf = phantoms.marschner_lobb_tf()

    def resident():
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")

    techniques = [("raycast", {}), ("slice3d", {}), ("slice2d", {})]
    soak = dvr_gl.Renderer()
    for frame in range(1000):
        technique, opts = techniques[frame % 3]
        cam = dvr_gl.default_camera(vol, azimuth=frame * 0.7, elevation=20)
        soak.render(dvr_gl.Scene(vol, tf, cam, width=24, height=24), technique=technique, **opts)
        if frame == 99:
            before, made = resident(), len(soak.created)
    growth = resident() - before
    from dvr_gl.gl.context import current
    with current(soak.ctx):
        error = soak.ctx.error
    new_objects = len(soak.created) - made
    soak.release()
    assert error == "GL_NO_ERROR" and new_objects == 0
    record("1000 frames, three techniques", "resident memory growth, frames 100-1000 (MB)", 16.0,
           growth / 2 ** 20)


# -- 2. another library's EGL teardown ----------------------------------------------------------

VTK_TEARDOWN = r"""
import json, numpy as np, dvr_gl
from dvr_gl.gl.context import context_lost
import vtk
vol = dvr_gl.Volume(np.random.default_rng(0).random((8, 9, 10)).astype(np.float32))
tf = dvr_gl.TransferFunction(color=[(0, 1, 0.5, 0.2), (1, 0.2, 0.5, 1)], opacity=[(0, 0.2), (1, 0.9)])
scene = dvr_gl.Scene(vol, tf, dvr_gl.default_camera(vol, azimuth=20), width=48, height=40)

def finalise_a_vtk_window():
    w = vtk.vtkRenderWindow()
    w.SetOffScreenRendering(1)
    w.AddRenderer(vtk.vtkRenderer())
    w.SetSize(16, 16)
    w.Render()
    w.Finalize()

r = dvr_gl.Renderer(backend="egl")
first = r.render(scene)
finalise_a_vtk_window()
lost = context_lost(r.ctx)
same = r.render(scene)
finalise_a_vtk_window()
fresh = dvr_gl.Renderer(backend="egl").render(scene)
print(json.dumps({"lost": bool(lost), "alpha": float(first[..., 3].max()),
                  "same": float(np.abs(same - first).max()), "fresh": float(np.abs(fresh - first).max())}))
"""


def test_a_vtk_window_finalised_between_renders_costs_nothing():
    """VTK's Finalize terminates the process's EGL display, which destroys dvr_gl's
    context too: the renderer notices and moves to a new context, images unchanged."""
    pytest.importorskip("vtk")
    out = subprocess.run([sys.executable, "-c", VTK_TEARDOWN], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["lost"], "VTK's teardown no longer destroys the context: the test shows nothing"
    assert result["alpha"] > 0.1
    record("VTK window finalised between renders", "raycast, same renderer", 0.0, result["same"])
    record("VTK window finalised between renders", "raycast, new renderer", 0.0, result["fresh"])


# -- 3. images larger than one GL target ------------------------------------------------------

def _tiling_scenes():
    vol, tf = phantoms.marschner_lobb(17), phantoms.marschner_lobb_tf()
    grid = dvr_gl.Scene(vol, tf, dvr_gl.default_camera(vol, azimuth=30, elevation=20), width=101, height=83)
    pts = np.random.default_rng(1).random((200, 3))
    mesh = dvr_gl.TetMesh.from_points(pts, np.sin(4 * pts[:, 0]) + pts[:, 1])
    mesh_tf = dvr_gl.TransferFunction(color=[(-1, 1, 0, 0), (2, 0, 0, 1)], opacity=[(-1, 0.2), (2, 0.9)],
                                      unit_distance=0.1)
    meshed = dvr_gl.Scene(mesh, mesh_tf, dvr_gl.default_camera(mesh, azimuth=30, elevation=20), width=101, height=83)
    return grid, meshed


TILED = [("grid", "raycast", {}), ("grid", "raycast", {"jitter_seed": 3}), ("grid", "slice3d", {}),
         ("grid", "slice3d", {"proxy": "vertex"}), ("grid", "slice3d", {"shells": True}), ("grid", "slice2d", {}),
         ("grid", "particles", {"repetitions": 2}), ("grid", "splat", {}), ("mesh", "tetra", {}),
         ("mesh", "particles", {"repetitions": 2}), ("mesh", "splat", {})]


@pytest.mark.parametrize("data,technique,opts", TILED, ids=str)
def test_images_larger_than_one_target_render_in_tiles(renderer, data, technique, opts):
    """Each tile is a window of the same camera: every pixel's ray is the one of the
    single render, so ray-driven techniques give the same bits. Point sprites are drawn
    with a margin (GL clips them by their centres). Projected tetrahedra rasterise faces
    moved by the tile's projection, so a pixel on a shared face may take its segment
    from the other cell: float32 rounding of the segment ends (the bound of test_tetra,
    1e-4)."""
    grid, meshed = _tiling_scenes()
    scene = grid if data == "grid" else meshed
    whole = renderer.render(scene, technique=technique, **opts)
    tiled_renderer = dvr_gl.Renderer(max_tile=300 if technique in ("particles", "splat") else 40)
    tiled = tiled_renderer.render(scene, technique=technique, **opts)
    tiled_renderer.release()
    assert whole[..., 3].max() > 0.3
    bound = 1e-4 if technique == "tetra" else 0.0
    record("101x83 image in tiles of at most 40 (sprites: 40 + margins)", f"{technique} {opts} on a {data}",
           bound, float(np.abs(tiled - whole).max()))


def test_tiles_cover_the_image_once():
    from dvr_gl.rendering.renderer import tiles
    for width, height, edge in ((101, 83, 40), (16384, 16384, 3838), (1, 1, 16), (4097, 5, 4096)):
        cover = np.zeros((height, width), np.int32)
        for x, y, w, h in tiles(width, height, edge):
            assert 0 < w <= edge and 0 < h <= edge
            cover[y:y + h, x:x + w] += 1
        assert (cover == 1).all()


def test_too_large_for_memory_is_a_named_error_before_any_work(renderer, monkeypatch, capsys):
    from dvr_gl.rendering import renderer as renderer_module
    from dvr_gl.frontends.cli import main
    monkeypatch.setattr(renderer_module, "available_memory", lambda: 2 ** 30)
    vol, tf = phantoms.marschner_lobb(9), phantoms.marschner_lobb_tf()
    scene = dvr_gl.Scene(vol, tf, dvr_gl.default_camera(vol), width=16384, height=16384)
    with pytest.raises(renderer_module.ImageTooLarge, match=r"16384x16384.*4\.0 GiB.*1\.0 GiB"):
        renderer.render(scene)
    assert main(["render", "builtin:synthetic", "--size", "16384x16384", "--out", "never.png"]) == 2
    assert "16384x16384" in capsys.readouterr().err
    assert not os.path.exists("never.png")


def test_one_target_limits_are_checked(renderer):
    vol, tf = phantoms.marschner_lobb(9), phantoms.marschner_lobb_tf()
    scene = dvr_gl.Scene(vol, tf, dvr_gl.default_camera(vol), width=64, height=64)
    with pytest.raises(ValueError, match="max_tile"):
        dvr_gl.Renderer(max_tile=8)
    small = dvr_gl.Renderer(max_tile=32)
    with pytest.raises(ValueError, match="render_target"):
        small.render_target(scene)
    with pytest.raises(ValueError, match="margin"):
        small.render(scene, technique="particles")
    small.release()
    info = renderer.info()
    assert renderer.max_tile <= min(info["max_texture_size"], *info["max_viewport_dims"])


# -- meshes: rays through edges and vertices, slivers, views along faces -----------------------

MESH_TOL = 1e-4  # test_tetra's float32 bound (planes, chords and blending over ~12 segments)


def _delaunay(n, seed):
    pts = np.random.default_rng(seed).random((n, 3))
    return dvr_gl.TetMesh.from_points(pts, np.sin(4 * pts[:, 0]) + pts[:, 1])


MESH_TF = dvr_gl.TransferFunction(color=[(-1, 1, 0, 0), (2, 0, 0, 1)], opacity=[(-1, 0.2), (2, 0.9)],
                                  unit_distance=0.1)


def _lattice():
    """A 4^3 grid's Kuhn tetrahedralisation: views along the axes put pixel rays exactly
    in shared faces and along edges, through vertices."""
    from dvr_gl.model.cell_split import grid_to_tets
    z, y, x = np.mgrid[0:4, 0:4, 0:4].astype(np.float32)
    return grid_to_tets(dvr_gl.Volume((x + 2 * y + 3 * z) / 18.0, spacing=(1.0, 1.0, 1.0)))


MESH_CASES = {
    # random points: slivers, and pixel rays within rounding of edges seen edge-on
    "Delaunay of 200 random points, oblique": lambda: (_delaunay(200, 1), dict(azimuth=30, elevation=20)),
    "Delaunay of 400 random points, orthographic": lambda: (_delaunay(400, 2), dict(azimuth=-50, elevation=40,
                                                                                     ortho=True)),
    # pixel centres on the lattice's vertices and edges: 3 units over 12 pixels
    "lattice along an axis, rays in faces and along edges": lambda: (_lattice(), "axis"),
    "lattice along a face diagonal": lambda: (_lattice(), "diagonal"),
}


def _mesh_scene(case):
    mesh, view = MESH_CASES[case]()
    if view == "axis":
        cam = dvr_gl.Camera((1.5, 1.5, 10.0), (1.5, 1.5, 1.5), ortho_height=4.0)   # 1/3 unit per pixel at 12 px
        return dvr_gl.Scene(mesh, dvr_gl.TransferFunction(color=[(0, 0, 0.5, 1), (1, 1, 0.5, 0)],
                                                          opacity=[(0, 0.5), (1, 0.9)]), cam, width=12, height=12)
    if view == "diagonal":
        cam = dvr_gl.Camera((11.5, 11.5, 1.5), (1.5, 1.5, 1.5), up=(0, 0, 1), ortho_height=6.0)
        return dvr_gl.Scene(mesh, dvr_gl.TransferFunction(color=[(0, 0, 0.5, 1), (1, 1, 0.5, 0)],
                                                          opacity=[(0, 0.5), (1, 0.9)]), cam, width=48, height=48)
    return dvr_gl.Scene(mesh, MESH_TF, dvr_gl.default_camera(mesh, **view), width=96, height=96)


@pytest.mark.parametrize("sort", ["mpvo", "walk"])
@pytest.mark.parametrize("case", list(MESH_CASES))
def test_projected_tetrahedra_on_edges_vertices_and_slivers(renderer, case, sort):
    """Against the float64 reference (exact segments of every ray in every cell): no
    pixel may lose or double a cell, wherever its ray meets the mesh's edges, in a
    visibility order (MPVO) or walked cell to cell (the default; a ray in a shared face's
    plane belongs to one of its two cells, and the walk crosses to it)."""
    scene = _mesh_scene(case)
    gl = renderer.render(scene, technique="tetra", sort=sort)
    ref = reference.render(scene, technique="tetra")
    assert ref[..., 3].max() > 0.3
    record(case, f"tetra ({sort}) vs float64 reference", MESH_TOL, metrics.max_abs_error(gl, ref))


# -- 4. a reader that closes the pipe ---------------------------------------------------------

@pytest.mark.parametrize("argv", [["info"], ["render", "builtin:synthetic", "--size", "24x24", "--out", "{out}"]],
                         ids=["info", "render"])
def test_closing_stdout_early_is_quiet_and_not_an_error(tmp_path, argv):
    """``dvr-gl ... | head -1``: the reader takes one line and closes the pipe; dvr-gl
    stops quietly, status 0, and the image it wrote is whole."""
    out = tmp_path / "out.png"
    argv = [a.replace("{out}", str(out)) for a in argv]
    reader = ("import subprocess, sys\n"
              f"p = subprocess.Popen([sys.executable, '-m', 'dvr_gl'] + {argv!r}, stdout=subprocess.PIPE, "
              "stderr=subprocess.PIPE)\n"
              "p.stdout.readline(); p.stdout.close()\n"
              "err = p.stderr.read().decode(); code = p.wait()\n"
              "print(code); print(err)\n")
    done = subprocess.run([sys.executable, "-c", reader], capture_output=True, text=True, timeout=120)
    code, _, err = done.stdout.partition("\n")
    assert "Traceback" not in err and "BrokenPipe" not in err, err
    record("stdout closed after one line", f"dvr-gl {argv[0]}: exit status", 0, abs(int(code)))
    if argv[0] == "render":
        from PIL import Image
        assert Image.open(out).size == (24, 24)


# -- loaders: truncated and corrupted files ----------------------------------------------------

def _valid_files(folder):
    """Small valid files of each format the loaders read: (name, loader keyword arguments)."""
    import gzip
    import meshio
    data = (np.arange(4 * 5 * 6, dtype=np.float32).reshape(4, 5, 6) / 7.0)
    np.save(folder / "v.npy", data)
    header = ("NRRD0004\ntype: float\ndimension: 3\nsizes: 6 5 4\nspacings: 1 1 2\nendian: little\n"
              "encoding: raw\n\n")
    (folder / "v.nrrd").write_bytes(header.encode() + data.tobytes())
    mha = ("ObjectType = Image\nNDims = 3\nDimSize = 6 5 4\nElementSpacing = 1 1 2\nElementType = MET_FLOAT\n"
           "ElementDataFile = LOCAL\n")
    (folder / "v.mha").write_bytes(mha.encode() + data.tobytes())
    (folder / "v.raw.gz").write_bytes(gzip.compress(data.tobytes()))
    pts = np.random.default_rng(0).random((30, 3))
    mesh = dvr_gl.TetMesh.from_points(pts, pts[:, 0])
    meshio.write(folder / "m.vtu", meshio.Mesh(mesh.points, [("tetra", mesh.tets)], point_data={"s": mesh.scalars}))
    np.savez(folder / "m.npz", points=mesh.points, tets=mesh.tets, s=mesh.scalars)
    import nibabel
    nibabel.save(nibabel.Nifti1Image(np.transpose(data, (2, 1, 0)), np.diag([1.0, 1.0, 2.0, 1.0])),
                 str(folder / "v.nii.gz"))
    (folder / "v_6x5x4_float32.raw").write_bytes(data.astype("<f4").tobytes())
    return [("v.npy", {}), ("v.nrrd", {}), ("v.mha", {}), ("v.nii.gz", {}), ("v_6x5x4_float32.raw", {}),
            ("v.raw.gz", {"shape": (4, 5, 6), "dtype": "float32", "spacing": (1, 1, 2)}),
            ("m.vtu", {}), ("m.npz", {})]


def test_truncated_and_corrupted_files_give_named_errors(tmp_path_factory):
    """Every loader, on its valid file cut short at any byte or with any byte changed,
    either loads (the change was harmless) or raises dvr_gl.formats.InputError naming the
    field (or, where the bytes read fine but hold a NaN, the Volume's own error naming
    "data"); nothing else escapes (hypothesis explores the cuts and the changes)."""
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st
    from dvr_gl import formats as dvr_io
    folder = tmp_path_factory.mktemp("fuzz")
    files = _valid_files(folder)
    outcomes = {"loaded": 0, "named error": 0}

    # derandomized: the same 200 cases on every run (CI must not flake); other seeds were
    # explored while writing it (--hypothesis-seed=N, 2000 cases, no escape)
    @settings(max_examples=200, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
    @given(which=st.integers(0, len(files) - 1), cut=st.booleans(), where=st.floats(0, 1),
           byte=st.integers(0, 255))
    def check(which, cut, where, byte):
        name, kwargs = files[which]
        raw = bytearray((folder / name).read_bytes())
        at = min(int(where * len(raw)), len(raw) - 1)
        if cut:
            raw = raw[:at]
        else:
            raw[at] = byte
        target = folder / ("bad_" + name)
        target.write_bytes(bytes(raw))
        load = dvr_io.load_mesh if name.startswith("m.") else dvr_io.load_volume
        try:
            load(str(target), **kwargs)
            outcomes["loaded"] += 1
        except dvr_io.InputError as e:
            assert e.field and str(e), e
            outcomes["named error"] += 1
        except ValueError as e:   # read whole, but the values are not a volume (a NaN): Volume says so
            assert str(e).split(" ")[0] in ("data", "points", "tets", "scalars", "spacing", "origin"), e
            outcomes["named error"] += 1

    check()
    assert outcomes["named error"] > 0
    record("loaders on truncated or corrupted files (200 cases)", "errors other than a named InputError", 0, 0)


@pytest.mark.parametrize("distance", [60.0, 120.0, 300.0])
def test_geometry_of_a_far_small_box_is_not_lost_to_the_depth_range(renderer, distance):
    """A 9-unit box seen from up to 300 units with a narrow view. With a near plane of
    1e-6 of the box's diagonal every vertex's clip z and w were equal to float32 rounding
    and GL's far-plane clip dropped pieces of 2D slices, Gaussian splats and particles at
    random (GL against reference 0.06 to 1.0 before the fix; ``common.near_plane``). GL
    against reference within the suite's bounds for each: 1e-4 for slices (float32 on
    one slab per slice) and the splats, and the identical particle set."""
    z, y, x = np.mgrid[0:1:10j, 0:1:10j, 0:1:10j]
    vol = dvr_gl.Volume((100 * np.exp(-((x - .5) ** 2 + (y - .5) ** 2 + (z - .5) ** 2) / 0.1)).astype(np.float32))
    tf = dvr_gl.TransferFunction([(0, 0.9, 0.5, 0.1), (100, 0.1, 0.5, 0.9)], [(0, 0.05), (100, 0.5)],
                                 unit_distance=2.0)
    direction = np.array([-0.1, 0.9, -0.45])
    direction /= np.linalg.norm(direction)
    fov = float(np.degrees(2 * np.arctan(9 / distance)))
    scene = dvr_gl.Scene(vol, tf, dvr_gl.Camera(4.5 + direction * distance, (4.5, 4.5, 4.5), fov=fov), 32, 32)
    for technique, opts, bound in (("slice2d", {}, 1e-4), ("splat", {"kernel": "gaussian"}, 1e-4),
                                   ("particles", {"seed": 1}, 1e-4)):
        gl = renderer.render(scene, technique=technique, **opts)
        ref = reference.render(scene, technique=technique, **opts)
        assert ref[..., 3].max() > 0.3, technique
        assert np.abs(gl - ref).max() < bound, (technique, float(np.abs(gl - ref).max()))


def test_slice3d_of_a_box_thinner_than_a_step_is_the_gap_pass(renderer):
    """No slice plane falls inside a box 1 unit deep along the view at a step of 2: every
    ray is integrated by the gap pass (which used to be skipped, leaving the image empty
    where the reference and exact have alpha 0.8). GL against reference within 1e-4,
    and the reference within the midpoint rule's error of exact on this linear field."""
    z, y, x = np.mgrid[0:1:2j, 0:1:8j, 0:1:8j]
    vol = dvr_gl.Volume((50 + 50 * x * y).astype(np.float32))
    tf = dvr_gl.TransferFunction([(0, 0.9, 0.5, 0.1), (100, 0.1, 0.5, 0.9)], [(0, 0.4), (100, 0.8)],
                                 unit_distance=1.0)
    scene = dvr_gl.Scene(vol, tf, dvr_gl.Camera((3.5, 3.5, 10.2), (3.5, 3.5, 0.0), fov=50.0), 24, 24)
    from dvr_gl.techniques import slice3d
    assert slice3d.make_plan(scene, 2.0).count == 0
    gl = renderer.render(scene, technique="slice3d", step=2.0)
    ref = reference.render(scene, technique="slice3d", step=2.0)
    assert ref[..., 3].max() > 0.8
    assert np.abs(gl - ref).max() < 1e-4
    assert metrics.rmse(ref, reference.exact(scene)) < 1e-2


def test_sabella_peak_on_a_plateau_is_its_first_point(renderer):
    """A constant field under Sabella's model: the peak is the plateau's first point on
    each ray (the contract's tie rule). The reference's interpolation used to return the
    plateau value +- 1 ulp, so its peak search took a random sample and its depth-faded
    saturation was off by 0.31. Reference, GL and exact now agree: the reference within
    the midpoint rule's 3e-3 of exact here, GL within 1e-5 of the reference."""
    s = 1.6097516036551733
    vol = dvr_gl.Volume(np.full((21, 7, 20), 1082, np.uint16), spacing=(s, s, s))
    tf = dvr_gl.TransferFunction([(1000.0, 0.6073, 0.8693, 0.4383), (1200.0, 0.2443, 0.0179, 0.9959)],
                                 [(1000.0, 0.3789), (1200.0, 0.7574)], unit_distance=0.781)
    centre = vol.bounds[0] + vol.extent / 2
    cam = dvr_gl.Camera(centre + (68.0, 0, 0), centre, up=(0, 1, 0), fov=40.0)
    scene = dvr_gl.Scene(vol, tf, cam, 10, 40, optical_model="sabella")
    opts = dict(step=0.4024, ert_transmittance=0.0)
    ref = reference.render(scene, **opts)
    assert np.abs(ref - reference.exact(scene)).max() < 3e-3
    assert np.abs(renderer.render(scene, **opts) - ref).max() < 1e-5


@pytest.mark.parametrize("technique, opts", [("raycast", {"step": 0.2, "ert_transmittance": 0.0}),
                                             ("slice3d", {"step": 0.2}), ("slice2d", {}), ("splat", {})])
def test_rays_lying_in_a_face_plane_are_in_the_closed_box(renderer, technique, opts):
    """The eye on the plane of the box's upper y face, the middle row of an odd-height
    image parallel to it: those rays lie in the closed box, as exact and GL have them.
    The references lost them (the origin, made relative to the box's corner, rounded
    just outside the face): 1.0 per pixel. GL against reference within 1e-4 now, and the
    row as opaque as exact."""
    s = 0.8952079109917946
    vol = dvr_gl.Volume(np.full((2, 5, 23), 1.0, np.float32), spacing=(s, s, s),
                        origin=(37.888256345129236, 16.364832830530545, 5.529244782430439))
    lo, hi = vol.bounds
    tf = dvr_gl.TransferFunction([(0, 1, 0.5, 0.2), (2, 1, 0.5, 0.2)], [(0, 0.5), (2, 0.5)], unit_distance=1.0)
    eye = np.array([lo[0] - 20, hi[1], 0.5 * (lo[2] + hi[2])])
    scene = dvr_gl.Scene(vol, tf, dvr_gl.Camera(eye, eye + [1, 0, 0], up=(0, 1, 0), fov=40.0), 23, 37)
    ref = reference.render(scene, technique=technique, **opts)
    assert ref[18, 11, 3] > 0.99 and reference.exact(scene)[18, 11, 3] > 0.99
    assert np.abs(renderer.render(scene, technique=technique, **opts) - ref).max() < 1e-4
