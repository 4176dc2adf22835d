"""The interactive viewer: ``dvr-gl view INPUT [render options]``.

About the viewer
----------------
A glfw window (OpenGL 3.3 core) whose moderngl context is handed to a
:class:`dvr_gl.Renderer`: every frame is rendered by the very same technique modules and
shader programs as headless rendering, into the renderer's float target at the window's
framebuffer size. That texture is then drawn to the window with one full-screen triangle,
composited over a background colour (``C + (1 - A) * B``), and the transfer-function
editor (:mod:`dvr_gl.frontends.viewer_overlay`) is drawn over it. Screenshots are read from the
float target, so they never contain the overlay and equal ``dvr-gl render``'s PNG of the
same camera.

Input handling is plain Python: :meth:`Viewer.on_mouse_button`, :meth:`Viewer.on_cursor`,
:meth:`Viewer.on_scroll`, :meth:`Viewer.on_key` and :meth:`Viewer.on_resize` take the
values glfw reports (window coordinates, glfw's key and button codes) and change the
viewer's state; the glfw callbacks only forward to them, and tests call them directly
with synthetic events.

Progressive quality: while the user drags or scrolls, frames are rendered at
``coarse_scale`` of the resolution and ``coarse_step`` times the step; once no input has
arrived for ``settle_s`` seconds, one full-quality frame follows.

Techniques are found through :func:`dvr_gl.techniques.names`; those whose ``make_plan``
refuses the current volume are left out of the cycle, and options (``step``,
``preintegrate``, ``interpolate``, ``sort``) are only passed to techniques that take them.

Tetrahedral meshes: :class:`Settings` may hold a :class:`dvr_gl.TetMesh` instead of a
Volume. Only techniques whose ``make_plan`` accepts a mesh scene are offered (today
``tetra``: projected tetrahedra); a Settings technique that renders the other kind of data
(``raycast``, the default) is replaced by the first one that renders this data, and the
viewer says so. Whatever assumes a grid has a mesh path: tetra takes no step (the ``-`` /
``=`` keys say so, coarse frames while dragging lower only the resolution), key ``c``
switches its cell order (``sort``: ``mpvo`` / ``centroid``), the editor's histogram counts
``mesh.scalars``, the title shows points and tets instead of the grid's shape, modes tetra
cannot render are skipped with the usual message, and a double click picks along the ray
through the cells themselves (:func:`pick_point_mesh`: the ray is intersected with every
tetrahedron, the piecewise-linear field is sampled inside the mesh only, and the same
rule as on grids picks the point; empty space falls back to the box centre).

glfw is imported inside functions only, so ``import dvr_gl.frontends.viewer`` works without it.
"""

from __future__ import annotations

import argparse
import contextlib
import inspect
import math
import os
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from .. import formats as dvr_io
from ..gl.context import current, idle_framebuffer
from ..model.scene import ILLUSTRATION_TERMS, MODES, OPTICAL_MODELS, Camera, Scene
from .viewer_overlay import OverlayDrawer, TFEditor

PROG = "dvr-gl view"

# glfw's codes (stable parts of its API), so the handlers need no glfw import.
PRESS, RELEASE, REPEAT = 1, 0, 2
MOUSE_LEFT, MOUSE_RIGHT, MOUSE_MIDDLE = 0, 1, 2
MOD_SHIFT, MOD_CONTROL, MOD_ALT, MOD_SUPER = 0x1, 0x2, 0x4, 0x8
KEY_ESCAPE, KEY_F1 = 256, 290
KEY_MINUS, KEY_EQUAL, KEY_COMMA, KEY_PERIOD = 45, 61, 44, 46
KEY_LEFT_BRACKET, KEY_RIGHT_BRACKET = 91, 93
KEY_KP_SUBTRACT, KEY_KP_ADD = 333, 334


# keys that act again while held down (the others act once per press)
_REPEATABLE = {KEY_MINUS, KEY_EQUAL, KEY_COMMA, KEY_PERIOD, KEY_LEFT_BRACKET, KEY_RIGHT_BRACKET,
               KEY_KP_SUBTRACT, KEY_KP_ADD}


def key_code(char):
    """glfw's code of a letter or digit key (its upper-case ASCII code)."""
    return ord(char.upper())


KEYS_HELP = """\
dvr-gl view: keys and mouse
  left drag            orbit (trackball: no flip over the poles)
  right drag, wheel    zoom
  middle / shift drag  pan
  ctrl + left drag     window/level of the transfer function (x: level, y: width)
  double click         recentre on the point under the cursor (on nothing: the volume centre)
  r                    reset the view
  t / T                next / previous technique (those that can render this data)
  m / M                next / previous mode (composite, mip, minip, average, isosurface)
  , / .                iso value down / up (isosurface mode; shift: 5x)
  l                    shading on / off (on at the start where the technique lights samples)
  x                    optical model: emission-absorption, absorption only, emission only, Sabella
  i                    illustration: none, boundary, silhouette, tone, depth cue, all four
  p                    pre-integration on / off (techniques that offer it)
  c                    cell order mpvo / centroid (tetra, for meshes)
  - / =                coarser / finer step (slice2d: fewer / more interpolated slices;
                       tetra: none, each cell is integrated exactly; raycast with
                       --tolerance: twice / half the tolerance)
  1..9                 transfer function: 1 the one given, then the presets
  [ / ]                opacity scale down / up
  e                    show / hide the transfer-function editor
  o                    orthographic / perspective
  b                    cycle the background colour
  s / S                save a screenshot: the render (no overlay) / the window as shown
  ctrl+s / ctrl+o      save / load the transfer function (JSON for dvr-gl render --tf)
  h, F1                print this list
  q, Esc               quit
transfer-function editor (bottom panel)
  left click / drag    add / move a control point (opacity curve above, colours below)
  right click          remove a control point
  wheel on a colour    turn its hue"""


class WindowError(RuntimeError):
    """No window could be opened (no display, no OpenGL 3.3)."""


# ----------------------------------------------------------------------------- the camera

def _rotation(axis, angle):
    """The 3x3 matrix turning by ``angle`` radians about unit ``axis`` (right-handed)."""
    x, y, z = axis
    c, s = math.cos(angle), math.sin(angle)
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return c * np.eye(3) + s * k + (1 - c) * np.outer(axis, axis)


