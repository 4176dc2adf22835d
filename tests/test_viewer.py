"""The interactive viewer under Xvfb, driven by synthetic input through its handlers.

The module starts one Xvfb server (skipped, with the reason, only when the Xvfb binary is
missing on a user's machine; under CI a missing Xvfb fails). Viewers are small windows
(at most 200x150) so the whole module stays well under a minute on llvmpipe.

Agreement with headless rendering: the viewer renders with the same technique modules
and shader programs, in its window's context, into the renderer's float target; its
screenshot is that target written as ``dvr-gl render`` writes PNGs. It is compared with
the PNG of ``Renderer().render`` (the headless EGL/OSMesa context) of the same arguments
within ``1 level + 255 * derived_tolerance`` per channel: one 8-bit level because both
sides round floats to 8 bits, plus the ray caster's float32 tolerance
(``test_raycast.derived_tolerance``), the most two GL evaluations of the same integral
may differ by. When both contexts report the same renderer string the programs run on
the same driver and must agree to one level (in practice they are bit-identical).
"""

import math
import os
import select
import shutil
import subprocess
import sys
import types

import numpy as np
import pytest
from PIL import Image

import dvr_gl
from dvr_gl.frontends.inputs import first_camera
import dvr_gl.techniques.raycast
from dvr_gl.frontends import cli
from dvr_gl import data
from dvr_gl.model import transfer
from dvr_gl import formats as dvr_io
from dvr_gl.gl.context import current
from dvr_gl.techniques import names as technique_names

viewer_mod = pytest.importorskip("dvr_gl.frontends.viewer")
from dvr_gl.frontends.viewer import (KEY_COMMA, KEY_EQUAL, KEY_MINUS, KEY_PERIOD, KEY_RIGHT_BRACKET, MOD_CONTROL,  # noqa: E402
                           MOD_SHIFT, MOUSE_LEFT, MOUSE_MIDDLE, MOUSE_RIGHT, PRESS, RELEASE, key_code)

from test_raycast import derived_tolerance  # noqa: E402  (the ray caster's float32 bound)

SIZE = "160x120"


# ----------------------------------------------------------------------------- fixtures

def _end_with_parent():
    """In the child before exec: ask Linux to send SIGTERM when the parent dies."""
    if sys.platform.startswith("linux"):
        import ctypes
        import signal
        ctypes.CDLL(None).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG


@pytest.fixture(scope="module")
def display():
    """A private Xvfb display for this module; DISPLAY points at it meanwhile."""
    xvfb = shutil.which("Xvfb")
    if xvfb is None:
        message = "the Xvfb binary is not installed (scripts/test.sh installs it: apt-get install xvfb)"
        if os.environ.get("CI"):
            pytest.fail(message)
        pytest.skip(message)
    read_fd, write_fd = os.pipe()
    # -terminate: the server ends when its last client (glfw) goes, so a test process that
    # dies abruptly (an X error exits it) leaves no server behind; on Linux it also gets
    # SIGTERM when this process ends, whatever the cause.
    proc = subprocess.Popen([xvfb, "-displayfd", str(write_fd), "-screen", "0", "1024x768x24", "-nolisten", "tcp",
                             "-terminate"], pass_fds=(write_fd,), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, preexec_fn=_end_with_parent)
    os.close(write_fd)
    number = b""
    while not number.endswith(b"\n"):
        ready, _, _ = select.select([read_fd], [], [], 15)
        chunk = os.read(read_fd, 16) if ready else b""
        if not chunk:
            proc.kill()
            pytest.fail("Xvfb did not report a display number")
        number += chunk
    os.close(read_fd)
    patch = pytest.MonkeyPatch()
    name = ":" + number.decode().strip()
    patch.setenv("DISPLAY", name)
    try:
        yield name
    finally:
        import glfw
        glfw.terminate()  # glfw holds the display open; let it go before the server
        patch.undo()
        if proc.poll() is None:
            proc.terminate()
        proc.wait(10)


@pytest.fixture
def open_viewer(display):
    """Open viewers with command-line arguments; each is checked for GL errors and
    closed after the test."""
    made = []

    def make(*argv):
        v = viewer_mod.open_viewer(list(argv))
        made.append(v)
        return v

    yield make
    _close_checked(made)


def head_viewer(open_viewer, *extra):
    return open_viewer("builtin:ct_head", "--azimuth", "0", "--elevation", "90", "--size", SIZE, *extra)


def drag(v, start, end, button=MOUSE_LEFT, mods=0, steps=4):
    v.on_mouse_button(button, PRESS, mods, *start)
    for k in range(1, steps + 1):
        t = k / steps
        v.on_cursor(start[0] + t * (end[0] - start[0]), start[1] + t * (end[1] - start[1]))
    v.on_mouse_button(button, RELEASE, mods)


def press(v, char_or_key, mods=0):
    key = key_code(char_or_key) if isinstance(char_or_key, str) else char_or_key
    v.on_key(key, PRESS, mods)


def _close_checked(viewers):
    """Close the viewers a fixture opened, each first checked for GL errors."""
    for v in viewers:
        if v.window is not None:
            with current(v.ctx):
                assert v.ctx.error == "GL_NO_ERROR"
        v.close()


def png(path):
    return np.asarray(Image.open(path))


def assert_matches_headless(v, renderer, image8):
    """``image8`` (the viewer's 8-bit screenshot) against the headless PNG of the same
    scene, technique, step and options; returns the largest difference in levels."""
    scene, name, step, options = v.render_arguments()
    headless = dvr_io.to_png_array(renderer.render(scene, name, step, **options), v.settings.background)
    assert image8.shape == headless.shape
    diff = int(np.abs(image8.astype(int) - headless.astype(int)).max())
    plan = dvr_gl.techniques.raycast.make_plan(scene, step if name == "raycast" else None)
    levels = 1 + math.ceil(255 * derived_tolerance(plan))
    assert diff <= levels, f"viewer and headless differ by {diff} levels (allowed {levels})"
    with current(v.ctx):
        window_gl = v.ctx.info["GL_RENDERER"]
    if window_gl == renderer.info().get("renderer", renderer.info().get("GL_RENDERER")):
        assert diff <= 1, f"same driver ({window_gl}), yet {diff} levels apart"
    return diff


# ----------------------------------------------------------------------------- agreement

def _grid_techniques():
    """The techniques for grid volumes (the head); tetra (DATA "mesh") has its own tests."""
    from dvr_gl.techniques import get_technique

    def kinds(n):
        data = getattr(get_technique(n), "DATA", "volume")
        return (data,) if isinstance(data, str) else data
    return [n for n in technique_names() if "volume" in kinds(n)]


@pytest.mark.parametrize("technique", _grid_techniques())
def test_screenshot_matches_headless(open_viewer, renderer, tmp_path, technique):
    v = head_viewer(open_viewer, "--technique", technique, "--screenshot", str(tmp_path / "shot.png"))
    v.refine()
    assert v.last_frame.quality == "full" and v.last_frame.target_size == (160, 120)
    press(v, "s")
    image = png(tmp_path / "shot.png")
    assert image.shape == (120, 160, 4) and image[..., 3].max() > 50, "the head must show"
    assert_matches_headless(v, renderer, image)


