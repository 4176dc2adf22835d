"""The :class:`Viewer`: one window showing one volume or mesh, with its camera, its
rendering choices and its transfer function.

The Viewer holds the state and the frame loop; its collaborators do the rest:
:class:`~.controls.Controls` turns input into changes (the ``on_*`` handlers hand every
event to it), :mod:`.choices` changes the rendering choices as the keys ask,
:class:`~.frames.Presenter` renders and shows frames, :mod:`.tf_actions` switches,
saves and loads transfer functions, :mod:`.screenshots` writes images and
:class:`~.status.StatusLine` says what happened.

Every change of the picture bumps ``version`` (:meth:`Viewer.changed`); a change of the
editor or the background only bumps ``overlay_version`` (:meth:`Viewer.overlay_changed`),
which composes the frame again without rendering it. Progressive quality: while the user
drags or scrolls, frames are rendered at ``coarse_scale`` of the resolution and
``coarse_step`` times the step; once no input has arrived for ``settle_s`` seconds, one
full-quality frame follows (particles then average ever more sets while the view stays
still, up to ``max_accumulate``).
"""

from __future__ import annotations

import math
import time

import numpy as np

from ...model.scene import Scene
from ...rendering.pyramid import MOVING_SAMPLES, has_pyramid, moving_volume, settings as pyramid_settings
from .choices import move_iso, next_mode, next_sort, next_technique, scale_step, switch_option
from .controls import Controls, connect
from .frames import Presenter
from .layers import framing, shown_volumes
from .orbit import Orbit
from .overlay import TFEditor
from .picking import pick_data, pick_point
from .probe import TechniqueInfo, fallback_step, probe_techniques, starting_technique
from .screenshots import full_image, write_screenshot, write_window_screenshot
from .settings import PROG, Settings
from .status import StatusLine, window_title
from .tf_actions import preset_list, read_tf, use_preset, write_tf
from .window import destroy_window, gl_current, open_window, resize_window


