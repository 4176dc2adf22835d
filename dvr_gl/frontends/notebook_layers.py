"""The volume widget's several volumes: ``VolumeWidget(source, layers=..., labels=...,
channels=..., blend=...)``, meant as ``dvr_gl.render`` means them. The volumes are read
by ``layer_inputs.layered_input``; a checkbox per volume shows or hides it and a menu
picks the blend. Showing and hiding follow the viewer's rules (``viewer.layers``, keys
F2..F5): a hidden volume is left out of the scene, the first volume shown is the scene's
own, a label volume is drawn with a scan (so the first volume shown must be one), and one
volume stays shown. :class:`WidgetVolumes` holds what those functions read of a viewer,
so they apply here unchanged. Several volumes are rendered by the techniques of
``LAYER_TECHNIQUES``, unlit whichever are shown (lighting them is not rendered yet), so
hiding one changes nothing else.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from . import inputs
from .layer_inputs import layered_input, wants_layers
from ..formats import InputError
from ..model.layers import BLENDS, check_layers

#: the preset menu's one entry for channels: each channel glows in its own ramp
CHANNELS_PRESET = "channels"


def _viewer_layers():
    from .viewer import layers         # the viewer's rules, read only where there are several volumes
    return layers


def load_volumes(source, tf, layers, labels, channels, blend, options):
    """A :class:`WidgetVolumes` for the volumes named, or None when there is one (then a
    ``blend`` is an InputError, as in ``dvr_gl.render``). ``options`` are the widget's
    technique options: ``mode`` decides the blends allowed, ``shading`` must not be on."""
    if not wants_layers(layers, labels, channels):
        if blend is not None:
            raise InputError("blend", f"combines several volumes (layers, labels or channels); got blend={blend!r} "
                                      "with one")
        return None
    if options.get("shading"):
        raise InputError("shading", "lighting several volumes is not rendered yet; leave shading out with layers, "
                                    "labels or channels")
    main = []

    def load_main():
        main.append(inputs.load_input(source))
        return main[0]
    layered = layered_input(source, tf, layers, labels, channels, blend, load_main=load_main,
                            load_input=inputs.load_input, resolve_tf=inputs.resolve_tf)
    volumes = WidgetVolumes(layered, CHANNELS_PRESET if channels else main[0][1], options.get("mode", "composite"))
    try:
        volumes.validate()
    except ValueError as e:              # the mode the blend or a label volume cannot render
        raise InputError("mode", str(e)) from None
    return volumes


class WidgetVolumes:
    """The volumes of one widget (``layered``, a ``LayeredInput``) and which of them are
    hidden, with what the functions of ``viewer.layers`` read of a viewer: ``volume``,
    ``tf``, ``layers``, ``blend``, ``hidden_layers``, ``settings.layer_names``, ``say``,
    ``validate`` and ``changed``. ``preset`` names volume 1's transfer function for the
    preset menu; ``mode`` is the widget's."""

    def __init__(self, layered, preset, mode="composite"):
        self.volume, self.tf, self.layers = layered.volume, layered.tf, tuple(layered.layers)
        self.blend, self.mode, self.preset = layered.blend, mode, preset
        self.channels = preset == CHANNELS_PRESET
        self.names = tuple(layered.names)
        self.framing = layered.framing        # the box around every volume: the cuts' bounds
        self.hidden_layers = frozenset()
        self.settings = SimpleNamespace(layer_names=self.names)
        self._said = None

    # -- what viewer.layers calls --------------------------------------------------------
    def say(self, text):
        self._said = text

    def changed(self):
        """The widget renders when its values change; nothing to do here."""

    def validate(self):
        """Raise ValueError where the volumes shown cannot be rendered with this blend in
        this mode (the Scene's own check of its layers)."""
        volume, tf, extra = _viewer_layers().shown_volumes(self, self.tf)
        check_layers(extra.get("layers", ()), volume, tf, mode=self.mode, blend=self.blend, shading=False,
                     optical_model="emission_absorption", tf_2d=None, illustration=())

    # -- the widget's controls -----------------------------------------------------------
    @property
    def shown(self):
        """A bool per volume: the checkboxes."""
        return [i not in self.hidden_layers for i in range(len(self.names))]

    def blends(self):
        """The blends this widget's mode allows with every volume shown (the menu's)."""
        return [blend for blend in BLENDS if self.refusal(blend=blend) is None]

    def check_shown(self, value):
        """``value`` checked: True or False for each volume, else an InputError naming ``shown``."""
        if (not isinstance(value, (list, tuple)) or len(value) != len(self.names)
                or not all(isinstance(v, (bool, np.bool_)) for v in value)):
            raise InputError("shown", f"expected {len(self.names)} values True or False, one per volume "
                                      f"({', '.join(self.names)}), got {value!r}")
        return [bool(v) for v in value]

    def refusal(self, shown=None, blend=None):
        """Why the volumes ``shown`` (default: as they are) cannot be rendered with
        ``blend`` (default: as it is), in the viewer's words, or None."""
        saved = self.hidden_layers, self.blend, self._said
        target = saved[0] if shown is None else frozenset(i for i, on in enumerate(shown) if not on)
        self.blend = saved[1] if blend is None else blend
        try:
            changed = sorted(target ^ saved[0])
            if changed:
                # toggle_layer checks the state it toggles to, so this is the target state
                # whichever changed volume it names (a browser changes one at a time)
                self.hidden_layers, self._said = target ^ {changed[0]}, None
                _viewer_layers().toggle_layer(self, changed[0])
                return None if self.hidden_layers == target else self._said
            try:
                self.validate()
            except ValueError as e:
                return f"cannot use blend {self.blend}: {e}"
            return None
        finally:
            self.hidden_layers, self.blend, self._said = saved

    def take(self, shown, blend):
        """The controls' values, checked and kept: the next frame's."""
        self.hidden_layers = frozenset(i for i, on in enumerate(shown) if not on)
        self.blend = blend

    def scene(self, tf):
        """(volume, tf, keywords) of the next frame for ``dvr_gl.render``: the first volume
        shown (volume 1 classified by ``tf``, the preset menu's), the others shown as its
        ``layers`` with their ``blend``, and ``shading=False``."""
        volume, tf, extra = _viewer_layers().shown_volumes(self, tf)
        return volume, tf, {"shading": False, **extra}

    def describe(self):
        """A few words for the status line: which volumes are shown and the blend."""
        return _viewer_layers().describe_shown(self)


