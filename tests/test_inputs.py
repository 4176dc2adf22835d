"""dvr_gl.inputs: what the command line, the viewer and dvr_gl.render share, and the
one-line dvr_gl.render."""

import numpy as np
import pytest

import dvr_gl
from dvr_gl import inputs
from dvr_gl.io import InputError
from dvr_gl.transfer import auto_preset


def test_render_an_array_in_one_line_is_the_scene_it_stands_for(renderer):
    data = np.random.default_rng(0).random((12, 14, 16)).astype(np.float32)
    image = dvr_gl.render(data, size=(40, 32), azimuth=30, elevation=20)
    vol = dvr_gl.Volume(data)
    scene = dvr_gl.Scene(vol, auto_preset(vol), dvr_gl.default_camera(vol, azimuth=30, elevation=20), 40, 32)
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
