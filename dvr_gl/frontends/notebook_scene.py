"""The volume widget's cuts and surfaces: its clip planes, crop box and opaque geometry,
held as the widget's controls hold them (plain values a browser sends and shows), and
turned into what a Scene takes (``clip_planes``, ``crop_box``, ``geometry``).

A clip plane's control is ``{"on", "axis", "flip", "offset"}``: ``axis`` is the normal
(``x``, ``y``, ``z``, or ``oblique``: the normal the plane was given with), ``offset``
the plane's place along that normal in world units (from the data's one end to the
other, ``clip_limits``), and ``flip`` keeps the other side without moving the plane. A
new normal keeps the plane through the point it went through. The crop box's control is
``[[x0, x1], [y0, y1], [z0, z1]]`` within the data's bounds; the whole of the bounds
is no crop at all.
"""

from __future__ import annotations

import itertools

import numpy as np

from .. import formats as dvr_io
from ..model.clipping import check_clip_planes, check_crop_box
from ..model.geometry import Surface

AXES = ("x", "y", "z")
NORMALS = AXES + ("oblique",)
CLIP_KEYS = ("on", "axis", "flip", "offset")


def load_surfaces(geometry):
    """``geometry`` (a Surface, a surface file, or a sequence of them) as a tuple of
    Surfaces, files read by ``formats.load_surface`` as ``--geometry`` reads them; a file
    that cannot be read or anything else is an InputError naming ``geometry``."""
    if geometry is None:
        return ()
    items = (geometry,) if isinstance(geometry, (str, bytes, Surface)) or hasattr(geometry, "__fspath__") \
        else geometry
    try:
        items = tuple(items)
    except TypeError:
        raise dvr_io.InputError("geometry", f"expected dvr_gl.Surface objects or surface files, "
                                            f"got {geometry!r}") from None
    surfaces = []
    for i, item in enumerate(items):
        if isinstance(item, Surface):
            surfaces.append(item)
            continue
        if not (isinstance(item, str) or hasattr(item, "__fspath__")):
            raise dvr_io.InputError("geometry", f"geometry[{i}] must be a dvr_gl.Surface or a surface file, "
                                                f"got {type(item).__name__}")
        try:
            surfaces.append(dvr_io.load_surface(item))
        except dvr_io.InputError as e:
            raise dvr_io.InputError("geometry", e.detail) from None
    return tuple(surfaces)


def _number(field, value):
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise dvr_io.InputError(field, f"must be a number, got {value!r}")
    value = float(value)
    if not np.isfinite(value):
        raise dvr_io.InputError(field, f"must be finite, got {value!r}")
    return value


def _within(field, value, lo, hi, what):
    """``value`` clamped into [lo, hi] when it misses by a rounding (a browser's slider),
    an InputError when it misses by more."""
    slack = 1e-9 * max(hi - lo, 1.0)
    if not lo - slack <= value <= hi + slack:
        raise dvr_io.InputError(field, f"{value:g} lies outside the data {what} ({lo:g} to {hi:g})")
    return min(max(value, lo), hi)


