"""dvr_gl in Jupyter: images that show themselves, and an interactive volume widget.

- :class:`RenderedImage` is what :func:`dvr_gl.render` returns: a plain float32 NumPy
  array (premultiplied RGBA, row 0 on top) that Jupyter, through ``_repr_png_``, shows as
  a picture composited over its ``background`` (white unless set).
- :class:`VolumeWidget` (``pip install "dvr-gl[notebook]"``: anywidget) orbits, zooms and
  re-classifies a volume or mesh in the notebook, cuts it open with clip planes and a
  crop box around opaque surfaces (``notebook_scene``), and shows or hides each of
  several volumes (``notebook_layers``). The kernel renders every frame with the
  same headless renderer :func:`dvr_gl.render` uses (EGL, else OSMesa) and sends it as a
  PNG; the browser side only shows the frame and turns pointer and wheel events into a
  new view. While the pointer is down the kernel renders at half resolution, so a drag
  keeps up on llvmpipe; letting go renders the full frame.

Works wherever anywidget does: JupyterLab, Notebook 7, VS Code, Colab, Voila.
"""

from __future__ import annotations

import math
import time

import numpy as np

from . import inputs
from .notebook_layers import CHANNELS_PRESET, LAYERS_JS, load_volumes
from .notebook_scene import CONTROLS_CSS, CONTROLS_JS, SceneCuts, load_surfaces, summary
from .images import DEFAULT_BACKGROUND, RenderedImage, png_bytes  # noqa: F401 (RenderedImage: documented here)
from .. import formats as dvr_io
from ..model.layers import BLENDS
from ..rendering.pyramid import moving_volume, MOVING_SAMPLES


def has_pyramid_levels(data):
    """Whether ``data`` is a volume with pyramid levels (a multiscale store)."""
    return len(getattr(data, "levels", ()) or ()) > 1

try:
    import anywidget
    import traitlets
except ImportError:                     # the widget is an optional extra
    anywidget = None


