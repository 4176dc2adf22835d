"""Several volumes in the front ends: the scenes ``dvr_gl.render``, ``dvr-gl render``,
``dvr-gl movie`` and the viewer build from ``layers`` / ``--volume``, ``labels`` /
``--labels``, ``channels`` / ``--channels`` and ``blend`` / ``--blend``, and their errors.

Most tests check the Scene handed to the renderer (a stand-in renderer records it), so
they do not depend on how the ray caster draws layers. The tests named ``*_renders_*``
render for real and check what only a layered render shows (each channel's colour where
only that channel is, the additive blend's sum); they need the ray caster's layer path.
"""

import types

import numpy as np
import pytest

import dvr_gl
from dvr_gl import data
from dvr_gl.formats import InputError
from dvr_gl.frontends import cli, inputs
from dvr_gl.frontends.layer_inputs import LABEL_OPACITY, LABEL_PALETTE, label_colors
from dvr_gl.model.layers import CHANNEL_COLORS, MAX_LAYERS, LabelColors, Layer
from dvr_gl.model.volume import Volume

from test_viewer import display  # noqa: F401,E402  (a private Xvfb display for the viewer test)


# ----------------------------------------------------------------------------- stand-ins

class SceneRecorder:
    """A renderer that records the scenes it is asked to draw and returns blank images
    (for dvr_gl.render, the CLI's ``with Renderer(...)`` and render_movie)."""

    def __init__(self, **kwargs):
        self.scenes, self.techniques = [], []

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def render(self, scene, technique="raycast", **options):
        self.scenes.append(scene)
        self.techniques.append(technique)
        return np.zeros((scene.height, scene.width, 4), np.float32)

    def release(self):
        pass


@pytest.fixture
def recorder(monkeypatch):
    rec = SceneRecorder()
    monkeypatch.setitem(inputs._RENDERERS, "auto", rec)
    monkeypatch.setattr("dvr_gl.rendering.renderer.Renderer", lambda **kw: rec)
    return rec


def blob(shape=(12, 12, 12), centre=(6, 6, 6), radius=4.0):
    """A smooth ball of values 0..1 (z, y, x) centred at ``centre`` (x, y, z)."""
    z, y, x = np.indices(shape, dtype=np.float32)
    r2 = (x - centre[0]) ** 2 + (y - centre[1]) ** 2 + (z - centre[2]) ** 2
    return np.exp(-r2 / radius ** 2).astype(np.float32)


def segmentation(shape=(12, 12, 12)):
    seg = np.zeros(shape, np.uint8)
    seg[8:11, 1:4, 1:4] = 1          # a corner towards +z, away from blob()'s core
    seg[5:8, 5:8, 5:8] = 3           # inside the core
    return seg


def fractional_labels():
    seg = segmentation().astype(np.float32)
    seg[0, 0, 0] = 2.5
    return seg


@pytest.fixture
def files(tmp_path):
    """A scan, a second scan, a segmentation, a non-integer "segmentation", 3- and
    5-channel stacks and two series of 5 and 4 steps, as .npy files."""
    paths = types.SimpleNamespace()
    for name, array in (("scan", blob()), ("other", blob(centre=(8, 5, 6))), ("seg", segmentation()),
                        ("fraction", fractional_labels()), ("c3", np.stack([blob(), blob(centre=(3, 6, 6)),
                                                                     blob(centre=(9, 6, 6))])),
                        ("c5", np.stack([blob()] * 5)), ("t5", np.stack([blob() * (k + 1) for k in range(5)])),
                        ("t4", np.stack([blob()] * 4))):
        path = tmp_path / f"{name}.npy"
        np.save(path, array)
        setattr(paths, name, str(path))
    return paths


# ----------------------------------------------------------------------------- dvr_gl.render

def test_render_builds_extra_scans_each_with_its_own_automatic_tf(recorder):
    scan, other = blob(), blob(shape=(10, 14, 16), centre=(8, 7, 5)) * 300
    dvr_gl.render(scan, layers=[other, "builtin:synthetic"], size=16)
    scene = recorder.scenes[-1]
    assert scene.blend == "mix" and len(scene.layers) == 2 and not scene.shading   # layers are not lit yet
    assert recorder.techniques[-1] == "raycast"
    np.testing.assert_array_equal(scene.layers[0].volume.data, other)
    for layer, source in zip(scene.layers, (other, "builtin:synthetic")):
        volume, preset = inputs.load_input(source)
        assert layer.tf.key() == inputs.resolve_tf(None, volume, preset)[1].key()   # as the main input's
        assert not layer.placed and not layer.is_labels
    assert scene.tf.key() == inputs.resolve_tf(None, Volume(scan), "auto")[1].key()
    # the camera frames every volume: the box around all of them (synthetic is 64 across)
    lo, hi = scene.bounds
    np.testing.assert_allclose(scene.camera.target, (lo + hi) / 2)
    np.testing.assert_allclose(hi, (63, 63, 63))


