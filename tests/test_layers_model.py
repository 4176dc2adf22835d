"""The layer model: validation with named errors, placement, digests, channels."""

import math

import numpy as np
import pytest

from dvr_gl import Camera, LabelColors, Layer, Scene, TransferFunction, Volume
from dvr_gl.model.layers import MAX_LAYERS, channel_layers, union_bounds


def _volume(shape=(6, 7, 8), seed=0, **kw):
    return Volume(np.random.default_rng(seed).random(shape).astype(np.float32), **kw)


TF = TransferFunction([(0, 1, 1, 1), (1, 1, 0, 0)], [(0, 0), (1, 0.5)])
LABELS = LabelColors({1: (1, 0, 0, 0.5), 3: (0, 1, 0, 1)})
CAMERA = Camera((4, 4, 40), (4, 4, 3), (0, 1, 0))


def _rotation_z(angle, shift=(0, 0, 0)):
    c, s = math.cos(angle), math.sin(angle)
    return [[c, -s, 0, shift[0]], [s, c, 0, shift[1]], [0, 0, 1, shift[2]], [0, 0, 0, 1]]


def test_placement_maps_to_world_and_back():
    layer = Layer(_volume(), TF, _rotation_z(0.4, (1, 2, 3)))
    p = np.random.default_rng(1).random((10, 3)) * 5
    assert np.allclose(layer.to_local(layer.to_world(p)), p, atol=1e-12)
    # a rotation by +0.4 about z takes the x axis to (cos, sin, 0)
    assert np.allclose(layer.to_world([[1, 0, 0]]) - layer.to_world([[0, 0, 0]]), [[math.cos(0.4), math.sin(0.4), 0]])
    lo, hi = layer.world_bounds()
    assert np.all(layer.corners() >= lo - 1e-12) and np.all(layer.corners() <= hi + 1e-12)


def test_union_bounds_covers_every_layer():
    a = Layer(_volume(), TF)
    b = Layer(_volume(spacing=(2, 2, 2)), TF, _rotation_z(1.0, (-5, 0, 1)))
    lo, hi = union_bounds([a, b])
    for layer in (a, b):
        assert np.all(layer.corners() >= lo - 1e-12) and np.all(layer.corners() <= hi + 1e-12)


def test_scene_from_layers_and_digest():
    a, b = Layer(_volume(), TF), Layer(_volume(seed=2), TF, _rotation_z(0.3))
    scene = Scene.from_layers([a, b], CAMERA, width=16, height=16)
    assert scene.volume is a.volume and scene.layers == (b,) and scene.blend == "mix"
    assert len(scene.all_layers) == 2 and scene.all_layers[1] is b
    alone = Scene(a.volume, TF, CAMERA, width=16, height=16)
    assert alone.digest() != scene.digest()
    assert scene.replace(blend="add").digest() != scene.digest()
    moved = Scene.from_layers([a, Layer(b.volume, TF, _rotation_z(0.31))], CAMERA, width=16, height=16)
    assert moved.digest() != scene.digest()
    assert scene.replace(width=20).layers == (b,)
    # the default camera sees the box around all layers
    cam_scene = Scene.from_layers([a, b], width=16, height=16)
    assert np.allclose(cam_scene.camera.target, (scene.bounds[0] + scene.bounds[1]) / 2)


@pytest.mark.parametrize("kwargs, message", [
    (dict(blend="over"), "blend must be one of mix, add"),
    (dict(mode="mip"), "blend='mix' renders mode 'composite'"),
    (dict(shading=True), "lighting several volumes"),
    (dict(optical_model="absorption"), "emission-absorption"),
])
def test_scene_with_layers_refuses_what_it_cannot_mean(kwargs, message):
    with pytest.raises(ValueError, match=message):
        Scene(_volume(), TF, CAMERA, layers=[Layer(_volume(seed=3), TF)], **kwargs)


def test_named_errors():
    with pytest.raises(ValueError, match="rigid motion"):
        Layer(_volume(), TF, [[2, 0, 0], [0, 1, 0], [0, 0, 1]])
    with pytest.raises(ValueError, match="rigid motion"):
        Layer(_volume(), TF, [[-1, 0, 0], [0, 1, 0], [0, 0, 1]])        # a reflection
    with pytest.raises(TypeError, match="layers\\[0\\] must be a dvr_gl.Layer"):
        Scene(_volume(), TF, CAMERA, layers=[_volume()])
    with pytest.raises(ValueError, match=f"at most {MAX_LAYERS} volumes"):
        Scene(_volume(), TF, CAMERA, layers=[Layer(_volume(), TF)] * MAX_LAYERS)
    with pytest.raises(ValueError, match="integer labels, got 0.5"):
        Layer(Volume(np.full((3, 3, 3), 0.5, np.float32)), LABELS)
    with pytest.raises(ValueError, match="labels must be integers from 0"):
        LabelColors({-1: (1, 1, 1, 1)})
    with pytest.raises(ValueError, match="colors\\[2\\] must be four numbers"):
        LabelColors({2: (1, 1, 1, 2)})
    with pytest.raises(ValueError, match="first layer gives the scene its world"):
        Scene.from_layers([Layer(_volume(), TF, _rotation_z(0.2)), Layer(_volume(), TF)], CAMERA)
    with pytest.raises(ValueError, match="first layer gives the scene its world"):
        Scene.from_layers([Layer(Volume(np.ones((3, 3, 3), np.uint8)), LABELS)], CAMERA)
    with pytest.raises(ValueError, match="label layers are composited"):
        Scene(_volume(), TF, CAMERA, mode="mip", blend="add",
              layers=[Layer(Volume(np.ones((3, 3, 3), np.uint8)), LABELS)])


def test_label_colors_table():
    rgba = LABELS.rgba(np.array([0, 1, 2, 3, 7]))
    assert np.array_equal(rgba, [[0, 0, 0, 0], [1, 0, 0, 0.5], [0, 0, 0, 0], [0, 1, 0, 1], [0, 0, 0, 0]])
    tau = LABELS.extinction(np.array([1, 3]))
    assert tau[0] == pytest.approx(math.log(2)) and math.isinf(tau[1])


def test_crop_box_is_checked_against_all_layers():
    a = Layer(_volume(), TF)
    b = Layer(_volume(), TF, _rotation_z(0.0, (20, 0, 0)))
    # a box that misses the first volume but holds part of the second is kept
    scene = Scene.from_layers([a, b], CAMERA, crop_box=((21, 1, 1), (24, 4, 4)))
    assert scene.crop_box is not None
    with pytest.raises(ValueError):
        Scene.from_layers([a, b], CAMERA, crop_box=((100, 1, 1), (104, 4, 4)))


def test_channel_layers():
    data = np.random.default_rng(4).random((3, 5, 6, 7)).astype(np.float32)
    layers = channel_layers(data, spacing=(1, 1, 2), windows=[(0, 1)] * 3, max_opacity=0.25)
    assert len(layers) == 3 and all(not layer.placed for layer in layers)
    assert np.array_equal(layers[1].volume.data, data[1])
    assert np.allclose(layers[0].tf.color(0.5), (1, 0, 1)) and np.allclose(layers[1].tf.color(0.5), (0, 1, 0))
    assert layers[2].tf.opacity(1.0) == pytest.approx(0.25) and layers[2].tf.opacity(0.0) == 0
    with pytest.raises(ValueError, match="2 to 4 channels"):
        channel_layers(data[:1])
    with pytest.raises(ValueError, match="one RGB colour per channel"):
        channel_layers(data, colors=[(1, 0, 0)])