class Orbit:
    """An orbiting camera: a target point, an orientation (the columns of ``rotation``
    are the camera's right, up and back axes in world space) and a distance.

    Rotations turn the orientation matrix about the camera's own axes, so there are no
    poles to flip over (no angles are stored). Orthographic views show a height of
    ``2 * distance * tan(fov / 2)`` at the target, the height a perspective view shows
    there, and put the eye ``2 * radius`` from the target (outside the volume's bounding
    sphere), as :func:`dvr_gl.default_camera` does.
    """

    def __init__(self, volume, azimuth=None, elevation=None, zoom=1.0, fov=30.0, ortho=False):
        self.volume = volume
        lo, hi = volume.bounds
        self.radius = float(np.linalg.norm(hi - lo)) / 2
        self.fov = float(fov)
        self.start = dict(azimuth=azimuth, elevation=elevation, zoom=zoom, fov=fov, ortho=ortho)
        self.reset()

    def reset(self):
        """Back to the command line's view (``inputs.first_camera`` of its angles)."""
        from .inputs import first_camera
        cam = first_camera(self.volume, **self.start)
        self.ortho = cam.is_ortho
        self.target = cam.target.copy()
        self.rotation = np.column_stack([cam.right, cam.true_up, -cam.forward])
        if self.ortho:
            self.distance = cam.ortho_height / (2 * math.tan(math.radians(self.fov) / 2))
        else:
            self.distance = cam.distance

    @property
    def right(self):
        return self.rotation[:, 0]

    @property
    def up(self):
        return self.rotation[:, 1]

    @property
    def back(self):
        return self.rotation[:, 2]

    @property
    def ortho_height(self):
        return 2 * self.distance * math.tan(math.radians(self.fov) / 2)

    def camera(self) -> Camera:
        if self.ortho:
            return Camera(self.target + 2 * self.radius * self.back, self.target, self.up,
                          ortho_height=self.ortho_height)
        return Camera(self.target + self.distance * self.back, self.target, self.up, fov=self.fov)

    def _orthonormalise(self):
        back = self.back / np.linalg.norm(self.back)
        right = np.cross(self.up, back)
        right /= np.linalg.norm(right)
        self.rotation = np.column_stack([right, np.cross(back, right), back])

    def orbit(self, yaw, pitch):
        """Turn the eye about the target: ``yaw`` radians about the camera's up axis
        (positive moves the eye to the right), then ``pitch`` about its right axis
        (positive moves it up)."""
        right, up = self.right.copy(), self.up.copy()
        turn = _rotation(right, -pitch) @ _rotation(up, yaw)
        self.rotation = turn @ self.rotation
        self._orthonormalise()

    def zoom(self, factor):
        """``factor`` > 1 moves closer (perspective) or magnifies (orthographic)."""
        self.distance = max(self.distance / factor, 1e-4 * self.radius)

    def pan(self, right, up):
        """Move the target (and the eye with it) by world distances along the camera's
        right and up axes."""
        self.target = self.target + right * self.right + up * self.up

    def world_per_pixel(self, window_height):
        """World size of one window pixel at the target's depth."""
        return self.ortho_height / max(window_height, 1)

    def ray(self, x, y, width, height):
        """Origin and unit direction of the ray through window point (x, y) of a
        ``width`` x ``height`` window (continuous coordinates, y down)."""
        cam = self.camera()
        sx, sy = cam.screen_scale(width, height)
        nx, ny = 2 * x / width - 1, 1 - 2 * y / height
        offset = nx * sx * cam.right + ny * sy * cam.true_up
        if cam.is_ortho:
            return cam.eye + offset, cam.forward.copy()
        d = cam.forward + offset
        return cam.eye.copy(), d / np.linalg.norm(d)


def pick_point(volume, tf, mode, iso_value, origin, direction, samples=512, values=None):
    """The point a user means by clicking this ray: the first crossing of the iso value
    (isosurface mode), the maximum (mip), else where the accumulated opacity reaches 0.5
    (or the strongest contribution if it never does). None when the ray shows nothing.
    Trilinear samples from scipy, on the CPU: one ray is cheap. A :class:`TetMesh` is
    picked by :func:`pick_point_mesh` (``values``: its :func:`mesh_pick_data`)."""
    if _is_mesh(volume):
        return pick_point_mesh(volume, tf, mode, iso_value, origin, direction, samples, cells=values)
    from scipy.ndimage import map_coordinates

    span = _ray_box(*volume.bounds, origin, direction)
    if span is None:
        return None
    t0, t1 = span
    dt = (t1 - t0) / samples
    t = t0 + (np.arange(samples) + 0.5) * dt
    p = origin + t[:, None] * direction
    index = ((p - volume.origin) / volume.spacing).T[::-1]          # (z, y, x) rows
    if values is None:
        values = volume.values(np.float32)
    s = map_coordinates(values, index, order=1, mode="nearest")
    return _pick_along(p, s, dt, tf, mode, iso_value)


def _is_mesh(volume):
    from ..model.scene import TetMesh

    return isinstance(volume, TetMesh)


def _ray_box(lo, hi, origin, direction):
    """(t_enter, t_exit) of the ray in the box [lo, hi] (t_enter >= 0), or None."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t_a = (lo - origin) / direction
        t_b = (hi - origin) / direction
    t_near = np.where(np.isnan(t_a), -np.inf, np.minimum(t_a, t_b))
    t_far = np.where(np.isnan(t_b), np.inf, np.maximum(t_a, t_b))
    t0, t1 = max(float(np.max(t_near)), 0.0), float(np.min(t_far))
    return (t0, t1) if t1 > t0 else None


def _pick_along(p, s, dt, tf, mode, iso_value):
    """The picking rule of :func:`pick_point` on samples ``s`` at points ``p`` (in ray
    order, ``dt`` world units apart)."""
    if mode == "isosurface":
        inside = s >= iso_value
        hit = np.nonzero(inside != inside[0])[0]
        return p[hit[0]] if hit.size else None
    if mode == "mip":
        k = int(np.argmax(s))
        return p[k] if tf.opacity(s[k]) > 0 else None
    alpha = 1.0 - (1.0 - np.clip(tf.opacity(s), 0.0, 1.0)) ** (dt / tf.unit_distance)
    transmittance = np.concatenate([[1.0], np.cumprod(1.0 - alpha)[:-1]])
    reached = np.nonzero(1.0 - transmittance * (1.0 - alpha) >= 0.5)[0]
    if reached.size:
        return p[reached[0]]
    weight = alpha * transmittance
    k = int(np.argmax(weight))
    return p[k] if weight[k] > 1e-3 else None


def mesh_pick_data(mesh):
    """What picking on ``mesh`` needs, made once per mesh: for every cell of non-zero
    volume its first vertex, the inverse of its edge matrix (world point to barycentric
    coordinates) and its four vertex values."""
    tets = mesh.tets
    vol = np.abs(mesh.signed_volumes())
    ok = np.flatnonzero(vol > 1e-12 * max(float(np.max(vol, initial=0.0)), 1e-300))
    p = mesh.points[tets[ok]]                                     # (m, 4, 3)
    edges = np.transpose(p[:, 1:] - p[:, :1], (0, 2, 1))         # columns p1-p0, p2-p0, p3-p0
    return {"p0": p[:, 0], "inverse": np.linalg.inv(edges), "values": mesh.scalars[tets[ok]]}


def ray_cells(mesh, origin, direction, cells=None):
    """The cells the ray crosses, as ``(t_in, t_out, value_in, slope)`` arrays sorted by
    ``t_in`` (the ray is ``origin + t * direction``, ``t >= 0``; the field in a cell is
    ``value_in + slope * (t - t_in)``): each cell's barycentric coordinates are linear in
    t, and the ray is inside while all four are non-negative."""
    cells = cells if cells is not None else mesh_pick_data(mesh)
    inv = cells["inverse"]
    a = np.einsum("mij,mj->mi", inv, origin - cells["p0"])        # lambda_1..3 at t = 0
    b = np.einsum("mij,j->mi", inv, direction)                    # and their rates
    a = np.concatenate([1.0 - a.sum(axis=1, keepdims=True), a], axis=1)
    b = np.concatenate([-b.sum(axis=1, keepdims=True), b], axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        root = -a / b
    lower = np.where(b > 0, root, np.where((b == 0) & (a < 0), np.inf, -np.inf)).max(axis=1)
    upper = np.where(b < 0, root, np.inf).min(axis=1)
    t_in, t_out = np.maximum(lower, 0.0), upper
    hit = np.flatnonzero(t_out > t_in)
    order = hit[np.argsort(t_in[hit], kind="stable")]
    values = cells["values"][order]
    rate = (b[order] * values).sum(axis=1)
    start = (a[order] * values).sum(axis=1) + rate * t_in[order]
    return t_in[order], t_out[order], start, rate


def pick_point_mesh(mesh, tf, mode, iso_value, origin, direction, samples=512, cells=None):
    """:func:`pick_point` on a TetMesh: the ray is intersected with every cell
    (:func:`ray_cells`; non-convex meshes and gaps included), the linear field is sampled
    at ``samples`` points between where it first enters and last leaves the mesh, the
    samples outside every cell are dropped (they are empty space), and the grid's rule
    picks among the rest. None when the ray misses the mesh or shows nothing."""
    origin, direction = np.asarray(origin, np.float64), np.asarray(direction, np.float64)
    if _ray_box(*mesh.bounds, origin, direction) is None:
        return None
    t_in, t_out, start, rate = ray_cells(mesh, origin, direction, cells)
    if t_in.size == 0:
        return None
    t0, t1 = float(t_in[0]), float(t_out.max())
    dt = (t1 - t0) / samples
    t = t0 + (np.arange(samples) + 0.5) * dt
    k = np.searchsorted(t_in, t, side="right") - 1
    inside = (k >= 0) & (t <= t_out[np.maximum(k, 0)] + 1e-9 * (t1 - t0))
    if not inside.any():
        return None
    t, k = t[inside], k[inside]
    s = start[k] + rate[k] * (t - t_in[k])
    return _pick_along(origin + t[:, None] * direction, s, dt, tf, mode, iso_value)


# ----------------------------------------------------------------------------- techniques

@dataclass
class TechniqueInfo:
    """What the viewer knows about a technique, found by asking its module."""
    name: str
    applies: bool
    accepts_step: bool
    params: frozenset | None      # make_plan's keyword options; None: it takes any
    default_step: float | None
    reason: str = ""

    def accepts(self, option):
        return self.params is None or option in self.params


def _renders_data_of(name, volume):
    """Whether technique ``name`` is for this kind of data (its module's ``DATA``:
    "volume" for grids, "mesh" for TetMesh, or both), whatever else it may refuse."""
    from ..techniques import get_technique

    try:
        data = getattr(get_technique(name), "DATA", "volume")
    except Exception:
        return False
    kinds = (data,) if isinstance(data, str) else tuple(data)
    return ("mesh" if _is_mesh(volume) else "volume") in kinds


def _plan_params(make_plan):
    try:
        sig = inspect.signature(make_plan)
    except (TypeError, ValueError):
        return None
    if any(p.kind is p.VAR_KEYWORD for p in sig.parameters.values()):
        return None
    return frozenset(n for n in list(sig.parameters)[2:] if n != "tables")


def fallback_step(volume):
    """The step offered to a technique that takes one but names no default: half the
    smallest spacing of a grid, half the typical cell size of a mesh (whose technique,
    tetra, takes no step: only a technique module without ``TAKES_STEP`` is tried with
    it)."""
    spacing = getattr(volume, "min_spacing", None)
    if spacing is None:
        spacing = getattr(volume, "cell_size", 1.0)
    return 0.5 * float(spacing)


def describe_data(volume):
    """A few words on the data for the title and the console: the grid's shape (x, y, z),
    or a mesh's point and cell counts."""
    if _is_mesh(volume):
        return f"{volume.n_points} points, {volume.n_tets} tets"
    nz, ny, nx = volume.shape
    return f"{nx}x{ny}x{nz}"


