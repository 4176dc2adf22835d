"""dvr_gl.inputs: what the command line, the viewer and dvr_gl.render share, and the
one-line dvr_gl.render."""

import os

import numpy as np
import pytest
from PIL import Image

import dvr_gl
from dvr_gl import inputs
from dvr_gl.io import InputError
from dvr_gl.transfer import auto_preset

SHARED_DATA = os.environ.get("DVR_GL_DATA") or os.path.join(
    os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "shared", "data")


def test_render_an_array_in_one_line_is_the_scene_it_stands_for(renderer):
    data = np.random.default_rng(0).random((12, 14, 16)).astype(np.float32)
    image = dvr_gl.render(data, size=(40, 32), azimuth=30, elevation=20)
    vol = dvr_gl.Volume(data)
    scene = dvr_gl.Scene(vol, auto_preset(vol), dvr_gl.default_camera(vol, azimuth=30, elevation=20), 40, 32,
                         shading=True)   # lit by default where the technique lights
    assert image.shape == (32, 40, 4) and image[..., 3].max() > 0.1
    np.testing.assert_array_equal(image, renderer.render(scene))
    stepped = dvr_gl.render(data, size=40, azimuth=30, elevation=20, technique="slice3d", step=0.4)
    np.testing.assert_array_equal(stepped, renderer.render(scene.replace(width=40, height=40), technique="slice3d",
                                                           step=0.4))


def test_render_bundled_data_files_and_meshes(tmp_path):
    assert dvr_gl.render("builtin:synthetic", size=24)[..., 3].max() > 0.05
    pts = np.random.default_rng(1).random((40, 3))
    mesh = dvr_gl.TetMesh.from_points(pts, pts[:, 0])
    np.savez(tmp_path / "m.npz", points=mesh.points, tets=mesh.tets, s=mesh.scalars)
    image = dvr_gl.render(str(tmp_path / "m.npz"), size=24, tf="auto")          # a mesh: tetra
    assert image[..., 3].max() > 0.05
    np.save(tmp_path / "v.npy", np.ones((4, 5, 6), np.float32))
    assert dvr_gl.render(tmp_path / "v.npy", size=16, spacing=(1, 1, 2)).shape == (16, 16, 4)


def test_inputs_errors_name_their_field(tmp_path):
    with pytest.raises(InputError) as e:
        inputs.load_input("builtin:nothing")
    assert e.value.field == "path" and "builtin:ct_head" in str(e.value)
    with pytest.raises(InputError) as e:
        inputs.load_input("builtin:ct_head", shape=(1, 2, 3))
    assert e.value.field == "shape"
    with pytest.raises(InputError) as e:
        inputs.load_input(3.5)
    assert e.value.field == "path"
    vol = dvr_gl.Volume(np.ones((3, 3, 3), np.float32))
    with pytest.raises(InputError) as e:
        inputs.resolve_tf("no_such_preset", vol)
    assert e.value.field == "tf" and "auto" in str(e.value)
    with pytest.raises(InputError, match="no such file"):
        inputs.resolve_tf(str(tmp_path / "missing.json"), vol)
    tf = dvr_gl.TransferFunction(color=[(0, 1, 1, 1)], opacity=[(0, 0.5)])
    assert inputs.resolve_tf(tf, vol) == ("given", tf)
    with pytest.raises(InputError) as e:
        dvr_gl.render(np.ones((3, 3, 3), np.float32), size="big")
    assert e.value.field == "size"


def test_the_first_view_is_oblique_and_faces_an_oriented_subject():
    """No angles: an oblique view (azimuth 30, elevation 20) in the data's frame; for a
    volume with an anatomical orientation that frame has the eye in front of the face and
    the head up, whichever way the axes run."""
    from dvr_gl.inputs import first_camera
    data = np.zeros((6, 7, 8), np.float32)
    plain = dvr_gl.Volume(data)
    cam = first_camera(plain)
    ref = dvr_gl.default_camera(plain, azimuth=30, elevation=20)
    assert np.allclose(cam.eye, ref.eye) and np.allclose(cam.true_up, ref.true_up)
    for codes, anterior, superior in (("RAS", (0, 1, 0), (0, 0, 1)), ("LPS", (0, -1, 0), (0, 0, 1)),
                                      ("RSP", (0, 0, -1), (0, 1, 0)), ("AIL", (1, 0, 0), (0, -1, 0))):
        vol = dvr_gl.Volume(data, orientation=codes)
        straight = first_camera(vol, azimuth=0, elevation=0)
        centre = np.mean(vol.bounds, axis=0)
        to_eye = (straight.eye - centre) / np.linalg.norm(straight.eye - centre)
        assert np.allclose(to_eye, anterior) and np.allclose(straight.true_up, superior), codes
        oblique = first_camera(vol)
        to_eye = (oblique.eye - centre) / np.linalg.norm(oblique.eye - centre)
        assert np.isclose(to_eye @ np.array(superior), np.sin(np.radians(20)))   # raised 20 degrees
        assert to_eye @ np.array(anterior) > 0.7                                  # still in front