def test_background_option_gives_rgb_like_render(open_viewer, renderer, tmp_path):
    v = head_viewer(open_viewer, "--background", "0.2,0.3,0.4", "--screenshot", str(tmp_path / "bg.png"))
    v.refine()
    press(v, "s")
    image = png(tmp_path / "bg.png")
    assert image.shape == (120, 160, 3)
    assert_matches_headless(v, renderer, image)


# ----------------------------------------------------------------------------- camera

def test_orbit_by_a_known_drag(open_viewer):
    v = head_viewer(open_viewer)
    o = v.orbit
    back, up, right = o.back.copy(), o.up.copy(), o.right.copy()
    drag(v, (80, 40), (110, 40))                       # 30 px right
    expected = 30 * math.pi / 120                      # half a turn per window height
    assert math.acos(np.clip(back @ o.back, -1, 1)) == pytest.approx(expected, abs=1e-9)
    assert np.allclose(o.up, up, atol=1e-12)           # turned about the camera's up axis
    assert o.back @ right < 0                          # dragging right swings the eye left
    back = o.back.copy()
    drag(v, (80, 40), (80, 20))                        # 20 px up: the eye goes down
    assert math.acos(np.clip(back @ o.back, -1, 1)) == pytest.approx(20 * math.pi / 120, abs=1e-9)
    assert o.back @ up < back @ up
    cam = v.orbit.camera()
    assert np.linalg.norm(cam.eye - cam.target) == pytest.approx(o.distance)


def test_orbit_over_the_pole_does_not_flip(open_viewer):
    v = head_viewer(open_viewer)
    start = v.orbit.rotation.copy()
    up = v.orbit.up.copy()
    for _ in range(24):                                # 24 x 10 px x (pi / 120) = 2 pi
        v.on_mouse_button(MOUSE_LEFT, PRESS, 0, 80, 30)
        v.on_cursor(80, 40)
        v.on_mouse_button(MOUSE_LEFT, RELEASE, 0)
        assert v.orbit.up @ up > 0.95                  # up turns smoothly, never jumps
        up = v.orbit.up.copy()
    assert np.allclose(v.orbit.rotation, start, atol=1e-9)  # a full turn comes back


def test_zoom_and_pan(open_viewer):
    v = head_viewer(open_viewer)
    o = v.orbit
    d0 = o.distance
    v.on_cursor(80, 30)
    v.on_scroll(0, 2)
    assert o.distance == pytest.approx(d0 / 1.1 ** 2)
    drag(v, (80, 60), (80, 30), button=MOUSE_RIGHT)   # right drag up 30 px: closer
    assert o.distance == pytest.approx(d0 / 1.1 ** 2 / math.exp(2 * 30 / 120))
    # pan: the point at the target follows the cursor
    for button, mods in ((MOUSE_MIDDLE, 0), (MOUSE_LEFT, MOD_SHIFT)):
        target = o.target.copy()
        drag(v, (80, 60), (92, 51), button=button, mods=mods)
        cam = o.camera()
        rel = target - cam.eye
        sx, sy = cam.screen_scale(160, 120)
        depth = rel @ cam.forward
        x = (rel @ cam.right / depth / sx + 1) * 80
        y = (1 - rel @ cam.true_up / depth / sy) * 60
        assert (x, y) == (pytest.approx(92, abs=1e-6), pytest.approx(51, abs=1e-6))
    press(v, "r")
    default = dvr_gl.default_camera(data.ct_head(), elevation=90)
    assert np.allclose(v.orbit.camera().eye, default.eye) and np.allclose(v.orbit.camera().up, default.true_up)


def assert_double_click_on_empty_space_recentres(v, o, clock, lo, hi):
    """A double click where the ray meets nothing (the window's corner) sets the orbit's
    target back to the data's centre."""
    clock[0] += 1.0
    for _ in range(2):
        v.on_mouse_button(MOUSE_LEFT, PRESS, 0, 2, 2)
        v.on_mouse_button(MOUSE_LEFT, RELEASE, 0)
        clock[0] += 0.1
    assert np.allclose(o.target, (lo + hi) / 2)


def test_double_click_recentres(open_viewer):
    v = head_viewer(open_viewer)
    clock = [100.0]
    v.clock = lambda: clock[0]
    o = v.orbit
    forward = -o.back.copy()
    target, distance = o.target.copy(), o.distance
    for _ in range(2):
        v.on_mouse_button(MOUSE_LEFT, PRESS, 0, 80, 40)
        v.on_mouse_button(MOUSE_LEFT, RELEASE, 0)
        clock[0] += 0.1
    moved = o.target - target
    assert np.linalg.norm(moved) > 1.0                          # onto the skull, not the centre
    assert np.allclose(o.back, -forward) and o.distance == distance  # same view direction
    lo, hi = data.ct_head().bounds
    assert np.all(o.target >= lo - 1e-9) and np.all(o.target <= hi + 1e-9)
    # the picked point is where the ray under the cursor is half opaque: it sits on that ray
    origin, direction = o.ray(80, 60, 160, 120)                   # the centre ray now
    assert np.linalg.norm(np.cross(o.target - origin, direction)) < 1e-6
    assert_double_click_on_empty_space_recentres(v, o, clock, lo, hi)


def test_orthographic_toggle(open_viewer, renderer, tmp_path):
    v = head_viewer(open_viewer, "--screenshot", str(tmp_path / "o.png"))
    press(v, "o")
    assert v.orbit.camera().is_ortho
    v.refine()
    press(v, "s")
    assert_matches_headless(v, renderer, png(tmp_path / "o.png"))


# ----------------------------------------------------------------------------- window

def test_resize_follows_the_framebuffer(open_viewer):
    import glfw

    v = head_viewer(open_viewer)
    v.refine()
    v.set_window_size(200, 150)
    assert v.framebuffer_size == tuple(glfw.get_framebuffer_size(v.window)) == (200, 150)
    v.refine()
    assert v.last_frame.target_size == v.last_frame.framebuffer_size == (200, 150)
    assert v.render_image().shape == (150, 200, 4)
    assert v.editor.panel[2] == pytest.approx(200 - 8)           # the editor follows the window
    v.on_resize(0, 0)                                           # minimised: nothing to draw
    assert v.frame() is None


def test_close_frees_gl_resources(open_viewer):
    v = head_viewer(open_viewer)
    v.refine()
    renderer = v.renderer
    assert renderer.programs._programs
    v.close()
    assert renderer._released and v.window is None and not renderer.programs._programs
    v.close()                                                    # twice is harmless


# ----------------------------------------------------------------------------- techniques, modes, steps

def _fake_technique(refuse_step=False, refuse_data=False):
    from dvr_gl.techniques import raycast

    mod = types.ModuleType("fake_technique")

    def make_plan(scene, step=None, *, tables=None, **options):
        if refuse_data:
            raise TypeError("this technique renders tetrahedral meshes, not volumes")
        if refuse_step and step is not None:
            raise ValueError(f"takes no step, got {step!r}")
        return raycast.make_plan(scene, None, tables=tables)

    mod.make_plan = make_plan
    mod.draw = raycast.draw
    return mod