def probe_technique(name, scene, tables):
    """Ask technique ``name`` whether it can render ``scene``'s data and whether it
    takes a ``step``: the module attribute ``TAKES_STEP`` of the technique interface
    settles the latter; a module without it has ``make_plan`` tried with a step and, if
    it refuses, without one."""
    from ..techniques import get_technique

    try:
        tech = get_technique(name)
    except Exception as e:  # a module that fails to import is simply not offered
        return TechniqueInfo(name, False, False, frozenset(), None, f"{type(e).__name__}: {e}")
    params = _plan_params(tech.make_plan)
    default = None
    if callable(getattr(tech, "default_step", None)):
        try:
            default = float(tech.default_step(scene.volume))
        except Exception:
            default = None
    step_guess = default if default is not None else fallback_step(scene.volume)
    flag = getattr(tech, "TAKES_STEP", None)
    tries = [(True, step_guess), (False, None)] if flag is None else [(bool(flag), step_guess if flag else None)]
    reason = ""
    for accepts, step in tries:
        try:
            tech.make_plan(scene, step, tables=tables)
        except (TypeError, ValueError, NotImplementedError) as e:
            reason = str(e)
            continue
        return TechniqueInfo(name, True, accepts, params, default if accepts else None)
    return TechniqueInfo(name, False, False, params, default, reason)


# ----------------------------------------------------------------------------- the viewer

@dataclass
class Settings:
    """What the command line decided. ``volume``: a :class:`dvr_gl.Volume` or a
    :class:`dvr_gl.TetMesh` (shown with a technique that renders meshes: tetra)."""
    volume: object
    tf: object
    tf_name: str = "auto"
    input_name: str = ""
    technique: str = "raycast"
    mode: str = "composite"
    iso: float | None = None
    step: float | None = None
    size: tuple = (512, 512)
    azimuth: float | None = None         # None: the first view's (inputs.first_camera)
    elevation: float | None = None
    zoom: float = 1.0
    fov: float = 30.0
    ortho: bool = False
    background: tuple | None = None     # screenshots: RGB over this, else RGBA (as render)
    screenshot: str | None = None
    tf_out: str = "dvr-gl-tf.json"
    editor: bool = True
    vsync: bool = True
    visible: bool = True
    options: dict = field(default_factory=dict)   # technique options (preintegrate, interpolate, ...)
    shading: bool | None = None          # lit composite (key l switches it); None: lit where defined
    optical_model: str = "emission_absorption"   # composite's optical model (key x cycles it)
    illustration: tuple = ()             # Ebert-Rheingans terms by name (key i cycles them)
    lights: tuple | None = None          # dvr_gl.Light objects; None: the headlight
    tolerance: float | None = None       # raycast: full frames at the step for this RMSE


@dataclass
class FrameInfo:
    quality: str                 # "full" or "coarse"
    target_size: tuple           # (width, height) rendered
    framebuffer_size: tuple      # (width, height) of the window's framebuffer
    step: float | None
    seconds: float               # render + present, GL finished
    key: tuple = field(default=(), repr=False)
    render_key: tuple = field(default=(), repr=False)
    accumulated: int = 1         # particle sets averaged (particles only)


