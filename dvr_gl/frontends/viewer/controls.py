"""Input handling: what the mouse, the wheel, the keys and window changes do to a viewer.

Plain Python: :class:`Controls` takes the values glfw reports (window coordinates, glfw's
key and button codes, :mod:`.keys`) and changes the viewer's state. The glfw callbacks
(:func:`connect`) only forward to the viewer's ``on_*`` handlers, which hand the event to
its Controls; tests call the handlers directly with synthetic events.

Mouse gestures on the transfer-function editor's panel belong to the editor
(:class:`~.overlay.TFEditor`); elsewhere a left drag orbits, a right drag zooms, a
middle (or shift + left) drag pans, ctrl + left drag sets the window/level of the
transfer function, alt + left drag moves the clip plane (:mod:`.clipping`), and a double
click recentres (:meth:`Viewer.recentre`).
"""

from __future__ import annotations

import math
import os

from .choices import next_illustration, next_optical_model, switch_shading
from .clipping import aim_clip, move_clip, toggle_clip, toggle_geometry
from .layers import LAYER_KEYS, toggle_layer
from .keys import (KEY_COMMA, KEY_EQUAL, KEY_ESCAPE, KEY_F1, KEY_KP_ADD, KEY_KP_SUBTRACT, KEY_LEFT_BRACKET,
                   KEY_MINUS, KEY_PERIOD, KEY_RIGHT_BRACKET, KEYS_HELP, MOD_ALT, MOD_CONTROL, MOD_SHIFT, MOUSE_LEFT,
                   MOUSE_MIDDLE, MOUSE_RIGHT, PRESS, RELEASE, REPEAT, REPEATABLE)


def connect(glfw, window, viewer):
    """Forward the window's glfw callbacks to ``viewer``'s handlers."""
    glfw.set_cursor_pos_callback(window, lambda w, x, y: viewer.on_cursor(x, y))
    glfw.set_mouse_button_callback(window, lambda w, b, a, m: viewer.on_mouse_button(b, a, m))
    glfw.set_scroll_callback(window, lambda w, dx, dy: viewer.on_scroll(dx, dy))
    glfw.set_key_callback(window, lambda w, k, sc, a, m: viewer.on_key(k, a, m))
    glfw.set_framebuffer_size_callback(window, lambda w, fw, fh: viewer.on_resize(fw, fh))
    glfw.set_window_size_callback(window, lambda w, ww, wh: viewer.on_window_size(ww, wh))
    glfw.set_drop_callback(window, lambda w, paths: viewer.on_drop(paths))
    glfw.set_window_refresh_callback(window, lambda w: viewer.overlay_changed())