def test_technique_switching_is_data_driven(open_viewer, monkeypatch, renderer):
    import dvr_gl.techniques as techniques

    monkeypatch.setitem(sys.modules, "fake_stepless", _fake_technique(refuse_step=True))
    monkeypatch.setitem(sys.modules, "fake_mesh_only", _fake_technique(refuse_data=True))
    monkeypatch.setitem(techniques._MODULES, "stepless", "fake_stepless")
    monkeypatch.setitem(techniques._MODULES, "mesh_only", "fake_mesh_only")
    v = head_viewer(open_viewer)
    available = v.available_techniques
    assert "mesh_only" not in available and "stepless" in available and available[0] == "raycast"
    assert not v.techniques["stepless"].accepts_step and v.techniques["raycast"].accepts_step
    seen = []
    for _ in range(len(available)):
        press(v, "t")
        seen.append(v.technique)
        v.refine()                                   # every technique renders in the window
        assert v.last_frame.step == v.effective_step()
    assert sorted(seen) == sorted(available) and seen[-1] == "raycast"
    press(v, "t", MOD_SHIFT)                         # backwards
    assert v.technique == available[-1]
    while v.technique != "stepless":
        press(v, "t")
    assert v.render_arguments()[2] is None           # no step passed to a technique that refuses one
    press(v, KEY_EQUAL)
    assert any("fixed sample distance" in m for m in v.messages)


def test_mode_switching_and_iso(open_viewer, renderer, tmp_path):
    v = head_viewer(open_viewer, "--screenshot", str(tmp_path / "m.png"))
    seen = []
    for _ in range(5):
        press(v, "m")
        seen.append(v.mode)
    assert seen == ["mip", "minip", "average", "isosurface", "composite"]
    press(v, "m", MOD_SHIFT)
    assert v.mode == "isosurface"
    lo, hi = data.ct_head().data_range
    iso = v.iso
    assert lo < iso < hi
    press(v, KEY_PERIOD)
    press(v, KEY_COMMA, MOD_SHIFT)
    assert v.iso == pytest.approx(iso - 4 * 0.01 * (hi - lo))
    v.refine()
    press(v, "s")
    assert_matches_headless(v, renderer, png(tmp_path / "m.png"))
    # shading: isosurfaces are shaded anyway; composite samples are lit from the start,
    # l switches it off and on
    press(v, "m")
    assert v.mode == "composite" and v.render_arguments()[0].shading
    press(v, "l")
    assert v.messages[-1] == "shading off" and not v.render_arguments()[0].shading
    press(v, "l")
    assert v.messages[-1] == "shading on" and v.render_arguments()[0].shading
    v.refine()
    press(v, "s")
    assert_matches_headless(v, renderer, png(tmp_path / "m.png"))
    press(v, "m")                                      # mip has no lit samples: unlit there
    assert v.mode == "mip" and not v.render_arguments()[0].shading
    press(v, "l")
    assert "cannot switch shading: raycast in mode mip" in v.messages[-1]


def test_lit_start_with_lights_and_gradient_texture(open_viewer, renderer, tmp_path):
    """--shading, --light and --gradients reach the viewer's scene; the frame is the
    headless one; l switches the light off and on."""
    v = head_viewer(open_viewer, "--screenshot", str(tmp_path / "l.png"), "--shading", "--light", "world:1,1,0",
                    "--light", "view:0,0,1:0.5", "--gradients", "texture")
    scene, name, step, options = v.render_arguments()
    assert scene.shading and len(scene.lights) == 2 and options.get("gradients") == "texture"
    v.refine()
    press(v, "s")
    assert_matches_headless(v, renderer, png(tmp_path / "l.png"))
    press(v, "l")
    assert not v.render_arguments()[0].shading
    # x cycles the optical model; absorption only cannot be lit, so with l on it is skipped
    press(v, "x")
    assert v.render_arguments()[0].optical_model == "absorption" and v.messages[-1] == "optical model absorption"
    v.refine()
    assert v.render_image()[..., :3].max() == 0 and v.render_image()[..., 3].max() > 0.1
    press(v, "l")
    assert "cannot switch shading" in v.messages[-1] and "absorption does not light samples" in v.messages[-1]
    for model in ("emission", "sabella", "emission_absorption"):
        press(v, "x")
        assert v.optical_model == model
    # i cycles the illustration terms: each one alone, then all four, then none
    seen = []
    for _ in range(6):
        press(v, "i")
        seen.append(v.render_arguments()[0].illustration)
    assert [tuple(t) for t in seen] == [("boundary",), ("silhouette",), ("tone",), ("depth_cue",),
                                        ("boundary", "silhouette", "tone", "depth_cue"), ()]
    press(v, "i")
    v.refine()
    press(v, "s")
    assert_matches_headless(v, renderer, png(tmp_path / "l.png"))


def test_slice2d_and_modes_it_cannot_render(open_viewer):
    if "slice2d" not in technique_names():
        pytest.skip("slice2d has not landed")
    v = head_viewer(open_viewer, "--technique", "slice2d", "--interpolate", "2")
    assert not v.info.accepts_step and v.render_arguments()[2] is None
    assert v.render_arguments()[3] == {"interpolate": 2}        # from the command line
    press(v, KEY_MINUS)
    press(v, KEY_MINUS)
    press(v, "m")                                    # only to modes slice2d can render
    if v.mode == "composite":
        assert "slice2d renders only mode composite" in v.messages[-1]
    else:
        v.refine()
        press(v, "m", MOD_SHIFT)
    press(v, "t", MOD_SHIFT)                         # back to raycast, then on to mip ...
    assert v.technique == "raycast"
    press(v, "m")
    assert v.mode == "mip"
    for _ in range(len(v.available_techniques) - 1):  # ... where slice2d is skipped if it cannot
        press(v, "t")
        assert v.mode == "mip"
        if v.technique == "slice2d":
            break
        if "slice2d: " in v.messages[-1]:          # skipped, and said why
            break
    else:
        pytest.fail("slice2d was neither chosen nor skipped")
    while v.mode != "composite":
        press(v, "m")
    while v.technique != "slice2d":
        press(v, "t")
    press(v, KEY_EQUAL)                              # finer: one more interpolated slice
    assert v.render_arguments()[3].get("interpolate") == 1
    v.refine()
    assert v.last_frame.quality == "full"


def test_step_and_preintegration_keys(open_viewer, renderer, tmp_path):
    v = head_viewer(open_viewer, "--step", "1.5", "--screenshot", str(tmp_path / "p.png"))
    press(v, KEY_EQUAL)
    assert v.effective_step() == pytest.approx(1.5 / math.sqrt(2))
    press(v, KEY_MINUS)
    press(v, KEY_MINUS)
    assert v.effective_step() == pytest.approx(1.5 * math.sqrt(2))
    v.refine()
    assert v.last_frame.step == pytest.approx(1.5 * math.sqrt(2))
    press(v, "p")
    if v.info.accepts("preintegrate"):
        assert v.render_arguments()[3] == {"preintegrate": True}
        v.refine()
        press(v, "s")
        assert_matches_headless(v, renderer, png(tmp_path / "p.png"))
        press(v, "p")
        assert v.render_arguments()[3] == {}
    else:
        assert any("no preintegrate option" in m for m in v.messages)


