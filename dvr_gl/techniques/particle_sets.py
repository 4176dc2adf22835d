"""Particles for particle-based volume rendering (PBVR): opaque spheres whose density
follows the transfer function, so that the first particle a ray meets has, in
expectation, the colour of the emission-absorption integral.

Why it works. Let the particle centres be a Poisson process of intensity ``rho(x)`` and
every particle a sphere of radius ``r`` (world units), seen from any direction as a disc
of area ``A = pi r^2``. A ray meets the particles whose centres lie within ``r`` of it:
along a stretch ``dt`` of the ray their number is Poisson with mean ``rho A dt`` (for
``rho`` that varies little across the width ``2 r``). With

    rho(x) = tau(s(x)) / A,    tau(s) = -ln(1 - alpha(s)) / unit_distance

the probability that the ray meets none up to ``t`` is ``exp(-integral tau)``, which is
the contract's transmittance, and the first particle met lies in ``[t, t + dt]`` with
probability ``tau T dt``. Drawing that particle with the colour ``c(s)`` at its centre and
opacity 1 gives a pixel whose expected value is ``integral c tau T dt`` with expected
alpha ``1 - T``: the emission-absorption image. What remains is noise, which averaging
``R`` independent particle sets divides by ``sqrt(R)``, and a bias of order ``r^2``
(``rho`` averaged over the ray's cylinder, and the domain's edge cutting it), which a
radius of at most half a pixel and half a cell keeps small.

Sampling by thinning (``sampler="rejection"``). Per cell (grid cell or tetrahedron) the
largest extinction over the cell's scalar range bounds ``tau`` there; a Poisson number of
candidates with mean ``tau_max V / A`` is placed uniformly in the cell and each is kept
with probability ``tau(s) / tau_max``. Thinning a Poisson process this way gives exactly
the Poisson process of intensity ``tau(s(x)) / A``: no bias from the sampler. Cells
whose range has zero opacity make no candidates.

The classic samplers are there to compare with: ``"uniform"`` draws a Poisson number of
particles with mean ``tau`` averaged over the cell's corners times ``V / A`` and places
them uniformly; ``"metropolis"`` takes the same count and moves each particle by an
independence Metropolis chain inside its cell (``METROPOLIS_STEPS`` uniform proposals,
accepted with ``min(1, tau' / tau)``), so positions follow ``tau`` within the cell. Both
are biased where ``tau`` is not linear over a cell (the corner average is not the cell's
integral); docs/guide/particles.md reports by how much.

A grid's particles are made per tile of ``GENERATION_TILE`` cells a side, each tile with
its own random stream (keyed by seed, repetition and the tile's index) and its own
samples, so that bricks, which make the tiles they hold, make the same particles
(``point_bricks``). A mesh's come from one stream.

Opacity 1 is infinite extinction; it is capped at ``alpha = 1 - 1e-6`` (``TAU_CAP``), a
transmittance of 1e-6 per unit distance.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass

import numpy as np

SAMPLERS = ("rejection", "uniform", "metropolis")
METROPOLIS_STEPS = 16          # independence-sampler steps per particle
ALPHA_CAP = 1.0 - 1e-6          # opacity 1 would need infinitely many particles
MAX_PARTICLES = 50_000_000      # per set: beyond this the radius is too small for memory
_CELL_CHUNK = 1 << 18           # cells processed at a time


@dataclass
class ParticleSet:
    """One independent set: ``points`` (N, 3) float32 relative to the data's lower corner,
    ``scalars`` (N,) float32, ``colors`` (N, 3) float32 (the exact TF's at each scalar,
    made with the set: a set belongs to one TF), how many candidates were drawn, and the
    cell of each particle (a lit mesh's particles take their cell's gradient)."""
    points: np.ndarray
    scalars: np.ndarray
    colors: np.ndarray
    candidates: int
    cells: int                   # cells that can emit (non-zero opacity in their range)
    owners: np.ndarray = None    # (N,) the cell (grid cell or tetrahedron) each particle is in

    @property
    def count(self):
        return len(self.scalars)


def extinction(tf, s):
    """tau(s) = -ln(1 - alpha(s)) / unit_distance, alpha capped at ALPHA_CAP."""
    return _tau(tf.opacity(np.asarray(s, np.float64)), tf)


def _tau(alpha, tf):
    return -np.log1p(-np.minimum(alpha, ALPHA_CAP)) / tf.unit_distance


def max_extinction(tf, lo, hi):
    """The largest tau over each scalar interval [lo, hi] (arrays): opacity is piecewise
    linear, so its maximum is at an end or at an opacity control point inside."""
    alpha = np.maximum(tf.opacity(lo), tf.opacity(hi))
    for s, a in tf.opacity_points:
        inside = (lo < s) & (s < hi)
        alpha = np.where(inside, np.maximum(alpha, a), alpha)
    return _tau(alpha, tf)


def default_radius(scene):
    """Half the width of a pixel at the distance of the data's centre from the eye (at
    least a quarter of the data's diagonal, for an eye inside the data; orthographic:
    half a pixel), and at most half the data's resolution (the smallest grid spacing, or
    a mesh's median edge): particles no wider than a pixel or a cell, since the bias
    grows with the radius squared times the density's curvature. Rounded to 6
    significant digits, so that turning the camera about the data keeps the radius (and
    the particles)."""
    cam = scene.camera
    data = scene.volume
    lo, hi = data.bounds
    half_height = cam.screen_scale(scene.width, scene.height)[1]
    if cam.is_ortho:
        pixel = 2.0 * half_height / scene.height
    else:
        distance = max(float(np.dot(0.5 * (lo + hi) - cam.eye, cam.forward)), 0.25 * float(np.linalg.norm(hi - lo)))
        pixel = 2.0 * half_height * distance / scene.height
    cell = data.cell_size if hasattr(data, "tets") else data.min_spacing
    return float(f"{0.5 * min(pixel, cell):.6g}")


def candidate_count(data, tf, radius):
    """The mean number of candidates thinning draws per set (an upper bound of the
    particles): the cells' largest extinction times their volume over pi r^2."""
    cells = _cells(data)
    return float((max_extinction(tf, cells.lo, cells.hi) * cells.volume).sum() / (math.pi * radius ** 2))