class Viewer:
    """A window showing one volume, with its camera, technique and transfer-function
    state. Open with :func:`open_viewer` (or construct from :class:`Settings`), drive
    with :meth:`run` or :meth:`frame` and the ``on_*`` handlers, end with :meth:`close`."""

    settle_s = 0.2        # no input for this long: render at full quality
    max_accumulate = 64   # particles: sets averaged at most while the view stays still
    coarse_scale = 0.5    # resolution while interacting
    coarse_step = 2.0     # step multiplier while interacting
    double_click_s = 0.35

    def __init__(self, settings: Settings):
        from ..techniques import names

        self.settings = settings
        self.volume = settings.volume
        self.clock = time.perf_counter
        self.quit = False
        self.status = ""
        self._status_until = 0.0
        self.messages = []                 # everything said, for tests and scripts
        self.orbit = Orbit(self.volume, settings.azimuth, settings.elevation, settings.zoom,
                           settings.fov, settings.ortho)
        self.editor = TFEditor(settings.tf, self.volume, visible=settings.editor)
        self.initial_tf = settings.tf
        self.mode = settings.mode
        self.iso = settings.iso if settings.iso is not None else self._default_iso()
        self.shading = True if settings.shading is None else settings.shading   # the wish; see lit
        self.optical_model = settings.optical_model
        self.illustration = tuple(settings.illustration)
        self.lights = settings.lights
        self.step = settings.step          # None: the technique's default
        self.tolerance = settings.tolerance  # raycast: an RMSE the full frames are rendered to
        self.options = dict(settings.options)  # technique options: command line, then keys
        self.technique = settings.technique
        self.backgrounds = []
        for bg in (settings.background, (0.0, 0.0, 0.0), (0.5, 0.5, 0.5), (1.0, 1.0, 1.0)):
            if bg is not None and tuple(bg) not in self.backgrounds:
                self.backgrounds.append(tuple(float(v) for v in bg))
        self.background = self.backgrounds[0]
        self._values = None                # float32 samples for picking, made on first use
        self._version = 0                  # bumped by every change of the picture
        self.accumulated = 1               # particle sets averaged in the picture shown
        self._overlay_version = 0
        self._uploaded_overlay = None
        self._last_input = -math.inf
        self._drag = None
        self._last_click = None
        self._cursor = (0.0, 0.0)
        self._fbo = None
        self._good_state = None            # the last choices that rendered
        self.last_frame = None
        self.frame_times = []
        self.window = None
        self._open_window(settings)
        self.techniques = {}
        try:
            # which techniques can render this data at all (in the plain composite mode)
            probe = Scene(self.volume, self.tf, self.orbit.camera(), width=8, height=8)
            for name in names():
                self.techniques[name] = probe_technique(name, probe, self.renderer.tables)
            info = self.techniques.get(self.technique)
            if info is not None and not info.applies and not _renders_data_of(self.technique, self.volume):
                # e.g. the default raycast on a mesh: the first technique for this kind of data
                fallback = next(iter(self.available_techniques), None)
                if fallback is not None:
                    self.say(f"technique {fallback} ({self.technique} cannot render this data: {info.reason})")
                    self.technique = fallback
                    info = self.techniques[fallback]
            if info is None or not info.applies:
                why = info.reason if info is not None else "unknown technique"
                raise ValueError(f"--technique: {self.technique} cannot render this data: {why}")
            self._validate()  # and the mode and options asked for
        except BaseException:
            self.close()
            raise

    # -- window and GL ---------------------------------------------------------------
    def _open_window(self, settings):
        glfw = _import_glfw()
        import moderngl

        from ..rendering.renderer import Renderer

        width, height = settings.size
        old = glfw.ERROR_REPORTING
        glfw.ERROR_REPORTING = "raise"
        if (sys.platform.startswith("linux") and os.environ.get("DISPLAY") and hasattr(glfw, "PLATFORM_X11")
                and hasattr(glfw, "init_hint")):
            # moderngl's Linux windows are GLX: ask for an X11 window (XWayland under Wayland)
            try:
                glfw.init_hint(glfw.PLATFORM, glfw.PLATFORM_X11)
            except glfw.GLFWError:  # a glfw older than 3.4 has only X11 anyway
                pass
        try:
            try:
                ok = glfw.init()
            except glfw.GLFWError as e:
                raise WindowError(_no_display_message(str(e))) from None
            if not ok:
                raise WindowError(_no_display_message("glfw could not be initialised"))
            glfw.default_window_hints()
            glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, 3)
            glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, 3)
            glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
            glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, True)
            glfw.window_hint(glfw.VISIBLE, bool(settings.visible))
            _release_current_egl()  # glfw makes its new context current to test it
            try:
                window = glfw.create_window(width, height, PROG, None, None)
            except glfw.GLFWError as e:
                raise WindowError(f"cannot open an OpenGL 3.3 core window: {e}") from None
            if not window:
                raise WindowError("cannot open an OpenGL 3.3 core window")
        finally:
            glfw.ERROR_REPORTING = old
        self._glfw = glfw
        self.window = window
        glfw.make_context_current(window)
        glfw.swap_interval(1 if settings.vsync else 0)
        self.ctx = _window_context(moderngl)
        self.renderer = Renderer(ctx=self.ctx)
        with self._gl():
            self._present = self.renderer.programs.get("viewer/present.vert", "viewer/present.frag")
            self._present_vao = self.ctx.vertex_array(self._present, [])
            self.overlay = OverlayDrawer(self.renderer)
        self.window_size = glfw.get_window_size(window)
        self.framebuffer_size = glfw.get_framebuffer_size(window)
        self.editor.layout(*self.window_size)
        glfw.set_cursor_pos_callback(window, lambda w, x, y: self.on_cursor(x, y))
        glfw.set_mouse_button_callback(window, lambda w, b, a, m: self.on_mouse_button(b, a, m))
        glfw.set_scroll_callback(window, lambda w, dx, dy: self.on_scroll(dx, dy))
        glfw.set_key_callback(window, lambda w, k, sc, a, m: self.on_key(k, a, m))
        glfw.set_framebuffer_size_callback(window, lambda w, fw, fh: self.on_resize(fw, fh))
        glfw.set_window_size_callback(window, lambda w, ww, wh: self.on_window_size(ww, wh))
        glfw.set_drop_callback(window, lambda w, paths: self.on_drop(paths))
        glfw.set_window_refresh_callback(window, lambda w: self._touch_overlay())

    @contextlib.contextmanager
    def _gl(self):
        """Make the window's context current for a block of GL work, and current to
        nothing afterwards. libglvnd refuses to make a GLX context current on a thread
        where an EGL context is current (an X error that ends the process), and the other
        way round (silently: a headless Renderer's calls would go into the window's
        context). So the viewer drops any current EGL context before its GL work and
        holds its own context only inside these blocks."""
        _release_current_egl()
        self._glfw.make_context_current(self.window)
        try:
            with current(self.ctx):
                yield self.ctx
        finally:
            self._glfw.make_context_current(None)

    def close(self):
        """Free the GL resources and the window (idempotent)."""
        if self.window is None:
            return
        with self._gl():
            self.overlay.release()
            self._present_vao.release()
            self.renderer.release()
        self._glfw.destroy_window(self.window)
        self.window = None
        self._fbo = None
        # dvr_gl.gl.context keys per-context state by id(ctx); keep this context object
        # alive so that a later context cannot reuse its id.
        _CLOSED_CONTEXTS.append(self.ctx)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    @property
    def should_close(self):
        return self.quit or self.window is None or bool(self._glfw.window_should_close(self.window))

    def set_window_size(self, width, height):
        """Resize the window (as a user would) and process the events that follow."""
        self._glfw.set_window_size(self.window, int(width), int(height))
        for _ in range(50):
            self._glfw.poll_events()
            if tuple(self._glfw.get_window_size(self.window)) == (width, height):
                break
            time.sleep(0.005)
        self._glfw.poll_events()

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

    def _scene(self, width, height, tf=None):
        return Scene(self.volume, tf or self.tf, self.orbit.camera(), width=width, height=height,
                     mode=self.mode, iso_value=self.iso if self.mode == "isosurface" else None,
                     shading=self.lit, **({"lights": self.lights} if self.lights else {}),
                     optical_model=self.optical_model, illustration=self.illustration)

    @property
    def lit(self):
        """Whether the scene is lit: the user's wish (key l), where lighting is defined."""
        from .inputs import shading_for
        return shading_for(self.technique, self.mode, self.optical_model, self.shading)

    def _options(self, name=None):
        info = self.techniques[name or self.technique]
        return {k: v for k, v in self.options.items() if info.accepts(k)}

    def render_arguments(self, width=None, height=None, coarse=False):
        """``(scene, technique, step, options)`` for ``Renderer.render`` /
        ``render_target``: what the next frame renders (at the framebuffer size unless
        given). Tests render the same arguments headless to compare."""
        fw, fh = self.framebuffer_size
        width, height = width or fw, height or fh
        step = self.effective_step()
        if step is not None and coarse:
            step *= self.coarse_step
        options = self._options()
        if self._accumulates():
            options["repetitions"] = 1 if coarse else self.accumulated
        scene = self._scene(width, height)
        if self.tolerance is not None and self.technique == "raycast" and not coarse:
            # progressive: coarse frames while the view moves, then the step (and
            # way of sampling) the error model picks for the tolerance, once it is still
            step, sampling = self.renderer.tolerance_settings(scene, self.tolerance, "raycast", **options)
            options.update(sampling)
        return scene, self.technique, step, options

    def _accumulates(self):
        """Whether the technique averages independent sets (particles) and the user left
        their number to the viewer: it then grows while the view stays still."""
        return self.info.accepts("repetitions") and self.info.params is not None and "repetitions" not in self.options

    def _validate(self):
        """Raise if the current state cannot be rendered (make_plan on a tiny scene)."""
        from ..techniques import get_technique

        scene, name, step, options = self.render_arguments(8, 8)
        get_technique(name).make_plan(scene, step, tables=self.renderer.tables, **options)

    def _state(self):
        """The rendering choices (not the camera or the transfer function)."""
        return (self.technique, self.mode, self.iso, self.shading, self.optical_model, self.illustration,
                dict(self.options), self.step)

    def _restore(self, state, changed=True):
        (self.technique, self.mode, self.iso, self.shading, self.optical_model, self.illustration, options,
         self.step) = state
        self.options = dict(options)
        if changed:
            self._changed()

    def _try(self, change, what, quiet=False):
        """Apply ``change()``; if the result cannot be rendered, undo it and say why (or
        return the reason when ``quiet``). True when the change was kept."""
        saved = self._state()
        try:
            change()
            self._validate()
        except (TypeError, ValueError, NotImplementedError) as e:
            self._restore(saved, changed=False)
            if quiet:
                return str(e)
            self.say(f"cannot {what}: {e}")
            return False
        self._changed()
        return True

    def _changed(self, interactive=False):
        self._version += 1
        self.accumulated = 1
        if interactive:
            self._last_input = self.clock()

    def _touch_overlay(self):
        self._overlay_version += 1

    def say(self, message):
        """A message on stdout and, for a few seconds, in the window title."""
        self.messages.append(message)
        print(f"{PROG}: {message}", flush=True)
        self.status = message
        self._status_until = self.clock() + 4.0

    # -- input handlers (pure Python: tests call them with synthetic events) ------------
    def on_cursor(self, x, y):
        x, y = float(x), float(y)
        px, py = self._cursor
        self._cursor = (x, y)
        drag = self._drag
        if drag is None:
            before = self.editor.hover
            self.editor.move(x, y)
            if self.editor.hover != before:
                self._touch_overlay()
            return
        dx, dy = x - px, y - py
        ww, wh = self.window_size
        kind = drag["kind"]
        if kind == "editor":
            if self.editor.move(x, y):
                self._tf_edited()
            self._touch_overlay()
            return
        if kind == "orbit":
            rate = math.pi / max(wh, 1)      # half a turn per window height
            self.orbit.orbit(-dx * rate, dy * rate)
        elif kind == "pan":
            wpp = self.orbit.world_per_pixel(wh)
            self.orbit.pan(-dx * wpp, dy * wpp)
        elif kind == "zoom":
            self.orbit.zoom(math.exp(-2.0 * dy / max(wh, 1)))
        elif kind == "window_level":
            x0, y0 = drag["start"]
            shift = (x - x0) / max(ww, 1) * (self.editor.hi - self.editor.lo)
            scale = math.exp(2.0 * (y - y0) / max(wh, 1))
            self.editor.window_level(drag["base"], shift, scale)
            self._touch_overlay()
        if dx or dy:
            self._changed(interactive=True)

    def on_mouse_button(self, button, action, mods=0, x=None, y=None):
        if x is not None and y is not None:
            self._cursor = (float(x), float(y))
        x, y = self._cursor
        if action == RELEASE:
            drag = self._drag
            if drag is not None:
                if drag["kind"] == "editor":
                    self.editor.release(button, x, y)
                    self._touch_overlay()
                if drag["button"] == button:
                    self._drag = None
                    # a press and release without moving is a click; two make a double click
                    sx, sy = drag["start"]
                    if button == MOUSE_LEFT and drag["kind"] == "orbit" and math.hypot(x - sx, y - sy) <= 3:
                        self._last_click = (self.clock(), x, y)
            return
        if action != PRESS:
            return
        if self.editor.contains(x, y):
            if self.editor.press(button, x, y):
                self._tf_edited()
            if self.editor.drag is not None:
                self._drag = {"kind": "editor", "button": button, "start": (x, y)}
            self._touch_overlay()
            return
        if button == MOUSE_LEFT:
            last, self._last_click = self._last_click, None
            if (last is not None and not mods and self.clock() - last[0] <= self.double_click_s
                    and math.hypot(x - last[1], y - last[2]) <= 5):
                self.recentre(x, y)
                return
            if mods & MOD_CONTROL:
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
        self._drag = {"kind": kind, "button": button, "start": (x, y), "base": self.tf}

    def on_scroll(self, dx, dy):
        x, y = self._cursor
        if self.editor.contains(x, y):
            if self.editor.scroll(x, y, dy):
                self._tf_edited()
                self._touch_overlay()
            return
        if dy:
            self.orbit.zoom(1.1 ** dy)
            self._changed(interactive=True)

    def on_resize(self, width, height):
        """The framebuffer's new size (pixels; on high-DPI screens not the window's)."""
        self.framebuffer_size = (int(width), int(height))
        self._changed()

    def on_window_size(self, width, height):
        """The window's new size in window coordinates (the cursor's units)."""
        self.window_size = (int(width), int(height))
        self.editor.layout(width, height)
        self._touch_overlay()

    def on_drop(self, paths):
        for path in paths:
            if str(path).lower().endswith(".json"):
                self.load_tf(path)
            else:
                self.say(f"drop a transfer-function .json file here, not {os.path.basename(str(path))!r}")

    def on_key(self, key, action, mods=0):
        if action == REPEAT and key not in _REPEATABLE:
            return
        if action not in (PRESS, REPEAT):
            return
        shift, ctrl = bool(mods & MOD_SHIFT), bool(mods & MOD_CONTROL)
        char = chr(key).lower() if 32 <= key < 127 else None
        if ctrl:
            if char == "s":
                self.save_tf()
            elif char == "o":
                self.load_tf()
            return
        if key in (KEY_ESCAPE,) or char == "q":
            self.quit = True
            if self.window is not None:
                self._glfw.set_window_should_close(self.window, True)
        elif char == "h" or key == KEY_F1:
            print(KEYS_HELP, flush=True)
        elif char == "r":
            self.orbit.reset()
            self._changed()
        elif char == "t":
            self.cycle_technique(-1 if shift else 1)
        elif char == "m":
            self.cycle_mode(-1 if shift else 1)
        elif key in (KEY_COMMA, KEY_PERIOD):
            self.nudge_iso((1 if key == KEY_PERIOD else -1) * (5 if shift else 1))
        elif char == "l":
            from .inputs import shading_for
            if not shading_for(self.technique, self.mode, self.optical_model):
                self.say(f"cannot switch shading: {self.technique} in mode {self.mode} with optical model "
                         f"{self.optical_model} does not light samples")
            elif self._try(lambda: setattr(self, "shading", not self.shading), "switch shading"):
                self.say("shading " + ("on" if self.lit else "off"))
        elif char == "i":
            choices = [()] + [(name,) for name in ILLUSTRATION_TERMS] + [tuple(ILLUSTRATION_TERMS)]
            current = choices.index(self.illustration) if self.illustration in choices else 0
            terms = choices[(current + 1) % len(choices)]
            if self._try(lambda: setattr(self, "illustration", terms), "use illustration terms"):
                self.say("illustration " + (", ".join(terms) if terms else "off"))
        elif char == "x":
            models = OPTICAL_MODELS
            model = models[(models.index(self.optical_model) + 1) % len(models)]
            if self._try(lambda: setattr(self, "optical_model", model), f"use optical model {model}"):
                self.say(f"optical model {model}")
        elif char == "p":
            self.toggle_option("preintegrate")
        elif char == "c":
            self.cycle_sort()
        elif key in (KEY_MINUS, KEY_KP_SUBTRACT):
            self.change_step(coarser=True)
        elif key in (KEY_EQUAL, KEY_KP_ADD):
            self.change_step(coarser=False)
        elif char is not None and char.isdigit() and char != "0":
            self.apply_preset(int(char))
        elif key in (KEY_LEFT_BRACKET, KEY_RIGHT_BRACKET):
            self.editor.scale_opacity(1.25 if key == KEY_RIGHT_BRACKET else 0.8)
            self._tf_edited(interactive=False)
        elif char == "e":
            self.editor.visible = not self.editor.visible
            self.editor.drag = None
            self._touch_overlay()
        elif char == "o":
            self.orbit.ortho = not self.orbit.ortho
            self._changed()
        elif char == "b":
            i = self.backgrounds.index(self.background)
            self.background = self.backgrounds[(i + 1) % len(self.backgrounds)]
            self._touch_overlay()
        elif char == "s":
            if shift:
                self.save_window_screenshot()
            else:
                self.save_screenshot()

    # -- actions -----------------------------------------------------------------------
    def _tf_edited(self, interactive=True):
        self._touch_overlay()
        self._changed(interactive=interactive)

    def cycle_technique(self, direction=1):
        """Switch to the next technique (in the registry's order) that can render the
        current data in the current mode."""
        names = self.available_techniques
        start = names.index(self.technique)
        skipped = []
        for k in range(1, len(names)):
            name = names[(start + direction * k) % len(names)]
            result = self._try(lambda: setattr(self, "technique", name), f"use {name}", quiet=True)
            if result is True:
                self.say(f"technique {name}" + (f" (skipped {', '.join(skipped)})" if skipped else ""))
                return True
            skipped.append(f"{name}: {result}")
        self.say(f"no other technique can render this: {'; '.join(skipped)}" if skipped
                 else f"{self.technique} is the only technique that can render this data")
        return False

    def cycle_mode(self, direction=1):
        """Switch to the next mode the current technique can render."""
        i = MODES.index(self.mode)
        skipped = []
        for k in range(1, len(MODES)):
            mode = MODES[(i + direction * k) % len(MODES)]
            result = self._try(lambda: setattr(self, "mode", mode), f"use mode {mode}", quiet=True)
            if result is True:
                self._touch_overlay()
                why = "lit" if self.lit else ""
                self.say(f"mode {mode}" + (f" {self.iso:g}" if mode == "isosurface" else "")
                         + (f" ({self.technique} cannot render {', '.join(skipped)}{' ' + why if why else ''})"
                            if skipped else ""))
                return True
            skipped.append(mode)
        self.say(f"{self.technique} renders only mode {self.mode}")
        return False

    def nudge_iso(self, steps):
        if self.mode != "isosurface":
            self.say("the iso value applies in isosurface mode (press m)")
            return
        lo, hi = self.volume.data_range
        self.iso = float(self.iso + steps * 0.01 * (hi - lo))
        self._touch_overlay()
        self._changed()

    def toggle_option(self, option):
        if not self.info.accepts(option):
            self.say(f"{self.technique} has no {option} option")
            return
        on = not self.options.get(option, False)

        def change():
            if on:
                self.options[option] = True
            else:
                self.options.pop(option, None)
                if option == "preintegrate":      # refinement cuts pre-integrated segments only
                    self.options.pop("refine", None)
        if self._try(change, f"switch {option} {'on' if on else 'off'}"):
            self.say(f"{option} {'on' if on else 'off'}")

    def cycle_sort(self):
        """Key c: the next cell order of a technique with a ``sort`` option (tetra:
        "mpvo", exact per pixel, and "centroid", cheaper)."""
        if not self.info.accepts("sort") or self.info.params is None:
            self.say(f"{self.technique} has no sort option (tetra's cell order, for meshes)")
            return False
        from ..techniques import get_technique

        sorts = tuple(getattr(get_technique(self.technique), "SORTS", ("mpvo", "centroid")))
        now = self.options.get("sort", sorts[0])
        new = sorts[(sorts.index(now) + 1) % len(sorts)] if now in sorts else sorts[0]
        if self._try(lambda: self.options.__setitem__("sort", new), f"use sort {new}"):
            self.say(f"sort {new}")
            return True
        return False

    def change_step(self, coarser):
        factor = math.sqrt(2.0)
        if self.tolerance is not None and self.technique == "raycast":
            self.tolerance *= 2.0 if coarser else 0.5
            self._changed()
            self.say(f"tolerance {self.tolerance:.3g}")
            return
        if self.info.accepts_step:
            step = self.effective_step()
            new = step * factor if coarser else step / factor
            if self._try(lambda: setattr(self, "step", new), f"use step {new:.4g}"):
                self.say(f"step {new:.4g}")
        elif self.info.accepts("interpolate") and self.info.params is not None:
            k = int(self.options.get("interpolate", 0)) + (-1 if coarser else 1)
            k = min(max(k, 0), 15)
            self._try(lambda: self.options.__setitem__("interpolate", k), f"use interpolate={k}")
        elif _is_mesh(self.volume):
            self.say(f"{self.technique} has a fixed sample distance: it takes no step "
                     "(each cell is integrated exactly)")
        else:
            self.say(f"{self.technique} has a fixed sample distance")

    def presets(self):
        """The transfer functions keys 1..9 choose: the one given, then the presets that
        suit the data (``inputs.suitable_presets``)."""
        from .inputs import PRESETS, suitable_presets

        items = [(self.settings.tf_name, lambda volume: self.initial_tf)]
        items += [(name, PRESETS[name]) for name in suitable_presets(self.volume)]
        return items[:9]

    def apply_preset(self, number):
        items = self.presets()
        if not 1 <= number <= len(items):
            self.say(f"no transfer function {number}; 1..{len(items)}: {', '.join(n for n, _ in items)}")
            return
        name, make = items[number - 1]
        try:
            tf = make(self.volume)
        except (TypeError, ValueError, AttributeError, NotImplementedError) as e:
            # a preset made for grids (auto, before it learns meshes) on a mesh
            self.say(f"cannot use transfer function {number} ({name}) here: {e}")
            return
        self.editor.set_tf(tf)
        self._tf_edited(interactive=False)
        self.say(f"transfer function {number}: {name}")

    def save_tf(self, path=None):
        from ..model.transfer import save_tf_json

        path = path or self.settings.tf_out
        try:
            save_tf_json(path, self.tf)
        except OSError as e:
            self.say(f"cannot save the transfer function to {path!r}: {e}")
            return None
        self.say(f"saved the transfer function to {path} (dvr-gl render --tf {path})")
        return path

    def load_tf(self, path=None):
        from ..model.transfer import load_tf_json

        path = path or self.settings.tf_out
        try:
            tf = load_tf_json(path)
        except (OSError, ValueError, TypeError) as e:
            self.say(f"cannot load a transfer function from {path!r}: {e}")
            return False
        self.editor.set_tf(tf)
        self._tf_edited(interactive=False)
        self.say(f"loaded the transfer function {path}")
        return True

    def recentre(self, x, y):
        """Move the target to the point under window point (x, y), keeping the view's
        direction and distance; on empty space, back to the volume's centre."""
        ww, wh = self.window_size
        origin, direction = self.orbit.ray(x, y, ww, wh)
        if self._values is None:  # float32 samples of a grid, or a mesh's cells
            self._values = (mesh_pick_data(self.volume) if _is_mesh(self.volume)
                            else self.volume.values(np.float32))
        p = pick_point(self.volume, self.tf, self.mode, self.iso, origin, direction, values=self._values)
        if p is None:
            lo, hi = self.volume.bounds
            p = (lo + hi) / 2
        self.orbit.target = np.asarray(p, dtype=np.float64)
        self._changed()

    # -- frames ------------------------------------------------------------------------
    def quality(self):
        """"coarse" while input keeps arriving, "full" once it has settled."""
        return "coarse" if self.clock() - self._last_input < self.settle_s else "full"

    def needs_frame(self):
        last = self.last_frame
        if last is None or last.key[2:] != (self._version, self._overlay_version, self.background):
            return True
        if last.quality == "full" and self.quality() == "full" and self._accumulates() \
                and last.accumulated == self.accumulated < self.max_accumulate:
            # still: average twice as many particle sets (progressive refinement)
            self.accumulated = min(2 * self.accumulated, self.max_accumulate)
            return True
        return last.quality == "coarse" and self.quality() == "full"

    def frame(self, quality=None, force=False, grab=False):
        """Render (when something changed) and show one frame. Returns the window's
        pixels ((H, W, 3) uint8, row 0 on top, overlay included) when ``grab``."""
        quality = quality or self.quality()
        fw, fh = self.framebuffer_size
        if fw < 1 or fh < 1:  # minimised
            return None
        scale = self.coarse_scale if quality == "coarse" else 1.0
        tw, th = max(1, round(fw * scale)), max(1, round(fh * scale))
        key = (quality, (tw, th, fw, fh), self._version, self.accumulated)
        render = force or self._fbo is None or self.last_frame is None or self.last_frame.render_key != key
        t0 = time.perf_counter()
        ctx = self.ctx
        with self._gl():
            if render:
                scene, name, step, options = self.render_arguments(tw, th, coarse=quality == "coarse")
                try:
                    self._fbo = self.renderer.render_target(scene, name, step, **options)
                except Exception as e:  # a shader that fails to build, a plan the GPU refuses
                    if self._good_state is None:
                        raise
                    self._restore(self._good_state)
                    self.say(f"rendering {name} failed, back to the last state that worked: {_first_error(e)}")
                    scene, name, step, options = self.render_arguments(tw, th, coarse=quality == "coarse")
                    self._fbo = self.renderer.render_target(scene, name, step, **options)
                self._good_state = self._state()
                self._rendered = (tw, th, quality, step)
            pixels = None
            if grab:  # the same drawing into an 8-bit framebuffer of our own, read back
                texture = ctx.texture((fw, fh), 4, dtype="f1")
                fbo = ctx.framebuffer([texture])
                fbo.use()
                self._compose(fw, fh)
                raw = fbo.read(viewport=(0, 0, fw, fh), components=3, alignment=1)
                pixels = np.frombuffer(raw, np.uint8).reshape(fh, fw, 3)[::-1].copy()
                idle_framebuffer(ctx).use()  # never leave a released framebuffer bound
                fbo.release()
                texture.release()
            ctx.screen.use()
            self._compose(fw, fh)
            ctx.finish()
            self._glfw.swap_buffers(self.window)
        seconds = time.perf_counter() - t0
        tw, th, q, step = self._rendered
        if render:
            self.frame_times.append(seconds)
        self.last_frame = FrameInfo(q, (tw, th), (fw, fh), step, seconds if render else
                                    (self.last_frame.seconds if self.last_frame else seconds),
                                    key=(q, (tw, th, fw, fh), self._version, self._overlay_version,
                                         self.background), render_key=key,
                                    accumulated=self.accumulated if q == "full" else 1)
        self._update_title()
        return pixels

    def _compose(self, fw, fh):
        """Draw the render target (over the background) and the overlay into the bound
        framebuffer of size ``fw`` x ``fh``."""
        ctx = self.ctx
        ctx.viewport = (0, 0, fw, fh)
        ctx.disable(ctx.BLEND | ctx.DEPTH_TEST | ctx.CULL_FACE)
        self._fbo.color_attachments[0].use(location=0)
        tw, th = self._rendered[:2]
        prog = self._present
        prog["t_image"].value = 0
        prog["u_ratio"].value = (tw / fw, th / fh)
        prog["u_background"].value = self.background
        self._present_vao.render(vertices=3)
        if self.editor.visible:
            overlay_key = (self._overlay_version, self.window_size, self._iso_shown())
            if self._uploaded_overlay != overlay_key:
                self.overlay.upload(self.editor.geometry(iso_value=self._iso_shown()))
                self._uploaded_overlay = overlay_key
            self.overlay.draw(self.window_size)

    def _iso_shown(self):
        return self.iso if self.mode == "isosurface" else None

    def _update_title(self):
        f = self.last_frame
        step = f"step {f.step:.3g}" if f.step is not None else "fixed sampling"
        if self.tolerance is not None and self.technique == "raycast":
            step = f"tolerance {self.tolerance:.3g}, {step}"
        if "interpolate" in self._options():
            step += f", interpolate {self._options()['interpolate']}"
        extras = [k for k in ("preintegrate",) if self._options().get(k)]
        if self.info.accepts("sort") and self.info.params is not None:
            extras.append(str(self._options().get("sort", "mpvo")))
        if self.lit:
            extras.append("shaded")
        if self._accumulates():
            extras.append(f"{f.accumulated} sets")
        mode = self.mode + (f" {self.iso:g}" if self.mode == "isosurface" else "")
        title = (f"{PROG}: {self.settings.input_name} ({describe_data(self.volume)}) | {self.technique} {mode}"
                 + (f" ({', '.join(extras)})" if extras else "")
                 + f" | {step} | {f.target_size[0]}x{f.target_size[1]} | {1e3 * f.seconds:.1f} ms"
                 + (" (refining)" if f.quality == "coarse" else ""))
        if self.status and self.clock() < self._status_until:
            title += f" | {self.status}"
        self.title = title
        self._glfw.set_window_title(self.window, title)

    def render_image(self):
        """The current view at full quality as a float image (H, W, 4), premultiplied,
        row 0 on top, from the render target (no overlay)."""
        fw, fh = self.framebuffer_size
        scene, name, step, options = self.render_arguments(fw, fh)
        with self._gl():
            fbo = self.renderer.render_target(scene, name, step, **options)
            return self.renderer.read_target(fbo, fw, fh)

    def _screenshot_path(self, suffix=""):
        path = self.settings.screenshot
        if path is not None:
            if suffix:
                root, ext = os.path.splitext(path)
                path = f"{root}{suffix}{ext}"
            return path
        for n in range(1, 10000):
            path = f"dvr-gl-view-{n:03d}{suffix}.png"
            if not os.path.exists(path):
                return path
        return f"dvr-gl-view{suffix}.png"

    def save_screenshot(self, path=None):
        """Write the current view at full quality, without overlays, as ``dvr-gl render``
        would (RGB over ``--background`` if given, else un-premultiplied RGBA); atomic."""
        path = path or self._screenshot_path()
        try:
            dvr_io.save_png(path, self.render_image(), background=self.settings.background)
        except (OSError, ValueError) as e:
            self.say(f"cannot save the screenshot {path!r}: {e}")
            return None
        self.say(f"wrote {path}")
        return path

    def save_window_screenshot(self, path=None):
        """Write the window as shown (overlay included, over the display background)."""
        from PIL import Image
        import io

        path = path or self._screenshot_path("-window")
        pixels = self.frame(quality="full", grab=True)
        if pixels is None:
            return None
        buffer = io.BytesIO()
        Image.fromarray(pixels).save(buffer, format="PNG", optimize=True)
        try:
            dvr_io.atomic_write(path, buffer.getvalue())
        except OSError as e:
            self.say(f"cannot save the window screenshot {path!r}: {e}")
            return None
        self.say(f"wrote {path}")
        return path

    def refine(self, max_frames=100):
        """Render frames until nothing is pending (input settled, full quality shown)."""
        for _ in range(max_frames):
            self._glfw.poll_events()
            if not self.needs_frame():
                return
            self.frame()

    def run(self):
        """The interactive loop, until the window is closed or q/Esc is pressed."""
        glfw = self._glfw
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
            self._glfw.poll_events()
            self.frame(quality="full", force=True)
            times.append(self.last_frame.seconds)
        return times


