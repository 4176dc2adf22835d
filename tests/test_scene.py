"""Every bad input to the scene model fails at construction with a message that names
the parameter and the value."""

import re

import numpy as np
import pytest

import dvr_gl

DATA = np.zeros((3, 4, 5), np.float32)
VOL = dvr_gl.Volume(DATA)
TF = dvr_gl.TransferFunction(color=[(0, 0, 0, 0), (1, 1, 1, 1)], opacity=[(0, 0), (1, 0.5)])
CAM = dvr_gl.Camera((2, 1.5, 10), (2, 1.5, 1))


@pytest.mark.parametrize("kwargs,exc,message", [
    (dict(data=[[[1.0]]]), TypeError, "data must be a numpy array, got list"),
    (dict(data=np.zeros((3, 4, 5), np.int32)), TypeError, "data dtype must be one of .*, got int32"),
    (dict(data=np.zeros((3, 4, 5), bool)), TypeError, "got bool"),
    (dict(data=np.zeros((4, 5))), ValueError, "data must be 3-D \\(nz, ny, nx\\), got ndim=2"),
    (dict(data=np.zeros((1, 4, 5))), ValueError, "at least 2 samples on every axis, got shape=\\(1, 4, 5\\)"),
    (dict(data=np.array([[[np.nan, 1], [1, 1]], [[1, 1], [1, 1]]])), ValueError, "non-finite values .*index \\(0, 0, 0\\): nan"),
    (dict(spacing=(1, 0, 1)), ValueError, "spacing must be positive on every axis, got \\(1, 0, 1\\)"),
    (dict(spacing=(1, -2, 1)), ValueError, "spacing must be positive"),
    (dict(spacing=(1, np.inf, 1)), ValueError, "spacing must be finite"),
    (dict(spacing=(1, 1)), ValueError, "spacing must have 3 components"),
    (dict(spacing="abc"), TypeError, "spacing must be three numbers, got 'abc'"),
    (dict(origin=(0, np.nan, 0)), ValueError, "origin must be finite"),
])
def test_volume_rejects(kwargs, exc, message):
    args = dict(data=DATA)
    args.update(kwargs)
    with pytest.raises(exc, match=message):
        dvr_gl.Volume(**args)


def test_volume_all_nonfinite_even_when_masked():
    with pytest.raises(ValueError, match="no finite value"):
        dvr_gl.Volume(np.full((2, 2, 2), np.nan), mask_nonfinite=True)


def test_volume_is_immutable_and_keeps_its_dtype():
    data = np.arange(24, dtype=np.uint16).reshape(2, 3, 4)
    v = dvr_gl.Volume(data)
    data[0, 0, 0] = 99  # the volume holds its own copy
    assert v.data[0, 0, 0] == 0 and v.data.dtype == np.uint16
    with pytest.raises(ValueError):
        v.data[0, 0, 0] = 1
    assert v.data_range == (0.0, 23.0)
    np.testing.assert_array_equal(v.dims, [4, 3, 2])


