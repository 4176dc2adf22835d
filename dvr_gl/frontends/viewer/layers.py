"""The viewer's volumes when it shows several (``--volume``, ``--labels``, ``--channels``):
F2, F3, F4 and F5 show or hide volume 1 to 4 (1 is INPUT, or its first channel; then the
``--volume`` files in order, then ``--labels``). A hidden volume is left out of the
scene: when INPUT is hidden, the first volume shown takes its place as the scene's own
(every volume here is placed by the identity, so nothing moves). A label volume is drawn
with a scan, so the first volume shown must be one, and one volume at least stays
shown. The picture is unlit while the viewer holds several volumes (lighting them is not
rendered yet), whichever are shown, so that hiding one changes nothing else.
"""

from __future__ import annotations

from ...model.layers import Extent, Layer, union_bounds
from .keys import KEY_F2, KEY_F3, KEY_F4, KEY_F5

LAYER_KEYS = (KEY_F2, KEY_F3, KEY_F4, KEY_F5)     # volume 1, 2, 3, 4


def framing(volume, tf, layers):
    """What the orbit frames: the box around every volume (``volume`` alone when there
    are no layers), in ``volume``'s anatomical frame."""
    if not layers:
        return volume
    extent = Extent(union_bounds((Layer(volume, tf),) + tuple(layers)))
    extent.orientation = getattr(volume, "orientation", None)
    return extent


def layer_count(v):
    """How many volumes the viewer holds (1 without layers)."""
    return 1 + len(v.layers)


def shown_volumes(v, tf):
    """``(volume, tf, extra)`` of the scene: the first volume shown with its transfer
    function (``tf``, the editor's, for INPUT) and the Scene's ``layers`` and ``blend``
    for the others shown (nothing when there is one)."""
    if not v.layers:
        return v.volume, tf, {}
    every = (Layer(v.volume, tf),) + tuple(v.layers)
    shown = [layer for i, layer in enumerate(every) if i not in v.hidden_layers]
    first, rest = shown[0], tuple(shown[1:])
    return first.volume, first.tf, ({"layers": rest, "blend": v.blend} if rest else {})


def describe_shown(v):
    """A few words for the title: which volumes are shown (by number), and the blend."""
    marks = "".join("-" if i in v.hidden_layers else str(i + 1) for i in range(layer_count(v)))
    return f"volumes {marks} {v.blend}"


def _name(v, index):
    names = getattr(v.settings, "layer_names", ()) or ()
    return names[index] if index < len(names) else f"volume {index + 1}"


def toggle_layer(v, index):
    """Keys F2..F5: hide volume ``index`` (0 is INPUT), or show it again."""
    n = layer_count(v)
    if n == 1:
        v.say("one volume: F2..F5 show or hide the volumes of --volume, --labels and --channels")
        return
    if index >= n:
        v.say(f"no volume {index + 1}: there are {n} (F2..F{n + 1})")
        return
    every = (Layer(v.volume, v.tf),) + tuple(v.layers)
    hidden = frozenset(v.hidden_layers ^ {index})
    shown = [i for i in range(n) if i not in hidden]
    what = f"volume {index + 1} ({_name(v, index)})"
    if not shown:
        v.say(f"cannot hide {what}: it is the last one shown")
        return
    if every[shown[0]].is_labels or every[shown[0]].placed:
        v.say(f"cannot hide {what}: a label volume is drawn with a scan, so the first volume shown must be a scan")
        return
    before, v.hidden_layers = v.hidden_layers, hidden
    try:
        v.validate()
    except (TypeError, ValueError, NotImplementedError) as e:
        v.hidden_layers = before
        v.say(f"cannot {'hide' if index in hidden else 'show'} {what}: {e}")
        return
    v.changed()
    v.say(f"{what} {'hidden' if index in hidden else 'shown'} ({describe_shown(v)})")