def test_refined_pre_integration_in_the_viewer(open_viewer, renderer, tmp_path):
    """`dvr-gl view --preintegrate --refine 4` renders refined segments (the headless
    image of the same arguments); switching pre-integration off drops the refinement."""
    v = head_viewer(open_viewer, "--preintegrate", "--refine", "4", "--step", "2", "--screenshot",
                    str(tmp_path / "r.png"))
    assert v.render_arguments()[3] == {"preintegrate": True, "refine": 4}
    v.refine()
    press(v, "s")
    assert_matches_headless(v, renderer, png(tmp_path / "r.png"))
    press(v, "p")
    assert v.render_arguments()[3] == {}
    assert not any("error" in m.lower() for m in v.messages), v.messages


def test_presets_opacity_scale_and_help(open_viewer, capsys):
    v = head_viewer(open_viewer)
    press(v, "h")
    assert "left drag" in capsys.readouterr().out
    assert v.tf.key() == data.ct_head_tf().key()      # builtin:ct_head's own preset
    names = [n for n, _ in v.presets()]
    press(v, str(names.index("auto") + 1))
    assert v.tf.key() == transfer.auto_preset(data.ct_head()).key()
    press(v, "1")
    assert v.tf.key() == data.ct_head_tf().key()
    press(v, "9")
    assert "no transfer function 9" in v.messages[-1]
    before = v.tf.opacity_points[:, 1].copy()
    press(v, KEY_RIGHT_BRACKET)
    assert np.allclose(v.tf.opacity_points[:, 1], np.minimum(before * 1.25, 1))


# ----------------------------------------------------------------------------- the TF editor

def _point_xy(v, i):
    e = v.editor
    return float(e.value_to_x(e.opacity[i, 0])), float(e.alpha_to_y(e.opacity[i, 1]))


def test_edit_a_control_point_renders_the_edited_tf(open_viewer, renderer, tmp_path):
    v = head_viewer(open_viewer, "--screenshot", str(tmp_path / "e.png"))
    v.refine()
    before = v.render_image()
    i = int(np.argmax(v.tf.opacity_points[:, 1]))     # the bone point, alpha 0.25
    x, y = _point_xy(v, i)
    s0 = v.tf.opacity_points[i, 0]
    drag(v, (x, y), (x, y - 12))
    expected = v.editor.y_to_alpha(y - 12)
    assert v.tf.opacity_points[i, 1] == pytest.approx(expected) and expected > 0.3
    assert v.tf.opacity_points[i, 0] == pytest.approx(s0, rel=1e-9, abs=1e-6 * 4000)
    v.refine()
    press(v, "s")
    assert_matches_headless(v, renderer, png(tmp_path / "e.png"))
    assert np.abs(v.render_image() - before).max() > 0.05   # the edit shows


def test_add_and_remove_points(open_viewer):
    v = head_viewer(open_viewer)
    e = v.editor
    n_opacity, n_color = len(e.opacity), len(e.color)
    x = float(e.value_to_x(3000.0))
    y = 0.5 * (e.curve[1] + e.curve[3])
    v.on_mouse_button(MOUSE_LEFT, PRESS, 0, x, y)      # click on the curve area: a new point
    v.on_mouse_button(MOUSE_LEFT, RELEASE, 0)
    assert len(v.tf.opacity_points) == n_opacity + 1
    k = int(np.argmin(np.abs(v.tf.opacity_points[:, 0] - 3000.0)))
    assert v.tf.opacity_points[k, 1] == pytest.approx(e.y_to_alpha(y))
    v.on_mouse_button(MOUSE_RIGHT, PRESS, 0, x, y)     # right click on it: gone
    v.on_mouse_button(MOUSE_RIGHT, RELEASE, 0)
    assert len(v.tf.opacity_points) == n_opacity
    strip_y = 0.5 * (e.strip[1] + e.strip[3])
    x = float(e.value_to_x(1900.0))
    v.on_mouse_button(MOUSE_LEFT, PRESS, 0, x, strip_y)   # a colour point, keeping the colour there
    v.on_mouse_button(MOUSE_LEFT, RELEASE, 0)
    assert len(v.tf.color_points) == n_color + 1
    s = e.x_to_value(x)
    assert np.allclose(v.tf.color(s), data.ct_head_tf().color(s), atol=1e-9)
    k = int(np.argmin(np.abs(v.tf.color_points[:, 0] - s)))
    rgb = v.tf.color_points[k, 1:].copy()
    v.on_scroll(0, 3)                                  # turns its hue
    assert not np.allclose(v.tf.color_points[k, 1:], rgb)
    v.on_mouse_button(MOUSE_RIGHT, PRESS, 0, x, strip_y)
    v.on_mouse_button(MOUSE_RIGHT, RELEASE, 0)
    assert len(v.tf.color_points) == n_color
    press(v, "e")                                      # hidden: clicks there orbit instead
    back = v.orbit.back.copy()
    drag(v, (x, strip_y), (x + 10, strip_y))
    assert not np.allclose(v.orbit.back, back)


def test_window_level_drag(open_viewer):
    v = head_viewer(open_viewer)
    base = v.tf
    span = v.editor.hi - v.editor.lo
    drag(v, (40, 30), (56, 30), mods=MOD_CONTROL)       # 16 px right: level up
    assert np.allclose(v.tf.opacity_points[:, 0], base.opacity_points[:, 0] + 16 / 160 * span)
    assert np.allclose(v.tf.color_points[:, 1:], base.color_points[:, 1:])
    drag(v, (40, 30), (40, 18), mods=MOD_CONTROL)       # 12 px up: a narrower window
    knots = v.tf.knots
    assert knots[-1] - knots[0] == pytest.approx((base.knots[-1] - base.knots[0]) * math.exp(-2 * 12 / 120))


def test_tf_save_and_load_for_render(open_viewer, tmp_path, capsys):
    out = tmp_path / "edited.json"
    v = head_viewer(open_viewer, "--tf-out", str(out))
    x, y = _point_xy(v, 1)
    drag(v, (x, y), (x + 5, y - 5))
    press(v, "s", MOD_CONTROL)
    assert transfer.load_tf_json(out).key() == v.tf.key()
    assert not [p for p in os.listdir(tmp_path) if p.endswith(".tmp")]
    edited = v.tf
    press(v, "2")                                       # another preset, then load the file back
    assert v.tf.key() != edited.key()
    press(v, "o", MOD_CONTROL)
    assert v.tf.key() == edited.key()
    # dvr-gl render reads it
    assert cli.main(["render", "builtin:ct_head", "--tf", str(out), "--size", "16x16",
                     "--out", str(tmp_path / "r.png")]) == 0
    assert (tmp_path / "r.png").is_file()
    capsys.readouterr()
    bad = tmp_path / "bad.json"
    bad.write_text("{")
    v.on_drop([str(bad)])
    assert "cannot load" in v.messages[-1] and v.tf.key() == edited.key()


# ----------------------------------------------------------------------------- screenshots

