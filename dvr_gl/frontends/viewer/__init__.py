"""The interactive viewer: ``dvr-gl view INPUT [render options]``.

About the viewer
----------------
A glfw window (OpenGL 3.3 core) whose moderngl context is handed to a
:class:`dvr_gl.Renderer`: every frame is rendered by the very same technique modules and
shader programs as headless rendering, into the renderer's float target at the window's
framebuffer size. That texture is then drawn to the window with one full-screen triangle,
composited over a background colour (``C + (1 - A) * B``), and the transfer-function
editor (:mod:`.overlay`) is drawn over it. Screenshots are read from the float target, so
they never contain the overlay and equal ``dvr-gl render``'s PNG of the same camera.

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
switches its cell order (``sort``: ``mpvo`` / ``centroid`` / ``walk``), the editor's histogram counts
``mesh.scalars``, the title shows points and tets instead of the grid's shape, modes tetra
cannot render are skipped with the usual message, and a double click picks along the ray
through the cells themselves (:func:`pick_point_mesh`: the ray is intersected with every
tetrahedron, the piecewise-linear field is sampled inside the mesh only, and the same
rule as on grids picks the point; empty space falls back to the box centre).

glfw is imported inside functions only, so ``import dvr_gl.frontends.viewer`` works without it.

The modules
-----------
Each module is one idea; the arrows of their imports point down this list.

- ``command``: ``dvr-gl view`` (:func:`main`) and :func:`open_viewer`
- ``app``: the :class:`Viewer`: its state, its window and the frame loop
- ``controls``: input handling (mouse, wheel, keys, window changes)
- ``choices``: the keys' changes of the rendering choices (technique, mode, step, ...)
- ``frames``: rendering a frame and showing it in the window (:class:`FrameInfo`)
- ``tf_actions``: presets, saving and loading transfer functions
- ``screenshots``: the keys s and S
- ``status``: messages and the window title
- ``probe``: which techniques can render the data (:class:`TechniqueInfo`)
- ``settings``: the command line's :class:`Settings`, :func:`build_parser`
- ``window``: glfw, the window and its GL context (:class:`WindowError`)
- ``overlay``: the transfer-function editor and its drawing
- ``orbit``: the camera (:class:`Orbit`);  ``picking``: point picking on grids and meshes
- ``keys``: glfw's key codes and the key list (``KEYS_HELP``)
- ``clipping``: the clip plane's keys (k, K) and alt + drag
- ``layers``: several volumes, the keys F2..F5 that show or hide each
"""

from .app import Viewer
from .command import main, open_viewer
from .frames import FrameInfo
from .keys import (KEY_COMMA, KEY_EQUAL, KEY_ESCAPE, KEY_F1, KEY_KP_ADD, KEY_KP_SUBTRACT, KEY_LEFT_BRACKET,
                   KEY_MINUS, KEY_PERIOD, KEY_RIGHT_BRACKET, KEYS_HELP, MOD_ALT, MOD_CONTROL, MOD_SHIFT, MOD_SUPER,
                   MOUSE_LEFT, MOUSE_MIDDLE, MOUSE_RIGHT, PRESS, RELEASE, REPEAT, key_code)
from .orbit import Orbit
from .overlay import OverlayDrawer, TFEditor
from .picking import mesh_pick_data, pick_point, pick_point_mesh, ray_cells
from .probe import TechniqueInfo, fallback_step, probe_technique
from .settings import PROG, Settings, build_parser, describe_data, settings_from_args
from .window import WindowError

__all__ = [
    "main", "open_viewer", "Viewer", "Settings", "build_parser", "settings_from_args", "PROG",
    "FrameInfo", "Orbit", "TFEditor", "OverlayDrawer", "WindowError",
    "TechniqueInfo", "probe_technique", "fallback_step", "describe_data",
    "pick_point", "pick_point_mesh", "ray_cells", "mesh_pick_data",
    "key_code", "KEYS_HELP", "PRESS", "RELEASE", "REPEAT", "MOUSE_LEFT", "MOUSE_RIGHT", "MOUSE_MIDDLE",
    "MOD_SHIFT", "MOD_CONTROL", "MOD_ALT", "MOD_SUPER", "KEY_ESCAPE", "KEY_F1", "KEY_MINUS", "KEY_EQUAL",
    "KEY_COMMA", "KEY_PERIOD", "KEY_LEFT_BRACKET", "KEY_RIGHT_BRACKET", "KEY_KP_SUBTRACT", "KEY_KP_ADD",
]