def test_render_labels_get_the_default_palette(recorder):
    dvr_gl.render(blob(), labels=segmentation(), size=16)
    (layer,) = recorder.scenes[-1].layers
    assert layer.is_labels and set(layer.tf.colors) == {1, 3}          # the labels present, 0 left out
    assert layer.tf.colors[1] == (*LABEL_PALETTE[0], LABEL_OPACITY)
    assert layer.tf.colors[3] == (*LABEL_PALETTE[2], LABEL_OPACITY)
    assert layer.tf.rgba([0])[0, 3] == 0 and layer.tf.unit_distance == 1.0
    # colours follow the label's value, cycling after ten: label 11 looks like label 1
    seg = np.zeros((4, 4, 4), np.int16)
    seg[0, 0, :3] = (1, 11, 12)
    colors = label_colors(Volume(seg, spacing=(0.5, 2.0, 1.0))).colors
    assert colors[11] == colors[1] and colors[12][:3] == LABEL_PALETTE[1] != colors[1][:3]
    assert label_colors(Volume(seg, spacing=(0.5, 2.0, 1.0))).unit_distance == 0.5


def test_extras_without_geometry_lie_on_the_main_grid(recorder, files):
    """A .npy segmentation (or an array) of the scan's shape takes the scan's spacing and
    origin: it was made from that scan; one of another shape keeps its own grid."""
    main = Volume(blob(), spacing=(3.2, 3.2, 1.5), origin=(10.0, -4.0, 2.0))
    dvr_gl.render(main, labels=files.seg, layers=[blob(shape=(10, 14, 16))], size=16)
    scan, labels = recorder.scenes[-1].layers
    np.testing.assert_array_equal(labels.volume.spacing, main.spacing)
    np.testing.assert_array_equal(labels.volume.origin, main.origin)
    np.testing.assert_array_equal(scan.volume.spacing, (1.0, 1.0, 1.0))     # another shape: its own grid
    dvr_gl.render(main, layers=[blob()], size=16)
    np.testing.assert_array_equal(recorder.scenes[-1].layers[0].volume.spacing, main.spacing)


def test_render_channels_are_the_first_axis_blended_additively(recorder):
    stack = np.stack([blob(), blob(centre=(3, 6, 6)), blob(centre=(9, 6, 6))])
    dvr_gl.render(stack, channels=True, mode="mip", size=16, spacing=(1.0, 1.0, 2.0))
    scene = recorder.scenes[-1]
    assert scene.blend == "add" and scene.mode == "mip" and len(scene.layers) == 2
    volumes = (scene.volume,) + tuple(layer.volume for layer in scene.layers)
    tfs = (scene.tf,) + tuple(layer.tf for layer in scene.layers)
    for k, (volume, tf) in enumerate(zip(volumes, tfs)):
        np.testing.assert_array_equal(volume.data, stack[k])
        assert tuple(volume.spacing) == (1.0, 1.0, 2.0)
        np.testing.assert_allclose(tf.color(np.array([0.5]))[0], CHANNEL_COLORS[k])
    dvr_gl.render(stack[:2], channels=True, blend="mix", size=16)
    assert recorder.scenes[-1].blend == "mix"


def test_render_passes_layers_as_they_are(recorder):
    turn = np.array([[0.0, -1.0, 0.0, 20.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0, 0, 0, 1]])
    placed = Layer(Volume(blob()), dvr_gl.TransferFunction([(0, 0, 1, 0), (1, 0, 1, 0)], [(0, 0), (1, 0.5)]), turn)
    own_labels = Layer(Volume(segmentation()), LabelColors({3: (1, 0, 0, 0.9)}))
    dvr_gl.render(blob(), layers=placed, labels=own_labels, blend="add", size=16)
    scene = recorder.scenes[-1]
    assert scene.layers == (placed, own_labels) and scene.blend == "add"
    np.testing.assert_array_equal(scene.layers[0].matrix, turn)