_CLOSED_CONTEXTS = []


def _release_current_egl():
    """Make no EGL context current on this thread, if libEGL is loaded at all. A headless
    context may be left current (``gl.context.create_context`` leaves a new EGL context
    current, even after it is released), and libglvnd then refuses glXMakeCurrent."""
    if not sys.platform.startswith("linux"):
        return
    egl = _EGL.get("lib")
    if egl is None:
        import ctypes

        try:  # RTLD_NOLOAD: only a libEGL the process has already loaded
            egl = ctypes.CDLL("libEGL.so.1", mode=os.RTLD_NOLOAD | os.RTLD_LAZY)
        except (OSError, AttributeError):
            return
        egl.eglGetCurrentContext.restype = ctypes.c_void_p
        egl.eglGetCurrentDisplay.restype = ctypes.c_void_p
        egl.eglMakeCurrent.argtypes = [ctypes.c_void_p] * 4
        egl.eglMakeCurrent.restype = ctypes.c_uint
        _EGL["lib"] = egl
    if egl.eglGetCurrentContext():
        egl.eglMakeCurrent(egl.eglGetCurrentDisplay(), None, None, None)


_EGL = {}


def _first_error(exc):
    """The telling line of an exception's message (a GLSL log's first error)."""
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    errors = [line for line in lines if "error" in line.lower()]
    return f"{type(exc).__name__}: {(errors or lines or [''])[0]}"


