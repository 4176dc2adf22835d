"""Transfer-function tables and presets.

The GL path classifies through a lookup table (LUT): the piecewise-linear transfer
function sampled at ``LUT_SIZE`` evenly spaced data values between its first and last
control point, and interpolated linearly between entries *in the shader's own arithmetic*
(two ``texelFetch`` and a ``mix``, not the texture unit's filter, whose weight precision
is the rasteriser's business). The NumPy twin is :func:`lookup`. The LUT differs from the
exact function only inside the LUT cells that contain an interior control point; its
error is reported by :func:`lut_max_error`.
"""

from __future__ import annotations

import json
import os

import numpy as np

from .mesh import TetMesh
from .transfer_function import TransferFunction

LUT_SIZE = 4096


class LookupTable:
    """RGBA (colour, opacity) samples of a transfer function, float32, with the mapping
    from data values to table index: ``u = (s - lo) * scale``, clamped to [0, n-1].

    ``transparency`` holds ``1 - alpha`` per entry, computed in float64 before rounding:
    near alpha = 1 it keeps the relative precision that a float32 alpha has lost, and
    interpolating it linearly is the same as interpolating alpha."""

    def __init__(self, tf: TransferFunction, size: int = LUT_SIZE):
        knots = tf.knots
        lo, hi = float(knots[0]), float(knots[-1])
        if hi <= lo:  # a single control point: the function is constant
            lo, hi = lo - 0.5, lo + 0.5
        s = np.linspace(lo, hi, size)
        table = np.empty((size, 4), dtype=np.float64)
        table[:, :3] = tf.color(s)
        table[:, 3] = tf.opacity(s)
        self.lo = lo
        self.hi = hi
        self.size = size
        self.scale = (size - 1) / (hi - lo)
        self.table = table.astype(np.float32)
        self.transparency = (1.0 - table[:, 3]).astype(np.float32)

    def interpolate(self, rows, s):
        """Twin of GLSL ``lerpTableRow``: rows (this table's, or one of the same entries such
        as ``step_table``) linear between entries at values ``s``, float64 arithmetic."""
        u = np.clip((np.asarray(s, dtype=np.float64) - self.lo) * self.scale, 0.0, self.size - 1)
        i0 = np.minimum(np.floor(u).astype(np.int64), self.size - 2)
        f = (u - i0).reshape(u.shape + (1,) * (rows.ndim - 1))
        t = rows.astype(np.float64)
        return t[i0] * (1 - f) + t[i0 + 1] * f

    def lookup(self, s):
        """RGBA at data values ``s`` (float64 arithmetic on the float32 table)."""
        return self.interpolate(self.table, s)

    def lookup_transparency(self, s):
        """1 - alpha at data values ``s``, from the transparency row."""
        return self.interpolate(self.transparency, s)

    def texture_rows(self):
        """(2, n, 4) float32: row 0 RGBA, row 1 transparency in its first channel."""
        rows = np.zeros((2, self.size, 4), np.float32)
        rows[0] = self.table
        rows[1, :, 0] = self.transparency
        return rows

    def step_table(self, length_over_unit):
        """(n, 4) float32: each entry's segment for one full step of ``length_over_unit``
        unit distances, premultiplied and opacity-corrected, ``(c alpha_L, alpha_L)`` with
        ``alpha_L = 1 - (1 - alpha)^(L/u)`` (from the float32 entries, in float64). The
        ray caster interpolates it for every full-length segment instead of correcting
        each sample (GLSL ``lookupStepTF``); the difference is ``step_table_error``."""
        a = self.table[:, 3].astype(np.float64)
        corrected = correct_opacity(a, length_over_unit, self.transparency.astype(np.float64))
        out = np.empty((self.size, 4))
        out[:, :3] = self.table[:, :3].astype(np.float64) * corrected[:, None]
        out[:, 3] = corrected
        return out.astype(np.float32)

    def step_table_error(self, length_over_unit, per_interval=64):
        """Largest difference, over values between the entries, between interpolating
        ``step_table`` and correcting the interpolated entry (what a sample gets either
        way, float64): the price of the table, per segment."""
        f = np.linspace(0.0, 1.0, per_interval + 1)[1:-1]
        t = self.table.astype(np.float64)
        w = self.transparency.astype(np.float64)
        lerp = lambda rows: rows[:-1, None] * (1 - f[:, None]) + rows[1:, None] * f[:, None]   # noqa: E731
        rgba = lerp(t)                                          # (n - 1, k, 4)
        exact_a = correct_opacity(rgba[..., 3], length_over_unit, lerp(w[:, None])[..., 0])
        exact = np.concatenate([rgba[..., :3] * exact_a[..., None], exact_a[..., None]], axis=-1)
        return float(np.abs(lerp(self.step_table(length_over_unit).astype(np.float64)) - exact).max())

    def max_opacity_between(self, smin, smax):
        """Largest LUT opacity over each value interval [smin, smax] (arrays): the
        interpolated end points and every table entry strictly inside."""
        a = self.table[:, 3].astype(np.float64)
        ends = np.maximum(self.lookup(smin)[..., 3], self.lookup(smax)[..., 3])
        u0 = np.clip((np.asarray(smin, np.float64) - self.lo) * self.scale, 0, self.size - 1)
        u1 = np.clip((np.asarray(smax, np.float64) - self.lo) * self.scale, 0, self.size - 1)
        i0 = np.ceil(u0).astype(np.int64)
        i1 = np.floor(u1).astype(np.int64)
        # running maximum over table ranges via a sparse table would be faster; the
        # number of bricks is small, so a prefix over sorted entries is enough here.
        out = ends.copy()
        flat_i0, flat_i1, flat_out = i0.ravel(), i1.ravel(), out.ravel()
        for k in np.nonzero(flat_i1 >= flat_i0)[0]:
            flat_out[k] = max(flat_out[k], a[flat_i0[k]:flat_i1[k] + 1].max())
        return flat_out.reshape(out.shape)