def generate(data, tf, radius, seed=0, repetition=0, sampler="rejection"):
    """One particle set for a Volume or a TetMesh, reproducible from (seed, repetition).
    A grid's is made tile by tile (``grid_tiles``), each tile from its own random stream,
    so that bricks (``generate_bricks``) make the very same particles."""
    if sampler not in SAMPLERS:
        raise ValueError(f"sampler must be one of {', '.join(SAMPLERS)}, got {sampler!r}")
    if not (isinstance(radius, (int, float)) and math.isfinite(radius) and radius > 0):
        raise ValueError(f"radius must be a positive number (world units), got {radius!r}")
    if not hasattr(data, "tets"):
        check_budget(data, tf, radius)
        values = _cells(data).values
        parts = [tile_particles(values, (0, 0, 0), tile, data, tf, radius, seed, repetition, sampler)
                 for tile in grid_tiles(data.shape)]
        return join_sets(parts, tf)
    rng = np.random.default_rng([int(seed), int(repetition)])
    cells = _cells(data)
    area = math.pi * radius ** 2
    tau_max = max_extinction(tf, cells.lo, cells.hi)
    emitting = np.flatnonzero((tau_max > 0) & (cells.volume > 0))
    if sampler == "rejection":
        mean = tau_max[emitting] * cells.volume[emitting] / area
    else:                       # the classic estimate: tau at the corners, averaged
        mean = np.concatenate([extinction(tf, cells.corners(emitting[i:i + _CELL_CHUNK])).mean(axis=1)
                               for i in range(0, emitting.size, _CELL_CHUNK)] or [np.zeros(0)])
        mean = mean * cells.volume[emitting] / area
    check_count(mean.sum(), radius)
    points, scalars, owners, candidates = [], [], [], 0
    for start in range(0, emitting.size, _CELL_CHUNK):
        owner = np.repeat(emitting[start:start + _CELL_CHUNK], rng.poisson(mean[start:start + _CELL_CHUNK]))
        candidates += owner.size
        p, s, owner = _thin(cells, owner, tf, tau_max, sampler, rng)
        points.append(p.astype(np.float32))
        scalars.append(s.astype(np.float32))
        owners.append(owner)
    part = Part(points, scalars, owners, candidates, int(emitting.size))
    return join_sets([part], tf)


def check_count(candidates, radius):
    if candidates > MAX_PARTICLES:
        raise ValueError(f"radius={radius!r} needs about {candidates:.3g} particle candidates per set "
                         f"(at most {MAX_PARTICLES:,}): use a larger radius or a smaller image")


def check_budget(data, tf, radius):
    """A grid's candidates per set (their largest count, ``candidate_count``) within
    MAX_PARTICLES, else a ValueError naming the radius."""
    check_count(candidate_count(data, tf, radius), radius)


def _thin(cells, owner, tf, tau_max, sampler, rng):
    """Candidates placed uniformly in their cells, then thinned (rejection) or moved
    (metropolis); (points, scalars, owners) of the particles kept."""
    p, s = cells.place(owner, rng)
    if sampler == "rejection":
        keep = rng.random(owner.size) * tau_max[owner] < extinction(tf, s)
        p, s, owner = p[keep], s[keep], owner[keep]
    elif sampler == "metropolis":
        p, s = _metropolis(cells, owner, p, s, tf, rng)
    return p, s, owner