def _window_context(moderngl):
    """A moderngl context for the GL context current now (the window's). On Linux it
    is made through glcontext's "detect" mode with an explicit GLX library, so that
    entering it makes the window's context current again: without settings,
    ``moderngl.create_context()`` in a process that has no context yet returns one whose
    enter and exit do nothing, and the first such context is also handed to every later
    caller."""
    settings = {}
    if sys.platform.startswith("linux"):
        import ctypes.util
        settings["libgl"] = ctypes.util.find_library("GL") or "libGL.so.1"
    return moderngl.create_context(require=330, **settings)


def _import_glfw():
    try:
        import glfw
    except ImportError as e:
        raise ImportError(f"the interactive viewer needs glfw (pip install glfw): {e}") from None
    return glfw


def _no_display_message(detail):
    if sys.platform.startswith("linux") and not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        return ("cannot open a window: no display (DISPLAY is not set). The viewer needs a screen; "
                "off-screen, run it under xvfb-run (xvfb-run -a dvr-gl view INPUT --screenshot out.png "
                "--frames 5) or use dvr-gl render")
    return f"cannot open a window: {detail}"


# ----------------------------------------------------------------------------- the command

def build_parser():
    """``dvr-gl render``'s options (:func:`dvr_gl.frontends.options.add_render_options`) plus the viewer's."""
    from .options import add_render_options, whole_number

    description = ("Open a volume in an interactive window. Takes every option of dvr-gl render "
                   "(--size is the window size). Press h in the window for the keys.")
    epilog = "Off-screen (scripts, CI): xvfb-run -a dvr-gl view INPUT --screenshot out.png --frames 5"
    parser = argparse.ArgumentParser(prog=PROG, description=description, epilog=epilog)
    add_render_options(parser)
    parser.add_argument("--out", "-o", help=argparse.SUPPRESS)
    for action in parser._actions:
        if action.dest == "out":  # render's --out: here another name for --screenshot
            action.required = False
            action.help = argparse.SUPPRESS
        elif action.dest == "size":
            action.help = "window size in pixels (default: 512x512)"
        elif action.dest == "backend":
            action.help = "accepted for dvr-gl render's sake; the viewer renders in its window's context"
    parser.add_argument("--screenshot", metavar="IMAGE.png",
                        help="where s (and --frames) write the screenshot: the render without overlays, "
                             "as dvr-gl render writes it (default: dvr-gl-view-NNN.png)")
    parser.add_argument("--frames", type=whole_number(1), metavar="N",
                        help="render N frames at full quality, save the screenshot (if --screenshot) and exit")
    parser.add_argument("--tf-out", default="dvr-gl-tf.json", metavar="FILE.json",
                        help="where ctrl+s saves the edited transfer function and ctrl+o loads it from "
                             "(default: dvr-gl-tf.json)")
    parser.add_argument("--hide-editor", action="store_true", help="start with the transfer-function editor hidden")
    return parser