@pytest.mark.parametrize("kwargs,exc,message", [
    (dict(color=[(1, 0, 0, 0), (0, 1, 1, 1)]), ValueError, "color positions must be strictly increasing, got 1.0 then 0.0"),
    (dict(opacity=[(0, 0), (0, 1)]), ValueError, "opacity positions must be strictly increasing, got 0.0 then 0.0"),
    (dict(color=[(0, 1.5, 0, 0)]), ValueError, "color values must lie in \\[0, 1\\], got 1.5"),
    (dict(opacity=[(0, -0.1)]), ValueError, "opacity values must lie in \\[0, 1\\], got -0.1"),
    (dict(opacity=[(0, 2.0)]), ValueError, "opacity values must lie in \\[0, 1\\], got 2.0"),
    (dict(color=[(0, 1, 1)]), ValueError, "color must be a non-empty list of 4-tuples"),
    (dict(color=[]), ValueError, "color must be a non-empty list"),
    (dict(opacity=[(0, np.nan)]), ValueError, "opacity must be finite"),
    (dict(opacity="high"), TypeError, "opacity must be a list of 2-tuples of numbers, got 'high'"),
    (dict(unit_distance=0), ValueError, "unit_distance must be positive, got 0"),
    (dict(unit_distance=-1.0), ValueError, "unit_distance must be positive, got -1.0"),
    (dict(unit_distance=float("inf")), ValueError, "unit_distance must be finite"),
    (dict(unit_distance="1"), TypeError, "unit_distance must be a number, got '1'"),
])
def test_transfer_function_rejects(kwargs, exc, message):
    args = dict(color=[(0, 0, 0, 0), (1, 1, 1, 1)], opacity=[(0, 0), (1, 1)])
    args.update(kwargs)
    with pytest.raises(exc, match=message):
        dvr_gl.TransferFunction(**args)


def test_transfer_function_is_piecewise_linear_and_clamped():
    tf = dvr_gl.TransferFunction(color=[(10, 0, 0, 0), (20, 1, 0.5, 0)], opacity=[(0, 0.2), (10, 1.0)], unit_distance=2)
    np.testing.assert_allclose(tf.color([5, 15, 25]), [[0, 0, 0], [0.5, 0.25, 0], [1, 0.5, 0]])
    np.testing.assert_allclose(tf.opacity([-5, 5, 50]), [0.2, 0.6, 1.0])
    assert tf.extinction(50) == np.inf
    np.testing.assert_allclose(tf.extinction(-5), -np.log(0.8) / 2)
    np.testing.assert_array_equal(tf.knots, [0, 10, 20])


@pytest.mark.parametrize("kwargs,exc,message", [
    (dict(eye=(1, 2, 3), target=(1, 2, 3)), ValueError, "eye must differ from target, both are \\(1.0, 2.0, 3.0\\)"),
    (dict(up=(0, 0, 1)), ValueError, "up \\(0.0, 0.0, 1.0\\) is parallel to the view direction"),
    (dict(up=(0, 0, 0)), ValueError, "up must be a non-zero vector"),
    (dict(fov=0), ValueError, "fov must be positive, got 0"),
    (dict(fov=-30), ValueError, "fov must be positive, got -30"),
    (dict(fov=180), ValueError, "fov must be below 180 degrees, got 180"),
    (dict(ortho_height=0.0), ValueError, "ortho_height must be positive, got 0.0"),
    (dict(ortho_height=-2), ValueError, "ortho_height must be positive"),
    (dict(eye=(0, np.nan, 1)), ValueError, "eye must be finite"),
    (dict(target=(0, 1)), ValueError, "target must have 3 components"),
])
def test_camera_rejects(kwargs, exc, message):
    args = dict(eye=(0, 0, 5), target=(0, 0, 0))
    args.update(kwargs)
    with pytest.raises(exc, match=message):
        dvr_gl.Camera(**args)


def test_camera_rays_through_pixel_centres():
    cam = dvr_gl.Camera((0, 0, 10), (0, 0, 0), fov=90)
    o, d = cam.rays(2, 2)
    # 90 degrees: the view spans [-1, 1] at unit distance; pixel centres at +-0.5
    expect = np.array([-0.5, 0.5, -1.0]) / np.linalg.norm([0.5, 0.5, 1.0])
    np.testing.assert_allclose(d[0, 0], expect)  # row 0 on top, column 0 on the left
    np.testing.assert_allclose(o, 0 * o + [0, 0, 10])
    ortho = dvr_gl.Camera((0, 0, 10), (0, 0, 0), ortho_height=4.0)
    o, d = ortho.rays(4, 2)
    np.testing.assert_allclose(o[1, 3], [3.0, -1.0, 10.0])  # aspect 2: width 8
    np.testing.assert_allclose(d[1, 3], [0, 0, -1])


