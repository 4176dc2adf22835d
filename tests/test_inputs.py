"""dvr_gl.frontends.inputs: what the command line, the viewer and dvr_gl.render share, and the
one-line dvr_gl.render."""

import os

import numpy as np
import pytest
from PIL import Image

import dvr_gl
from dvr_gl.frontends import inputs
from dvr_gl.formats import InputError
from dvr_gl.model.transfer import auto_preset

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
    from dvr_gl.frontends.inputs import first_camera
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
    from dvr_gl.frontends import cli
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
    from dvr_gl.model.transfer import auto_preset_name
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
    eight = dvr_gl.Volume(rng.integers(0, 256, (8, 9, 10)).astype(np.uint8))
    for preset in inputs.PRESETS:      # the 8-bit CT forms take 8-bit data (tested below)
        assert inputs.resolve_tf(preset, eight if preset.endswith("_8bit") else hu)[1].unit_distance > 0
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
    mesh = dvr_gl.formats.load_mesh(path)
    assert mesh.scalars_name == "Density" and mesh.scalars.tolist() == [0.1, 0.5, 0.9, 1.3, 2.0]
    assert dvr_gl.formats.load_mesh(path, scalars="IBlank").scalars_name == "IBlank"


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
    from dvr_gl.frontends import cli
    vol = dvr_gl.Volume(np.random.default_rng(1).random((5, 6, 7)).astype(np.float32))
    with pytest.warns(UserWarning, match="iso 7 is outside the data's range"):
        dvr_gl.render(vol, mode="isosurface", iso=7.0, size=16)
    np.save(tmp_path / "v.npy", vol.data)
    assert cli.main(["render", str(tmp_path / "v.npy"), "--iso", "7", "--size", "16x16", "-o",
                     str(tmp_path / "v.png")]) == 0
    assert "warning: --iso 7 is outside the data's range" in capsys.readouterr().err


# -- CT windowed to 8 bits ------------------------------------------------------------------

EIGHT_BIT_KINDS = ("ct_8bit", "ct_bone_8bit", "ct_lung_8bit")


@pytest.mark.parametrize("kind", EIGHT_BIT_KINDS)
@pytest.mark.parametrize("window", [None, (-160.0, 240.0), (-1024.0, 3071.0), (300.0, 301.0)])
def test_8bit_ct_preset_is_the_hu_preset_through_the_window(kind, window):
    """At stored value v the 8-bit preset's colour and opacity are the HU preset's at
    lo + (hi - lo) v / 255. The HU preset is piecewise linear and the window affine, so
    the composition is piecewise linear with the mapped HU knots inside the window and the
    window's ends at 0 and 255: no resampling, only the rounding of each mapped knot's
    position (a few ulps of 255, about 1e-13) times the largest slope in stored units
    (the presets change by at most 1 over 100 HU, times (hi - lo) / 255 HU per stored unit
    <= 16 for these windows): below 1e-11."""
    from dvr_gl.model.transfer import CT_8BIT_WINDOWS, ct_8bit_preset, ct_preset, stored_to_hu
    data = dvr_gl.Volume(np.random.default_rng(4).integers(0, 256, (6, 7, 8)).astype(np.uint8), spacing=(2, 1, 3))
    tf8 = ct_8bit_preset(data, kind, window)
    hu_tf = ct_preset(data, kind[:-len("_8bit")])
    window = window or CT_8BIT_WINDOWS[kind]
    v = np.concatenate([np.arange(256.0), np.linspace(0, 255, 25501)])
    hu = stored_to_hu(v, window)
    assert hu[0] == window[0] and hu[255] == window[1]
    np.testing.assert_allclose(tf8.color(v), hu_tf.color(hu), rtol=0, atol=1e-11)
    np.testing.assert_allclose(tf8.opacity(v), hu_tf.opacity(hu), rtol=0, atol=1e-11)
    assert tf8.knots[0] == 0 and tf8.knots[-1] == 255 and tf8.unit_distance == hu_tf.unit_distance == 1
    # the stored values are not HU: read as HU, the same data would get another picture
    assert np.abs(tf8.opacity(v) - hu_tf.opacity(v)).max() > 0.04