@pytest.mark.parametrize("kwargs, field, words", [
    ({"layers": [blob()] * MAX_LAYERS}, "layers", "at most 4 volumes in all, got 5"),
    ({"layers": [blob()] * 2, "channels": True}, "layers", "at most 4 volumes"),
    ({"labels": fractional_labels()}, "labels", "non-integer values such as 2.5"),
    ({"labels": -segmentation().astype(np.int16)}, "labels", "labels -3..0"),
    ({"labels": np.zeros((4, 4, 4), np.uint8)}, "labels", "only label 0"),
    ({"blend": "add"}, "blend", "combines several volumes"),
    ({"layers": [blob()], "blend": "over"}, "blend", "must be one of mix, add"),
    ({"channels": True}, "channels", "shape (12, 12, 12), so no channels"),
])
def test_render_errors_name_the_argument(recorder, kwargs, field, words):
    source = np.stack([blob()] * 3) if kwargs.get("channels") and "layers" in kwargs else blob()
    with pytest.raises(InputError) as e:
        dvr_gl.render(source, size=16, **kwargs)
    assert e.value.field == field and words in str(e.value)
    assert not recorder.scenes


@pytest.mark.parametrize("count", [1, 5])
def test_render_channel_counts_outside_2_to_4(recorder, count):
    with pytest.raises(InputError, match=f"2 to 4 channels .* so {count} channels") as e:
        dvr_gl.render(np.stack([blob()] * count), channels=True, size=16)
    assert e.value.field == "channels"
    with pytest.raises(InputError, match="own ramp") as e:
        dvr_gl.render(np.stack([blob()] * 2), channels=True, tf="grey", size=16)
    assert e.value.field == "tf"


def test_render_mixing_is_composite_only_and_unlit(recorder):
    with pytest.raises(ValueError, match="blend='mix' renders mode 'composite'"):
        dvr_gl.render(blob(), layers=[blob()], mode="mip", size=16)
    with pytest.raises(ValueError, match="lighting several volumes"):
        dvr_gl.render(blob(), layers=[blob()], shading=True, size=16)


# ----------------------------------------------------------------------------- dvr-gl render, info

def _cli(argv, capsys):
    code = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_cli_parses_the_layer_options(files):
    args = cli.build_parser().parse_args(["render", files.scan, "-o", "x.png", "--volume", files.other,
                                          "--volume", "builtin:synthetic", "--labels", files.seg, "--blend", "add"])
    assert args.volume == [files.other, "builtin:synthetic"] and args.labels == files.seg and args.blend == "add"
    assert not args.channels
    args = cli.build_parser().parse_args(["movie", files.c3, "-o", "x.gif", "--channels"])
    assert args.channels and args.volume is None and args.blend is None


def test_cli_render_builds_the_scene(recorder, files, tmp_path, capsys):
    code, out, err = _cli(["render", files.scan, "--volume", files.other, "--labels", files.seg, "--size", "24x16",
                           "-o", tmp_path / "l.png"], capsys)
    assert code == 0, err
    scene = recorder.scenes[-1]
    assert scene.blend == "mix" and not scene.shading and (scene.width, scene.height) == (24, 16)
    other, labels = scene.layers
    np.testing.assert_array_equal(other.volume.data, np.load(files.other))
    assert other.tf.key() == inputs.resolve_tf(None, other.volume, "auto")[1].key()
    assert labels.is_labels and set(labels.tf.colors) == {1, 3}
    assert "volumes    3, blend mix" in out and "2 labels" in out
    code, out, err = _cli(["render", files.c3, "--channels", "--mode", "average", "--size", "16x16",
                           "-o", tmp_path / "c.png"], capsys)
    assert code == 0, err
    scene = recorder.scenes[-1]
    assert scene.blend == "add" and scene.mode == "average" and len(scene.layers) == 2
    np.testing.assert_array_equal(scene.layers[1].volume.data, np.load(files.c3)[2])