@pytest.mark.parametrize("kwargs,exc,message", [
    (dict(volume=DATA), TypeError, "volume must be a dvr_gl.Volume or dvr_gl.TetMesh, got ndarray"),
    (dict(tf={"color": []}), TypeError, "tf must be a dvr_gl.TransferFunction or TransferFunction2D, got dict"),
    (dict(camera=None), TypeError, "camera must be a dvr_gl.Camera, got NoneType"),
    (dict(width=0), ValueError, "width must be between 1 and 65536 pixels, got 0"),
    (dict(height=100000), ValueError, "height must be between 1 and 65536 pixels, got 100000"),
    (dict(width=12.5), TypeError, "width must be an integer, got 12.5"),
    (dict(mode="xray"), ValueError, "mode must be one of composite, mip, minip, average, isosurface, got 'xray'"),
    (dict(mode="isosurface"), ValueError, "iso_value is required for mode='isosurface', got None"),
    (dict(mode="isosurface", iso_value=np.nan), ValueError, "iso_value must be finite, got nan"),
    (dict(shading=True, mode="mip"), ValueError, "shading applies to modes composite and isosurface .* "
     "got shading=True with mode='mip'"),
    (dict(shading="on"), TypeError, "shading must be True or False, got 'on'"),
    (dict(phong=(0.3, 0.7, 0.2)), ValueError, "phong must be four finite non-negative numbers"),
    (dict(phong=(0.3, 0.7, -0.2, 32)), ValueError, "phong must be four finite non-negative numbers"),
    (dict(lights=()), ValueError, r"lights must be 1 to 4 dvr_gl.Light objects, got \(\)"),
    (dict(lights=[dvr_gl.Light()] * 5), ValueError, "lights must be 1 to 4 dvr_gl.Light objects"),
    (dict(lights=("headlight",)), ValueError, r"lights must be 1 to 4 dvr_gl.Light objects, got \('headlight',\)"),
    (dict(lights=3), TypeError, "lights must be a dvr_gl.Light or a sequence of them, got 3"),
])
def test_scene_rejects(kwargs, exc, message):
    args = dict(volume=VOL, tf=TF, camera=CAM)
    args.update(kwargs)
    with pytest.raises(exc, match=message):
        dvr_gl.Scene(**args)


def test_isosurface_scenes_are_always_shaded():
    s = dvr_gl.Scene(VOL, TF, CAM, mode="isosurface", iso_value=0.5)
    assert s.shaded and not dvr_gl.Scene(VOL, TF, CAM).shaded
    assert s.replace(width=8).width == 8 and s.replace(width=8).mode == "isosurface"


def test_scene_digest_changes_with_what_defines_the_image():
    a = dvr_gl.Scene(VOL, TF, CAM, width=8, height=8)
    assert a.digest() == dvr_gl.Scene(dvr_gl.Volume(DATA.copy()), TF, CAM, width=8, height=8).digest()
    assert a.digest() != a.replace(width=9).digest()
    assert a.digest() != a.replace(camera=dvr_gl.Camera((2, 1.5, 11), (2, 1.5, 1))).digest()


def test_default_camera_fits_and_rotates():
    cam = dvr_gl.default_camera(VOL)
    np.testing.assert_allclose(cam.forward, [0, 0, -1])
    np.testing.assert_allclose(cam.target, (np.array([4, 3, 2]) / 2))
    side = dvr_gl.default_camera(VOL, azimuth=90)
    np.testing.assert_allclose(side.forward, [-1, 0, 0], atol=1e-12)
    top = dvr_gl.default_camera(VOL, elevation=90)  # looking straight down stays valid
    np.testing.assert_allclose(top.forward, [0, -1, 0], atol=1e-12)
    with pytest.raises(ValueError, match="zoom must be positive, got 0"):
        dvr_gl.default_camera(VOL, zoom=0)