def lut_max_error(tf: TransferFunction, size: int = LUT_SIZE, samples: int = 200001):
    """Largest absolute difference between the LUT and the exact transfer function."""
    lut = LookupTable(tf, size)
    s = np.linspace(lut.lo, lut.hi, samples)
    exact = np.concatenate([tf.color(s), tf.opacity(s)[:, None]], axis=1)
    return float(np.abs(lut.lookup(s) - exact).max())


# -- presets ----------------------------------------------------------------------------------

# Built-in colour ramps (no matplotlib needed): evenly spaced over the data's window.
RAMPS = {
    "warm": [(0.30, 0.06, 0.03), (0.78, 0.30, 0.10), (0.96, 0.66, 0.36), (1.00, 0.93, 0.80)],
    "coolwarm": [(0.23, 0.30, 0.75), (0.62, 0.74, 0.99), (0.87, 0.87, 0.87), (0.96, 0.60, 0.48),
                 (0.71, 0.02, 0.15)],
    "grey": [(0.0, 0.0, 0.0), (1.0, 1.0, 1.0)],
}
#: matplotlib colormaps offered by name (``--tf viridis``); any other as ``cmap:NAME``.
COLORMAPS = ("viridis", "magma", "inferno", "plasma", "cividis", "gray", "bone")


def _sample_values(data):
    if isinstance(data, TetMesh):
        return data.scalars, data.cell_size
    values = data.data[np.isfinite(data.data)] if data.has_nonfinite else data.data
    return values, data.min_spacing


def window(data, lo_pct=1.0, hi_pct=99.0):
    """The (lo, hi) percentiles of the data's values (its range, or a unit span, where
    they coincide)."""
    values, _ = _sample_values(data)
    lo, hi = (float(v) for v in np.percentile(values, [lo_pct, hi_pct]))
    if hi <= lo:
        lo, hi = data.data_range
        if hi <= lo:
            hi = lo + 1.0
    return lo, hi


