"""The volume widget with several volumes (``layers=``, ``labels=``, ``channels=``,
``blend=``), driven from the kernel as the browser drives it (by setting the synced
values): each checkbox and the blend menu render exactly the image ``dvr_gl.render``
gives for the volumes shown (same technique and parameters, so equal bit for bit), a
change the viewer refuses is undone with the viewer's message, and bad values are
errors naming the control. The grids are small, so that the file runs in seconds."""

import numpy as np
import pytest

import dvr_gl
from dvr_gl import formats as dvr_io
from dvr_gl.frontends.notebook import VolumeWidget
from dvr_gl.model.layers import channel_layers
from dvr_gl.techniques import common

SIZE = 32
N = 24


def _grids():
    z, y, x = np.mgrid[:N, :N, :N].astype(np.float32)
    ball = np.clip(1.0 - np.sqrt((x - 11) ** 2 + (y - 12) ** 2 + (z - 12) ** 2) / 10, 0, 1)
    blob = np.exp(-((x - 16) ** 2 + (y - 8) ** 2 + (z - 14) ** 2) / 30).astype(np.float32)
    labels = np.zeros((N, N, N), np.uint8)
    labels[8:16, 8:16, 4:12] = 1
    labels[10:20, 14:20, 12:20] = 3
    return ball, blob, labels


BALL, BLOB, LABELS = _grids()


def render(source, **kwargs):
    return np.asarray(dvr_gl.render(source, size=SIZE, **kwargs))


def test_each_checkbox_and_the_blend_render_what_dvr_gl_render_renders():
    w = VolumeWidget(BALL, size=SIZE, layers=[BLOB], labels=LABELS)
    assert (w.shown, w.volume_names, w.blend, w.blends) == ([True] * 3, ["ndarray"] * 3, "mix", ["mix", "add"])
    assert w.techniques == list(common.LAYER_TECHNIQUES) and "volumes 123 mix" in w.status
    every = render(BALL, layers=[BLOB], labels=LABELS)
    assert np.array_equal(w.image_array, every)
    # each volume hidden in turn: the scene of the others, unlit as with all three
    expected = [render(BLOB, labels=LABELS), render(BALL, labels=LABELS), render(BALL, layers=[BLOB])]
    images = []
    for i in range(3):
        frame = w.frame
        w.shown = [k != i for k in range(3)]
        assert w.frame == frame + 1 and np.array_equal(w.image_array, expected[i]), f"volume {i + 1} hidden"
        assert not np.array_equal(w.image_array, every)
        images.append(w.image_array)
        w.shown = [True] * 3
        assert np.array_equal(w.image_array, every)
    assert not np.array_equal(images[0], images[1]) and not np.array_equal(images[1], images[2])
    w.shown = [True, False, False]                     # one volume: no layers, still unlit
    assert np.array_equal(w.image_array, render(BALL, shading=False)) and "volumes 1-- mix" in w.status
    assert not np.array_equal(w.image_array, render(BALL))
    w.shown = [True] * 3
    w.blend = "add"
    added = render(BALL, layers=[BLOB], labels=LABELS, blend="add")
    assert np.array_equal(w.image_array, added) and not np.array_equal(added, every)
    assert "volumes 123 add" in w.status
    # a browser's message: the volumes and the blend at once
    w.set_state({"shown": [True, False, True], "blend": "mix"})
    assert np.array_equal(w.image_array, expected[1])
    # the preset menu classifies volume 1; the cuts' bounds hold every volume
    w.preset = "grey"
    assert np.array_equal(w.image_array, render(BALL, tf="grey", labels=LABELS))
    w.crop = [[0.0, 12.0], *w.crop[1:]]
    assert np.array_equal(w.image_array, render(BALL, tf="grey", labels=LABELS,
                                                crop_box=((0, 0, 0), (12, N - 1, N - 1))))