def test_8bit_ct_windows_named_and_their_errors():
    from dvr_gl.model.transfer import CT_8BIT_WINDOWS, ct_8bit_preset
    eight = dvr_gl.Volume(np.arange(2 * 3 * 256, dtype=np.int64).reshape(2, 3, 256).astype(np.uint8))
    assert CT_8BIT_WINDOWS["ct_bone_8bit"] == (-500, 1300) and CT_8BIT_WINDOWS["ct_lung_8bit"] == (-1350, 150)
    name, tf = inputs.resolve_tf("ct_8bit:-160,240", eight)          # the window the data was made with
    assert name == "ct_8bit:-160,240" and tf.key() == ct_8bit_preset(eight, "ct_8bit", (-160, 240)).key()
    assert tf.key() != inputs.PRESETS["ct_8bit"](eight).key()
    name, tf = inputs.resolve_tf("ct-bone-8bit: -500 , 1300", eight)
    assert name == "ct_bone_8bit: -500 , 1300" and tf.key() == inputs.PRESETS["ct_bone_8bit"](eight).key()
    for spec, fragment in (("ct_8bit:", "two numbers LO,HI"), ("ct_8bit:-160", "two numbers LO,HI"),
                           ("ct_8bit:a,b", "two numbers LO,HI"), ("ct_lung_8bit:1,2,3", "two numbers LO,HI"),
                           ("ct_8bit:240,-160", "LO < HI"), ("ct_8bit:5,5", "LO < HI"),
                           ("ct_bone_8bit:nan,300", "finite"), ("ct_8bit:-inf,300", "finite")):
        with pytest.raises(InputError) as e:
            inputs.resolve_tf(spec, eight)
        assert e.value.field == "tf" and fragment in str(e.value) and repr(spec.partition(":")[2]) in str(e.value)
    hu = dvr_gl.Volume(np.linspace(-1000, 2000, 24).reshape(2, 3, 4).astype(np.int16))
    with pytest.raises(InputError) as e:
        inputs.resolve_tf("ct_8bit", hu)
    assert e.value.field == "tf" and "-1000..2000" in str(e.value) and "use ct" in str(e.value)
    with pytest.raises(InputError, match="ct_8bit:LO,HI"):
        inputs.resolve_tf("ct_8bits", eight)


def test_auto_picks_the_8bit_ct_preset_from_the_modality():
    """8-bit data is taken for windowed CT only when its metadata says CT: an MRI or a
    microscope stack has most samples at 0 too."""
    from dvr_gl.model.transfer import auto_preset_name
    rng = np.random.default_rng(6)
    samples = np.where(rng.random((8, 9, 10)) < 0.8, 0, rng.integers(1, 256, (8, 9, 10))).astype(np.uint8)
    ct = dvr_gl.Volume(samples, modality="CT")
    assert auto_preset_name(ct) == "ct_8bit" and auto_preset(ct).key() == inputs.PRESETS["ct_8bit"](ct).key()
    assert inputs.resolve_tf(None, ct)[1].key() == inputs.PRESETS["ct_8bit"](ct).key()
    unknown = dvr_gl.Volume(samples)
    assert auto_preset_name(unknown) == "warm ramp"
    assert auto_preset_name(dvr_gl.Volume(samples, modality="MR")) == "mr"
    assert auto_preset_name(dvr_gl.Volume(samples, orientation="RAS")) == "mr"
    assert auto_preset_name(dvr_gl.Volume(samples, modality="CT", orientation="RAS")) == "ct_8bit"
    hu = dvr_gl.Volume(rng.integers(-1000, 1500, (8, 9, 10)).astype(np.int16), modality="CT")
    assert auto_preset_name(hu) == "ct"                            # CT in HU: the HU preset
    assert auto_preset_name(dvr_gl.Volume(samples.astype(np.float32), modality="CT")) == "warm ramp"
    assert inputs.suitable_presets(ct)[:4] == ["auto", "ct_8bit", "ct_bone_8bit", "ct_lung_8bit"]
    assert "ct_8bit" in inputs.suitable_presets(unknown)          # may be CT: offered, not chosen
    assert "ct_8bit" not in inputs.suitable_presets(dvr_gl.Volume(samples, modality="MR"))
    assert "ct_8bit" not in inputs.suitable_presets(hu) and "ct" in inputs.suitable_presets(hu)


@pytest.mark.skipif(not os.path.isdir(SHARED_DATA), reason="the shared data folder is not beside the checkout")
def test_the_shared_8bit_chest_ct_under_its_presets():
    """LIDC2, a chest CT windowed to 0..255 (most samples clipped to 0): the plain 8-bit
    preset leaves stored 0 (air, lungs) clear; under the usual soft-tissue window the HU
    preset's skin veil would fill the box."""
    from dvr_gl.model.transfer import ct_8bit_preset
    vol, _ = inputs.load_input(os.path.join(SHARED_DATA, "vtkjs_lidc2_ct", "LIDC2_256x256x133_uint8.raw.gz"))
    assert vol.data.dtype == np.uint8 and (vol.data == 0).mean() > 0.8
    assert inputs.PRESETS["ct_8bit"](vol).opacity(0.0) == 0.0
    assert ct_8bit_preset(vol, "ct_8bit", (-160, 240)).opacity(0.0) > 0.01
    assert inputs.PRESETS["ct_bone_8bit"](vol).opacity(255.0) > 0.8       # bone, opaque


