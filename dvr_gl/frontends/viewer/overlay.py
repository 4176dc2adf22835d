"""The viewer's transfer-function editor: its state and geometry (plain Python and NumPy,
testable without GL) and the small GL drawer that puts it on the window.

The editor is a panel along the bottom of the window:

    +--------------------------------------------------------------+
    |   histogram of the data (grey bars, log counts)               |
    |   opacity curve (white) over a fill coloured with c(s)        |
    |   o control points: drag to move, click to add,               |
    |     right click to remove                                     |
    |==============================================================|
    |  colour strip c(s)        v colour points (same gestures;     |
    |                             the scroll wheel turns the hue)   |
    +--------------------------------------------------------------+

The histogram counts a grid's samples or a tetrahedral mesh's point scalars.
The horizontal axis is the data value, from the smaller to the larger of the data's range
and the transfer function's control points. The vertical axis shows ``sqrt(alpha)``:
typical volume opacities are a few percent, which a linear axis would squash against the
bottom. All positions here are window coordinates (pixels, x right, y down), the units
glfw reports the cursor in.
"""

from __future__ import annotations

import colorsys
import math

import numpy as np

from ...model.mesh import TetMesh
from ...model.transfer_function import TransferFunction

HISTOGRAM_BINS = 128
CURVE_SAMPLES = 256
PICK_RADIUS = 7.0      # pixels: how close a click must be to grab a control point

# Colours of the panel (straight RGBA)
PANEL = (0.07, 0.07, 0.09, 0.80)
BARS = (0.36, 0.36, 0.42, 0.45)
CURVE = (1.0, 1.0, 1.0, 0.95)
POINT = (1.0, 1.0, 1.0, 1.0)
ACTIVE = (1.0, 0.85, 0.2, 1.0)
ISO = (0.3, 0.9, 1.0, 0.9)


def data_values(volume):
    """The values the histogram counts: a grid's finite samples, or a
    :class:`~dvr_gl.TetMesh`'s point scalars (always finite)."""
    if isinstance(volume, TetMesh):
        return volume.scalars
    if not hasattr(volume, "data"):       # a LazyVolume: its samples are not all read for a histogram
        return np.zeros(0)
    return volume.data[np.isfinite(volume.data)] if volume.has_nonfinite else volume.data


def data_histogram(volume, lo, hi, bins=HISTOGRAM_BINS):
    """Counts of the volume's finite samples (a mesh's point scalars) in ``bins`` equal
    bins over [lo, hi], scaled as ``log(1 + count) / log(1 + max count)`` (0..1)."""
    values = data_values(volume)
    counts, _ = np.histogram(values, bins=bins, range=(lo, hi))
    top = float(counts.max()) if counts.size else 0.0
    if top <= 0:
        return np.zeros(bins)
    return np.log1p(counts) / math.log1p(top)