def test_refused_changes_are_undone_with_the_viewers_message():
    w = VolumeWidget(BALL, size=SIZE, labels=LABELS)
    frame, image = w.frame, w.image
    w.shown = [False, True]
    assert w.shown == [True, True] and w.image == image and w.frame == frame + 1
    assert w.status == ("cannot hide volume 1 (ndarray): a label volume is drawn with a scan, so the first "
                        "volume shown must be a scan")
    w.shown = [True, False]
    w.shown = [False, False]
    assert w.shown == [True, False] and w.status == "cannot hide volume 1 (ndarray): it is the last one shown"
    # as a browser's message; with two volumes changed at once, the state they lead to is checked
    w.set_state({"shown": [False, True]})
    assert w.shown == [True, False] and w.status.endswith("the first volume shown must be a scan")
    # a mode that a mix cannot render: add only, and mix refused
    w = VolumeWidget(BALL, size=SIZE, layers=[BLOB], mode="mip", blend="add")
    assert w.blends == ["add"] and np.array_equal(w.image_array, render(BALL, layers=[BLOB], mode="mip", blend="add"))
    frame, image = w.frame, w.image
    w.blend = "mix"
    assert w.blend == "add" and w.image == image and w.frame == frame + 1
    assert w.status.startswith("cannot use blend mix: blend='mix' renders mode 'composite'")
    assert w.status.endswith("got mode 'mip'")
    # only the techniques that render layers
    w.technique = "slice3d"
    assert w.technique == "raycast" and w.status == "cannot use slice3d: slice3d renders one volume; several are " \
                                                    f"rendered by {', '.join(common.LAYER_TECHNIQUES)}"


def test_channels_glow_in_their_own_ramps():
    stack = np.stack([BALL, BLOB])
    w = VolumeWidget(stack, size=SIZE, channels=True)
    assert (w.blend, w.presets, w.preset, w.volume_names) == ("add", ["channels"], "channels",
                                                               ["channel 1", "channel 2"])
    assert np.array_equal(w.image_array, render(stack, channels=True))
    w.shown = [False, True]
    second = channel_layers(stack)[1]
    assert np.array_equal(w.image_array, render(second.volume, tf=second.tf, shading=False))
    image = w.image
    w.preset = "warm"                                  # a channel's colour is its own
    assert w.image == image and "tf: each channel is coloured by its own ramp" in w.status


def test_bad_input_is_named():
    bad = [
        (dict(layers=[BLOB], blend="max"), "blend: must be one of mix, add, got 'max'"),
        (dict(blend="add"), "blend: combines several volumes"),
        (dict(labels=LABELS, technique="slice2d"), "technique: 'slice2d' does not render several volumes in the "
                                                   "widget; choose one of raycast"),
        (dict(labels=LABELS, shading=True), "shading: lighting several volumes is not rendered yet"),
        (dict(labels=BALL), "labels: ndarray holds non-integer values"),
        (dict(labels=LABELS, mode="mip", blend="add"), "mode: label layers are composited; mode 'mip'"),
        (dict(layers=[BLOB], mode="mip"), "mode: blend='mix' renders mode 'composite'"),
        (dict(channels=True), "channels: reads 2 to 4 channels along the first axis"),
        (dict(layers=[BLOB] * 4), "layers: a scene holds at most 4 volumes"),
    ]
    for kwargs, message in bad:
        with pytest.raises(dvr_io.InputError, match=message):
            VolumeWidget(BALL, size=SIZE, **kwargs)
    with pytest.raises(dvr_io.InputError, match="tf: each channel is coloured by its own ramp"):
        VolumeWidget(np.stack([BALL, BLOB]), size=SIZE, channels=True, tf="warm")
    w = VolumeWidget(BALL, size=SIZE, labels=LABELS)
    frame = w.frame
    for name, value, message in [
        ("shown", [True], r"shown: expected 2 values True or False, one per volume \(ndarray, ndarray\)"),
        ("shown", ["yes", True], "shown: expected 2 values True or False"),
        ("blend", "max", "blend: must be one of mix, add, got 'max'"),
    ]:
        with pytest.raises(dvr_io.InputError, match=message):
            setattr(w, name, value)
    assert (w.shown, w.blend, w.frame) == ([True, True], "mix", frame)          # nothing changed
    one = VolumeWidget(BALL, size=SIZE)
    assert (one.shown, one.volume_names, one.blends) == ([], [], [])
    with pytest.raises(dvr_io.InputError, match="shown: there is one volume"):
        one.shown = [True]