@dataclass
class Part:
    """A piece of a set (a tile's, or a mesh's whole): lists of arrays, joined once."""
    points: list
    scalars: list
    owners: list
    candidates: int
    cells: int


def join_sets(parts, tf):
    """One ParticleSet of the pieces ``parts`` (``Part`` or ParticleSet), in order; the
    colours made once, from the scalars (the exact TF's)."""
    points, scalars, owners = [np.zeros((0, 3), np.float32)], [np.zeros(0, np.float32)], [np.zeros(0, np.int64)]
    candidates = cells = 0
    for part in parts:
        if isinstance(part, ParticleSet):
            points.append(part.points), scalars.append(part.scalars), owners.append(part.owners)
        else:
            points += part.points
            scalars += part.scalars
            owners += part.owners
        candidates += part.candidates
        cells += part.cells
    scalars = np.concatenate(scalars)
    colors = tf.color(scalars.astype(np.float64)).reshape(-1, 3).astype(np.float32)
    return ParticleSet(np.concatenate(points), scalars, colors, candidates, cells, np.concatenate(owners))


# ----------------------------------------------------------------------------- grids, tile by tile

GENERATION_TILE = 32     # a grid's particles are made per tile of this many cells a side


def grid_tiles(shape, box=None):
    """The generation tiles of a grid of ``shape`` (nz, ny, nx) samples, each
    ((z0, z1), (y0, y1), (x0, x1)) half-open in cells, z slowest; with ``box`` (the same
    form) only those that meet it."""
    cells = [max(n - 1, 1) for n in shape]
    ranges = []
    for axis, c in enumerate(cells):
        lo, hi = (0, c) if box is None else box[axis]
        first = lo // GENERATION_TILE * GENERATION_TILE
        ranges.append([(t, min(t + GENERATION_TILE, c)) for t in range(first, hi, GENERATION_TILE)])
    return [(z, y, x) for z in ranges[0] for y in ranges[1] for x in ranges[2]]