@pytest.mark.parametrize("extra, option, words", [
    (["--volume", "{scan}"] * 4, "--volume", "at most 4 volumes in all, got 5"),
    (["--volume", "{scan}", "--volume", "{scan}", "--labels", "{seg}", "--channels"], "--volume", "at most 4"),
    (["--labels", "{fraction}"], "--labels", "non-integer values such as 2.5"),
    (["--labels", "{c3}"], "--labels", "4-D array"),
    (["--channels"], "--channels", "is not one"),
    (["--volume", "{scan}", "--technique", "slice3d"], "--technique", "slice3d renders one volume"),
    (["--volume", "{scan}", "--mode", "mip"], "--mode", "use --blend add"),
    (["--labels", "{seg}", "--blend", "add", "--mode", "mip"], "--labels", "composited"),
    (["--volume", "{scan}", "--shading"], "--shading", "not rendered yet"),
    (["--blend", "add"], "--blend", "give --volume, --labels or --channels"),
    (["--volume", "{c3}"], "--volume", "4-D array"),
])
def test_cli_render_errors_name_the_option(recorder, files, tmp_path, capsys, extra, option, words):
    extra = [e.format(**vars(files)) for e in extra]
    code, out, err = _cli(["render", files.scan, "-o", tmp_path / "x.png", *extra], capsys)
    assert code == 2 and f"error: {option}: " in err and words in err, err
    assert not recorder.scenes and not (tmp_path / "x.png").exists()


@pytest.mark.parametrize("name, count", [("c5", 5), ("c3", 3)])
def test_cli_channel_counts(recorder, files, tmp_path, capsys, name, count):
    code, out, err = _cli(["render", getattr(files, name), "--channels", "-o", tmp_path / "x.png", "--size", "8x8"],
                          capsys)
    assert (code == 0) == (count <= 4), err
    if count > 4:
        assert "--channels: reads 2 to 4 channels" in err and "so 5 channels" in err
        code, out, err = _cli(["render", getattr(files, name), "--channels", "--tf", "grey", "-o", tmp_path / "x.png"],
                              capsys)
        assert code == 2 and "--tf: --channels colours each channel" in err


def test_info_says_a_4d_file_reads_as_channels_or_time(files, capsys):
    code, out, err = _cli(["info", files.c3], capsys)
    assert code == 0, err
    assert "3 x 12x12x12" in out and "as time    3 time steps" in out and "as channels 3 channels" in out
    code, out, err = _cli(["info", files.c5], capsys)
    assert code == 0 and "as channels no" in out and "this file has 5" in out


# ----------------------------------------------------------------------------- dvr-gl movie

def test_movie_time_counts_must_agree(files, tmp_path, capsys):
    pytest.importorskip("imageio")
    code, out, err = _cli(["movie", files.t5, "--volume", files.t4, "-o", tmp_path / "m.gif", "--size", "16x16"],
                          capsys)
    assert code == 2 and "--volume: volumes with different time counts" in err
    assert f"{files.t5} has 5 steps, {files.t4} has 4" in err
    assert not (tmp_path / "m.gif").exists()
    from dvr_gl.frontends.movie import movie_volumes
    with pytest.raises(InputError, match="different time counts: .* has 5 steps, .* has 4") as e:
        movie_volumes(files.scan, layers=[files.t5, files.t4])          # two series beside a still input
    assert e.value.field == "layers"


def test_movie_frames_step_every_series_and_keep_the_still_ones(files, tmp_path):
    pytest.importorskip("imageio")
    from dvr_gl.frontends.movie import render_movie
    rec = SceneRecorder()
    result = render_movie(files.scan, tmp_path / "m.gif", layers=[files.t5], labels=files.seg, size=16, renderer=rec,
                          progress=False)
    assert result.frames == 5 and len(rec.scenes) == 5                  # the series' steps, no orbit
    series = np.load(files.t5)
    for k, scene in enumerate(rec.scenes):
        series_layer, labels = scene.layers
        np.testing.assert_array_equal(series_layer.volume.data, series[k])
        np.testing.assert_array_equal(scene.volume.data, np.load(files.scan))
        assert labels.is_labels and scene.blend == "mix" and not scene.shading
        assert series_layer.tf is rec.scenes[0].layers[0].tf            # one TF for every frame
    np.testing.assert_allclose(rec.scenes[0].camera.eye, rec.scenes[-1].camera.eye)
    rec = SceneRecorder()
    render_movie(files.c3, tmp_path / "c.gif", channels=True, frames=3, size=16, renderer=rec, progress=False)
    assert len(rec.scenes) == 3 and rec.scenes[0].blend == "add" and len(rec.scenes[0].layers) == 2
    assert not np.allclose(rec.scenes[0].camera.eye, rec.scenes[1].camera.eye)   # a still scene turns