def ramp_preset(data, colors, lo=None, hi=None, peak=0.5, unit_distance=None) -> TransferFunction:
    """``colors`` evenly spaced from ``lo`` to ``hi`` (default: the 1st and 99th
    percentiles), opacity rising linearly from 0 to ``peak`` over the same window; unit
    distance one voxel (a mesh: one cell) unless given."""
    _, unit = _sample_values(data)
    if lo is None or hi is None:
        lo, hi = window(data)
    xs = np.linspace(lo, hi, len(colors))
    return TransferFunction(color=[(float(x), *c) for x, c in zip(xs, colors)],
                            opacity=[(lo, 0.0), (hi, peak)], unit_distance=unit_distance or unit)


def colormap_preset(data, name, peak=0.5) -> TransferFunction:
    """A matplotlib colormap (``viridis``, ``magma``, ...) as a ramp preset."""
    try:
        import matplotlib
    except ImportError:
        raise ValueError(f"the colormap preset {name!r} needs matplotlib: pip install matplotlib") from None
    try:
        cmap = matplotlib.colormaps[name]
    except KeyError:
        raise ValueError(f"matplotlib has no colormap {name!r}") from None
    return ramp_preset(data, [tuple(float(c) for c in rgba[:3]) for rgba in cmap(np.linspace(0, 1, 9))], peak=peak)


def looks_like_hu(data):
    """CT in Hounsfield units: signed values reaching down to air (about -1000) and up
    to bone."""
    if isinstance(data, TetMesh):
        return False
    lo, hi = window(data, 0.5, 99.5)
    return lo <= -500 and hi >= 200


def ct_preset(data, kind="ct") -> TransferFunction:
    """CT in Hounsfield units: ``ct`` skin a faint flesh-coloured veil and bone ivory;
    ``ct_bone`` bone alone; ``ct_lung`` the lungs' airways and vessels. Unit distance one
    voxel; meant to be lit."""
    _, unit = _sample_values(data)
    if kind == "ct_bone":
        return TransferFunction(color=[(150, 0.75, 0.55, 0.40), (400, 0.95, 0.88, 0.74), (1500, 1.0, 1.0, 0.96)],
                                opacity=[(150, 0.0), (300, 0.25), (1000, 0.85)], unit_distance=unit)
    if kind == "ct_lung":
        return TransferFunction(color=[(-950, 0.55, 0.65, 0.85), (-600, 0.85, 0.55, 0.55), (0, 0.9, 0.3, 0.25)],
                                opacity=[(-1000, 0.0), (-920, 0.0), (-800, 0.02), (-600, 0.0), (-200, 0.0),
                                         (0, 0.15), (200, 0.0)], unit_distance=unit)
    return TransferFunction(
        color=[(-600, 0.55, 0.25, 0.15), (-100, 0.85, 0.55, 0.45), (100, 0.88, 0.60, 0.48),
               (300, 0.90, 0.80, 0.62), (1200, 1.00, 0.98, 0.92)],
        opacity=[(-600, 0.0), (-300, 0.0), (-100, 0.03), (100, 0.01), (200, 0.0), (300, 0.15),
                 (1200, 0.7)], unit_distance=unit)


#: the Hounsfield window each 8-bit CT preset assumes the data was made with, (lo, hi):
#: stored 0 is ``lo`` HU (and everything below), 255 is ``hi`` (and everything above).
#: ``ct_bone_8bit``: the usual bone window, width 1800 and level 400; ``ct_lung_8bit``:
#: the usual lung window, W1500 L-600. ``ct_8bit`` (skin and bone together) W1000 L100:
#: the usual soft-tissue window (W400 L40) puts stored 0, the air around the body, at
#: -160 HU, inside ``ct``'s skin veil, and cuts bone off at 240 HU, below where ``ct``
#: makes it opaque; on a chest CT windowed to 8 bits, W1000 L100 shows skin, heart and
#: ribs (docs/guide/install.md, "The first picture"). ``NAME:LO,HI`` gives the window the data was made with.
CT_8BIT_WINDOWS = {"ct_8bit": (-400.0, 600.0), "ct_bone_8bit": (-500.0, 1300.0), "ct_lung_8bit": (-1350.0, 150.0)}
#: the highest stored value of 8-bit data: the window's top
STORED_MAX = 255.0