def tile_particles(values, offset, tile, data, tf, radius, seed, repetition, sampler):
    """The particles of the cells of ``tile``, from its own random stream (keyed by seed,
    repetition and the tile's index) and its samples alone: ``values`` (float64) holds
    them, its first sample being the volume's ``offset`` (z, y, x). The same whichever
    array holds the samples: every position is the tile's cell index plus a fraction,
    times the spacing, in float64, and every value is interpolated from the same corners."""
    (z0, z1), (y0, y1), (x0, x1) = tile
    oz, oy, ox = offset
    v = values[z0 - oz:z1 + 1 - oz, y0 - oy:y1 + 1 - oy, x0 - ox:x1 + 1 - ox]
    nz, ny, nx = z1 - z0, y1 - y0, x1 - x0
    eight = [v[z:z + nz, y:y + ny, x:x + nx] for z in (0, 1) for y in (0, 1) for x in (0, 1)]
    lo = np.minimum.reduce(eight).ravel()
    hi = np.maximum.reduce(eight).ravel()
    volume = np.full(lo.size, float(np.prod(data.spacing)))
    if data.cell_valid is not None:
        volume[~data.cell_valid[z0:z1, y0:y1, x0:x1].ravel()] = 0.0
    tau_max = max_extinction(tf, lo, hi)
    emitting = np.flatnonzero((tau_max > 0) & (volume > 0))
    if emitting.size == 0:
        return Part([], [], [], 0, 0)
    cells = _block_cells(v, (z0, y0, x0), data.spacing)
    area = math.pi * radius ** 2
    if sampler == "rejection":
        mean = tau_max[emitting] * volume[emitting] / area
    else:                       # the classic estimate: tau at the corners, averaged
        mean = extinction(tf, cells.corners(emitting)).mean(axis=1) * volume[emitting] / area
    T = GENERATION_TILE
    rng = np.random.default_rng([int(seed), int(repetition), z0 // T, y0 // T, x0 // T])
    owner = np.repeat(emitting, rng.poisson(mean))
    candidates = owner.size
    p, s, owner = _thin(cells, owner, tf, tau_max, sampler, rng)
    k, rem = np.divmod(owner, ny * nx)          # the tile's cell index to the volume's
    j, i = np.divmod(rem, nx)
    cz, cy, cx = (max(n - 1, 1) for n in data.shape)
    global_owner = ((k + z0) * cy + (j + y0)) * cx + (i + x0)
    return Part([p.astype(np.float32)], [s.astype(np.float32)], [global_owner], candidates, int(emitting.size))


def _block_cells(v, first, spacing):
    """``_Cells``-like placing and corners for the cells of the block of samples ``v``
    whose first sample is the volume's ``first`` (z, y, x)."""
    nz, ny, nx = (n - 1 for n in v.shape)
    z0, y0, x0 = first

    def place(cells, rng):
        k, rem = np.divmod(cells, ny * nx)
        j, i = np.divmod(rem, nx)
        f = rng.random((cells.size, 3))
        fx, fy, fz = f[:, 0], f[:, 1], f[:, 2]
        c00 = v[k, j, i] * (1 - fx) + v[k, j, i + 1] * fx
        c10 = v[k, j + 1, i] * (1 - fx) + v[k, j + 1, i + 1] * fx
        c01 = v[k + 1, j, i] * (1 - fx) + v[k + 1, j, i + 1] * fx
        c11 = v[k + 1, j + 1, i] * (1 - fx) + v[k + 1, j + 1, i + 1] * fx
        s = (c00 * (1 - fy) + c10 * fy) * (1 - fz) + (c01 * (1 - fy) + c11 * fy) * fz
        p = (np.stack([i + x0, j + y0, k + z0], axis=1) + f) * spacing
        return p, s

    def corners(cells):
        k, rem = np.divmod(cells, ny * nx)
        j, i = np.divmod(rem, nx)
        return np.stack([v[k + dz, j + dy, i + dx] for dz in (0, 1) for dy in (0, 1) for dx in (0, 1)], axis=1)
    return _Cells(None, None, None, place, corners)


def particle_gradients(particle_set, data):
    """(N, 3) float32: the gradient at each particle, for lighting it. A grid's is the
    contract's gradient at the particle's centre; a mesh's, its cell's (constant)."""
    from ..model.field import point_gradients
    return point_gradients(data, particle_set.points, particle_set.owners).astype(np.float32)


def _metropolis(cells, owner, p, s, tf, rng):
    """Each particle's position moved by an independence Metropolis chain inside its cell
    (uniform proposals, accepted with min(1, tau' / tau)): after the steps its
    distribution approaches tau(s(x)) within the cell."""
    tau = extinction(tf, s)
    for _ in range(METROPOLIS_STEPS):
        q, t = cells.place(owner, rng)
        tau_q = extinction(tf, t)
        accept = rng.random(owner.size) * tau <= tau_q
        p = np.where(accept[:, None], q, p)
        s = np.where(accept, t, s)
        tau = np.where(accept, tau_q, tau)
    return p, s


@dataclass
class _Cells:
    """Per cell (grid cell or tetrahedron): scalar min and max, volume; ``place(cells,
    rng)`` draws one uniform point in each listed cell (relative to the data's lower
    corner) with the field there; ``corners(cells)`` gives their corner values."""
    lo: np.ndarray
    hi: np.ndarray
    volume: np.ndarray
    place: object
    corners: object
    values: np.ndarray = None    # a grid's samples, float64


_CELLS = weakref.WeakKeyDictionary()    # data -> _Cells, while the data lives


def _cells(data):
    cells = _CELLS.get(data)
    if cells is None:
        cells = _CELLS[data] = _tet_cells(data) if hasattr(data, "tets") else _grid_cells(data)
    return cells


def _grid_cells(vol):
    """A grid's cell ranges and volumes (``candidate_count``) and its samples, float64
    (placing is per tile: ``tile_particles``)."""
    v = vol.values(np.float64)
    eight = [v[z:z + v.shape[0] - 1, y:y + v.shape[1] - 1, x:x + v.shape[2] - 1]
             for z in (0, 1) for y in (0, 1) for x in (0, 1)]
    lo = np.minimum.reduce(eight).ravel()
    hi = np.maximum.reduce(eight).ravel()
    volume = np.full(lo.size, float(np.prod(vol.spacing)))
    if vol.cell_valid is not None:
        volume[~vol.cell_valid.ravel()] = 0.0
    return _Cells(lo, hi, volume, None, None, v)


def _tet_cells(mesh):
    pts = mesh.points - mesh.bounds[0]
    tets = mesh.tets                     # (the closures hold arrays, never the mesh: cached weakly)
    vals = mesh.scalars[tets]
    volume = np.abs(mesh.signed_volumes())

    def place(cells, rng):
        # uniform in a simplex: normalised exponential spacings (Dirichlet(1, 1, 1, 1))
        w = -np.log1p(-rng.random((cells.size, 4)))
        w /= w.sum(axis=1, keepdims=True)
        p = np.einsum("nk,nkj->nj", w, pts[tets[cells]])
        s = np.einsum("nk,nk->n", w, vals[cells])
        return p, s
    return _Cells(vals.min(axis=1), vals.max(axis=1), volume, place, lambda cells: vals[cells])