# The browser side: shows the kernel's PNG frames, and turns drags, the wheel and the
# controls into a new view, clip planes, crop box or volumes shown. At most one change is in flight:
# the next is sent when the kernel's frame counter moves, so a slow renderer is never
# queued behind stale views.
_ESM = CONTROLS_JS + LAYERS_JS + r"""
function render({ model, el }) {
  const root = document.createElement("div");
  root.className = "dvr-gl-widget";
  const bar = document.createElement("div");
  bar.className = "dvr-gl-bar";
  const choose = (name, key, listKey) => {
    const label = document.createElement("label");
    label.textContent = name + " ";
    const select = document.createElement("select");
    select.className = "dvr-gl-" + key;
    const fill = () => {
      select.innerHTML = "";
      for (const option of model.get(listKey)) {
        const item = document.createElement("option");
        item.value = option; item.textContent = option;
        select.appendChild(item);
      }
      select.value = model.get(key);
    };
    fill();
    model.on("change:" + listKey, fill);
    model.on("change:" + key, () => { select.value = model.get(key); });
    select.addEventListener("change", () => { model.set(key, select.value); model.save_changes(); });
    label.appendChild(select);
    bar.appendChild(label);
  };
  choose("TF", "preset", "presets");
  choose("technique", "technique", "techniques");
  const reset = document.createElement("button");
  reset.className = "dvr-gl-reset";
  reset.textContent = "reset view";
  bar.appendChild(reset);

  const img = document.createElement("img");
  img.className = "dvr-gl-frame";
  img.draggable = false;
  const [width, height] = model.get("size");
  img.style.width = width + "px";
  img.style.height = height + "px";
  const status = document.createElement("div");
  status.className = "dvr-gl-status";
  root.append(bar, img, status);
  el.appendChild(root);

  let url = null;
  const showFrame = () => {
    const png = model.get("image");
    if (!png || png.byteLength === 0) return;
    const next = URL.createObjectURL(new Blob([png], { type: "image/png" }));
    img.src = next;
    if (url) URL.revokeObjectURL(url);
    url = next;
  };
  const showStatus = () => { status.textContent = model.get("status"); };

  let view = Object.assign({}, model.get("view"));
  let busy = false;
  const pending = {};
  const latest = (key) => key in pending ? pending[key] : model.get(key);
  const flush = () => {
    if (busy || Object.keys(pending).length === 0) return;
    busy = true;
    for (const key of Object.keys(pending)) { model.set(key, pending[key]); delete pending[key]; }
    model.save_changes();
  };
  // a value the kernel holds already would bring no frame back: it is not sent
  const push = (key, value) => {
    if (!(key in pending) && JSON.stringify(value) === JSON.stringify(model.get(key))) return;
    pending[key] = value;
    flush();
  };
  const send = () => push("view", Object.assign({}, view));
  model.on("change:image", showFrame);
  model.on("change:status", showStatus);
  model.on("change:frame", () => { busy = false; flush(); });
  model.on("change:view", () => { if (!busy && !("view" in pending)) view = Object.assign({}, model.get("view")); });
  root.insertBefore(layerControls(model, push, latest), img);
  root.insertBefore(cutControls(model, push, latest), img);

  let drag = null;
  img.addEventListener("pointerdown", (e) => {
    drag = { x: e.clientX, y: e.clientY };
    img.setPointerCapture(e.pointerId);
    view.coarse = true;
    e.preventDefault();
  });
  img.addEventListener("pointermove", (e) => {
    if (!drag) return;
    const turn = model.get("degrees_per_pixel");
    view.azimuth -= (e.clientX - drag.x) * turn;
    view.elevation = Math.max(-89, Math.min(89, view.elevation + (e.clientY - drag.y) * turn));
    drag = { x: e.clientX, y: e.clientY };
    send();
  });
  const release = (e) => {
    if (!drag) return;
    drag = null;
    view.coarse = false;
    send();
  };
  img.addEventListener("pointerup", release);
  img.addEventListener("pointercancel", release);
  img.addEventListener("wheel", (e) => {
    view.zoom = Math.max(0.1, Math.min(20, view.zoom * Math.exp(-e.deltaY * 0.002)));
    send();
    e.preventDefault();
  }, { passive: false });
  reset.addEventListener("click", () => {
    view = Object.assign({}, model.get("home"), { coarse: false });
    send();
  });
  showFrame();
  showStatus();
  return () => { if (url) URL.revokeObjectURL(url); };
}
export default { render };
"""

_CSS = CONTROLS_CSS + """
.dvr-gl-widget { display: inline-block; font: 12px sans-serif; }
.dvr-gl-bar { display: flex; gap: 12px; align-items: center; margin-bottom: 4px; }
.dvr-gl-frame { display: block; cursor: grab; touch-action: none; user-select: none; }
.dvr-gl-status { color: #555; margin-top: 2px; }
"""


def _size_pair(size):
    try:
        width, height = (int(size), int(size)) if np.isscalar(size) else (int(size[0]), int(size[1]))
    except (TypeError, ValueError, IndexError):
        raise dvr_io.InputError("size", f"expected an int or (width, height), got {size!r}") from None
    if not (8 <= width <= 4096 and 8 <= height <= 4096):
        raise dvr_io.InputError("size", f"each side must be 8 to 4096 pixels, got {width}x{height}")
    return width, height