def settings_from_args(args) -> Settings:
    """Check the options and load the input (no window yet): a bad file fails here."""
    from .options import UsageError, check_png, check_technique, load_input_args, resolve_tf_option, \
        technique_options

    screenshot, option = (args.screenshot, "--screenshot") if args.screenshot else (args.out, "--out")
    if screenshot:
        check_png(screenshot, option)
    check_technique(args.technique)
    options = dict(technique_options(args))    # checks that each option fits the technique
    options.pop("technique", None)
    options.pop("step", None)
    tolerance = options.pop("tolerance", None)
    # unlike render, isosurface mode needs no --iso: the viewer picks one (keys , and . move it)
    mode = args.mode or ("isosurface" if args.iso is not None else "composite")
    if args.iso is not None and mode != "isosurface":
        raise UsageError("--iso", f"is only used with --mode isosurface, not --mode {mode}")
    if args.dtype is not None:
        try:
            dvr_io._parse_dtype(args.dtype)
        except dvr_io.InputError as e:
            raise UsageError("--dtype", e.detail) from None
    if not args.tf_out.lower().endswith(".json"):
        raise UsageError("--tf-out", f"must name a .json file, got {args.tf_out!r}")
    volume, default_preset = load_input_args(args)
    tf_name, tf = resolve_tf_option(args.tf, volume, default_preset)
    return Settings(volume=volume, tf=tf, tf_name=tf_name, input_name=os.path.basename(args.input) or args.input,
                    technique=args.technique, mode=mode, iso=args.iso, step=args.step, size=tuple(args.size),
                    azimuth=args.azimuth, elevation=args.elevation, zoom=args.zoom, fov=args.fov,
                    ortho=args.ortho, background=args.background, screenshot=screenshot,
                    tf_out=args.tf_out, editor=not args.hide_editor, vsync=args.frames is None,
                    options=options, shading=getattr(args, "shading", None),
                    lights=tuple(args.light) if getattr(args, "light", None) else None,
                    optical_model=getattr(args, "optical_model", None) or "emission_absorption",
                    illustration=tuple(getattr(args, "illustration", None) or ()), tolerance=tolerance)


