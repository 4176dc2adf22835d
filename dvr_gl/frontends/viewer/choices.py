"""Changes of a viewer's rendering choices, as the keys make them: the technique (t), the
mode (m), the iso value (, and .), shading (l), the optical model (x), illustration
terms (i), technique options (p: pre-integration, c: tetra's cell order) and the step
(- and =).

Each change is tried (:meth:`Viewer.try_change`): when the technique cannot render the
result, it is undone and the viewer says why, so a key never leaves a state that does
not render. Techniques and modes that cannot render the data are skipped, and named.
"""

from __future__ import annotations

import math

from ...model.scene import ILLUSTRATION_TERMS, MODES, OPTICAL_MODELS
from .settings import is_mesh


def next_technique(v, direction=1):
    """Switch to the next technique (in the registry's order) that can render the
    current data in the current mode."""
    names = v.available_techniques
    start = names.index(v.technique)
    skipped = []
    for k in range(1, len(names)):
        name = names[(start + direction * k) % len(names)]
        result = v.try_change(lambda: setattr(v, "technique", name), f"use {name}", quiet=True)
        if result is True:
            v.say(f"technique {name}" + (f" (skipped {', '.join(skipped)})" if skipped else ""))
            return True
        skipped.append(f"{name}: {result}")
    v.say(f"no other technique can render this: {'; '.join(skipped)}" if skipped
          else f"{v.technique} is the only technique that can render this data")
    return False


def next_mode(v, direction=1):
    """Switch to the next mode the current technique can render."""
    i = MODES.index(v.mode)
    skipped = []
    for k in range(1, len(MODES)):
        mode = MODES[(i + direction * k) % len(MODES)]
        result = v.try_change(lambda: setattr(v, "mode", mode), f"use mode {mode}", quiet=True)
        if result is True:
            v.overlay_changed()
            why = "lit" if v.lit else ""
            v.say(f"mode {mode}" + (f" {v.iso:g}" if mode == "isosurface" else "")
                  + (f" ({v.technique} cannot render {', '.join(skipped)}{' ' + why if why else ''})"
                     if skipped else ""))
            return True
        skipped.append(mode)
    v.say(f"{v.technique} renders only mode {v.mode}")
    return False


def move_iso(v, steps):
    """Move the iso value by ``steps`` hundredths of the data range (isosurface mode)."""
    if v.mode != "isosurface":
        v.say("the iso value applies in isosurface mode (press m)")
        return
    lo, hi = v.volume.data_range
    v.iso = float(v.iso + steps * 0.01 * (hi - lo))
    v.overlay_changed()
    v.changed()


def switch_shading(v):
    """Key l: shading on / off, where the technique lights samples in this mode."""
    from ..inputs import shading_for

    if v.layers:
        v.say("cannot switch shading: lighting several volumes is not rendered yet")
    elif not shading_for(v.technique, v.mode, v.optical_model):
        v.say(f"cannot switch shading: {v.technique} in mode {v.mode} with optical model "
              f"{v.optical_model} does not light samples")
    elif v.try_change(lambda: setattr(v, "shading", not v.shading), "switch shading"):
        v.say("shading " + ("on" if v.lit else "off"))


def next_illustration(v):
    """Key i: no illustration terms, each term alone, then all of them."""
    options = [()] + [(name,) for name in ILLUSTRATION_TERMS] + [tuple(ILLUSTRATION_TERMS)]
    now = options.index(v.illustration) if v.illustration in options else 0
    terms = options[(now + 1) % len(options)]
    if v.try_change(lambda: setattr(v, "illustration", terms), "use illustration terms"):
        v.say("illustration " + (", ".join(terms) if terms else "off"))


def next_optical_model(v):
    """Key x: the next optical model."""
    models = OPTICAL_MODELS
    model = models[(models.index(v.optical_model) + 1) % len(models)]
    if v.try_change(lambda: setattr(v, "optical_model", model), f"use optical model {model}"):
        v.say(f"optical model {model}")


def switch_option(v, option):
    """Switch a technique option on or off (key p: ``preintegrate``)."""
    if not v.info.accepts(option):
        v.say(f"{v.technique} has no {option} option")
        return
    on = not v.options.get(option, False)

    def change():
        if on:
            v.options[option] = True
        else:
            v.options.pop(option, None)
            if option == "preintegrate":      # refinement cuts pre-integrated segments only
                v.options.pop("refine", None)
    if v.try_change(change, f"switch {option} {'on' if on else 'off'}"):
        v.say(f"{option} {'on' if on else 'off'}")


def next_sort(v):
    """Key c: the next cell order of a technique with a ``sort`` option (tetra: from the
    default walk, each ray walked from cell to cell on the GPU, exact with no order at
    all, to "mpvo", exact per pixel; "centroid", cheaper; and "walk" again)."""
    if not v.info.accepts("sort") or v.info.params is None:
        v.say(f"{v.technique} has no sort option (tetra's cell order, for meshes)")
        return False
    from ...techniques import get_technique

    sorts = tuple(getattr(get_technique(v.technique), "SORTS", ("mpvo", "centroid")))
    now = v.options.get("sort", "walk")       # (the default, auto, is the walk where it takes the mesh)
    new = sorts[(sorts.index(now) + 1) % len(sorts)] if now in sorts else sorts[0]
    if v.try_change(lambda: v.options.__setitem__("sort", new), f"use sort {new}"):
        v.say(f"sort {new}")
        return True
    return False


def scale_step(v, coarser):
    """Keys - and =: a coarser or finer step (a factor sqrt(2)); raycast with a
    tolerance doubles or halves the tolerance instead, and slice2d changes its number
    of interpolated slices."""
    factor = math.sqrt(2.0)
    if v.tolerance is not None and v.technique in ("raycast", "tetra"):
        v.tolerance *= 2.0 if coarser else 0.5
        v.changed()
        v.say(f"tolerance {v.tolerance:.3g}")
        return
    if v.info.accepts_step:
        step = v.effective_step()
        new = step * factor if coarser else step / factor
        if v.try_change(lambda: setattr(v, "step", new), f"use step {new:.4g}"):
            v.say(f"step {new:.4g}")
    elif v.info.accepts("interpolate") and v.info.params is not None:
        k = int(v.options.get("interpolate", 0)) + (-1 if coarser else 1)
        k = min(max(k, 0), 15)
        v.try_change(lambda: v.options.__setitem__("interpolate", k), f"use interpolate={k}")
    elif is_mesh(v.volume):
        v.say(f"{v.technique} has a fixed sample distance: it takes no step "
              "(each cell is integrated exactly)")
    else:
        v.say(f"{v.technique} has a fixed sample distance")