# The browser side: a checkbox per volume (its number and file name) and the blend menu.
# ``push`` sends a change as the cuts' controls send theirs; a refused change comes back
# as the value the kernel kept.
LAYERS_JS = r"""
function layerControls(model, push, latest) {
  const row = document.createElement("div");
  row.className = "dvr-gl-row dvr-gl-volumes";
  const names = model.get("volume_names");
  if (names.length === 0) return row;
  const boxes = names.map((name, i) => {
    const on = Object.assign(document.createElement("input"), { type: "checkbox", className: "dvr-gl-shown" });
    const label = document.createElement("label");
    label.title = name;
    label.append(on, " " + (i + 1) + " " + name.split(/[\\/]/).pop());
    row.appendChild(label);
    on.addEventListener("change", () => {
      const next = latest("shown").slice();
      next[i] = on.checked;
      push("shown", next);
    });
    return on;
  });
  const blend = Object.assign(document.createElement("select"), { className: "dvr-gl-blend" });
  for (const name of model.get("blends")) {
    blend.appendChild(Object.assign(document.createElement("option"), { value: name, textContent: name }));
  }
  const label = document.createElement("label");
  label.append("blend ", blend);
  row.appendChild(label);
  blend.addEventListener("change", () => push("blend", blend.value));
  const update = () => {
    latest("shown").forEach((on, i) => { boxes[i].checked = on; });
    blend.value = latest("blend");
  };
  model.on("change:shown", update);
  model.on("change:blend", update);
  update();
  return row;
}
"""