def parse_hu_window(text):
    """``"LO,HI"`` (Hounsfield units, LO < HI) -> (lo, hi); a ValueError says what is wrong."""
    parts = [p.strip() for p in str(text).split(",")]
    try:
        if len(parts) != 2:
            raise ValueError
        lo, hi = (float(p) for p in parts)
    except ValueError:
        raise ValueError(f"the window must be two numbers LO,HI in Hounsfield units (such as -160,240), "
                         f"got {text!r}") from None
    if not (np.isfinite(lo) and np.isfinite(hi)) or lo >= hi:
        raise ValueError(f"the window LO,HI must be finite with LO < HI, got {text!r}")
    return lo, hi


def stored_to_hu(v, window):
    """The Hounsfield value that stored 8-bit value ``v`` stands for under ``window``
    (lo, hi): lo + (hi - lo) v / 255, linear (as windowing maps HU onto 0..255)."""
    lo, hi = window
    return lo + (hi - lo) * np.asarray(v, dtype=np.float64) / STORED_MAX


def ct_8bit_preset(data, kind="ct_8bit", window=None) -> TransferFunction:
    """A CT preset for CT windowed to 8 bits: stored values 0..255 stand for the Hounsfield
    ``window`` (lo, hi) linearly (default: ``CT_8BIT_WINDOWS[kind]``), and the colour and
    opacity at stored ``v`` are the HU preset's (``ct``, ``ct_bone``, ``ct_lung`` for
    ``kind`` without ``_8bit``) at ``stored_to_hu(v, window)``.

    The HU preset is piecewise linear and the map affine, so their composition is
    piecewise linear in stored values with the HU control points inside the window as
    knots, plus the window's ends at 0 and 255: the result equals the HU preset at the
    window's HU for every stored value in 0..255 (to float rounding; no resampling).
    Data outside 0..255 is an error: it was not windowed to 8 bits."""
    if kind not in CT_8BIT_WINDOWS:
        raise ValueError(f"no 8-bit CT preset {kind!r}; there are {', '.join(CT_8BIT_WINDOWS)}")
    lo, hi = CT_8BIT_WINDOWS[kind] if window is None else window
    if not (np.isfinite(lo) and np.isfinite(hi)) or lo >= hi:
        raise ValueError(f"the window must be finite with low < high, got {window!r}")
    d_lo, d_hi = data.data_range
    if d_lo < 0 or d_hi > STORED_MAX:
        raise ValueError(f"{kind} is for CT windowed to 8 bits (stored values 0..255); these values run "
                         f"{d_lo:g}..{d_hi:g}; for CT in Hounsfield units use {kind[:-len('_8bit')]}")
    hu_tf = ct_preset(data, kind[:-len("_8bit")])

    def through_window(points, values):
        inner = points[:, 0][(points[:, 0] > lo) & (points[:, 0] < hi)]
        hu = np.concatenate([[lo], inner, [hi]])
        stored = np.concatenate([[0.0], (inner - lo) * (STORED_MAX / (hi - lo)), [STORED_MAX]])
        return [(float(v), *(float(c) for c in np.atleast_1d(row))) for v, row in zip(stored, values(hu))]

    return TransferFunction(color=through_window(hu_tf.color_points, hu_tf.color),
                            opacity=through_window(hu_tf.opacity_points, hu_tf.opacity),
                            unit_distance=hu_tf.unit_distance)


