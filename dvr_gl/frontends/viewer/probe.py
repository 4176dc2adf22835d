"""Which techniques the viewer offers, found by asking each technique module.

Techniques are found through :func:`dvr_gl.techniques.names`; those whose ``make_plan``
refuses the data are left out of the cycle (key t), and options (``step``,
``preintegrate``, ``interpolate``, ``sort``) are only passed to techniques that take them
(:class:`TechniqueInfo`). A technique whose ``make_plan`` names no default step is
offered :func:`fallback_step`.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass

from .settings import is_mesh


@dataclass
class TechniqueInfo:
    """What the viewer knows about a technique, found by asking its module."""
    name: str
    applies: bool
    accepts_step: bool
    params: frozenset | None      # make_plan's keyword options; None: it takes any
    default_step: float | None
    reason: str = ""

    def accepts(self, option):
        return self.params is None or option in self.params


def renders_data_of(name, volume):
    """Whether technique ``name`` is for this kind of data (its module's ``DATA``:
    "volume" for grids, "mesh" for TetMesh, or both), whatever else it may refuse."""
    from ...techniques import get_technique

    try:
        data = getattr(get_technique(name), "DATA", "volume")
    except Exception:
        return False
    kinds = (data,) if isinstance(data, str) else tuple(data)
    return ("mesh" if is_mesh(volume) else "volume") in kinds


def _plan_params(make_plan):
    try:
        sig = inspect.signature(make_plan)
    except (TypeError, ValueError):
        return None
    if any(p.kind is p.VAR_KEYWORD for p in sig.parameters.values()):
        return None
    return frozenset(n for n in list(sig.parameters)[2:] if n != "tables")


def fallback_step(volume):
    """The step offered to a technique that takes one but names no default: half the
    smallest spacing of a grid, half the typical cell size of a mesh (whose technique,
    tetra, takes no step: only a technique module without ``TAKES_STEP`` is tried with
    it)."""
    spacing = getattr(volume, "min_spacing", None)
    if spacing is None:
        spacing = getattr(volume, "cell_size", 1.0)
    return 0.5 * float(spacing)


def probe_technique(name, scene, tables):
    """Ask technique ``name`` whether it can render ``scene``'s data and whether it
    takes a ``step``: the module attribute ``TAKES_STEP`` of the technique interface
    settles the latter; a module without it has ``make_plan`` tried with a step and, if
    it refuses, without one."""
    from ...techniques import get_technique

    try:
        tech = get_technique(name)
    except Exception as e:  # a module that fails to import is simply not offered
        return TechniqueInfo(name, False, False, frozenset(), None, f"{type(e).__name__}: {e}")
    params = _plan_params(tech.make_plan)
    default = None
    if callable(getattr(tech, "default_step", None)):
        try:
            default = float(tech.default_step(scene.volume))
        except Exception:
            default = None
    step_guess = default if default is not None else fallback_step(scene.volume)
    flag = getattr(tech, "TAKES_STEP", None)
    tries = [(True, step_guess), (False, None)] if flag is None else [(bool(flag), step_guess if flag else None)]
    reason = ""
    for accepts, step in tries:
        try:
            tech.make_plan(scene, step, tables=tables)
        except (TypeError, ValueError, NotImplementedError) as e:
            reason = str(e)
            continue
        return TechniqueInfo(name, True, accepts, params, default if accepts else None)
    return TechniqueInfo(name, False, False, params, default, reason)


def probe_techniques(scene, tables):
    """:func:`probe_technique` for every registered technique, in the registry's order
    (the order key t cycles through)."""
    from ...techniques import names

    return {name: probe_technique(name, scene, tables) for name in names()}


def starting_technique(techniques, wanted, volume):
    """The technique to start with, as ``(name, message)``: ``wanted`` (message None) if
    it can render the data; where it is for the other kind of data (the default raycast
    on a mesh), the first technique that can render this data, with a message saying so.
    ValueError when neither can."""
    info = techniques.get(wanted)
    if info is not None and not info.applies and not renders_data_of(wanted, volume):
        fallback = next((name for name, t in techniques.items() if t.applies), None)
        if fallback is not None:
            return fallback, f"technique {fallback} ({wanted} cannot render this data: {info.reason})"
    if info is None or not info.applies:
        why = info.reason if info is not None else "unknown technique"
        raise ValueError(f"--technique: {wanted} cannot render this data: {why}")
    return wanted, None