class SceneCuts:
    """The clip planes and crop box of one widget over ``data``: the planes it was given
    (``clip_planes``: ``(point, normal)`` pairs; none: one plane, off, through the data's
    centre across z, whose ``oblique`` normal is ``default_normal``) and its ``crop_box`` (``(lower, upper)``, cut to
    the data's bounds). Bad ones are InputErrors naming ``clip_planes`` or ``crop_box``."""

    def __init__(self, data, clip_planes=(), crop_box=None, default_normal=(0.0, 0.0, -1.0)):
        lo, hi = (np.asarray(b, np.float64) for b in data.bounds)
        self.lower, self.upper = lo, hi
        try:
            planes = check_clip_planes(clip_planes)
        except (TypeError, ValueError) as e:
            raise dvr_io.InputError("clip_planes", str(e)) from None
        self.given = bool(planes)
        if not planes:
            planes = (((lo + hi) / 2, np.asarray(default_normal, np.float64)),)
        # each plane's point (it moves when its normal changes) and the normal it was given
        self.points = [np.array(p, np.float64) for p, _ in planes]
        self.normals = [np.array(n, np.float64) for _, n in planes]
        try:
            box = check_crop_box(crop_box, (lo, hi))
        except (TypeError, ValueError) as e:
            raise dvr_io.InputError("crop_box", str(e)) from None
        if box is not None:
            box = np.maximum(box[0], lo), np.minimum(box[1], hi)
            if not np.all(box[0] < box[1]):
                raise dvr_io.InputError("crop_box", f"{crop_box!r} only touches the data's boundary "
                                                    f"({tuple(lo)} to {tuple(hi)}): it keeps nothing")
        self.initial_crop = [[float(a), float(b)] for a, b in zip(*(box if box is not None else (lo, hi)))]

    # -- clip planes ---------------------------------------------------------------------
    def _unit(self, i, axis):
        """The unit normal that ``axis`` names for plane ``i`` (unflipped)."""
        if axis == "oblique":
            return self.normals[i] / np.linalg.norm(self.normals[i])
        return np.eye(3)[AXES.index(axis)]

    def limits(self, i, axis):
        """[lowest, highest] offset along ``axis``'s normal that meets the data."""
        if axis in AXES:
            k = AXES.index(axis)
            return [float(self.lower[k]), float(self.upper[k])]
        corners = np.array(list(itertools.product(*zip(self.lower, self.upper))))
        along = corners @ self._unit(i, axis)
        return [float(along.min()), float(along.max())]

    def all_limits(self):
        """Per plane, ``{axis: [lowest, highest]}`` (the offset slider's ends)."""
        return [{axis: self.limits(i, axis) for axis in NORMALS} for i in range(len(self.points))]

    def initial_clip(self):
        """The controls of the planes as given: an axis-aligned normal is that axis
        (flipped where it points down it), any other ``oblique``."""
        states = []
        for i, (point, normal) in enumerate(zip(self.points, self.normals)):
            nonzero = np.flatnonzero(normal)
            if not self.given:                 # the plane offered: z, "oblique" faces the first view
                axis, flip = "z", False
            elif len(nonzero) == 1:
                axis, flip = AXES[nonzero[0]], bool(normal[nonzero[0]] < 0)
            else:
                axis, flip = "oblique", False
            lo, hi = self.limits(i, axis)
            offset = float(point @ self._unit(i, axis))
            states.append({"on": self.given, "axis": axis, "flip": flip, "offset": min(max(offset, lo), hi)})
        return states

    def _point(self, i, state):
        """Plane ``i``'s point under ``state``: its point moved along the normal to ``offset``."""
        point, axis = self.points[i], state["axis"]
        if axis in AXES:
            moved = point.copy()
            moved[AXES.index(axis)] = state["offset"]       # exact: the other coordinates stay
            return moved
        unit = self._unit(i, axis)
        along = float(point @ unit)
        return point if state["offset"] == along else point + (state["offset"] - along) * unit

    def check_clip(self, states, previous=()):
        """``states`` (the controls of every plane) checked, each a fresh dict; a plane
        whose normal changes from ``previous`` keeps going through the point it went
        through (its offset follows, unless also changed). InputError naming ``clip``."""
        if not isinstance(states, (list, tuple)) or len(states) != len(self.points):
            raise dvr_io.InputError("clip", f"expected {len(self.points)} clip plane control(s), got {states!r}")
        out = []
        for i, state in enumerate(states):
            field = f"clip[{i}]"
            if not isinstance(state, dict) or set(state) != set(CLIP_KEYS):
                raise dvr_io.InputError(field, f"expected a dict of {', '.join(CLIP_KEYS)}, got {state!r}")
            for key in ("on", "flip"):
                if not isinstance(state[key], (bool, np.bool_)):
                    raise dvr_io.InputError(f"{field}.{key}", f"must be True or False, got {state[key]!r}")
            if state["axis"] not in NORMALS:
                raise dvr_io.InputError(f"{field}.axis", f"must be one of {', '.join(NORMALS)}, "
                                                         f"got {state['axis']!r}")
            offset = _number(f"{field}.offset", state["offset"])
            old = previous[i] if i < len(previous) else None
            if old is not None and old["axis"] != state["axis"]:
                self.points[i] = self._point(i, old)          # where the plane is now
                if offset == old["offset"]:
                    lo, hi = self.limits(i, state["axis"])
                    offset = min(max(float(self.points[i] @ self._unit(i, state["axis"])), lo), hi)
            lo, hi = self.limits(i, state["axis"])
            offset = _within(f"{field}.offset", offset, lo, hi, f"along {state['axis']}")
            out.append({"on": bool(state["on"]), "axis": state["axis"], "flip": bool(state["flip"]),
                        "offset": offset})
        return out

    def clip_planes(self, states):
        """The Scene's ``clip_planes`` for the controls ``states``: the planes that are on."""
        planes = []
        for i, state in enumerate(states):
            if state["on"]:
                normal = self.normals[i] if state["axis"] == "oblique" else self._unit(i, state["axis"])
                planes.append((self._point(i, state), -normal if state["flip"] else normal.copy()))
        return tuple(planes)

    # -- crop box ------------------------------------------------------------------------
    def check_crop(self, crop):
        """``[[x0, x1], [y0, y1], [z0, z1]]`` checked: within the data's bounds, each
        lower end below its upper end. InputError naming ``crop``."""
        try:
            pairs = [list(pair) for pair in crop]
        except TypeError:
            pairs = None
        if pairs is None or len(pairs) != 3 or any(len(p) != 2 for p in pairs):
            raise dvr_io.InputError("crop", f"expected [[x0, x1], [y0, y1], [z0, z1]], got {crop!r}")
        out = []
        for k, (axis, (a, b)) in enumerate(zip(AXES, pairs)):
            field = f"crop.{axis}"
            lo, hi = float(self.lower[k]), float(self.upper[k])
            a = _within(field, _number(field, a), lo, hi, f"along {axis}")
            b = _within(field, _number(field, b), lo, hi, f"along {axis}")
            if not a < b:
                raise dvr_io.InputError(field, f"the lower end must be below the upper end, got {a:g} to {b:g}")
            out.append([a, b])
        return out

    def crop_box(self, crop):
        """The Scene's ``crop_box`` for the control ``crop``: None for the whole data."""
        lower = np.array([a for a, _ in crop], np.float64)
        upper = np.array([b for _, b in crop], np.float64)
        if np.array_equal(lower, self.lower) and np.array_equal(upper, self.upper):
            return None
        return lower, upper