def test_render_inside_an_entered_context_reads_back_the_image(renderer):
    """Renderer calls nest inside a caller's ``current(ctx)`` block: moderngl's own
    ``with ctx`` does not nest (leaving the inner block leaves no context current, and a
    read-back returns uninitialised memory)."""
    from dvr_gl.gl.context import current
    volume = dvr_gl.Volume(np.linspace(0, 1, 64, dtype=np.float32).reshape(4, 4, 4))
    tf = dvr_gl.TransferFunction([(0, 1, 1, 1), (1, 1, 1, 1)], [(0, 0.5), (1, 0.5)])
    scene = dvr_gl.Scene(volume, tf, dvr_gl.default_camera(volume), width=16, height=16)
    plain = renderer.render(scene)
    with current(renderer.ctx):
        fbo = renderer.render_target(scene)
        inner = renderer.read_target(fbo, 16, 16)
        again = renderer.render(scene)
    assert np.isfinite(inner).all() and plain[..., 3].max() > 0
    np.testing.assert_array_equal(inner, plain)
    np.testing.assert_array_equal(again, plain)


# -- TetMesh -------------------------------------------------------------------------------
_PTS = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], float)
_TETS = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
_VALS = np.arange(5.0)


@pytest.mark.parametrize("points, tets, scalars, exc, text", [
    (_PTS[:, :2], _TETS, _VALS, ValueError, r"points must have shape \(N, 3\)"),
    (np.where(_PTS == 1, np.nan, _PTS), _TETS, _VALS, ValueError, "points must be finite, point 1"),
    (_PTS, _TETS.astype(float), _VALS, TypeError, "tets must be integer indices, got dtype float64"),
    (_PTS, _TETS[:, :3], _VALS, ValueError, r"tets must have shape \(M, 4\)"),
    (_PTS, np.array([[0, 1, 2, 5]]), _VALS, ValueError, r"tets\[0\] has index 5 out of range for 5 points"),
    (_PTS, np.array([[0, 1, -1, 2]]), _VALS, ValueError, r"tets\[0\] has index -1 out of range"),
    (_PTS, np.array([[0, 1, 2, 2]]), _VALS, ValueError, r"tets\[0\] repeats a vertex"),
    (_PTS, _TETS, _VALS[:4], ValueError, r"scalars must have shape \(5,\)"),
    (_PTS, _TETS, np.array([0, 1, np.inf, 3, 4.0]), ValueError, r"scalars\[2\] is inf"),
    (_PTS, _TETS, "abc", TypeError, "scalars must be an array of numbers"),
])
def test_tetmesh_rejects(points, tets, scalars, exc, text):
    with pytest.raises(exc, match=text):
        dvr_gl.TetMesh(points, tets, scalars)


def test_tetmesh_keeps_either_orientation_and_flat_cells():
    flipped = np.array([[0, 2, 1, 3], [1, 2, 3, 4]])
    m = dvr_gl.TetMesh(_PTS, flipped, _VALS)
    vols = m.signed_volumes()
    assert vols[0] < 0 < vols[1]
    flat = dvr_gl.TetMesh(np.vstack([_PTS, [[0.5, 0.5, 0]]]), [[0, 1, 2, 5]], np.arange(6.0))
    assert flat.signed_volumes()[0] == 0
    assert m.data_range == (0.0, 4.0) and m.n_tets == 2 and m.n_points == 5
    assert not m.points.flags.writeable and not m.tets.flags.writeable
    lo, hi = m.bounds
    assert np.array_equal(lo, [0, 0, 0]) and np.array_equal(hi, [1, 1, 1])
    assert m.digest() != flat.digest()
    scene = dvr_gl.Scene(m, dvr_gl.TransferFunction([(0, 1, 1, 1)], [(0, 0.5)]), dvr_gl.default_camera(m))
    assert scene.is_mesh and scene.digest() == scene.replace().digest()


