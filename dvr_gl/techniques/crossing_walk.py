"""The walk by crossings of the ray caster (``refine_walk="crossings"`` with
``preintegrate=True, refine=k``; ``shaders/common/crossing_walk.glsl``, NumPy twin
``dvr_gl.reference.crossing_walk``).

Pre-integration takes the field as linear between a segment's ends; along a ray the
trilinear field is a cubic in each cell, and a narrow opacity band is crossed where that
cubic passes through the band's values. This walk goes from cell to cell: cells whose
corner values reach no value with opacity are passed over many at a time (per cell and
octant of ray directions the largest empty cube with a corner at the cell lying that
way: a ray leaves the whole cube in one round); in the others the cubic is made from
the cell's trilinear coefficients (stored for those cells only, two texture reads) and
the cell's stretch of ray is cut where it turns and where it crosses a knot of the TF,
every piece at most ``step / refine`` long (the parameter the error shrinks with), each
read from the pre-integrated table of that length with the cubic's values at its ends. The TF is one
line over each piece and the field monotone along it, so the only error left is the
cubic's distance from its chord over the piece, second order in the piece's length.
"""

from __future__ import annotations

import dataclasses

import numpy as np

MAX_KNOTS = 16      # knots the shader tests (KNOT_COUNT, compiled in)
# Nodes of the walk's pre-integrated tables (512 elsewhere, preintegration.TABLE_SIZE):
# its pieces are cut where they enter and leave the values with opacity, over which the
# table's nodes are spread, so a coarser table costs little: on the Marschner-Lobb spike
# the error against the exact image at pieces of 1, 1/4 and 1/16 voxel is 2.73e-3,
# 5.92e-4 and 3.57e-5 with 128 nodes against 2.73e-3, 5.92e-4 and 3.47e-5 with 512 (7.1e-5
# at 1/16 voxel with 64). Its two tables then take 0.5 MiB, not 8, and stay in the CPU's
# caches: 9 to 12 % faster frames on llvmpipe (docs/notes/error_targets.md).
TABLE_SIZE = 128


@dataclasses.dataclass
class CrossingPlan:
    """What the walk adds to a RaycastPlan (``raycast.RaycastPlan.crossings``)."""
    knots: np.ndarray          # float64 values where the TF bends near opacity
    support: tuple             # (lo, hi): values outside have zero opacity
    part: float                # the longest piece, world units
    rounds: int                # a bound on one ray's rounds
    tol: float                 # values this close to a knot count as on it (float32 rounding)
    walk_map: np.ndarray = None       # uint32 per cell: the octants' codes, or n << 4 in visible cell n
    coefficients: np.ndarray = None   # (rows, 2 COEFFICIENT_ROW, 4) float32 (walk_cells)

    @property
    def empty_cubes(self):
        """(8, cz, cy, cx) uint8: per octant and cell the empty cube's code (empty_cubes),
        read back from the walk map (0 in a cell that may show something)."""
        empty = (self.walk_map & 15) != 0
        return np.stack([np.where(empty, (self.walk_map >> np.uint32(4 * octant)) & 15, 0).astype(np.uint8)
                         for octant in range(8)])


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


COEFFICIENT_ROW = 2048   # cells per row of the coefficient texture (two texels each)
MAX_VISIBLE_CELLS = 1 << 24   # cells that may show something: 8192 rows of the coefficient texture


def cell_coefficients(volume, cells):
    """The trilinear field's eight coefficients in each of ``cells`` (n, 3 as z, y, x),
    float32 (n, 8): the constant, the x, y, z terms, then the xy, xz, yz and xyz terms,
    so that a cell's cubic takes two texture reads instead of eight corners."""
    v = volume.values(np.float64)
    k, j, i = cells.T

    def corner(dz, dy, dx):
        return v[k + dz, j + dy, i + dx]
    v000, v100, v010, v110 = corner(0, 0, 0), corner(0, 0, 1), corner(0, 1, 0), corner(0, 1, 1)
    v001, v101, v011, v111 = corner(1, 0, 0), corner(1, 0, 1), corner(1, 1, 0), corner(1, 1, 1)
    return np.stack([v000, v100 - v000, v010 - v000, v001 - v000,
                     v110 - v100 - v010 + v000, v101 - v100 - v001 + v000, v011 - v010 - v001 + v000,
                     v111 - v110 - v101 - v011 + v100 + v010 + v001 - v000], axis=1).astype(np.float32)