def _first_pictures_app():
    import importlib.util
    path = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "apps", "first_pictures.py")
    spec = importlib.util.spec_from_file_location("first_pictures", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.skipif(not os.path.isdir(SHARED_DATA), reason="the shared data folder is not beside the checkout")
def test_every_shared_file_renders_in_colour_with_no_options(tmp_path, capsys):
    """`dvr-gl render FILE -o OUT` (only a small size given, for time) on every volume and
    mesh file the contact sheet shows: exit 0, something drawn, in colour, lit where the
    technique lights."""
    from dvr_gl import cli
    files = _first_pictures_app().data_files(SHARED_DATA)
    assert len(files) >= 15
    for path in files:
        out = tmp_path / "p.png"
        assert cli.main(["render", path, "-o", str(out), "--size", "48x48"]) == 0, path
        stdout = capsys.readouterr().out
        with Image.open(out) as im:
            assert im.mode == "RGB", path                # over white by default
            px = np.asarray(im).astype(int)
        assert (px.min(axis=-1) < 235).mean() > 0.05, path
        solid = px.min(axis=-1) < 200          # faint haze over white is pale whatever its hue
        spread = (px.max(axis=-1) - px.min(axis=-1))[solid]
        assert solid.any() and np.percentile(spread, 75) > 25, f"{path}: grey"
        assert ("rendered   tetra" in stdout) or (", lit," in stdout), path


def test_auto_picks_the_preset_the_data_suggests():
    from dvr_gl.transfer import auto_preset_name
    rng = np.random.default_rng(2)
    hu = dvr_gl.Volume(rng.integers(-1000, 1500, (8, 9, 10)).astype(np.int16))
    mri = dvr_gl.Volume(rng.random((8, 9, 10)).astype(np.float32) * 300, orientation="RAS")
    other = dvr_gl.Volume(rng.random((8, 9, 10)).astype(np.float32))
    assert auto_preset_name(hu) == "ct" and auto_preset(hu).key() == inputs.PRESETS["ct"](hu).key()
    assert auto_preset_name(mri) == "mr" and auto_preset(mri).key() == inputs.PRESETS["mr"](mri).key()
    assert auto_preset_name(other) == "warm ramp"
    assert inputs.suitable_presets(hu)[:4] == ["auto", "ct", "ct_bone", "ct_lung"]
    assert "mr" in inputs.suitable_presets(mri) and "ct" not in inputs.suitable_presets(mri)
    # colormaps through matplotlib, by name or as cmap:NAME; every named preset makes a TF
    name, tf = inputs.resolve_tf("cmap:twilight", other)
    assert name == "cmap:twilight" and len(tf.color_points) == 9
    for preset in inputs.PRESETS:
        assert inputs.resolve_tf(preset, hu)[1].unit_distance > 0
    with pytest.raises(InputError, match="matplotlib has no colormap 'nope'"):
        inputs.resolve_tf("cmap:nope", other)
    with pytest.raises(InputError, match="cmap:NAME for any matplotlib colormap"):
        inputs.resolve_tf("sunset", other)


def test_a_mesh_file_renders_its_first_field_not_a_flag(tmp_path):
    import meshio
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], float)
    cells = [("tetra", np.array([[0, 1, 2, 3], [1, 2, 3, 4]]))]
    path = tmp_path / "flagged.vtu"
    meshio.write(str(path), meshio.Mesh(points, cells, point_data={
        "IBlank": np.array([1, 1, 1, 0, -1], float), "Density": np.array([0.1, 0.5, 0.9, 1.3, 2.0])}))
    mesh = dvr_gl.io.load_mesh(path)
    assert mesh.scalars_name == "Density" and mesh.scalars.tolist() == [0.1, 0.5, 0.9, 1.3, 2.0]
    assert dvr_gl.io.load_mesh(path, scalars="IBlank").scalars_name == "IBlank"


def test_an_unknown_option_names_the_techniques_options(renderer):
    vol = dvr_gl.Volume(np.random.default_rng(1).random((5, 6, 7)).astype(np.float32))
    scene = dvr_gl.Scene(vol, auto_preset(vol), dvr_gl.default_camera(vol), 16, 16)
    with pytest.raises(TypeError, match="raycast has no option 'stepp'; its options are step, target, jitter_seed"):
        renderer.render(scene, "raycast", stepp=0.3)
    with pytest.raises(TypeError, match="slice2d has no option 'shells'; its options are target, interpolate"):
        dvr_gl.reference.render(scene, "slice2d", shells=True)
    with pytest.raises(TypeError, match="raycast has no option 'techniqe'"):
        dvr_gl.render(vol, techniqe="slice3d", size=16)


def test_an_iso_value_outside_the_data_warns(tmp_path, capsys):
    from dvr_gl import cli
    vol = dvr_gl.Volume(np.random.default_rng(1).random((5, 6, 7)).astype(np.float32))
    with pytest.warns(UserWarning, match="iso 7 is outside the data's range"):
        dvr_gl.render(vol, mode="isosurface", iso=7.0, size=16)
    np.save(tmp_path / "v.npy", vol.data)
    assert cli.main(["render", str(tmp_path / "v.npy"), "--iso", "7", "--size", "16x16", "-o",
                     str(tmp_path / "v.png")]) == 0
    assert "warning: --iso 7 is outside the data's range" in capsys.readouterr().err