class Viewer:
    """A window showing one volume, with its camera, technique and transfer-function
    state. Open with :func:`open_viewer` (or construct from :class:`Settings`), drive
    with :meth:`run` or :meth:`frame` and the ``on_*`` handlers, end with :meth:`close`."""

    settle_s = 0.2        # no input for this long: render at full quality
    max_accumulate = 64   # particles: sets averaged at most while the view stays still
    coarse_scale = 0.5    # resolution while interacting
    coarse_step = 2.0     # step multiplier while interacting
    moving_samples = MOVING_SAMPLES   # a pyramid's level while interacting: the finest this small
    double_click_s = 0.35

    def __init__(self, settings: Settings):
        self.settings = settings
        self.volume = settings.volume
        self.clock = time.perf_counter
        self.quit = False
        self.status_line = StatusLine(lambda: self.clock())
        self.layers, self.blend = tuple(settings.layers), settings.blend   # more volumes (keys F2..F5)
        self.hidden_layers = frozenset()   # which of them (0: INPUT) are left out of the scene
        self.orbit = Orbit(framing(self.volume, settings.tf, self.layers), settings.azimuth, settings.elevation,
                           settings.zoom, settings.fov, settings.ortho)
        self.editor = TFEditor(settings.tf, self.volume, visible=settings.editor)
        self.initial_tf = settings.tf
        self.mode = settings.mode
        self.iso = settings.iso if settings.iso is not None else self._default_iso()
        self.shading = True if settings.shading is None else settings.shading   # the wish; see lit
        self.optical_model = settings.optical_model
        self.illustration = tuple(settings.illustration)
        self.lights = settings.lights
        self.step = settings.step          # None: the technique's default
        self.clip_planes, self.crop_box = settings.clip_planes, settings.crop_box
        self.geometry = settings.geometry
        self.tolerance = settings.tolerance  # an RMSE: raycast's full frames, a mesh's moving ones
        self.options = dict(settings.options)  # technique options: command line, then keys
        self.technique = settings.technique
        self.backgrounds = []
        for bg in (settings.background, (0.0, 0.0, 0.0), (0.5, 0.5, 0.5), (1.0, 1.0, 1.0)):
            if bg is not None and tuple(bg) not in self.backgrounds:
                self.backgrounds.append(tuple(float(v) for v in bg))
        self.background = self.backgrounds[0]
        self.controls = Controls(self)
        self._pick_data = None             # what picking samples, made on first use
        self.version = 0                   # bumped by every change of the picture
        self.overlay_version = 0           # bumped by every change of the overlay only
        self.accumulated = 1               # particle sets averaged in the picture shown
        self._last_input = -math.inf
        self.last_frame = None
        self.frame_times = []
        self.window = None
        self._open_window(settings)
        self.techniques = {}
        try:
            # which techniques can render this data at all (in the plain composite mode)
            probe = Scene(self.volume, self.tf, self.orbit.camera(), width=8, height=8,
                          **({"layers": self.layers, "blend": self.blend} if self.layers else {}))
            self.techniques = probe_techniques(probe, self.renderer.tables)
            self.technique, message = starting_technique(self.techniques, self.technique, self.volume)
            if message:
                self.say(message)
            self.validate()  # and the mode and options asked for
        except BaseException:
            self.close()
            raise

    # -- window and GL ---------------------------------------------------------------
    def _open_window(self, settings):
        from ...rendering.renderer import Renderer

        self.glfw, self.window, self.ctx = open_window(settings.size, PROG, settings.visible, settings.vsync)
        self.renderer = Renderer(ctx=self.ctx)
        with self.gl():
            self.presenter = Presenter(self)
        self.window_size = self.glfw.get_window_size(self.window)
        self.framebuffer_size = self.glfw.get_framebuffer_size(self.window)
        self.editor.layout(*self.window_size)
        connect(self.glfw, self.window, self)

    def gl(self):
        """A block with the window's context current (:func:`.window.gl_current`); the
        viewer's GL work happens only inside such blocks."""
        return gl_current(self.glfw, self.window, self.ctx)

    def close(self):
        """Free the GL resources and the window (idempotent)."""
        if self.window is None:
            return
        with self.gl():
            self.presenter.release()
            self.renderer.release()
        destroy_window(self.glfw, self.window, self.ctx)
        self.window = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    @property
    def should_close(self):
        return self.quit or self.window is None or bool(self.glfw.window_should_close(self.window))

    def request_close(self):
        """End the interactive loop (keys q and Esc)."""
        self.quit = True
        if self.window is not None:
            self.glfw.set_window_should_close(self.window, True)

    def set_window_size(self, width, height):
        """Resize the window (as a user would) and process the events that follow."""
        resize_window(self.glfw, self.window, width, height)

    # -- the state -------------------------------------------------------------------
    @property
    def tf(self):
        return self.editor.tf

    @property
    def info(self) -> TechniqueInfo:
        return self.techniques[self.technique]

    @property
    def available_techniques(self):
        return [n for n, t in self.techniques.items() if t.applies]

    def effective_step(self, name=None):
        """The step the technique renders with at full quality (None if it takes none)."""
        info = self.techniques[name or self.technique]
        if not info.accepts_step:
            return None
        if self.step is not None:
            return self.step
        return info.default_step if info.default_step is not None else fallback_step(self.volume)

    def _default_iso(self):
        """An iso value to start isosurface mode with: where the opacity first reaches
        half its maximum, else the middle of the data range."""
        pts = self.editor.tf.opacity_points
        top = float(pts[:, 1].max())
        if top > 0:
            s = np.linspace(float(pts[0, 0]), float(pts[-1, 0]), 4097)
            a = self.editor.tf.opacity(s)
            return float(s[np.argmax(a >= 0.5 * top)])
        lo, hi = self.volume.data_range
        return 0.5 * (lo + hi)

    def iso_shown(self):
        """The iso value the editor marks: the iso value in isosurface mode, else None."""
        return self.iso if self.mode == "isosurface" else None

    def _scene(self, width, height, tf=None):
        volume, tf, layered = shown_volumes(self, tf or self.tf)   # the volumes shown (keys F2..F5)
        return Scene(volume, tf, self.orbit.camera(), width=width, height=height,
                     mode=self.mode, iso_value=self.iso if self.mode == "isosurface" else None,
                     shading=self.lit, **({"lights": self.lights} if self.lights else {}),
                     optical_model=self.optical_model, illustration=self.illustration,
                     clip_planes=self.clip_planes, crop_box=self.crop_box, geometry=self.geometry, **layered)

    @property
    def lit(self):
        """Whether the scene is lit: the user's wish (key l), where lighting is defined
        (not with several volumes: lighting them is not rendered yet)."""
        from ..inputs import shading_for
        return shading_for(self.technique, self.mode, self.optical_model, self.shading) and not self.layers

    def technique_options(self, name=None):
        """The options the technique (default: the current one) takes, of those set."""
        info = self.techniques[name or self.technique]
        return {k: v for k, v in self.options.items() if info.accepts(k)}

    def render_arguments(self, width=None, height=None, coarse=False, tolerance=True):
        """``(scene, technique, step, options)`` for ``Renderer.render`` /
        ``render_target``: what the next frame renders (at the framebuffer size unless
        given). Tests render the same arguments headless to compare. ``tolerance=False``
        leaves the tolerance's choice out (no pilot: for checks of the state alone)."""
        fw, fh = self.framebuffer_size
        width, height = width or fw, height or fh
        step = self.effective_step()
        if step is not None and coarse:
            step *= self.coarse_step
        options = self.technique_options()
        if self.accumulates():
            options["repetitions"] = 1 if coarse else self.accumulated
        scene = self._scene(width, height)
        if self.technique == "raycast" and has_pyramid(scene):     # a multiscale store (rendering.pyramid)
            if coarse:       # moving: one coarse level, its step as many of its voxels
                level = moving_volume(scene.volume, self.moving_samples)
                step = None if step is None else step * level.min_spacing / scene.volume.min_spacing
                return scene.replace(volume=level), self.technique, step, options
            if tolerance and self.tolerance is not None:    # still: the level (and step) chosen for it
                scene, step, options, self.renderer.last_choice = pyramid_settings(
                    self.renderer, scene, self.tolerance, "raycast", options)
                return scene, self.technique, step, options
        if tolerance and self.tolerance is not None and self.technique == "raycast" and not coarse:
            # progressive: coarse frames while the view moves, then the step (and
            # way of sampling) the error model picks for the tolerance, once it is still
            step, sampling = self.renderer.tolerance_settings(scene, self.tolerance, "raycast", **options)
            options.update(sampling)
        if tolerance and self.tolerance is not None and self.technique == "tetra" and coarse:
            # a mesh turns at the fastest way within the tolerance (rendering.mesh_tolerance,
            # picked once per view family); still frames are tetra's own
            return self.renderer.mesh_tolerance_settings(scene, self.tolerance, "tetra")
        return scene, self.technique, step, options

    def accumulates(self):
        """Whether the technique averages independent sets (particles) and the user left
        their number to the viewer: it then grows while the view stays still."""
        return self.info.accepts("repetitions") and self.info.params is not None and "repetitions" not in self.options

    def validate(self):
        """Raise if the current state cannot be rendered (make_plan on a tiny scene)."""
        from ...techniques import get_technique

        scene, name, step, options = self.render_arguments(8, 8, tolerance=False)
        get_technique(name).make_plan(scene, step, tables=self.renderer.tables, **options)

    def state(self):
        """The rendering choices (not the camera or the transfer function)."""
        return (self.technique, self.mode, self.iso, self.shading, self.optical_model, self.illustration,
                dict(self.options), self.step, self.geometry)

    def restore(self, state, changed=True):
        """Go back to rendering choices :meth:`state` returned."""
        (self.technique, self.mode, self.iso, self.shading, self.optical_model, self.illustration, options,
         self.step, self.geometry) = state
        self.options = dict(options)
        if changed:
            self.changed()

    def try_change(self, change, what, quiet=False):
        """Apply ``change()``; if the result cannot be rendered, undo it and say why (or
        return the reason when ``quiet``). True when the change was kept."""
        saved = self.state()
        try:
            change()
            self.validate()
        except (TypeError, ValueError, NotImplementedError) as e:
            self.restore(saved, changed=False)
            if quiet:
                return str(e)
            self.say(f"cannot {what}: {e}")
            return False
        self.changed()
        return True

    def changed(self, interactive=False):
        """The picture changed: render it again (coarsely while ``interactive`` input
        keeps arriving)."""
        self.version += 1
        self.accumulated = 1
        if interactive:
            self._last_input = self.clock()

    def overlay_changed(self):
        """Only the overlay (or the background) changed: compose the frame again."""
        self.overlay_version += 1

    def tf_edited(self, interactive=True):
        """The transfer function changed (an edit, a preset, a loaded file)."""
        self.overlay_changed()
        self.changed(interactive=interactive)

    def say(self, message):
        """A message on stdout and, for a few seconds, in the window title."""
        self.status_line.say(message)

    @property
    def messages(self):
        """Everything said, for tests and scripts."""
        return self.status_line.messages

    @property
    def status(self):
        """The message said last."""
        return self.status_line.text

    # -- input handlers (pure Python: tests call them with synthetic events) ------------
    def on_cursor(self, x, y):
        self.controls.on_cursor(x, y)

    def on_mouse_button(self, button, action, mods=0, x=None, y=None):
        self.controls.on_mouse_button(button, action, mods, x, y)

    def on_scroll(self, dx, dy):
        self.controls.on_scroll(dx, dy)

    def on_key(self, key, action, mods=0):
        self.controls.on_key(key, action, mods)

    def on_resize(self, width, height):
        """The framebuffer's new size (pixels; on high-DPI screens not the window's)."""
        self.controls.on_resize(width, height)

    def on_window_size(self, width, height):
        """The window's new size in window coordinates (the cursor's units)."""
        self.controls.on_window_size(width, height)

    def on_drop(self, paths):
        self.controls.on_drop(paths)

    # -- actions (the keys call these; see choices, tf_actions and screenshots) ---------
    def cycle_technique(self, direction=1):
        """Switch to the next technique (in the registry's order) that can render the
        current data in the current mode."""
        return next_technique(self, direction)

    def cycle_mode(self, direction=1):
        """Switch to the next mode the current technique can render."""
        return next_mode(self, direction)

    def nudge_iso(self, steps):
        """Keys , and .: move the iso value by ``steps`` hundredths of the data range."""
        move_iso(self, steps)

    def toggle_option(self, option):
        """Switch a technique option on or off (key p: ``preintegrate``)."""
        switch_option(self, option)

    def cycle_sort(self):
        """Key c: the next cell order of a technique with a ``sort`` option."""
        return next_sort(self)

    def change_step(self, coarser):
        """Keys - and =: a coarser or finer step (or tolerance, or slice2d's interpolation)."""
        scale_step(self, coarser)

    def presets(self):
        """The transfer functions keys 1..9 choose: the one given, then the presets that
        suit the data (``inputs.suitable_presets``)."""
        return preset_list(self)

    def apply_preset(self, number):
        """Keys 1..9: show the ``number``-th of :meth:`presets` (from 1)."""
        use_preset(self, number)

    def save_tf(self, path=None):
        """ctrl+s: write the edited transfer function as JSON (default ``--tf-out``); the
        path, or None when it cannot be written."""
        return write_tf(self, path)

    def load_tf(self, path=None):
        """ctrl+o (or a dropped file): show the transfer function in a JSON file (default
        ``--tf-out``); True when it loaded."""
        return read_tf(self, path)

    def render_image(self):
        """The current view at full quality as a float image (H, W, 4), premultiplied,
        row 0 on top, from the render target (no overlay)."""
        return full_image(self)

    def save_screenshot(self, path=None):
        """Write the current view at full quality, without overlays, as ``dvr-gl render``
        would (RGB over ``--background`` if given, else un-premultiplied RGBA); atomic."""
        return write_screenshot(self, path)

    def save_window_screenshot(self, path=None):
        """Write the window as shown (overlay included, over the display background)."""
        return write_window_screenshot(self, path)

    def recentre(self, x, y):
        """Move the target to the point under window point (x, y), keeping the view's
        direction and distance; on empty space, back to the volume's centre."""
        ww, wh = self.window_size
        origin, direction = self.orbit.ray(x, y, ww, wh)
        if self._pick_data is None:  # float32 samples of a grid, or a mesh's cells
            self._pick_data = pick_data(self.volume)
        p = pick_point(self.volume, self.tf, self.mode, self.iso, origin, direction, values=self._pick_data)
        if p is None:
            lo, hi = self.volume.bounds
            p = (lo + hi) / 2
        self.orbit.target = np.asarray(p, dtype=np.float64)
        self.changed()

    # -- frames ------------------------------------------------------------------------
    def quality(self):
        """"coarse" while input keeps arriving, "full" once it has settled. With a
        tolerance the first frame is coarse too: a picture at once, before the full frame
        waits for the error model's pilot."""
        if self.last_frame is None and self.tolerance is not None:
            return "coarse"
        return "coarse" if self.clock() - self._last_input < self.settle_s else "full"

    def needs_frame(self):
        last = self.last_frame
        if last is None or last.key[2:] != (self.version, self.overlay_version, self.background):
            return True
        if last.quality == "full" and self.quality() == "full" and self.accumulates() \
                and last.accumulated == self.accumulated < self.max_accumulate:
            # still: average twice as many particle sets (progressive refinement)
            self.accumulated = min(2 * self.accumulated, self.max_accumulate)
            return True
        return last.quality == "coarse" and self.quality() == "full"

    def frame(self, quality=None, force=False, grab=False):
        """Render (when something changed) and show one frame. Returns the window's
        pixels ((H, W, 3) uint8, row 0 on top, overlay included) when ``grab``."""
        return self.presenter.frame(quality or self.quality(), force, grab)

    def update_title(self):
        self.title = window_title(self)
        self.glfw.set_window_title(self.window, self.title)

    def refine(self, max_frames=100):
        """Render frames until nothing is pending (input settled, full quality shown)."""
        for _ in range(max_frames):
            self.glfw.poll_events()
            if not self.needs_frame():
                return
            self.frame()

    def run(self):
        """The interactive loop, until the window is closed or q/Esc is pressed."""
        glfw = self.glfw
        while not self.should_close:
            if self.needs_frame():
                self.frame()
                glfw.poll_events()
            elif self.last_frame is not None and self.last_frame.quality == "coarse":
                wait = self.settle_s - (self.clock() - self._last_input)
                glfw.wait_events_timeout(max(wait, 0.005))
            else:
                glfw.wait_events_timeout(0.5)

    def run_frames(self, count):
        """Render ``count`` full-quality frames (each one re-rendered; as scripts and CI
        use ``--frames``) and return their times in seconds."""
        times = []
        for _ in range(count):
            if self.should_close:
                break
            self.glfw.poll_events()
            self.frame(quality="full", force=True)
            times.append(self.last_frame.seconds)
        return times