if anywidget is not None:
    class ControlError(dvr_io.InputError, traitlets.TraitError):
        """A bad value for one of the widget's controls: an InputError naming it, and a
        TraitError, so that a browser's message that carried it is undone whole."""

    class VolumeWidget(anywidget.AnyWidget):
        """An interactive view of a volume or mesh in a notebook.

        >>> from dvr_gl.frontends.notebook import VolumeWidget                # doctest: +SKIP
        >>> VolumeWidget("head.nii.gz")                              # doctest: +SKIP

        ``source``: anything :func:`dvr_gl.render` takes (a file, ``builtin:NAME``, an
        array, a Volume or TetMesh). ``tf``: the first preset (default: the data's);
        ``technique``: the first technique (default: raycast for grids, tetra for meshes);
        ``size``: the frame in pixels; other keywords are the technique's options
        (``step``, ``sort``, ...) and apply while it is the one chosen. Drag to orbit,
        the wheel zooms; the bar picks the preset and the technique. ``view``,
        ``preset`` and ``technique`` can be set from Python too; ``image_array`` is
        the last frame as a float array, ``status`` says what it was or what went wrong.

        ``clip_planes`` (``(point, normal)`` pairs), ``crop_box`` (``(lower, upper)``)
        and ``geometry`` (:class:`dvr_gl.Surface` objects or surface files) are those of
        :class:`dvr_gl.Scene`. Controls under the bar move them: per clip plane an on/off
        box, its normal (x, y, z or ``oblique``, the one it was given), a flip box and its
        offset along the normal (with none given: one plane, off, across z through the
        data's centre, its ``oblique`` normal facing the first view); the crop box's x, y
        and z ranges; the surfaces on or off. From Python: ``clip`` (a list of ``{"on", "axis", "flip",
        "offset"}``, the offset's ends in ``clip_limits``), ``crop`` (``[[x0, x1], [y0,
        y1], [z0, z1]]`` within ``bounds``) and ``geometry_on``; a bad value is an
        InputError naming it. :meth:`scene_options` is what they give the Scene. A change
        the technique cannot draw (surfaces with a technique that does not draw them) is
        refused, as in the viewer: the value stays and ``status`` says why.

        ``layers``, ``labels``, ``channels`` and ``blend``: several volumes, as
        :func:`dvr_gl.render` takes them (``notebook_layers``), rendered by the techniques
        that render layers, unlit. A checkbox per volume shows or hides it (``shown``, a
        bool per volume of ``volume_names``), by the viewer's rules: the first volume shown
        must be a scan, one stays shown; a menu picks the ``blend`` (of ``blends``, those the
        mode allows). The preset menu classifies volume 1.
        """

        _esm = _ESM
        _css = _CSS
        image = traitlets.Bytes(b"").tag(sync=True)
        frame = traitlets.Int(0).tag(sync=True)
        status = traitlets.Unicode("").tag(sync=True)
        size = traitlets.List([384, 384]).tag(sync=True)
        view = traitlets.Dict().tag(sync=True)
        home = traitlets.Dict().tag(sync=True)
        preset = traitlets.Unicode("auto").tag(sync=True)
        presets = traitlets.List().tag(sync=True)
        technique = traitlets.Unicode("raycast").tag(sync=True)
        techniques = traitlets.List().tag(sync=True)
        degrees_per_pixel = traitlets.Float(0.5).tag(sync=True)
        clip = traitlets.List().tag(sync=True)
        clip_limits = traitlets.List().tag(sync=True)
        crop = traitlets.List().tag(sync=True)
        bounds = traitlets.List().tag(sync=True)
        geometry_on = traitlets.Bool(False).tag(sync=True)
        geometry_count = traitlets.Int(0).tag(sync=True)
        geometry_techniques = traitlets.List().tag(sync=True)
        shown = traitlets.List().tag(sync=True)
        volume_names = traitlets.List().tag(sync=True)
        blend = traitlets.Unicode("").tag(sync=True)
        blends = traitlets.List().tag(sync=True)
        moving_samples = MOVING_SAMPLES   # a pyramid's level while dragging: the finest this small

        def __init__(self, source, *, tf=None, technique=None, size=384, azimuth=None, elevation=None,
                     zoom=1.0, background=DEFAULT_BACKGROUND, clip_planes=(), crop_box=None, geometry=(),
                     layers=(), labels=None, channels=False, blend=None, **options):
            self._volumes = volumes = load_volumes(source, tf, layers, labels, channels, blend, options)
            if volumes is None:
                data, default_preset = inputs.load_input(source)
            else:
                data, default_preset = volumes.volume, volumes.preset
                options.pop("shading", None)           # several volumes are unlit (load_volumes checked)
            framing = data if volumes is None else volumes.framing
            width, height = _size_pair(size)
            from ..techniques import for_data
            names = [name for name in for_data(data) if volumes is None or name in _common().LAYER_TECHNIQUES]
            if technique is None:
                technique = names[0]
            elif technique not in names:
                raise dvr_io.InputError("technique", f"{technique!r} does not render "
                                                     f"{'this data' if volumes is None else 'several volumes'} in the "
                                                     f"widget; choose one of {', '.join(names)}")
            self._ready = False                # the checks of a change wait for the whole widget
            self._surfaces = load_surfaces(geometry)
            if self._surfaces and self._cannot_draw(technique, True, False):
                raise dvr_io.InputError("geometry", f"is drawn by technique {', '.join(_common().GEOMETRY_TECHNIQUES)}"
                                                    f", not {technique}")
            if volumes is None and inputs._is_lazy(data):     # a store: presets would read every sample
                presets = ["auto"]
            else:
                presets = inputs.suitable_presets(data) if volumes is None or not volumes.channels else []
            if default_preset not in presets:
                presets.insert(0, default_preset)
            preset = default_preset if tf is None else tf
            self._tfs = {} if volumes is None else {preset if isinstance(preset, str) else "given": volumes.tf}
            self._data = data
            self._default_preset = default_preset
            self._options = dict(options)
            self._options_for = technique
            self._background = background
            self.image_array = None
            self._tf_for(preset)          # a bad tf is an error now, not in the first frame
            if isinstance(preset, str) and preset not in presets:
                presets.append(preset)
            home = {"azimuth": inputs.FIRST_AZIMUTH if azimuth is None else float(azimuth),
                    "elevation": inputs.FIRST_ELEVATION if elevation is None else float(elevation),
                    "zoom": float(zoom), "coarse": False}
            facing = inputs.first_camera(framing, azimuth=home["azimuth"], elevation=home["elevation"]).forward
            self._cuts = SceneCuts(framing, clip_planes, crop_box, default_normal=facing)
            if self._cuts.given or crop_box is not None:
                reason = self._cannot_draw(technique, bool(self._surfaces), True)
                if reason:
                    raise dvr_io.InputError("clip_planes" if self._cuts.given else "crop_box", reason)
            super().__init__(size=[width, height], presets=presets, techniques=names, home=home,
                             view=dict(home), technique=technique,
                             preset=preset if isinstance(preset, str) else "given",
                             clip=self._cuts.initial_clip(), clip_limits=self._cuts.all_limits(),
                             crop=self._cuts.initial_crop,
                             bounds=[self._cuts.lower.tolist(), self._cuts.upper.tolist()],
                             geometry_on=bool(self._surfaces), geometry_count=len(self._surfaces),
                             geometry_techniques=list(_common().GEOMETRY_TECHNIQUES),
                             **({} if volumes is None else {"shown": volumes.shown, "volume_names": list(volumes.names),
                                                            "blend": volumes.blend, "blends": volumes.blends()}))
            if not isinstance(preset, str):
                self.presets = self.presets + ["given"]
            # the values last taken: a browser's message sets every value before checking any
            self._taken = {name: getattr(self, name) for name in ("technique", "geometry_on", "clip", "crop")}
            self._ready = True
            self.observe(self._on_change, names=["view", "preset", "technique", "clip", "crop", "geometry_on",
                                                 "shown", "blend"])
            self.render_frame()

        def scene_options(self):
            """``clip_planes``, ``crop_box`` and ``geometry`` as the controls set them: what
            the next frame's Scene (and ``dvr_gl.render``) is given."""
            return {"clip_planes": self._cuts.clip_planes(self.clip), "crop_box": self._cuts.crop_box(self.crop),
                    "geometry": self._surfaces if self.geometry_on else ()}

        def _cannot_draw(self, technique, surfaces, clips):
            """Why ``technique`` cannot draw the surfaces (when shown) or the cuts, or None:
            the techniques' own lists say which draw them."""
            drawing, clipping = _common().GEOMETRY_TECHNIQUES, _common().CLIPPING_TECHNIQUES
            if self._volumes is not None and technique not in _common().LAYER_TECHNIQUES:
                return (f"{technique} renders one volume; several are rendered by "
                        f"{', '.join(_common().LAYER_TECHNIQUES)}")
            if surfaces and technique not in drawing:
                return (f"{technique} does not draw surfaces; {', '.join(drawing)} do "
                        f"(untick geometry to use {technique})")
            if clips and technique not in clipping:
                return f"{technique} does not clip; {', '.join(clipping)} do (turn the cuts off first)"
            return None

        def _refuse(self, proposal, value, what, technique=None, surfaces=None, clips=None):
            """``value`` (the proposed one, checked), or, where the technique cannot draw
            what it asks for, the value as it was, with the reason in ``status`` (and a
            frame count, which the browser waits for)."""
            name = proposal.trait.name
            options = self.scene_options()
            reason = self._cannot_draw(self.technique if technique is None else technique,
                                       bool(options["geometry"]) if surfaces is None else surfaces,
                                       bool(options["clip_planes"] or options["crop_box"] is not None)
                                       if clips is None else clips)
            if reason is not None:
                self.status = f"cannot {what}: {reason}"
                self.frame += 1
                value = self._taken[name]
            return value

        @traitlets.validate("technique")
        def _check_technique(self, proposal):
            if not self._ready:
                return proposal.value
            return self._refuse(proposal, proposal.value, f"use {proposal.value}", technique=proposal.value)

        @traitlets.validate("geometry_on")
        def _check_geometry_on(self, proposal):
            if not self._ready:
                return proposal.value
            if proposal.value and not self._surfaces:
                raise ControlError("geometry_on", "there are no surfaces: give VolumeWidget(..., geometry=...)")
            return self._refuse(proposal, bool(proposal.value), "show the surfaces", surfaces=bool(proposal.value))

        @traitlets.validate("clip")
        def _check_clip(self, proposal):
            if not self._ready:
                return proposal.value
            try:
                value = self._cuts.check_clip(proposal.value, self._taken["clip"])
            except dvr_io.InputError as e:
                raise ControlError(e.field, e.detail) from None
            on = bool(self._cuts.clip_planes(value)) or self._cuts.crop_box(self.crop) is not None
            return self._refuse(proposal, value, "clip", clips=on)

        @traitlets.validate("crop")
        def _check_crop(self, proposal):
            if not self._ready:
                return proposal.value
            try:
                value = self._cuts.check_crop(proposal.value)
            except dvr_io.InputError as e:
                raise ControlError(e.field, e.detail) from None
            on = bool(self._cuts.clip_planes(self.clip)) or self._cuts.crop_box(value) is not None
            return self._refuse(proposal, value, "crop", clips=on)

        @traitlets.validate("shown", "blend")
        def _check_volumes(self, proposal):
            """A volume shown or hidden, or a blend: refused (the value as it was, the
            reason in ``status``) where the viewer refuses it or the mode does not allow it."""
            name = proposal.trait.name
            if not self._ready:
                return proposal.value
            if self._volumes is None:
                raise ControlError(name, "there is one volume: give VolumeWidget(..., layers=, labels= or channels=)")
            if name == "blend" and proposal.value not in BLENDS:
                raise ControlError("blend", f"must be one of {', '.join(BLENDS)}, got {proposal.value!r}")
            try:
                value = self._volumes.check_shown(proposal.value) if name == "shown" else proposal.value
            except dvr_io.InputError as e:
                raise ControlError(e.field, e.detail) from None
            reason = self._volumes.refusal(**{name: value})
            if reason is not None:
                self.status = reason
                self.frame += 1
                value = self._volumes.shown if name == "shown" else self._volumes.blend
            return value

        def _tf_for(self, preset):
            key = preset if isinstance(preset, str) else "given"
            if key not in self._tfs:
                if self._volumes is not None and self._volumes.channels:
                    raise dvr_io.InputError("tf", f"each channel is coloured by its own ramp (preset "
                                                  f"{CHANNELS_PRESET!r}); to choose them, pass Layers")
                self._tfs[key] = inputs.resolve_tf(preset, self._data, self._default_preset)[1]
            return self._tfs[key]

        def _on_change(self, change):
            if change.name in self._taken:
                self._taken[change.name] = change.new
            if change.name in ("shown", "blend"):
                self._volumes.take(self.shown, self.blend)
            if change.old == change.new:       # a browser's change refused: the value put back
                return
            self.render_frame()

        def render_frame(self):
            """Render the current view, preset and technique, and send the frame. An error
            (a preset or option the technique refuses) goes to ``status``; the last good
            frame stays."""
            view = dict(self.view)
            width, height = self.size
            if view.get("coarse"):
                width, height = max(8, width // 2), max(8, height // 2)
            options = self._options if self.technique == self._options_for else {}
            scene = self.scene_options()
            start = time.perf_counter()
            try:
                data, tf, shown = self._data, self._tf_for(self.preset), {}
                if self._volumes is not None:          # the volumes shown: the first is the scene's own
                    data, tf, shown = self._volumes.scene(tf)
                elif view.get("coarse") and self.technique == "raycast" and has_pyramid_levels(data):
                    # a multiscale store while dragging: one coarse level (rendering.pyramid), its
                    # step as many of its voxels; the still frame goes back to the data (and tolerance)
                    level = moving_volume(data, self.moving_samples)
                    options = {k: v for k, v in options.items() if k != "tolerance"}
                    if options.get("step") is not None:
                        options["step"] = options["step"] * level.min_spacing / data.min_spacing
                    data = level
                image = inputs.render(data, tf=tf, technique=self.technique, size=(width, height),
                                      azimuth=float(view["azimuth"]), elevation=float(view["elevation"]),
                                      zoom=float(view["zoom"]), **scene, **shown, **options)
                png = png_bytes(image, self._background)
            except Exception as e:          # shown in the widget: the kernel must not lose the view
                self.status = f"{self.technique}: {type(e).__name__}: {e}"
            else:
                self.image_array = np.asarray(image)
                self.image = png
                self.status = (f"azimuth {_degrees(view['azimuth'])}, elevation {_degrees(view['elevation'])}, "
                               f"zoom {float(view['zoom']):.2f} · {self.technique} · {width}x{height} in "
                               f"{(time.perf_counter() - start) * 1e3:.0f} ms")
                if self._volumes is not None:
                    self.status += f" · {self._volumes.describe()}"
                cuts = summary(scene["clip_planes"], scene["crop_box"], scene["geometry"])
                if cuts:
                    self.status += f" · {cuts}"
            self.frame += 1
else:
    class VolumeWidget:
        """Needs anywidget: ``pip install "dvr-gl[notebook]"``."""

        def __init__(self, *args, **kwargs):
            raise ImportError('dvr_gl.frontends.notebook.VolumeWidget needs anywidget: pip install "dvr-gl[notebook]"')


def _common():
    from ..techniques import common
    return common


def _degrees(value):
    value = float(value)
    return f"{value:.0f}°" if math.isfinite(value) else str(value)