def is_8bit(data):
    """Stored as 8-bit samples (uint8), as CT windowed for display is."""
    return not isinstance(data, TetMesh) and data.data.dtype == np.uint8


def mr_preset(data) -> TransferFunction:
    """MRI: the background (the darkest two fifths of the samples) clear, tissue from
    pink to white, opacity rising to 0.6 at the 99.5th percentile; meant to be lit."""
    lo, hi = window(data, 40.0, 99.5)
    return ramp_preset(data, [(0.55, 0.30, 0.28), (0.92, 0.72, 0.66), (1.0, 0.97, 0.93)], lo, hi, peak=0.6)


def auto_preset(volume, unit_distance=None) -> TransferFunction:
    """The preset the data suggests: 8-bit data whose metadata says CT (``modality``)
    gets ``ct_8bit``; CT in Hounsfield units ``ct``; an MRI (modality MR, or a volume
    with an anatomical orientation, from NIfTI, NRRD, MetaImage or DICOM) ``mr``; a mesh
    the ``coolwarm`` ramp over the 1st to 99th percentile; anything else the ``warm`` ramp
    (dark red to ivory) from the median to the 99.5th percentile; opacity rising from 0
    to 0.5. Unit distance one voxel (the smallest spacing; a mesh: the median edge
    length); a given ``unit_distance`` keeps to the ramps. 8-bit data without metadata is
    not taken for CT: MR scans and microscopy have most samples at 0 too."""
    name = auto_preset_name(volume)
    if name == "ct_8bit" and unit_distance is None:
        return ct_8bit_preset(volume)
    if name == "ct" and unit_distance is None:
        return ct_preset(volume)
    if name == "mr" and unit_distance is None:
        return mr_preset(volume)
    if isinstance(volume, TetMesh):
        return ramp_preset(volume, RAMPS["coolwarm"], unit_distance=unit_distance)
    # a scan's lower half is mostly background or noise: the ramp starts at the median
    lo, hi = window(volume, 50.0, 99.5)
    return ramp_preset(volume, RAMPS["warm"], lo, hi, unit_distance=unit_distance)


def auto_preset_name(data):
    """The name of the preset :func:`auto_preset` picks."""
    modality = getattr(data, "modality", None)
    if modality == "CT" and is_8bit(data):
        return "ct_8bit"
    if looks_like_hu(data):
        return "ct"
    if modality == "MR" or is_oriented_scan(data):
        return "mr"
    return "coolwarm ramp" if isinstance(data, TetMesh) else "warm ramp"


def is_oriented_scan(data):
    """Whether the file (or the user) says where the patient's axes are: an orientation
    that is only the format's convention (``Volume.orientation_assumed``) does not count."""
    return getattr(data, "orientation", None) is not None and not getattr(data, "orientation_assumed", False)


def read_json_object(path):
    """The JSON object a transfer function file holds, or a ValueError naming the file."""
    with open(path) as f:
        try:
            spec = json.load(f)
        except json.JSONDecodeError as e:
            raise ValueError(f"transfer function file {os.fspath(path)!r} is not valid JSON: {e}") from None
    if not isinstance(spec, dict):
        raise ValueError(f"transfer function file {os.fspath(path)!r} must hold a JSON object, got {type(spec).__name__}")
    return spec


def load_tf_json(path) -> TransferFunction:
    """Read ``{"color": [[s, r, g, b], ...], "opacity": [[s, a], ...], "unit_distance": u}``."""
    spec = read_json_object(path)
    missing = {"color", "opacity"} - spec.keys()
    if missing:
        raise ValueError(f"transfer function file {os.fspath(path)!r} lacks {sorted(missing)}")
    unknown = spec.keys() - {"color", "opacity", "unit_distance"}
    if unknown:
        raise ValueError(f"transfer function file {os.fspath(path)!r} has unknown keys {sorted(unknown)}")
    return TransferFunction(spec["color"], spec["opacity"], spec.get("unit_distance", 1.0))