# -- orientation given -----------------------------------------------------------------------

def test_orientation_given_to_load_input_and_its_errors(tmp_path):
    data = np.zeros((4, 5, 6), np.float32)
    vol, _ = inputs.load_input(data, orientation="lps")
    assert vol.orientation == "LPS"
    again, _ = inputs.load_input(vol, orientation="RAS")
    assert again.orientation == "RAS" and vol.orientation == "LPS" and np.array_equal(again.data, vol.data)
    assert inputs.load_input(vol)[0] is vol
    head, preset = inputs.load_input("builtin:ct_head", orientation="RPI")
    assert head.orientation == "RPI" and preset == "ct_head"
    np.save(tmp_path / "v.npy", data)
    assert inputs.load_input(tmp_path / "v.npy", orientation="PIR")[0].orientation == "PIR"
    pts = np.random.default_rng(1).random((10, 3))
    mesh = dvr_gl.TetMesh.from_points(pts, pts[:, 0])
    np.savez(tmp_path / "m.npz", points=mesh.points, tets=mesh.tets, s=mesh.scalars)
    for source in (mesh, tmp_path / "m.npz"):
        with pytest.raises(InputError) as e:
            inputs.load_input(source, orientation="RAS")
        assert e.value.field == "orientation" and "meshes" in str(e.value)
    with pytest.raises(InputError) as e:
        inputs.load_input(data, orientation="up")
    assert e.value.field == "orientation" and "'up'" in str(e.value)


def test_render_takes_an_orientation(renderer):
    """``dvr_gl.render(..., orientation=)`` is the render of the volume with that
    orientation: the first view in front of the face, the head up."""
    data = np.random.default_rng(7).random((10, 12, 14)).astype(np.float32)
    image = dvr_gl.render(data, size=32, orientation="RPI", tf="warm")
    vol = dvr_gl.Volume(data, orientation="RPI")
    scene = dvr_gl.Scene(vol, inputs.PRESETS["warm"](vol), inputs.first_camera(vol), 32, 32, shading=True)
    np.testing.assert_array_equal(image, renderer.render(scene))
    assert not np.array_equal(image, dvr_gl.render(data, size=32, tf="warm"))


@pytest.mark.parametrize("left, right", [("RPS", "LPS"), ("LPI", "RPI"), ("LAS", "RAS"), ("PIL", "AIL")])
def test_left_handed_data_is_not_drawn_mirrored(renderer, left, right):
    """A head whose index axes form a left-handed anatomical frame cannot be shown the
    right way round by any camera: the loaders reverse its x axis. The same anatomy
    stored both ways (x reversed, the x letter swapped) then loads as the same volume and
    renders the same picture; without the reversal the two are mirror images (the
    asymmetric phantom makes sure they differ)."""
    rng = np.random.default_rng(3)
    stored = rng.random((9, 10, 11)).astype(np.float32)
    stored[2:5, 3:6, 7:10] += 2.0                      # a blob on one side only
    mirrored = np.ascontiguousarray(stored[:, :, ::-1])
    a, _ = inputs.load_input(stored, orientation=right)
    b, _ = inputs.load_input(mirrored, orientation=left)
    assert a.orientation == right and b.orientation == right
    np.testing.assert_array_equal(a.data, b.data)
    images = [dvr_gl.render(v, size=32, tf="warm") for v in (a, b)]
    np.testing.assert_array_equal(images[0], images[1])
    raw = dvr_gl.Volume(mirrored, orientation=left)       # the mirror image the loaders avoid
    assert np.abs(dvr_gl.render(raw, size=32, tf="warm") - images[0]).max() > 0.05


@pytest.mark.skipif(not os.path.isdir(SHARED_DATA), reason="the shared data folder is not beside the checkout")
def test_a_file_with_a_left_handed_orientation_loads_reversed_in_x():
    from dvr_gl import formats as io
    path = os.path.join(SHARED_DATA, "vtk_headsq_quarter", "quarter.nhdr")
    plain = io.load_volume(path, orientation="RPI")         # right-handed: as stored
    given = io.load_volume(path, orientation="LPI")
    assert plain.orientation == "RPI" and given.orientation == "RPI"
    np.testing.assert_array_equal(given.data, plain.data[:, :, ::-1])
    assert io.right_handed(plain.data, "LPS")[0] is plain.data          # right-handed: untouched