def test_screenshot_key_writes_atomically(open_viewer, tmp_path, monkeypatch):
    writes = []
    real = dvr_io.atomic_write

    def recording(path, payload):
        writes.append(path)
        return real(path, payload)

    monkeypatch.setattr(dvr_io.images, "atomic_write", recording)     # where save_png looks it up
    monkeypatch.chdir(tmp_path)
    v = head_viewer(open_viewer)                        # no --screenshot: numbered names
    v.refine()
    press(v, "s")
    press(v, "s")
    assert sorted(os.listdir(tmp_path)) == ["dvr-gl-view-001.png", "dvr-gl-view-002.png"]
    assert [os.path.basename(p) for p in writes] == ["dvr-gl-view-001.png", "dvr-gl-view-002.png"]
    shot = png(tmp_path / "dvr-gl-view-001.png")
    assert np.array_equal(shot, dvr_io.to_png_array(v.render_image()))
    # S: the window as shown, overlay included; above the panel it is the composited render
    press(v, "s", MOD_SHIFT)
    window = png(tmp_path / "dvr-gl-view-001-window.png")
    assert window.shape == (120, 160, 3)
    shown = dvr_io.to_png_array(v.render_image(), background=v.background)
    top = int(v.editor.panel[1]) - 1
    assert np.abs(window[:top].astype(int) - shown[:top]).max() <= 1
    assert np.abs(window[top + 2:].astype(int) - shown[top + 2:]).max() > 40   # the editor is there


def test_progressive_refinement(open_viewer, renderer, tmp_path):
    v = head_viewer(open_viewer, "--screenshot", str(tmp_path / "r.png"))
    clock = [0.0]
    v.clock = lambda: clock[0]
    v.refine()
    full_step = v.effective_step()
    assert v.last_frame.quality == "full"
    v.on_mouse_button(MOUSE_LEFT, PRESS, 0, 80, 40)
    for k in range(3):                                   # dragging: coarse frames
        v.on_cursor(82 + 2 * k, 40)
        clock[0] += 0.03
        assert v.needs_frame()
        v.frame()
        assert v.last_frame.quality == "coarse"
        assert v.last_frame.target_size == (80, 60) and v.last_frame.step == pytest.approx(2 * full_step)
    clock[0] += 0.1                                      # held still, not yet settled
    assert not v.needs_frame()
    v.on_mouse_button(MOUSE_LEFT, RELEASE, 0)
    clock[0] += 0.15                                     # 0.25 s without input: refine
    assert v.needs_frame()
    v.frame()
    assert v.last_frame.quality == "full" and v.last_frame.target_size == (160, 120)
    assert v.last_frame.step == full_step and not v.needs_frame()
    press(v, "s")
    assert_matches_headless(v, renderer, png(tmp_path / "r.png"))


def test_particles_accumulate_while_still(open_viewer, renderer, tmp_path):
    """particles: the first full frame averages one set; while the view stays still each
    further frame averages twice as many, up to max_accumulate; any change starts again;
    a --repetitions given by the user is kept as it is."""
    v = head_viewer(open_viewer, "--technique", "particles", "--screenshot", str(tmp_path / "p.png"))
    v.max_accumulate = 8
    clock = [0.0]
    v.clock = lambda: clock[0]
    v.frame()
    assert v.last_frame.quality == "full" and v.last_frame.accumulated == 1
    seen = []
    while v.needs_frame():
        v.frame()
        seen.append(v.last_frame.accumulated)
    assert seen == [2, 4, 8] and "8 sets" in v.title
    assert v.render_arguments()[3] == {"repetitions": 8}
    press(v, "s")
    assert_matches_headless(v, renderer, png(tmp_path / "p.png"))
    v.on_mouse_button(MOUSE_LEFT, PRESS, 0, 80, 40)       # a drag: coarse single sets
    v.on_cursor(84, 40)
    clock[0] += 0.03
    v.frame()
    assert v.last_frame.quality == "coarse" and v.last_frame.accumulated == 1
    v.on_mouse_button(MOUSE_LEFT, RELEASE, 0)
    clock[0] += 0.5
    v.refine()
    assert v.last_frame.quality == "full" and v.last_frame.accumulated == 8
    fixed = head_viewer(open_viewer, "--technique", "particles", "--repetitions", "3")
    fixed.refine()
    assert fixed.last_frame.accumulated == 1 and fixed.render_arguments()[3] == {"repetitions": 3}


# ----------------------------------------------------------------------------- the command

def test_bad_input_exits_2_with_a_message(display, tmp_path, capsys):
    cases = [
        (["/nonexistent/head.npy"], "INPUT"),
        (["builtin:ct_head", "--tf", str(tmp_path / "missing.json")], "--tf"),
        (["builtin:ct_head", "--screenshot", str(tmp_path / "no" / "out.png")], "--screenshot"),
        (["builtin:ct_head", "--screenshot", str(tmp_path / "out.jpg")], "--screenshot"),
        (["builtin:ct_head", "--technique", "nonsense"], "--technique"),
        (["builtin:nothing"], "INPUT"),
    ]
    bad_json = tmp_path / "bad.json"
    bad_json.write_text('{"color": [[0, 1, 1, 1]], "opacity": [[1, 0.5], [0, 0.2]]}')
    cases.append((["builtin:ct_head", "--tf", str(bad_json)], "--tf"))
    raw = tmp_path / "x.raw"
    raw.write_bytes(b"\0" * 10)
    cases.append(([str(raw), "--shape", "2,2,2", "--dtype", "uint8", "--spacing", "1,1,1"], "--shape"))
    if hasattr(cli, "technique_options"):
        cases.append((["builtin:ct_head", "--interpolate", "1"], "--interpolate"))   # slice2d's option
    for argv, option in cases:
        assert viewer_mod.main(argv) == 2, argv
        err = capsys.readouterr().err
        assert err.startswith("dvr-gl view: error: ") and option in err and "Traceback" not in err, err
    assert cli.main(["view", "/nonexistent/head.npy"]) == 2     # through dvr-gl view
    assert "dvr-gl view: error: INPUT" in capsys.readouterr().err
    assert viewer_mod.main(["builtin:ct_head", "--frames", "0"]) == 2
    assert "--frames" in capsys.readouterr().err