def save_tf_json(path, tf: TransferFunction):
    """Write ``tf`` as the JSON :func:`load_tf_json` reads (and ``dvr-gl render --tf
    FILE``), one control point per line. Numbers are written with Python's shortest
    round-tripping ``repr``, so loading the file gives back exactly the same function.
    The write is atomic (:func:`dvr_gl.util.files.atomic_write`). Returns ``path``."""
    from ..util.files import atomic_write

    if not isinstance(tf, TransferFunction):
        raise TypeError(f"tf must be a dvr_gl.TransferFunction, got {type(tf).__name__}")
    spec = tf.to_dict()

    def rows(points):
        return ",\n".join("    " + json.dumps([float(v) for v in row]) for row in points)

    text = ("{\n"
            f'  "color": [\n{rows(spec["color"])}\n  ],\n'
            f'  "opacity": [\n{rows(spec["opacity"])}\n  ],\n'
            f'  "unit_distance": {json.dumps(float(spec["unit_distance"]))}\n'
            "}\n")
    atomic_write(os.fspath(path), text.encode("utf-8"))
    return path


def correct_opacity(alpha, length_over_unit, transparency=None):
    """Opacity of a segment ``length_over_unit`` unit distances long whose unit-distance
    opacity is ``alpha``: ``1 - (1 - alpha)^(L/u)``, computed as
    ``-expm1(L/u * log(1 - alpha))`` so small opacities keep their relative precision
    (GLSL ``correctOpacity``). ``log(1 - alpha)`` is taken from ``alpha`` up to 0.5 and
    from ``transparency`` (= 1 - alpha, precise near 1) above, when it is given.
    alpha = 1 gives 1 for any positive length; a zero length gives 0."""
    a = np.asarray(alpha, np.float64)
    x = np.asarray(length_over_unit, np.float64)
    b = 1 - a if transparency is None else np.asarray(transparency, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        log_t = np.where(a <= 0.5, np.log1p(-np.minimum(a, 0.5)), np.log(np.maximum(b, 0)))
        out = -np.expm1(x * log_t)
    return np.where(x <= 0, 0.0, np.where((a >= 1) | (b <= 0), 1.0, out))


class SegmentKnots:
    """The transfer function as the shader's knot table: positions, colour, opacity and
    transparency (1 - opacity, exact from the control points) at every knot. A single
    knot is doubled so that every value lies in (or beyond) one interval."""

    def __init__(self, tf):
        k = tf.knots
        if k.size == 1:
            k = np.array([k[0], k[0] + 1.0])
        self.s = k
        self.color = tf.color(k)
        self.alpha = tf.opacity(k)
        self.transparency = 1.0 - self.alpha
        self.inv_unit = 1.0 / tf.unit_distance

    @property
    def count(self):
        return self.s.size

    def texture_rows(self):
        """(2, count, 4) float32: row 0 (s, r, g, b), row 1 (alpha, 1 - alpha, 0, 0)."""
        rows = np.zeros((2, self.count, 4), np.float32)
        rows[0, :, 0] = self.s
        rows[0, :, 1:] = self.color
        rows[1, :, 0] = self.alpha
        rows[1, :, 1] = self.transparency
        return rows

    def at(self, j, s):
        """(colour, alpha, transparency) at values s on the lines of intervals j (-1:
        below the first knot, count - 1: above the last; constant there)."""
        n = self.count
        jj = np.clip(j, 0, n - 2)
        f = (s - self.s[jj]) / (self.s[jj + 1] - self.s[jj])
        f = np.where(j < 0, 0.0, np.where(j >= n - 1, 1.0, np.clip(f, 0.0, 1.0)))
        c = self.color[jj] * (1 - f)[:, None] + self.color[jj + 1] * f[:, None]
        a = self.alpha[jj] * (1 - f) + self.alpha[jj + 1] * f
        w = self.transparency[jj] * (1 - f) + self.transparency[jj + 1] * f
        return c, a, w
