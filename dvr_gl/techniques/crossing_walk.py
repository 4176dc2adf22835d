"""The walk by crossings of the ray caster (``refine_walk="crossings"`` with
``preintegrate=True, refine=k``; ``shaders/common/crossing_walk.glsl``, NumPy twin
``dvr_gl.reference.crossing_walk``).

Pre-integration takes the field as linear between a segment's ends; along a ray the
trilinear field is a cubic in each cell, and a narrow opacity band is crossed where that
cubic passes through the band's values. This walk goes from cell to cell: cells whose
corner values reach no value with opacity are passed over many at a time (a Chebyshev
distance map over the cells: a ray leaves the whole empty box around its cell in one
round); in the others the cubic is made from the eight corners and the cell's stretch
of ray is cut where it turns and where it crosses a knot of the TF, every piece at most
``step / refine`` long (the parameter the error shrinks with), each read from the
pre-integrated table of that length with the cubic's values at its ends. The TF is one
line over each piece and the field monotone along it, so the only error left is the
cubic's distance from its chord over the piece, second order in the piece's length.
"""

from __future__ import annotations

import dataclasses

import numpy as np

MAX_KNOTS = 16      # knots the shader tests (KNOT_COUNT, compiled in)


@dataclasses.dataclass
class CrossingPlan:
    """What the walk adds to a RaycastPlan (``raycast.RaycastPlan.crossings``)."""
    knots: np.ndarray          # float64 values where the TF bends near opacity
    support: tuple             # (lo, hi): values outside have zero opacity
    empty_reach: np.ndarray    # (cz, cy, cx) float32 per cell: distance in cells to a visible one
    part: float                # the longest piece, world units
    rounds: int                # a bound on one ray's rounds
    tol: float                 # values this close to a knot count as on it (float32 rounding)


def knot_values(tf):
    """The values the pieces are cut at: the edges of the TF's stretches with opacity
    (knots with zero opacity next to an interval with some), where a narrow band is
    entered and left. Inside a stretch the table integrates the TF exactly along each
    piece's straight line, moved to the cubic's mean; the remaining error is the cubic's
    distance from that line, bounded by the piece length. More than MAX_KNOTS edges: the
    first MAX_KNOTS (the piece length bounds the rest)."""
    knots = np.asarray(tf.knots, np.float64)
    alpha = tf.opacity(knots) > 0
    near = np.zeros(knots.size, bool)
    near[1:] |= alpha[:-1]
    near[:-1] |= alpha[1:]
    return knots[~alpha & near][:MAX_KNOTS]


def support(tf):
    """(lo, hi): no value outside has opacity (the knots around the first and last with
    opacity; infinite where the TF has opacity beyond its end knots)."""
    knots = tf.knots
    alpha = tf.opacity(knots) > 0
    if not alpha.any():
        return (np.inf, -np.inf)
    first, last = np.flatnonzero(alpha)[[0, -1]]
    lo = knots[first - 1] if first > 0 else -np.inf
    hi = knots[last + 1] if last + 1 < knots.size else np.inf
    return (float(lo), float(hi))


NARROW_SHARE = 0.1   # narrow_opacity: values with opacity at most this share of the data's range


def narrow_opacity(scene):
    """Whether the values with opacity are at most NARROW_SHARE of the data's value range
    (where the walk by crossings may pay: the bands are crossed in few places), counted
    on 4096 values across the range."""
    lo, hi = (float(v) for v in scene.volume.data_range)
    if not hi > lo:
        return False
    values = np.linspace(lo, hi, 4096)
    return float(np.mean(scene.tf.opacity(values) > 0)) <= NARROW_SHARE


def cell_ranges(volume):
    """Per cell (cz, cy, cx): the least and greatest of its eight corners, which bound
    the trilinear field in it."""
    from scipy.ndimage import maximum_filter, minimum_filter
    v = volume.values(np.float64)
    lo = minimum_filter(v, size=2, origin=-1, mode="nearest")[:-1, :-1, :-1]
    hi = maximum_filter(v, size=2, origin=-1, mode="nearest")[:-1, :-1, :-1]
    return lo, hi


def empty_reach(volume, tf, table, occupancy):
    """Per cell, float32: the Chebyshev distance in cells to the nearest cell that may
    show something (0: this one may), a cell showing nothing when no value within one
    table cell of its corners' range has opacity (``occupancy``: the ray caster's
    ``preint_occupancy``, passed in by it)."""
    from scipy.ndimage import distance_transform_cdt
    visible = occupancy(cell_ranges(volume), tf, table) > 0
    if not visible.any():
        return np.full(visible.shape, float(max(visible.shape) + 1), np.float32)
    return distance_transform_cdt(~visible, metric="chessboard").astype(np.float32)


def plan_walk(scene, step, refine, preint_fine, tables, defines, refine_walk, occupancy):
    """Set the defines of a refined plan's walk (REACH_WALK; CROSSING_WALK and its
    KNOT_COUNT) and return the walk by crossings' part of the plan (None for the other
    walks); a named error where it does not apply. ``occupancy``: see ``empty_reach``."""
    defines["REACH_WALK"] = int(refine_walk == "reach")
    if refine_walk != "crossings":
        return None
    volume = scene.volume
    if volume.has_nonfinite:
        raise ValueError("refine_walk='crossings' does not yet take volumes with non-finite samples")
    if min(volume.shape) < 2:
        raise ValueError(f"refine_walk='crossings' needs two samples along every axis, got shape {volume.shape}")
    knots = tables.get("crossing_knots", scene.tf, make=knot_values)
    reach = tables.get("crossing_empty_reach", volume, scene.tf, preint_fine,
                       make=lambda v, tf, table: empty_reach(v, tf, table, occupancy))
    part = step / refine
    cells = int(np.sum(np.array(volume.shape) - 1)) + 3
    diagonal = float(np.linalg.norm(volume.spacing))
    per_cell = 3 * (len(knots) + 2) + int(np.ceil(diagonal / part)) + 2
    defines.update(CROSSING_WALK=1, KNOT_COUNT=max(len(knots), 1))
    scale = max(np.abs(knots).max(initial=0.0), *np.abs(np.nan_to_num(volume.data_range)))
    return CrossingPlan(knots=knots, support=support(scene.tf), empty_reach=reach, part=part,
                        rounds=min(cells * (per_cell + 1), 1 << 24), tol=float(2.0 ** -20 * scale))


def add_inputs(renderer, plan, textures, uniforms):
    """What a ray-casting plan's optional features read (``common.add_optional_inputs``)
    and the walk by crossings' texture and uniforms."""
    from .common import add_optional_inputs
    add_optional_inputs(renderer, plan, textures, uniforms)
    crossings = getattr(plan, "crossings", None)
    if crossings is None:
        return
    from ..gl.resources import texture3d
    textures["t_empty_reach"] = renderer.resources.for_objects(
        "crossing_empty_reach", crossings.empty_reach,
        make=lambda: texture3d(renderer.ctx, crossings.empty_reach, 1, "f4", linear=False))
    knots = crossings.knots if len(crossings.knots) else np.array([np.inf])
    big = 3.0e38
    uniforms.update({"u_knots": np.clip(knots, -big, big).astype(np.float32).tobytes(),
                     "u_support": tuple(float(np.clip(v, -big, big)) for v in crossings.support),
                     "u_cw_part": float(crossings.part), "u_cw_nominal": float(plan.preint_fine.length),
                     "u_cw_rounds": int(crossings.rounds), "u_cw_tol": crossings.tol})