def open_viewer(argv) -> Viewer:
    """Parse ``argv`` (the viewer's arguments), load the input and open the window.
    Errors raise (``SystemExit`` for usage errors from argparse)."""
    args = build_parser().parse_args(list(argv))
    return Viewer(settings_from_args(args))


def main(argv=None) -> int:
    """``dvr-gl view``: returns the exit status (0; 1 no window or a failed frame; 2 bad
    input, with a one-line message; 130 interrupted). ``DVR_GL_DEBUG=1`` shows tracebacks."""
    from .options import OPTION_OF_FIELD, UsageError

    argv = list(sys.argv[1:] if argv is None else argv)
    debug = bool(os.environ.get("DVR_GL_DEBUG"))
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as e:  # --help or a usage error (already printed)
        return e.code if isinstance(e.code, int) else (0 if e.code is None else 2)
    try:
        return _run(args)
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
    except UsageError as e:
        if debug:
            raise
        return _fail(str(e), 2)
    except dvr_io.InputError as e:
        if debug:
            raise
        option = OPTION_OF_FIELD.get(e.field)
        return _fail(f"{option}: {e.detail}" if option else f"INPUT: {e}", 2)
    except ImportError as e:
        if debug:
            raise
        return _fail(str(e), 2)
    except (ValueError, TypeError, NotImplementedError) as e:
        if debug:
            raise
        return _fail(str(e).replace("pass mask_nonfinite=True", "pass --mask-nonfinite"), 2)
    except (RuntimeError, OSError) as e:  # no window, no GL 3.3, a failed frame, a full disk
        if debug:
            raise
        return _fail(str(e) if isinstance(e, WindowError) else f"{type(e).__name__}: {e}", 1)


def _fail(message, code):
    print(f"{PROG}: error: {message}", file=sys.stderr)
    return code


def _run(args):
    settings = settings_from_args(args)
    viewer = Viewer(settings)
    glfw = viewer._glfw
    try:
        v = settings.volume
        what = (describe_data(v) if _is_mesh(v) else f"{describe_data(v)} (x, y, z) {v.data.dtype}")
        print(f"{PROG}: {settings.input_name}: {what}, values "
              f"{v.data_range[0]:g}..{v.data_range[1]:g}; transfer function {settings.tf_name}; "
              f"techniques {', '.join(viewer.available_techniques)}", flush=True)
        if args.frames:
            times = viewer.run_frames(args.frames)
            if times:
                print(f"{PROG}: {len(times)} frames at {viewer.framebuffer_size[0]}x{viewer.framebuffer_size[1]}, "
                      f"median {1e3 * float(np.median(times)):.1f} ms (first {1e3 * times[0]:.1f} ms)", flush=True)
            if settings.screenshot and viewer.save_screenshot(settings.screenshot) is None:
                return 1
            return 0
        print(f"{PROG}: press h in the window for the keys", flush=True)
        viewer.run()
        return 0
    finally:
        viewer.close()
        glfw.terminate()