def test_no_display_is_a_clear_message(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env["PYTHONPATH"] = os.pathsep.join([os.path.dirname(os.path.dirname(dvr_gl.__file__)),
                                         env.get("PYTHONPATH", "")])
    proc = subprocess.run([sys.executable, "-m", "dvr_gl", "view", "builtin:synthetic"], env=env,
                          capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 1
    assert "dvr-gl view: error: cannot open a window: no display" in proc.stderr
    assert "xvfb-run" in proc.stderr and "Traceback" not in proc.stderr


def test_frames_screenshot_under_xvfb_run(display, renderer, tmp_path):
    if shutil.which("xvfb-run") is None:
        pytest.skip("xvfb-run is not installed")
    np.save(tmp_path / "head.npy", data.ct_head().data)
    env = dict(os.environ)
    env.pop("DISPLAY", None)
    env["PYTHONPATH"] = os.pathsep.join([os.path.dirname(os.path.dirname(dvr_gl.__file__)),
                                         env.get("PYTHONPATH", "")])
    proc = subprocess.run(["xvfb-run", "-a", sys.executable, "-m", "dvr_gl", "view", "head.npy",
                           "--screenshot", "out.png", "--frames", "5", "--size", "128x128"],
                          env=env, capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "5 frames at 128x128" in proc.stdout and "wrote out.png" in proc.stdout
    shot = png(tmp_path / "out.png")
    assert shot.shape == (128, 128, 4)
    covered = (shot[..., 3] > 0).mean()
    assert 0.2 < covered < 0.95, "a sensible picture: the head in the middle, background around"
    assert shot[64, 64, 3] > 0 and shot[0, 0, 3] == 0
    # the same picture dvr-gl render makes of it (default auto TF and camera)
    volume = dvr_io.load_volume(str(tmp_path / "head.npy"))
    scene = dvr_gl.Scene(volume, transfer.auto_preset(volume), first_camera(volume), width=128, height=128,
                         shading=True)    # lit from the start, as render
    headless = dvr_io.to_png_array(renderer.render(scene))
    plan = dvr_gl.techniques.raycast.make_plan(scene)
    assert np.abs(shot.astype(int) - headless).max() <= 1 + math.ceil(255 * derived_tolerance(plan))


def test_real_x_events_reach_the_handlers(open_viewer, display):
    """The glfw callbacks forward real X input: a drag sent through the XTest extension
    orbits, and q ends the interactive loop."""
    import ctypes
    import ctypes.util

    import glfw

    names = [ctypes.util.find_library("Xtst"), "libXtst.so.6"]
    try:
        xtst = ctypes.CDLL(next(n for n in names if n))
        x11 = ctypes.CDLL(ctypes.util.find_library("X11") or "libX11.so.6")
    except OSError as e:
        pytest.skip(f"libXtst is not available to send X events: {e}")
    x11.XOpenDisplay.restype = ctypes.c_void_p
    x11.XOpenDisplay.argtypes = [ctypes.c_char_p]
    x11.XStringToKeysym.restype = ctypes.c_ulong
    x11.XKeysymToKeycode.argtypes = [ctypes.c_void_p, ctypes.c_ulong]
    for name in ("XFlush", "XCloseDisplay"):
        getattr(x11, name).argtypes = [ctypes.c_void_p]
    xtst.XTestFakeMotionEvent.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_int, ctypes.c_int, ctypes.c_ulong]
    xtst.XTestFakeButtonEvent.argtypes = [ctypes.c_void_p, ctypes.c_uint, ctypes.c_int, ctypes.c_ulong]
    xtst.XTestFakeKeyEvent.argtypes = [ctypes.c_void_p, ctypes.c_uint, ctypes.c_int, ctypes.c_ulong]
    dpy = x11.XOpenDisplay(display.encode())
    assert dpy, f"cannot open {display}"
    try:
        v = head_viewer(open_viewer)
        glfw.set_window_pos(v.window, 0, 0)
        v.refine()
        x0, y0 = glfw.get_window_pos(v.window)
        back = v.orbit.back.copy()
        xtst.XTestFakeMotionEvent(dpy, -1, x0 + 60, y0 + 30, 0)
        xtst.XTestFakeButtonEvent(dpy, 1, True, 0)
        for k in range(1, 5):
            xtst.XTestFakeMotionEvent(dpy, -1, x0 + 60 + 5 * k, y0 + 30, 0)
        xtst.XTestFakeButtonEvent(dpy, 1, False, 0)
        x11.XFlush(dpy)
        expected = 20 * math.pi / 120
        for _ in range(300):   # until every motion event has arrived (they come in as X delivers them)
            glfw.poll_events()
            angle = math.acos(np.clip(back @ v.orbit.back, -1, 1))
            if abs(angle - expected) < 1e-9:
                break
            glfw.wait_events_timeout(0.01)
        assert angle == pytest.approx(expected, abs=1e-9)
        keycode = x11.XKeysymToKeycode(dpy, x11.XStringToKeysym(b"q"))
        xtst.XTestFakeKeyEvent(dpy, keycode, True, 0)
        xtst.XTestFakeKeyEvent(dpy, keycode, False, 0)
        x11.XFlush(dpy)
        v.run()                                          # returns once q arrives
        assert v.should_close
    finally:
        x11.XCloseDisplay(dpy)


def test_window_opens_after_a_headless_egl_context(display, tmp_path):
    """A headless EGL context left current on the thread (as ``dvr-gl info``'s probing
    leaves one) must not stop the window: libglvnd would refuse glXMakeCurrent with an X
    error that ends the process, hence a subprocess."""
    code = ("from dvr_gl.gl.context import create_context\n"
            "try:\n"
            "    ctx, _ = create_context('egl')\n"
            "    ctx.release()\n"
            "except Exception as e:\n"
            "    print('no egl', e)\n"
            "from dvr_gl.frontends import viewer\n"
            "v = viewer.open_viewer(['builtin:synthetic', '--size', '32x32'])\n"
            "v.refine()\n"
            "print('frame', v.last_frame.quality)\n"
            "v.close()\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([os.path.dirname(os.path.dirname(dvr_gl.__file__)),
                                                       os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120,
                          cwd=tmp_path)
    assert proc.returncode == 0 and "frame full" in proc.stdout, proc.stderr


# ----------------------------------------------------------------------------- tetrahedral meshes

@pytest.fixture
def mesh_viewer(display):
    """Open viewers on ``data.delaunay_ball()`` (with ``synthetic_tf()``) through
    :class:`Settings`, as ``dvr-gl view`` does with a mesh file; checked for GL errors and
    closed after the test."""
    made = []

    def make(**settings):
        settings = {"volume": data.delaunay_ball(), "tf": data.synthetic_tf(), "tf_name": "synthetic",
                    "input_name": "ball", "size": (160, 120), **settings}
        v = viewer_mod.Viewer(viewer_mod.Settings(**settings))
        made.append(v)
        return v

    yield make
    _close_checked(made)


def _tetra():
    from dvr_gl.techniques import get_technique
    return get_technique("tetra")


def _ball_region(image, panel_top):
    """Pixels of the window above the editor panel, where the ball is drawn."""
    return image[:panel_top]


def test_mesh_opens_with_tetra_and_shows_the_ball(mesh_viewer):
    v = mesh_viewer()                                   # Settings' default technique is raycast
    assert v.technique == "tetra" and v.available_techniques == ["tetra", "particles", "splat"]
    assert "technique tetra" in v.messages[-1] and "raycast" in v.messages[-1]
    for name in ("raycast", "slice2d", "slice3d"):
        if name in v.techniques:
            assert not v.techniques[name].applies and "TetMesh" in v.techniques[name].reason
    assert not v.info.accepts_step and v.effective_step() is None
    scene, name, step, options = v.render_arguments()
    assert scene.is_mesh and name == "tetra" and step is None
    v.refine()
    assert v.last_frame.quality == "full" and v.last_frame.target_size == (160, 120) and v.last_frame.step is None
    assert "4000 points" in v.title and "tets" in v.title and "tetra composite" in v.title
    # the render: the ball's torus and blob in the middle, nothing in the corners
    image = v.render_image()
    assert image.shape == (120, 160, 4)
    assert image[..., 3].max() > 0.5 and (image[..., 3] > 0.01).mean() > 0.03
    assert image[:8, :8, 3].max() == 0 and image[-8:, -8:, 3].max() == 0
    # the window as shown: the render over the background, the editor below
    pixels = v.frame(quality="full", grab=True)
    top = int(v.editor.panel[1]) - 1
    shown = _ball_region(pixels, top)
    assert shown.max() > 100 and (shown.max(axis=2) > 20).mean() > 0.03
    # the editor's histogram counts the mesh's point scalars
    from dvr_gl.frontends.viewer.overlay import data_histogram
    e = v.editor
    assert e.lo <= v.volume.data_range[0] and e.hi >= v.volume.data_range[1]
    assert np.allclose(e.histogram, data_histogram(v.volume, e.lo, e.hi)) and e.histogram.max() == 1.0
    counts, _ = np.histogram(v.volume.scalars, bins=len(e.histogram), range=(e.lo, e.hi))
    assert np.array_equal(e.histogram > 0, counts > 0)


def test_mesh_screenshot_matches_headless(mesh_viewer, renderer, tmp_path):
    v = mesh_viewer(screenshot=str(tmp_path / "ball.png"), elevation=30.0)
    v.refine()
    press(v, "s")
    image = png(tmp_path / "ball.png")
    assert image.shape == (120, 160, 4) and image[..., 3].max() > 100, "the ball must show"
    assert image[60, 80, 3] > 0 and image[0, 0, 3] == 0
    scene, name, step, options = v.render_arguments()
    headless = dvr_io.to_png_array(renderer.render(scene, name, step, **options))
    diff = int(np.abs(image.astype(int) - headless.astype(int)).max())
    with current(v.ctx):
        window_gl = v.ctx.info["GL_RENDERER"]
    if window_gl == renderer.info().get("renderer", renderer.info().get("GL_RENDERER")):
        assert diff <= 1, f"same driver ({window_gl}), yet {diff} levels apart"
    else:  # two drivers blending the same float fragments: close, not bit-equal
        assert np.abs(image.astype(int) - headless.astype(int)).mean() < 1.0 and diff <= 16


def test_mesh_orbit_sort_and_modes(mesh_viewer):
    v = mesh_viewer()
    clock = [0.0]                                       # input settles when the test says so
    v.clock = lambda: clock[0]
    v.refine()
    before = v.render_image()
    back = v.orbit.back.copy()
    drag(v, (80, 40), (110, 30))                        # orbit: a new view of the ball
    assert not np.allclose(v.orbit.back, back)
    clock[0] += 1.0
    v.refine()
    after = v.render_image()
    assert after[..., 3].max() > 0.5 and np.abs(after - before).max() > 0.05
    # c: tetra's cell order, from the default (auto: the walk) to mpvo -> centroid -> walk,
    # passed as its sort option
    assert "sort" not in v.render_arguments()[3] and "(auto)" in v.title
    press(v, "c")
    assert v.render_arguments()[3] == {"sort": "mpvo"} and v.messages[-1] == "sort mpvo"
    v.refine()
    mpvo = v.render_image()
    assert "(mpvo)" in v.title and np.abs(mpvo - after).max() < 1e-4
    press(v, "c")
    assert v.render_arguments()[3] == {"sort": "centroid"} and v.messages[-1] == "sort centroid"
    v.refine()
    assert "(centroid)" in v.title
    centroid = v.render_image()
    assert centroid[..., 3].max() > 0.5
    assert np.abs(centroid - after).mean() < 0.01      # another order of the same cells
    press(v, "c")                                      # the cell walk: no order, the same exact segments
    assert v.render_arguments()[3] == {"sort": "walk"} and v.messages[-1] == "sort walk"
    v.refine()
    assert "(walk)" in v.title and np.abs(v.render_image() - after).max() < 1e-4
    press(v, "c")
    assert v.render_arguments()[3] == {"sort": "mpvo"}
    v.refine()
    assert np.abs(v.render_image() - mpvo).max() < 1e-6
    # m: every mode tetra renders is reached; the others are skipped and named, never crash
    modes = _tetra().MODES
    seen = []
    for _ in range(len(modes)):                        # a full cycle through tetra's modes
        press(v, "m")
        seen.append(v.mode)
        v.refine()
        assert v.last_frame.quality == "full" and v.technique == "tetra"
        if v.mode in ("composite", "mip"):               # (minip: the ball's minimum is clear)
            assert v.render_image()[..., 3].max() > 0.1
    assert set(seen) == set(modes) and seen[-1] == "composite"
    if len(modes) == 1:
        assert "tetra renders only mode composite" in v.messages[-1]
    else:
        assert any("tetra cannot render isosurface" in m for m in v.messages)
    # keys for options tetra lacks: said, not crashed
    # t: the other techniques that render meshes (particles, splat), then back
    for name in ("particles", "splat"):
        press(v, "t")
        assert v.technique == name
        v.refine()
        assert v.last_frame.quality == "full" and v.render_image()[..., 3].max() > 0.1
    press(v, "t")
    assert v.technique == "tetra"
    v.refine()
    press(v, KEY_MINUS)
    assert "takes no step" in v.messages[-1] and v.render_arguments()[2] is None
    press(v, "p")
    assert "tetra has no preintegrate option" in v.messages[-1]
    press(v, "l")                                      # tetra lights when asked (not by default)
    assert "cannot switch shading: tetra" in v.messages[-1] and not v.lit
    for number in range(1, len(v.presets()) + 1):       # every preset, or a message
        press(v, str(number))
        v.refine()
    press(v, "1")
    assert v.tf.key() == data.synthetic_tf().key()
    v.refine()
    assert v.last_frame.quality == "full"


def test_mesh_sort_key_elsewhere(open_viewer):
    v = head_viewer(open_viewer)
    press(v, "c")
    assert "raycast has no sort option" in v.messages[-1] and "sort" not in v.render_arguments()[3]


def test_mesh_progressive_refinement(mesh_viewer):
    v = mesh_viewer()
    clock = [0.0]
    v.clock = lambda: clock[0]
    v.refine()
    v.on_mouse_button(MOUSE_LEFT, PRESS, 0, 80, 40)
    for k in range(2):                                  # dragging: half resolution, still no step
        v.on_cursor(84 + 4 * k, 40)
        clock[0] += 0.03
        v.frame()
        assert v.last_frame.quality == "coarse" and v.last_frame.target_size == (80, 60)
        assert v.last_frame.step is None
    v.on_mouse_button(MOUSE_LEFT, RELEASE, 0)
    clock[0] += 0.5
    assert v.needs_frame()
    v.frame()
    assert v.last_frame.quality == "full" and v.last_frame.target_size == (160, 120) and not v.needs_frame()


def test_mesh_double_click_recentres(mesh_viewer):
    v = mesh_viewer()
    clock = [100.0]
    v.clock = lambda: clock[0]
    o = v.orbit
    lo, hi = v.volume.bounds
    forward, distance = -o.back.copy(), o.distance
    origin, direction = o.ray(80, 40, 160, 120)
    for _ in range(2):
        v.on_mouse_button(MOUSE_LEFT, PRESS, 0, 80, 40)
        v.on_mouse_button(MOUSE_LEFT, RELEASE, 0)
        clock[0] += 0.1
    # on the ray under the cursor, inside the ball, at the torus in front of the centre
    assert np.linalg.norm(np.cross(o.target - origin, direction)) < 1e-6
    assert np.all(o.target >= lo - 1e-9) and np.all(o.target <= hi + 1e-9)
    assert np.linalg.norm(o.target - (lo + hi) / 2) > 5.0
    assert np.allclose(o.back, -forward) and o.distance == distance
    assert_double_click_on_empty_space_recentres(v, o, clock, lo, hi)


def test_mesh_picking_follows_the_cells():
    """No window: the ray's cells tile the chord through the (convex) ball without gaps,
    the field is continuous from cell to cell, and each mode picks by the grid's rule."""
    mesh, tf = data.delaunay_ball(), data.synthetic_tf()
    centre = (mesh.bounds[0] + mesh.bounds[1]) / 2
    origin = centre + np.array([3.0, -2.0, 100.0])
    direction = np.array([0.01, 0.02, -1.0])
    direction /= np.linalg.norm(direction)
    t_in, t_out, start, rate = viewer_mod.ray_cells(mesh, origin, direction)
    assert t_in.size > 10 and np.all(np.diff(t_in) >= 0)
    assert np.allclose(t_out[:-1], t_in[1:], atol=1e-6)          # no gaps, no overlaps
    end_values = start + rate * (t_out - t_in)
    assert np.allclose(end_values[:-1], start[1:], atol=1e-6)    # the field is continuous
    # the entry and exit lie on the ball's hull (radius 31.5 about its centre, roughly)
    for t in (t_in[0], t_out[-1]):
        assert 29.0 < np.linalg.norm(origin + t * direction - centre) < 31.6
    # mip: the largest value along the ray; isosurface: the first crossing of the iso value
    t = np.linspace(t_in[0], t_out[-1], 20001)
    k = np.clip(np.searchsorted(t_in, t, side="right") - 1, 0, None)
    field = start[k] + rate[k] * (t - t_in[k])
    p = viewer_mod.pick_point(mesh, tf, "mip", None, origin, direction)
    assert abs((p - origin) @ direction - t[np.argmax(field)]) < 0.5
    iso = 0.5 * (field.min() + field.max())
    assert field[0] < iso
    p = viewer_mod.pick_point(mesh, tf, "isosurface", iso, origin, direction)
    first = t[np.argmax(field >= iso)]
    assert abs((p - origin) @ direction - first) < 0.5
    p = viewer_mod.pick_point(mesh, tf, "composite", None, origin, direction)
    assert p is not None and np.linalg.norm(np.cross(p - origin, direction)) < 1e-6
    # a ray that misses the ball, and one through the box's corner outside the ball
    assert viewer_mod.pick_point(mesh, tf, "composite", None, origin + [200.0, 0, 0], direction) is None
    corner = mesh.bounds[1] - 0.5
    assert viewer_mod.pick_point(mesh, tf, "composite", None, corner + [0, 0, 100.0],
                                 np.array([0.0, 0.0, -1.0])) is None


def test_mesh_file_through_the_command_line(open_viewer, tmp_path):
    """``dvr-gl view ball.npz``: the viewer takes what the command line loads (when the
    command line reads mesh files)."""
    if not hasattr(cli, "input_is_mesh"):
        pytest.skip("the command line does not read mesh files yet")
    mesh = data.delaunay_ball()
    path = tmp_path / "ball.npz"
    np.savez(path, points=mesh.points, tets=mesh.tets, value=mesh.scalars)
    v = open_viewer(str(path), "--tf", "synthetic", "--size", SIZE, "--screenshot", str(tmp_path / "shot.png"))
    assert v.technique == "tetra" and isinstance(v.volume, dvr_gl.TetMesh)
    press(v, "c")
    v.refine()
    press(v, "s")
    assert png(tmp_path / "shot.png")[..., 3].max() > 100


def test_tolerance_refines_to_the_chosen_step_and_keys_change_it(open_viewer, renderer, tmp_path):
    """--tolerance: coarse frames while the view moves, then the full frame at the step
    (and way of sampling) the error model picks (the headless render with those settings
    is the same image); - and = double and halve the tolerance. The choice is compared
    with the viewer's own renderer's: where two ways of sampling are a close call, the
    timing that settles it can fall either way in two renderers."""
    v = head_viewer(open_viewer, "--tolerance", "2e-3", "--screenshot", str(tmp_path / "tol.png"))
    v.frame()                        # the first frame comes at once, before any pilot
    assert v.last_frame.quality == "coarse" and getattr(v.renderer, "last_choice", None) is None
    v.refine()
    assert v.last_frame.quality == "full"
    scene, name, step, options = v.render_arguments()
    chosen = v.renderer.last_choice
    assert chosen.tolerance == pytest.approx(2e-3)
    assert step == pytest.approx(chosen.step) and options["preintegrate"] == chosen.preintegrate
    headless = renderer.render(scene, name, step=step, **options)
    press(v, "s")
    assert np.abs(png(tmp_path / "tol.png").astype(int)
                  - dvr_io.to_png_array(headless, v.settings.background).astype(int)).max() <= 1
    press(v, "=")
    assert v.tolerance == pytest.approx(1e-3) and v.messages[-1] == "tolerance 0.001"
    assert v.render_arguments()[2] < step
    press(v, "-")
    press(v, "-")
    assert v.tolerance == pytest.approx(4e-3) and v.render_arguments()[2] > step


# ----------------------------------------------------------------------------- clipping

def test_clip_plane_keys_and_drag_match_the_headless_cut(open_viewer, renderer, tmp_path):
    from dvr_gl.frontends.viewer import MOD_ALT
    v = head_viewer(open_viewer, "--screenshot", str(tmp_path / "c.png"))
    assert v.clip_planes == ()
    press(v, "k")                                   # a plane through the centre, facing the eye
    (point, normal), = v.clip_planes
    np.testing.assert_allclose(point, np.mean(v.volume.bounds, axis=0))
    np.testing.assert_allclose(normal, v.orbit.camera().forward)
    before = point.copy()
    drag(v, (80, 60), (80, 30), mods=MOD_ALT)       # up: along the normal, the eye unmoved
    (moved, _), = v.clip_planes
    assert np.dot(moved - before, normal) > 0
    np.testing.assert_allclose(v.orbit.camera().eye, first_camera(v.volume, azimuth=0, elevation=90).eye)
    v.refine()
    press(v, "s")
    scene = v.render_arguments()[0]
    assert len(scene.clip_planes) == 1
    assert_matches_headless(v, renderer, png(tmp_path / "c.png"))
    press(v, "k")                                   # off, and on again where it was
    assert v.clip_planes == ()
    press(v, "k")
    np.testing.assert_allclose(v.clip_planes[0][0], moved)


def test_clip_option_reaches_the_viewer(open_viewer):
    v = head_viewer(open_viewer, "--clip", "100,100,70,1,0,0", "--crop", "0,0,0,150,150,100")
    scene = v.render_arguments()[0]
    assert len(scene.clip_planes) == 1 and scene.crop_box is not None


def test_geometry_key_hides_and_shows_the_surfaces(open_viewer, tmp_path):
    import meshio
    lo, hi = data.ct_head().bounds
    c = (lo + hi) / 2
    quad = np.array([c + (-40, -40, 0), c + (40, -40, 0), c + (40, 40, 0), c + (-40, 40, 0)])
    meshio.write(str(tmp_path / "quad.obj"), meshio.Mesh(quad, [("triangle", np.array([[0, 1, 2], [0, 2, 3]]))]))
    v = head_viewer(open_viewer, "--geometry", str(tmp_path / "quad.obj"))
    assert len(v.render_arguments()[0].geometry) == 1
    press(v, "g")
    assert v.render_arguments()[0].geometry == ()
    press(v, "g")
    assert len(v.render_arguments()[0].geometry) == 1
    from dvr_gl.techniques.common import GEOMETRY_TECHNIQUES
    seen = set()
    for _ in range(len(technique_names())):   # those that draw no surfaces are skipped, the surface kept
        press(v, "t")
        seen.add(v.technique)
        assert len(v.render_arguments()[0].geometry) == 1
    assert seen <= set(GEOMETRY_TECHNIQUES) and len(seen) > 1
