"""Whole transfer-function changes: the presets keys 1..9 choose, and saving and loading
the edited function as JSON (ctrl+s / ctrl+o, or a ``.json`` file dropped on the
window), the format ``dvr-gl render --tf`` reads.

Point-by-point edits are the editor's (:class:`~.overlay.TFEditor`); each change here
replaces the editor's function and re-renders.
"""

from __future__ import annotations


def preset_list(v):
    """The transfer functions keys 1..9 choose for viewer ``v``: the one given, then the
    presets that suit the data (``inputs.suitable_presets``), as ``(name, make)`` pairs
    (``make(volume)`` gives the function)."""
    from ..inputs import PRESETS, suitable_presets

    items = [(v.settings.tf_name, lambda volume: v.initial_tf)]
    items += [(name, PRESETS[name]) for name in suitable_presets(v.volume)]
    return items[:9]


def use_preset(v, number):
    """Key ``number``: show the ``number``-th of :func:`preset_list` (from 1)."""
    items = preset_list(v)
    if not 1 <= number <= len(items):
        v.say(f"no transfer function {number}; 1..{len(items)}: {', '.join(n for n, _ in items)}")
        return
    name, make = items[number - 1]
    try:
        tf = make(v.volume)
    except (TypeError, ValueError, AttributeError, NotImplementedError) as e:
        # a preset made for grids (auto, before it learns meshes) on a mesh
        v.say(f"cannot use transfer function {number} ({name}) here: {e}")
        return
    v.editor.set_tf(tf)
    v.tf_edited(interactive=False)
    v.say(f"transfer function {number}: {name}")


def write_tf(v, path=None):
    """Write the edited function to ``path`` (default ``--tf-out``); the path, or None."""
    from ...model.transfer import save_tf_json

    path = path or v.settings.tf_out
    try:
        save_tf_json(path, v.tf)
    except OSError as e:
        v.say(f"cannot save the transfer function to {path!r}: {e}")
        return None
    v.say(f"saved the transfer function to {path} (dvr-gl render --tf {path})")
    return path


def read_tf(v, path=None):
    """Show the function in ``path`` (default ``--tf-out``); True when it loaded."""
    from ...model.transfer import load_tf_json

    path = path or v.settings.tf_out
    try:
        tf = load_tf_json(path)
    except (OSError, ValueError, TypeError) as e:
        v.say(f"cannot load a transfer function from {path!r}: {e}")
        return False
    v.editor.set_tf(tf)
    v.tf_edited(interactive=False)
    v.say(f"loaded the transfer function {path}")
    return True