def cube_reach(code):
    """How far in cells an empty cube reaches from its corner cell, from its 4-bit code 1
    .. 15: sides 1, 3, 5, 7, 9, 13, 17, 25, 33, 49, 65, 97, 129, 193, 257, odd (so that
    each has a centre cell) and about 1.4x apart (cubeReach in the shader)."""
    code = np.asarray(code, np.int64)
    return np.where(code <= 5, 2 * code - 2, (12 + 4 * (code & 1)) << (np.maximum(code - 6, 0) // 2))


def empty_cubes(visible):
    """Per octant of ray directions and cell, (8, cz, cy, cx) uint8: the code (cube_reach)
    of the largest cube of cells with no visible cell that has a corner at the cell and
    lies towards the octant (bit 0: x falls along the ray, bit 1: y, bit 2: z); 0 in a
    visible cell. A ray of that octant leaves the cube through its far faces only, so
    one round takes it out of the whole cube: about twice as far as out of a cube
    centred on the cell. From the Chebyshev distance D to the nearest visible cell: the
    cube of side 2r + 1 is centred at the cell r steps towards the octant, and empty where
    D there exceeds r; at least the cube of side D (inside the centred cube of radius D -
    1) wherever its centre would lie beyond the volume."""
    from scipy.ndimage import distance_transform_cdt
    visible = np.asarray(visible, bool)
    shape = visible.shape
    if not visible.any():
        distance = np.full(shape, 2 * max(shape) + 1, np.int64)
    else:
        distance = distance_transform_cdt(~visible, metric="chessboard").astype(np.int64)
    sides = cube_reach(np.arange(1, 16)) + 1
    base = np.searchsorted(sides, distance, side="right").astype(np.uint8)   # sides <= D
    codes = np.repeat(base[None], 8, axis=0)
    for code, side in enumerate(sides, start=1):
        r = int(side - 1) // 2
        if r == 0:
            continue
        empty = distance > r                    # the cube of radius r about each cell
        if any(r >= n for n in shape) or not empty.any():
            break
        found = empty.astype(np.uint8) * np.uint8(code)
        for octant in range(8):
            falls = (octant & 4, octant & 2, octant & 1)      # z, y, x
            centre = tuple(slice(0, n - r) if f else slice(r, n) for f, n in zip(falls, shape))
            corner = tuple(slice(r, n) if f else slice(0, n - r) for f, n in zip(falls, shape))
            np.maximum(codes[octant][corner], found[centre], out=codes[octant][corner])
    return codes


def walk_cells(volume, tf, table, occupancy):
    """(the walk map, the coefficient texture). A cell
    may show something where a value within one table cell of its corners' range has
    opacity (``occupancy``: the ray caster's ``preint_occupancy``, passed in by it). The
    walk map is uint32 per cell: in an empty cell the eight octants' codes, four bits
    each (octant o in bits 4o to 4o + 3, none of them 0: empty_cubes); in the n-th cell that may show
    something n << 4 (its low four bits 0). The coefficient texture (rows of
    COEFFICIENT_ROW cells, RGBA32F) holds those cells' coefficients, cell n at texels
    2 (n % COEFFICIENT_ROW) and the one after, row n // COEFFICIENT_ROW: 32 bytes per
    such cell only (every cell's would be 8x a float32 volume)."""
    shows = occupancy(cell_ranges(volume), tf, table) > 0
    codes = empty_cubes(shows)
    visible = np.flatnonzero(shows.ravel())
    if visible.size > MAX_VISIBLE_CELLS:
        raise ValueError(f"refine_walk='crossings' takes at most {MAX_VISIBLE_CELLS} cells whose values may "
                         f"have opacity, got {visible.size}")
    walk_map = np.zeros(shows.shape, np.uint32)
    for octant in range(8):
        walk_map |= codes[octant].astype(np.uint32) << np.uint32(4 * octant)
    walk_map.ravel()[visible] = np.arange(visible.size, dtype=np.uint32) << np.uint32(4)
    rows = max(-(-visible.size // COEFFICIENT_ROW), 1)
    texels = np.zeros((rows * COEFFICIENT_ROW, 8), np.float32)
    texels[:visible.size] = cell_coefficients(volume, np.stack(np.unravel_index(visible, shows.shape), axis=1))
    return walk_map, texels.reshape(rows, 2 * COEFFICIENT_ROW, 4)


def plan_walk(scene, step, refine, preint_fine, tables, defines, refine_walk, occupancy):
    """Set the defines of a refined plan's walk (REACH_WALK; CROSSING_WALK and its
    KNOT_COUNT) and return the walk by crossings' part of the plan (None for the other
    walks); a named error where it does not apply. ``occupancy``: see ``walk_cells``."""
    defines["REACH_WALK"] = int(refine_walk == "reach")
    if refine_walk != "crossings":
        return None
    volume = scene.volume
    if volume.has_nonfinite:
        raise ValueError("refine_walk='crossings' does not yet take volumes with non-finite samples")
    if min(volume.shape) < 2:
        raise ValueError(f"refine_walk='crossings' needs two samples along every axis, got shape {volume.shape}")
    knots = tables.get("crossing_knots", scene.tf, make=knot_values)
    walk_map, coefficients = tables.get(
        "crossing_walk_cells", volume, scene.tf, preint_fine,
        make=lambda v, tf, table: walk_cells(v, tf, table, occupancy))
    part = step / refine
    cells = int(np.sum(np.array(volume.shape) - 1)) + 3
    diagonal = float(np.linalg.norm(volume.spacing))
    per_cell = 3 * (len(knots) + 2) + int(np.ceil(diagonal / part)) + 2
    defines.update(CROSSING_WALK=1, KNOT_COUNT=max(len(knots), 1), CW_COEFFICIENT_ROW=COEFFICIENT_ROW)
    scale = max(np.abs(knots).max(initial=0.0), *np.abs(np.nan_to_num(volume.data_range)))
    return CrossingPlan(knots=knots, support=support(scene.tf), part=part,
                        rounds=min(cells * (per_cell + 1), 1 << 24), tol=float(2.0 ** -20 * scale),
                        walk_map=walk_map, coefficients=coefficients)


def add_inputs(renderer, plan, textures, uniforms):
    """What a ray-casting plan's optional features read (``common.add_optional_inputs``)
    and the walk by crossings' texture and uniforms."""
    from .common import add_optional_inputs
    add_optional_inputs(renderer, plan, textures, uniforms)
    crossings = getattr(plan, "crossings", None)
    if crossings is None:
        return
    from ..gl.resources import texture3d

    def texture2d(ctx, texels):
        tex = ctx.texture(texels.shape[1::-1], 4, np.ascontiguousarray(texels).tobytes(), dtype="f4")
        tex.filter = (ctx.NEAREST, ctx.NEAREST)
        return tex
    textures["t_walk_map"] = renderer.resources.for_objects(
        "crossing_walk_map", crossings.walk_map,
        make=lambda: texture3d(renderer.ctx, crossings.walk_map, 1, "u4", linear=False))
    textures["t_cell_coefficients"] = renderer.resources.for_objects(
        "crossing_cell_coefficients", crossings.coefficients,
        make=lambda: texture2d(renderer.ctx, crossings.coefficients))
    knots = crossings.knots if len(crossings.knots) else np.array([np.inf])
    big = 3.0e38
    uniforms.update({"u_knots": np.clip(knots, -big, big).astype(np.float32).tobytes(),
                     "u_support": tuple(float(np.clip(v, -big, big)) for v in crossings.support),
                     "u_cw_part": float(crossings.part), "u_cw_nominal": float(plan.preint_fine.length),
                     "u_cw_rounds": int(crossings.rounds), "u_cw_tol": crossings.tol})
