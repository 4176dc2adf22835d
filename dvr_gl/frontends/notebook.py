"""dvr_gl in Jupyter: images that show themselves, and an interactive volume widget.

- :class:`RenderedImage` is what :func:`dvr_gl.render` returns: a plain float32 NumPy
  array (premultiplied RGBA, row 0 on top) that Jupyter, through ``_repr_png_``, shows as
  a picture composited over its ``background`` (white unless set).
- :class:`VolumeWidget` (``pip install "dvr-gl[notebook]"``: anywidget) orbits, zooms and
  re-classifies a volume or mesh in the notebook. The kernel renders every frame with the
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
from .images import DEFAULT_BACKGROUND, RenderedImage, png_bytes  # noqa: F401 (RenderedImage: documented here)
from .. import formats as dvr_io

try:
    import anywidget
    import traitlets
except ImportError:                     # the widget is an optional extra
    anywidget = None


# The browser side: shows the kernel's PNG frames, and turns drags and the wheel into a
# new view. At most one view is in flight: the next is sent when the kernel's frame
# counter moves, so a slow renderer is never queued behind stale views.
_ESM = r"""
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
  let busy = false, dirty = false;
  const send = () => {
    if (busy) { dirty = true; return; }
    busy = true; dirty = false;
    model.set("view", Object.assign({}, view));
    model.save_changes();
  };
  model.on("change:image", showFrame);
  model.on("change:status", showStatus);
  model.on("change:frame", () => { busy = false; if (dirty) send(); });
  model.on("change:view", () => { if (!busy && !dirty) view = Object.assign({}, model.get("view")); });

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

_CSS = """
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

        def __init__(self, source, *, tf=None, technique=None, size=384, azimuth=None, elevation=None,
                     zoom=1.0, background=DEFAULT_BACKGROUND, **options):
            data, default_preset = inputs.load_input(source)
            width, height = _size_pair(size)
            from ..techniques import for_data
            names = list(for_data(data))
            if technique is None:
                technique = names[0]
            elif technique not in names:
                raise dvr_io.InputError("technique", f"{technique!r} does not render this data in the widget; "
                                                     f"choose one of {', '.join(names)}")
            presets = inputs.suitable_presets(data)
            if default_preset not in presets:
                presets.insert(0, default_preset)
            preset = default_preset if tf is None else tf
            self._tfs = {}
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
            super().__init__(size=[width, height], presets=presets, techniques=names, home=home,
                             view=dict(home), technique=technique,
                             preset=preset if isinstance(preset, str) else "given")
            if not isinstance(preset, str):
                self.presets = self.presets + ["given"]
            self.observe(self._on_change, names=["view", "preset", "technique"])
            self.render_frame()

        def _tf_for(self, preset):
            key = preset if isinstance(preset, str) else "given"
            if key not in self._tfs:
                self._tfs[key] = inputs.resolve_tf(preset, self._data, self._default_preset)[1]
            return self._tfs[key]

        def _on_change(self, change):
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
            start = time.perf_counter()
            try:
                image = inputs.render(self._data, tf=self._tf_for(self.preset), technique=self.technique,
                                      size=(width, height), azimuth=float(view["azimuth"]),
                                      elevation=float(view["elevation"]), zoom=float(view["zoom"]), **options)
                png = png_bytes(image, self._background)
            except Exception as e:          # shown in the widget: the kernel must not lose the view
                self.status = f"{self.technique}: {type(e).__name__}: {e}"
            else:
                self.image_array = np.asarray(image)
                self.image = png
                self.status = (f"azimuth {_degrees(view['azimuth'])}, elevation {_degrees(view['elevation'])}, "
                               f"zoom {float(view['zoom']):.2f} · {self.technique} · {width}x{height} in "
                               f"{(time.perf_counter() - start) * 1e3:.0f} ms")
            self.frame += 1
else:
    class VolumeWidget:
        """Needs anywidget: ``pip install "dvr-gl[notebook]"``."""

        def __init__(self, *args, **kwargs):
            raise ImportError('dvr_gl.frontends.notebook.VolumeWidget needs anywidget: pip install "dvr-gl[notebook]"')


def _degrees(value):
    value = float(value)
    return f"{value:.0f}°" if math.isfinite(value) else str(value)