class TFEditor:
    """Control points of a transfer function, editable by mouse gestures.

    ``tf`` is always a valid :class:`TransferFunction` (positions strictly increasing,
    values in [0, 1]); every gesture that changes it returns True so the viewer
    re-renders. ``layout(width, height)`` must be called when the window size changes.
    """

    def __init__(self, tf, volume, visible=True):
        self.volume = volume
        self.visible = visible
        self.drag = None        # (kind, index) being dragged: kind "opacity" or "color"
        self.hover = None       # (kind, index) under the cursor
        self.width = self.height = 0
        self._hist_range = None
        self.set_tf(tf)
        self.layout(640, 480)

    # -- the function ------------------------------------------------------------------
    def set_tf(self, tf, keep_axis=False):
        """Show ``tf`` (a preset, a loaded file). The value axis is refitted to the data
        and the new control points unless ``keep_axis`` (edits in progress)."""
        self.opacity = np.array(tf.opacity_points, dtype=np.float64)
        self.color = np.array(tf.color_points, dtype=np.float64)
        self.unit_distance = tf.unit_distance
        self._tf = tf
        self.drag = self.hover = None
        if not keep_axis:
            lo, hi = self.volume.data_range
            knots = tf.knots
            lo, hi = min(lo, float(knots[0])), max(hi, float(knots[-1]))
            if hi <= lo:
                lo, hi = lo - 0.5, hi + 0.5
            self.lo, self.hi = lo, hi
            if self._hist_range != (lo, hi):
                self.histogram = data_histogram(self.volume, lo, hi)
                self._hist_range = (lo, hi)

    @property
    def tf(self) -> TransferFunction:
        if self._tf is None:
            self._tf = TransferFunction(self.color, self.opacity, self.unit_distance)
        return self._tf

    def _changed(self):
        self._tf = None
        return True

    # -- layout and mappings -----------------------------------------------------------
    def layout(self, width, height):
        """Place the panel for a window of ``width`` x ``height`` (window coordinates)."""
        self.width, self.height = float(width), float(height)
        margin = 8.0
        panel_h = min(max(0.28 * height, 48.0), 170.0, max(height - 2 * margin, 1.0))
        self.panel = (margin, height - margin - panel_h, max(width - margin, margin + 1), height - margin)
        x0, y0, x1, y1 = self.panel
        pad = 6.0
        strip_h = min(14.0, 0.2 * panel_h)
        self.strip = (x0 + pad, y1 - pad - strip_h, x1 - pad, y1 - pad)
        self.curve = (x0 + pad, y0 + pad, x1 - pad, self.strip[1] - 5.0)

    def contains(self, x, y):
        """True when (x, y) is on the visible panel (its events belong to the editor)."""
        if not self.visible:
            return False
        x0, y0, x1, y1 = self.panel
        return x0 <= x <= x1 and y0 <= y <= y1

    def value_to_x(self, s):
        x0, _, x1, _ = self.curve
        return x0 + (np.asarray(s, np.float64) - self.lo) / (self.hi - self.lo) * (x1 - x0)

    def x_to_value(self, x):
        x0, _, x1, _ = self.curve
        t = min(max((x - x0) / max(x1 - x0, 1e-9), 0.0), 1.0)
        return self.lo + t * (self.hi - self.lo)

    def alpha_to_y(self, a):
        _, y0, _, y1 = self.curve
        return y1 - np.sqrt(np.clip(a, 0.0, 1.0)) * (y1 - y0)

    def y_to_alpha(self, y):
        _, y0, _, y1 = self.curve
        t = min(max((y1 - y) / max(y1 - y0, 1e-9), 0.0), 1.0)
        return t * t

    def _in(self, rect, x, y, slack=0.0):
        x0, y0, x1, y1 = rect
        return x0 - slack <= x <= x1 + slack and y0 - slack <= y <= y1 + slack

    def _pick(self, kind, x, y):
        """Index of the control point of ``kind`` nearest (x, y) within PICK_RADIUS."""
        if kind == "opacity":
            px = self.value_to_x(self.opacity[:, 0])
            py = self.alpha_to_y(self.opacity[:, 1])
            d = np.hypot(px - x, py - y)
        else:
            d = np.abs(self.value_to_x(self.color[:, 0]) - x)
        i = int(np.argmin(d))
        return i if d[i] <= PICK_RADIUS else None

    def _area(self, x, y):
        if self._in(self.strip, x, y, slack=4.0):
            return "color"
        if self._in(self.curve, x, y, slack=PICK_RADIUS):
            return "opacity"
        return None

    # -- gestures ----------------------------------------------------------------------
    def press(self, button, x, y):
        """A mouse press on the panel: button 0 grabs or adds a point, 1 removes one.
        Returns True when the function changed."""
        kind = self._area(x, y)
        if kind is None:
            return False
        points = self.opacity if kind == "opacity" else self.color
        i = self._pick(kind, x, y)
        if button == 1:
            if i is None or len(points) <= 1:
                return False
            if kind == "opacity":
                self.opacity = np.delete(self.opacity, i, axis=0)
            else:
                self.color = np.delete(self.color, i, axis=0)
            self.hover = None
            return self._changed()
        if button != 0:
            return False
        if i is not None:
            self.drag = (kind, i)
            return False
        s = self.x_to_value(x)
        if kind == "opacity":
            row = [s, self.y_to_alpha(y)]
        else:
            row = [s] + [float(v) for v in self.tf.color(s)]
        self.drag = (kind, self._insert(kind, row))
        self.move(x, y)
        return self._changed()

    def _insert(self, kind, row):
        points = self.opacity if kind == "opacity" else self.color
        i = int(np.searchsorted(points[:, 0], row[0]))
        points = np.insert(points, i, row, axis=0)
        if kind == "opacity":
            self.opacity = points
        else:
            self.color = points
        return i

    def move(self, x, y):
        """The cursor moved: drag the grabbed point (True if the function changed), or
        update which point is highlighted."""
        if self.drag is None:
            area = self._area(x, y) if self.contains(x, y) else None
            i = self._pick(area, x, y) if area else None
            self.hover = (area, i) if i is not None else None
            return False
        kind, i = self.drag
        points = self.opacity if kind == "opacity" else self.color
        # Keep positions strictly increasing: a point stays between its neighbours.
        gap = 1e-6 * (self.hi - self.lo)
        lo = points[i - 1, 0] + gap if i > 0 else -math.inf
        hi = points[i + 1, 0] - gap if i + 1 < len(points) else math.inf
        s = min(max(self.x_to_value(x), lo), hi)
        old = points[i].copy()
        points[i, 0] = s
        if kind == "opacity":
            points[i, 1] = self.y_to_alpha(y)
        return self._changed() if not np.array_equal(old, points[i]) else False

    def release(self, button, x, y):
        if button == 0:
            self.drag = None

    def scroll(self, x, y, dy):
        """The wheel over a colour point turns its hue by 15 degrees a click."""
        if self._area(x, y) != "color":
            return False
        i = self._pick("color", x, y)
        if i is None:
            return False
        h, l, s = colorsys.rgb_to_hls(*self.color[i, 1:])
        if s == 0:  # a grey: give it some colour to turn
            s = 0.8
            l = min(max(l, 0.25), 0.75)
        self.color[i, 1:] = np.clip(colorsys.hls_to_rgb((h + dy / 24.0) % 1.0, l, s), 0.0, 1.0)
        return self._changed()

    # -- whole-function edits (keys and the window/level drag) --------------------------
    def scale_opacity(self, factor):
        self.opacity[:, 1] = np.clip(self.opacity[:, 1] * factor, 0.0, 1.0)
        return self._changed()

    def window_level(self, base, shift, scale):
        """Set the function to ``base`` with its control points moved as
        ``s' = c + (s - c) * scale + shift`` (c: the centre of base's knots)."""
        knots = base.knots
        c = 0.5 * (float(knots[0]) + float(knots[-1]))
        self.opacity = np.array(base.opacity_points, dtype=np.float64)
        self.color = np.array(base.color_points, dtype=np.float64)
        self.opacity[:, 0] = c + (self.opacity[:, 0] - c) * scale + shift
        self.color[:, 0] = c + (self.color[:, 0] - c) * scale + shift
        return self._changed()

    # -- geometry ----------------------------------------------------------------------
    def geometry(self, iso_value=None):
        """Triangles of the panel as an (n, 6) float32 array of (x, y, r, g, b, a) per
        vertex, in window coordinates."""
        tris = _Triangles()
        tris.rect(self.panel, PANEL)
        cx0, cy0, cx1, cy1 = self.curve
        # histogram
        n = len(self.histogram)
        edges = np.linspace(cx0, cx1, n + 1)
        for k, h in enumerate(self.histogram):
            if h > 0:
                tris.rect((edges[k], cy1 - h * (cy1 - cy0), edges[k + 1], cy1), BARS)
        # opacity fill and curve, sampled so the sqrt axis bends the lines correctly
        s = np.linspace(self.lo, self.hi, CURVE_SAMPLES)
        tf = self.tf
        xs = self.value_to_x(s)
        ys = self.alpha_to_y(tf.opacity(s))
        cs = tf.color(s)
        for k in range(CURVE_SAMPLES - 1):
            a, b = k, k + 1
            tris.quad([(xs[a], cy1), (xs[b], cy1), (xs[b], ys[b]), (xs[a], ys[a])],
                      [(*cs[a], 0.25), (*cs[b], 0.25), (*cs[b], 0.7), (*cs[a], 0.7)])
        for k in range(CURVE_SAMPLES - 1):
            tris.line(xs[k], ys[k], xs[k + 1], ys[k + 1], 1.5, CURVE)
        # colour strip
        sx0, sy0, sx1, sy1 = self.strip
        for k in range(CURVE_SAMPLES - 1):
            tris.quad([(xs[k], sy1), (xs[k + 1], sy1), (xs[k + 1], sy0), (xs[k], sy0)],
                      [(*cs[k], 1.0), (*cs[k + 1], 1.0), (*cs[k + 1], 1.0), (*cs[k], 1.0)])
        if iso_value is not None and self.lo <= iso_value <= self.hi:
            x = float(self.value_to_x(iso_value))
            tris.line(x, cy0, x, sy1, 2.0, ISO)
        # control points
        active = [self.drag, self.hover]
        for i, (v, r, g, b) in enumerate(self.color):
            x = float(self.value_to_x(v))
            edge = ACTIVE if ("color", i) in active else POINT
            tris.triangle([(x - 7, sy0 - 9), (x + 7, sy0 - 9), (x, sy0 + 2)], edge)
            tris.triangle([(x - 4.5, sy0 - 7.5), (x + 4.5, sy0 - 7.5), (x, sy0 - 1)], (r, g, b, 1.0))
        for i, (v, a) in enumerate(self.opacity):
            x, y = float(self.value_to_x(v)), float(self.alpha_to_y(a))
            edge = ACTIVE if ("opacity", i) in active else POINT
            tris.rect((x - 4, y - 4, x + 4, y + 4), edge)
            tris.rect((x - 2, y - 2, x + 2, y + 2), (0.1, 0.1, 0.1, 1.0))
        return tris.array()