# ----------------------------------------------------------------------------- the viewer's keys

class StubViewer:
    """What the viewer's layer keys read and call, without a window."""

    def __init__(self, layers, names=()):
        self.volume, self.tf = Volume(blob()), data.synthetic_tf()
        self.layers, self.blend, self.hidden_layers = tuple(layers), "mix", frozenset()
        self.settings = types.SimpleNamespace(layer_names=names)
        self.messages, self.version, self.refuse = [], 0, None
        self.editor = types.SimpleNamespace(hover=None)

    def say(self, message):
        self.messages.append(message)

    def changed(self, interactive=False):
        self.version += 1

    def validate(self):
        if self.refuse:
            raise ValueError(self.refuse)


def _scan_layer(k):
    return Layer(Volume(blob(centre=(3 + k, 6, 6))), data.synthetic_tf())


def test_viewer_layer_keys_leave_hidden_volumes_out(monkeypatch):
    from dvr_gl.frontends.viewer.controls import Controls
    from dvr_gl.frontends.viewer.keys import KEY_F2, KEY_F3, KEY_F4, KEY_F5, PRESS
    from dvr_gl.frontends.viewer.layers import describe_shown, shown_volumes
    scans = [_scan_layer(1), _scan_layer(2)]
    v = StubViewer(scans, names=("a.npy", "b.npy", "c.npy"))
    keys = Controls(v)
    volume, tf, extra = shown_volumes(v, v.tf)
    assert volume is v.volume and extra == {"layers": tuple(scans), "blend": "mix"}
    keys.on_key(KEY_F3, PRESS)                                    # hide volume 2
    assert v.hidden_layers == {1} and v.version == 1 and "volume 2 (b.npy) hidden" in v.messages[-1]
    assert shown_volumes(v, v.tf)[2]["layers"] == (scans[1],)
    assert describe_shown(v) == "volumes 1-3 mix"
    keys.on_key(KEY_F2, PRESS)                                    # hide INPUT: the next one shown takes its place
    volume, tf, extra = shown_volumes(v, v.tf)
    assert volume is scans[1].volume and tf is scans[1].tf and extra == {}
    keys.on_key(KEY_F4, PRESS)                                    # the last one shown stays
    assert v.hidden_layers == {0, 1} and "last one shown" in v.messages[-1]
    keys.on_key(KEY_F5, PRESS)
    assert "no volume 4: there are 3" in v.messages[-1]
    keys.on_key(KEY_F3, PRESS)
    keys.on_key(KEY_F2, PRESS)                                    # all shown again
    assert v.hidden_layers == frozenset() and shown_volumes(v, v.tf)[2]["layers"] == tuple(scans)
    v.refuse = "not this one"                                     # a scene the technique refuses is not kept
    keys.on_key(KEY_F3, PRESS)
    assert v.hidden_layers == frozenset() and "cannot hide volume 2 (b.npy): not this one" in v.messages[-1]


def test_viewer_label_volume_needs_a_scan_shown_first():
    from dvr_gl.frontends.viewer.layers import shown_volumes, toggle_layer
    labels = Layer(Volume(segmentation()), label_colors(Volume(segmentation())))
    v = StubViewer([labels])
    toggle_layer(v, 0)
    assert v.hidden_layers == frozenset() and "first volume shown must be a scan" in v.messages[-1]
    toggle_layer(v, 1)
    assert shown_volumes(v, v.tf) == (v.volume, v.tf, {})
    one = StubViewer([])
    toggle_layer(one, 0)
    assert "one volume" in one.messages[-1] and one.hidden_layers == frozenset()


def test_viewer_settings_carry_the_layers(files):
    from dvr_gl.frontends.viewer.settings import build_parser, settings_from_args
    args = build_parser().parse_args([files.scan, "--volume", files.other, "--labels", files.seg, "--blend", "mix"])
    settings = settings_from_args(args)
    assert len(settings.layers) == 2 and settings.layers[1].is_labels and settings.blend == "mix"
    assert settings.layer_names == (files.scan, files.other, files.seg)
    args = build_parser().parse_args([files.c3, "--channels"])
    settings = settings_from_args(args)
    assert settings.blend == "add" and len(settings.layers) == 2 and settings.tf_name == "channel 1"