def summary(planes, crop_box, surfaces):
    """A few words for the status line: what cuts the data and what is drawn in it."""
    words = []
    if planes:
        words.append(f"{len(planes)} clip plane" + ("s" if len(planes) > 1 else ""))
    if crop_box is not None:
        words.append("crop box")
    if surfaces:
        words.append(f"{len(surfaces)} surface" + ("s" if len(surfaces) > 1 else ""))
    return ", ".join(words)


# The browser side of the controls: a row per clip plane (on, normal, flip, offset), a
# two-thumb range slider per axis for the crop box, a checkbox for the surfaces. ``push``
# sends a change as the view is sent (one in flight at a time); ``latest`` is a value
# with the changes not yet sent.
CONTROLS_JS = r"""
function cutControls(model, push, latest) {
  const box = document.createElement("div");
  box.className = "dvr-gl-cuts";
  const make = (tag, cls, props) => Object.assign(document.createElement(tag), { className: cls }, props || {});
  const labelled = (text, input) => {
    const label = document.createElement("label");
    label.append(text + " ", input);
    return label;
  };
  const slider = (cls) => make("input", cls, { type: "range", step: "any" });
  const show = (v) => {
    const a = Math.abs(v);
    return a !== 0 && (a < 0.01 || a >= 1e5) ? v.toExponential(2) : v.toFixed(a < 10 ? 2 : 1);
  };

  const planes = model.get("clip");
  planes.forEach((_, i) => {
    const row = make("div", "dvr-gl-row dvr-gl-clip");
    const on = make("input", "dvr-gl-clip-on", { type: "checkbox" });
    const axis = make("select", "dvr-gl-clip-axis");
    for (const name of ["x", "y", "z", "oblique"]) {
      axis.appendChild(make("option", "", { value: name, textContent: name }));
    }
    const flip = make("input", "dvr-gl-clip-flip", { type: "checkbox" });
    const offset = slider("dvr-gl-clip-offset");
    const value = make("span", "dvr-gl-value");
    row.append(labelled(planes.length > 1 ? "clip " + (i + 1) : "clip", on), labelled("normal", axis),
               labelled("flip", flip), offset, value);
    box.appendChild(row);
    const update = () => {
      const p = latest("clip")[i];
      const [lo, hi] = model.get("clip_limits")[i][p.axis];
      on.checked = p.on; axis.value = p.axis; flip.checked = p.flip;
      offset.min = lo; offset.max = hi; offset.value = p.offset;
      value.textContent = show(p.offset);
      for (const e of [axis, flip, offset]) e.disabled = !p.on;
    };
    const change = (fields) => {
      const next = latest("clip").map((p) => Object.assign({}, p));
      Object.assign(next[i], fields);
      push("clip", next);
    };
    on.addEventListener("change", () => change({ on: on.checked }));
    axis.addEventListener("change", () => change({ axis: axis.value }));
    flip.addEventListener("change", () => change({ flip: flip.checked }));
    offset.addEventListener("input", () => {
      value.textContent = show(Number(offset.value));
      change({ offset: Number(offset.value) });
    });
    model.on("change:clip", update);
    update();
  });

  ["x", "y", "z"].forEach((name, k) => {
    const row = make("div", "dvr-gl-row dvr-gl-crop");
    const track = make("span", "dvr-gl-range");
    const lower = slider("dvr-gl-crop-lower"), upper = slider("dvr-gl-crop-upper");
    const value = make("span", "dvr-gl-value");
    track.append(lower, upper);
    row.append(make("span", "dvr-gl-name", { textContent: "crop " + name }), track, value);
    box.appendChild(row);
    const update = () => {
      const [lo, hi] = model.get("bounds"), c = latest("crop")[k];
      for (const s of [lower, upper]) { s.min = lo[k]; s.max = hi[k]; }
      lower.value = c[0]; upper.value = c[1];
      value.textContent = show(c[0]) + " to " + show(c[1]);
    };
    const change = (which) => {
      const [lo, hi] = model.get("bounds"), gap = (hi[k] - lo[k]) / 400;
      let a = Number(lower.value), b = Number(upper.value);
      if (which === 0) a = Math.max(lo[k], Math.min(a, b - gap)); else b = Math.min(hi[k], Math.max(b, a + gap));
      if (!(a < b)) { update(); return; }
      lower.value = a; upper.value = b;
      value.textContent = show(a) + " to " + show(b);
      const next = latest("crop").map((c) => c.slice());
      next[k] = [a, b];
      push("crop", next);
    };
    lower.addEventListener("input", () => change(0));
    upper.addEventListener("input", () => change(1));
    model.on("change:crop", update);
    update();
  });

  if (model.get("geometry_count") > 0) {
    const row = make("div", "dvr-gl-row dvr-gl-surfaces");
    const on = make("input", "dvr-gl-geometry", { type: "checkbox" });
    const label = labelled("geometry (" + model.get("geometry_count") + ")", on);
    row.append(label);
    box.appendChild(row);
    const update = () => {
      const drawn = model.get("geometry_techniques").includes(model.get("technique"));
      on.checked = model.get("geometry_on");
      on.disabled = !drawn && !on.checked;
      label.title = drawn ? "" : model.get("technique") + " does not draw surfaces; " +
        model.get("geometry_techniques").join(", ") + " do";
    };
    on.addEventListener("change", () => { model.set("geometry_on", on.checked); model.save_changes(); });
    model.on("change:geometry_on", update);
    model.on("change:technique", update);
    update();
  }
  return box;
}
"""

CONTROLS_CSS = """
.dvr-gl-cuts { margin-bottom: 4px; }
.dvr-gl-row { display: flex; gap: 8px; align-items: center; height: 22px; }
.dvr-gl-row input[type=range] { width: 180px; margin: 0; }
.dvr-gl-name { width: 46px; }
.dvr-gl-value { color: #555; font-variant-numeric: tabular-nums; }
.dvr-gl-range { position: relative; display: inline-block; width: 180px; height: 18px; }
.dvr-gl-range input[type=range] { position: absolute; left: 0; top: 0; pointer-events: none; background: none; }
.dvr-gl-range input[type=range]::-webkit-slider-thumb { pointer-events: auto; }
.dvr-gl-range input[type=range]::-moz-range-thumb { pointer-events: auto; }
"""