class _Triangles:
    """Collects coloured triangles (x, y, r, g, b, a per vertex)."""

    def __init__(self):
        self.rows = []

    def triangle(self, points, color):
        for x, y in points:
            self.rows.append((x, y, *color))

    def quad(self, points, colors):
        """Four corners in order, each with its own colour."""
        for k in (0, 1, 2, 0, 2, 3):
            self.rows.append((points[k][0], points[k][1], *colors[k]))

    def rect(self, rect, color):
        x0, y0, x1, y1 = rect
        self.quad([(x0, y0), (x1, y0), (x1, y1), (x0, y1)], [color] * 4)

    def line(self, xa, ya, xb, yb, width, color):
        dx, dy = xb - xa, yb - ya
        length = math.hypot(dx, dy)
        if length == 0:
            return
        nx, ny = -dy / length * width / 2, dx / length * width / 2
        self.quad([(xa + nx, ya + ny), (xb + nx, yb + ny), (xb - nx, yb - ny), (xa - nx, ya - ny)], [color] * 4)

    def array(self):
        return np.array(self.rows, dtype=np.float32).reshape(-1, 6)


class OverlayDrawer:
    """Draws editor geometry on the window's framebuffer with alpha blending. GL
    resources live in the renderer's context and are released by :meth:`release`."""

    def __init__(self, renderer):
        self.ctx = renderer.ctx
        self.prog = renderer.programs.get("viewer/overlay.vert", "viewer/overlay.frag")
        self.vbo = None
        self.vao = None
        self.count = 0

    def upload(self, vertices):
        data = np.ascontiguousarray(vertices, dtype=np.float32)
        self.count = len(data)
        if not self.count:
            return
        if self.vbo is None or self.vbo.size < data.nbytes:
            self._release_buffers()
            self.vbo = self.ctx.buffer(reserve=max(data.nbytes, 1 << 16), dynamic=True)
            self.vao = self.ctx.vertex_array(self.prog, [(self.vbo, "2f 4f", "a_pos", "a_color")])
        self.vbo.write(data.tobytes())

    def draw(self, window_size):
        """Draw what was uploaded last; the caller has bound the window's framebuffer."""
        if not self.count:
            return
        ctx = self.ctx
        self.prog["u_window"].value = tuple(float(v) for v in window_size)
        ctx.enable(ctx.BLEND)
        ctx.blend_func = ctx.SRC_ALPHA, ctx.ONE_MINUS_SRC_ALPHA
        self.vao.render(vertices=self.count)
        ctx.disable(ctx.BLEND)

    def _release_buffers(self):
        if self.vao is not None:
            self.vao.release()
        if self.vbo is not None:
            self.vbo.release()
        self.vao = self.vbo = None

    def release(self):
        self._release_buffers()
