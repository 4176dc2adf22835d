"""The viewer's clip plane and surfaces: k cuts the data with a plane through its centre
that faces the eye (the near half is cut away), K turns the plane to face the eye again,
alt + left drag moves it along its normal, and g shows or hides the surfaces given with
``--geometry``. The plane is a Scene clip plane like any other
(``Scene(clip_planes=...)``), so every technique renders the cut and the screenshot
matches ``dvr-gl render --clip``."""

from __future__ import annotations

import numpy as np


def _centre(v):
    lo, hi = v.volume.bounds
    return (np.asarray(lo, np.float64) + np.asarray(hi, np.float64)) / 2


def toggle_clip(v):
    """No clip plane: add one through the data's centre, facing the eye. Clip planes:
    remove them (k again brings them back)."""
    if v.clip_planes:
        v.removed_clip_planes, v.clip_planes = v.clip_planes, ()
        v.say("clip planes off (k: back on)")
    else:
        planes = getattr(v, "removed_clip_planes", ()) or ((_centre(v), v.orbit.camera().forward),)
        v.clip_planes = tuple((np.asarray(p, np.float64), np.asarray(n, np.float64)) for p, n in planes)
        v.say("clip plane on: alt + drag moves it, K turns it to face you, k removes it")
    v.changed()


def aim_clip(v):
    """Turn the first clip plane to face the eye, through the same point."""
    if not v.clip_planes:
        v.say("no clip plane (k adds one)")
        return
    point, _ = v.clip_planes[0]
    v.clip_planes = ((point, np.asarray(v.orbit.camera().forward, np.float64)),) + tuple(v.clip_planes[1:])
    v.changed()


def move_clip(v, pixels):
    """Move the first clip plane along its normal by ``pixels`` of the window's height
    (a world distance of what one pixel spans at the orbit's centre), staying within
    the data's bounds."""
    if not v.clip_planes:
        return
    point, normal = v.clip_planes[0]
    unit = normal / np.linalg.norm(normal)
    lo, hi = (np.asarray(b, np.float64) for b in v.volume.bounds)
    step = pixels * v.orbit.world_per_pixel(v.window_size[1])
    moved = np.clip(point + step * unit, lo, hi)
    v.clip_planes = ((moved, normal),) + tuple(v.clip_planes[1:])
    v.changed(interactive=True)


def toggle_geometry(v):
    """Hide the scene's surfaces (``--geometry``), or show them again; the choice is
    tried, so a technique that does not draw surfaces keeps them hidden and says why."""
    if v.geometry:
        v.hidden_geometry, v.geometry = v.geometry, ()
        v.say("surfaces hidden (g: shown)")
        v.changed()
        return
    hidden = getattr(v, "hidden_geometry", ())
    if not hidden:
        v.say("no surfaces to show (dvr-gl view ... --geometry FILE)")
        return
    if v.try_change(lambda: setattr(v, "geometry", hidden), "show the surfaces") is True:
        v.hidden_geometry = ()
        v.say("surfaces shown")