# ----------------------------------------------------------------------------- end to end (needs the GL layer path)

def _two_channels():
    """Two channels side by side along x on a 32 x 16 x 16 grid: each glows alone on its
    own half of a picture taken along -z (x to the right)."""
    return np.stack([blob((16, 16, 32), (8, 8, 8)), blob((16, 16, 32), (24, 8, 8))])


def test_render_channels_renders_each_in_its_colour_and_adds_them():
    stack = _two_channels()
    view = dict(azimuth=0, elevation=0, size=(64, 32), step=0.25)
    image = np.asarray(dvr_gl.render(stack, channels=True, **view))
    left, right = image[:, :32], image[:, 32:]
    # channel 1 (magenta: red and blue, no green) on the left, channel 2 (green) on the right
    assert left[..., 0].max() > 0.05 and left[..., 1].max() <= 0.1 * left[..., 0].max()
    assert right[..., 1].max() > 0.05 and right[..., 0].max() <= 0.1 * right[..., 1].max()
    # blend "add" is each channel's own image on the same rays, summed (docs/contract.md,
    # "Several volumes"): the same rays, step (60 samples across) and box for each, so
    # what differs is float32 rounding (the layered path reaches each layer's samples
    # through its own frame, and sums in another order): 1.2e-4 measured on llvmpipe, and
    # 5e-4 allows a driver four times as coarse; a missing or wrongly added channel is ~0.1
    from dvr_gl.model.layers import channel_layers
    alone = [np.asarray(dvr_gl.render(Volume(stack[k]), tf=layer.tf, shading=False, **view))
             for k, layer in enumerate(channel_layers(stack))]
    np.testing.assert_allclose(image[..., :3], alone[0][..., :3] + alone[1][..., :3], atol=5e-4)
    np.testing.assert_allclose(image[..., 3], 1 - (1 - alone[0][..., 3]) * (1 - alone[1][..., 3]), atol=5e-4)


def test_cli_renders_a_label_volume_over_a_scan(files, tmp_path, capsys):
    code, out, err = _cli(["render", files.scan, "--labels", files.seg, "--size", "48x48", "--azimuth", "0",
                           "--elevation", "0", "--transparent", "-o", tmp_path / "l.png"], capsys)
    assert code == 0, err
    from PIL import Image
    with_labels = np.asarray(Image.open(tmp_path / "l.png")).astype(int)
    code, out, err = _cli(["render", files.scan, "--no-shading", "--size", "48x48", "--azimuth", "0",
                           "--elevation", "0", "--transparent", "-o", tmp_path / "s.png"], capsys)
    assert code == 0, err
    alone = np.asarray(Image.open(tmp_path / "s.png")).astype(int)
    # the scan's warm ramp is never bluer than it is red; label 1's colour (Tableau blue,
    # 0.12, 0.47, 0.71) is, where its cube (outside the ball's bright core) is seen
    def bluish(png):
        return ((png[..., 2] - png[..., 0] > 40) & (png[..., 3] > 10)).sum()
    assert bluish(alone) == 0 and bluish(with_labels) >= 4


@pytest.fixture
def layer_viewer(request):
    """Open viewers (under a private Xvfb display, test_viewer's) and close them after."""
    request.getfixturevalue("display")
    from dvr_gl.frontends import viewer as viewer_mod
    made = []

    def make(*argv):
        v = viewer_mod.open_viewer([str(a) for a in argv])
        made.append(v)
        return v

    yield make
    for v in made:
        v.close()


def test_viewer_renders_layers_and_offers_raycast_only(layer_viewer, renderer, files):
    from dvr_gl.frontends.viewer.keys import KEY_F3, PRESS
    v = layer_viewer(files.scan, "--volume", files.other, "--labels", files.seg, "--size", "64x48")
    assert v.available_techniques == ["raycast"] and not v.lit
    scene = v.render_arguments()[0]
    assert len(scene.layers) == 2 and scene.blend == "mix"
    v.on_key(KEY_F3, PRESS)
    scene, name, step, options = v.render_arguments()
    assert scene.layers == (v.layers[1],)
    v.refine()
    assert "volumes 1-3 mix" in v.title
    image = v.render_image()
    headless = renderer.render(scene, name, step, **options)
    assert image.shape == headless.shape and image[..., 3].max() > 0
    np.testing.assert_allclose(image, headless, atol=1.5 / 255)