class Controls:
    """The input state of a viewer (the cursor, the drag in progress, the last click)
    and what each event does to the viewer."""

    def __init__(self, viewer):
        self.viewer = viewer
        self.cursor = (0.0, 0.0)
        self.drag = None          # {"kind", "button", "start", "base"} while a button is held
        self.last_click = None    # (time, x, y) of the last click, for double clicks

    # -- the mouse ---------------------------------------------------------------------
    def on_cursor(self, x, y):
        v = self.viewer
        x, y = float(x), float(y)
        px, py = self.cursor
        self.cursor = (x, y)
        drag = self.drag
        if drag is None:
            before = v.editor.hover
            v.editor.move(x, y)
            if v.editor.hover != before:
                v.overlay_changed()
            return
        dx, dy = x - px, y - py
        ww, wh = v.window_size
        kind = drag["kind"]
        if kind == "editor":
            if v.editor.move(x, y):
                v.tf_edited()
            v.overlay_changed()
            return
        if kind == "orbit":
            rate = math.pi / max(wh, 1)      # half a turn per window height
            v.orbit.orbit(-dx * rate, dy * rate)
        elif kind == "pan":
            wpp = v.orbit.world_per_pixel(wh)
            v.orbit.pan(-dx * wpp, dy * wpp)
        elif kind == "zoom":
            v.orbit.zoom(math.exp(-2.0 * dy / max(wh, 1)))
        elif kind == "clip":
            move_clip(v, -dy)      # up moves the plane along its normal
            return
        elif kind == "window_level":
            x0, y0 = drag["start"]
            shift = (x - x0) / max(ww, 1) * (v.editor.hi - v.editor.lo)
            scale = math.exp(2.0 * (y - y0) / max(wh, 1))
            v.editor.window_level(drag["base"], shift, scale)
            v.overlay_changed()
        if dx or dy:
            v.changed(interactive=True)

    def on_mouse_button(self, button, action, mods=0, x=None, y=None):
        v = self.viewer
        if x is not None and y is not None:
            self.cursor = (float(x), float(y))
        x, y = self.cursor
        if action == RELEASE:
            drag = self.drag
            if drag is not None:
                if drag["kind"] == "editor":
                    v.editor.release(button, x, y)
                    v.overlay_changed()
                if drag["button"] == button:
                    self.drag = None
                    # a press and release without moving is a click; two make a double click
                    sx, sy = drag["start"]
                    if button == MOUSE_LEFT and drag["kind"] == "orbit" and math.hypot(x - sx, y - sy) <= 3:
                        self.last_click = (v.clock(), x, y)
            return
        if action != PRESS:
            return
        if v.editor.contains(x, y):
            if v.editor.press(button, x, y):
                v.tf_edited()
            if v.editor.drag is not None:
                self.drag = {"kind": "editor", "button": button, "start": (x, y)}
            v.overlay_changed()
            return
        if button == MOUSE_LEFT:
            last, self.last_click = self.last_click, None
            if (last is not None and not mods and v.clock() - last[0] <= v.double_click_s
                    and math.hypot(x - last[1], y - last[2]) <= 5):
                v.recentre(x, y)
                return
            if mods & MOD_ALT and v.clip_planes:
                kind = "clip"
            elif mods & MOD_CONTROL:
                kind = "window_level"
            elif mods & MOD_SHIFT:
                kind = "pan"
            else:
                kind = "orbit"
        elif button == MOUSE_RIGHT:
            kind = "zoom"
        elif button == MOUSE_MIDDLE:
            kind = "pan"
        else:
            return
        self.drag = {"kind": kind, "button": button, "start": (x, y), "base": v.tf}

    def on_scroll(self, dx, dy):
        v = self.viewer
        x, y = self.cursor
        if v.editor.contains(x, y):
            if v.editor.scroll(x, y, dy):
                v.tf_edited()
                v.overlay_changed()
            return
        if dy:
            v.orbit.zoom(1.1 ** dy)
            v.changed(interactive=True)

    # -- the window --------------------------------------------------------------------
    def on_resize(self, width, height):
        """The framebuffer's new size (pixels; on high-DPI screens not the window's)."""
        v = self.viewer
        v.framebuffer_size = (int(width), int(height))
        v.changed()

    def on_window_size(self, width, height):
        """The window's new size in window coordinates (the cursor's units)."""
        v = self.viewer
        v.window_size = (int(width), int(height))
        v.editor.layout(width, height)
        v.overlay_changed()

    def on_drop(self, paths):
        v = self.viewer
        for path in paths:
            if str(path).lower().endswith(".json"):
                v.load_tf(path)
            else:
                v.say(f"drop a transfer-function .json file here, not {os.path.basename(str(path))!r}")

    # -- the keys (KEYS_HELP lists them) -------------------------------------------------
    def on_key(self, key, action, mods=0):
        v = self.viewer
        if action == REPEAT and key not in REPEATABLE:
            return
        if action not in (PRESS, REPEAT):
            return
        shift, ctrl = bool(mods & MOD_SHIFT), bool(mods & MOD_CONTROL)
        char = chr(key).lower() if 32 <= key < 127 else None
        if ctrl:
            if char == "s":
                v.save_tf()
            elif char == "o":
                v.load_tf()
            return
        if key in (KEY_ESCAPE,) or char == "q":
            v.request_close()
        elif char == "h" or key == KEY_F1:
            print(KEYS_HELP, flush=True)
        elif char == "r":
            v.orbit.reset()
            v.changed()
        elif char == "t":
            v.cycle_technique(-1 if shift else 1)
        elif char == "m":
            v.cycle_mode(-1 if shift else 1)
        elif key in (KEY_COMMA, KEY_PERIOD):
            v.nudge_iso((1 if key == KEY_PERIOD else -1) * (5 if shift else 1))
        elif char == "l":
            switch_shading(v)
        elif char == "i":
            next_illustration(v)
        elif char == "x":
            next_optical_model(v)
        elif char == "p":
            v.toggle_option("preintegrate")
        elif char == "c":
            v.cycle_sort()
        elif char == "g":
            toggle_geometry(v)
        elif key in LAYER_KEYS:
            toggle_layer(v, LAYER_KEYS.index(key))
        elif char == "k":
            if shift:
                aim_clip(v)
            else:
                toggle_clip(v)
        elif key in (KEY_MINUS, KEY_KP_SUBTRACT):
            v.change_step(coarser=True)
        elif key in (KEY_EQUAL, KEY_KP_ADD):
            v.change_step(coarser=False)
        elif char is not None and char.isdigit() and char != "0":
            v.apply_preset(int(char))
        elif key in (KEY_LEFT_BRACKET, KEY_RIGHT_BRACKET):
            v.editor.scale_opacity(1.25 if key == KEY_RIGHT_BRACKET else 0.8)
            v.tf_edited(interactive=False)
        elif char == "e":
            v.editor.visible = not v.editor.visible
            v.editor.drag = None
            v.overlay_changed()
        elif char == "o":
            v.orbit.ortho = not v.orbit.ortho
            v.changed()
        elif char == "b":
            i = v.backgrounds.index(v.background)
            v.background = v.backgrounds[(i + 1) % len(v.backgrounds)]
            v.overlay_changed()
        elif char == "s":
            if shift:
                v.save_window_screenshot()
            else:
                v.save_screenshot()