def test_tetmesh_from_points_delaunay():
    rng = np.random.default_rng(0)
    pts = rng.random((60, 3))
    m = dvr_gl.TetMesh.from_points(pts, pts[:, 0])
    # Delaunay fills the convex hull exactly
    from scipy.spatial import ConvexHull
    assert abs(np.abs(m.signed_volumes()).sum() - ConvexHull(pts).volume) < 1e-12
    with pytest.raises(ValueError, match="cannot be tetrahedralised"):
        dvr_gl.TetMesh.from_points(np.c_[pts[:, :2], np.zeros(60)], pts[:, 0])


@pytest.mark.parametrize("kwargs,exc,message", [
    (dict(direction=(0, 0, 0)), ValueError, "direction must not be the zero vector, got (0.0, 0.0, 0.0)"),
    (dict(direction=(1, 0)), ValueError, "direction must have 3 components"),
    (dict(direction=(1, 0, float("nan"))), ValueError, "direction must be finite"),
    (dict(direction=(1, 0, 0), space="eye"), ValueError, "space must be one of world, view, got 'eye'"),
    (dict(intensity=-1), ValueError, "intensity must be non-negative, got -1"),
    (dict(intensity="bright"), TypeError, "intensity must be a number, got 'bright'"),
])
def test_light_rejects(kwargs, exc, message):
    with pytest.raises(exc, match=re.escape(message)):
        dvr_gl.Light(**kwargs)


def test_light_directions():
    cam = dvr_gl.Camera((0, 0, 10), (0, 0, 0))
    assert dvr_gl.Light().is_headlight and dvr_gl.Light().world_direction(cam) is None
    np.testing.assert_allclose(dvr_gl.Light((0, 0, 5)).direction, (0, 0, 1))
    # view space: x right, y up, z towards the viewer
    turned = dvr_gl.Camera((10, 0, 0), (0, 0, 0))
    np.testing.assert_allclose(dvr_gl.Light((0, 0, 1), space="view").world_direction(turned), (1, 0, 0), atol=1e-12)
    np.testing.assert_allclose(dvr_gl.Light((0, 1, 0), space="view").world_direction(turned), (0, 1, 0), atol=1e-12)
    scene = dvr_gl.Scene(VOL, TF, CAM)
    assert scene.headlight_only and scene.replace(lights=dvr_gl.Light()).digest() == scene.digest()
    assert not scene.replace(lights=dvr_gl.Light(intensity=0.5)).headlight_only


@pytest.mark.parametrize("codes", ["RAA", "XYZ", "RA", "RASL", 5])
def test_volume_orientation_rejects(codes):
    with pytest.raises((ValueError, TypeError), match="orientation must be three letters"):
        dvr_gl.Volume(DATA, orientation=codes)


def test_volume_orientation_and_its_frame():
    from dvr_gl.model.scene import anatomical_frame
    assert dvr_gl.Volume(DATA).orientation is None and anatomical_frame(dvr_gl.Volume(DATA)) is None
    v = dvr_gl.Volume(DATA, orientation="lpi")
    assert v.orientation == "LPI"
    front, up = anatomical_frame(v)
    assert front.tolist() == [0, -1, 0] and up.tolist() == [0, 0, -1]
    assert v.digest() == dvr_gl.Volume(DATA).digest()   # it changes no image, only the first view


def test_volume_modality_is_a_short_code_or_none():
    assert dvr_gl.Volume(DATA).modality is None
    assert dvr_gl.Volume(DATA, modality=" ct ").modality == "CT"
    assert dvr_gl.Volume(DATA, modality="MR").digest() == dvr_gl.Volume(DATA).digest()   # metadata only
    for bad in ("", "   ", "C-T", "X" * 17, 3, b"CT", "é"):
        with pytest.raises(ValueError, match="modality must be a code such as 'CT'") as e:
            dvr_gl.Volume(DATA, modality=bad)
        assert repr(bad) in str(e.value)
