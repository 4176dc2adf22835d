"""Bricks for the point techniques that take grids: particles and splatting.

Neither draws a grid from a 3-D texture: particles are opaque spheres made on the CPU
and drawn with a depth test, Gaussian splats are classified samples composited back to
front, and the tent kernel's sheets add up per-sample values held in 2-D textures. What
needs the whole volume at once is making those primitives, which reads every sample.
Bricked (``brick_size=N``), they are made brick by brick instead, each brick from its own
block of samples (``bricks.partition``'s layout and halo, read through
``bricks.read_block``, so a source with a ``read`` method plugs in), and every primitive
is the one the whole volume makes, bit for bit:

- **Particles.** A grid's particles are made per generation tile of
  ``particle_sets.GENERATION_TILE`` cells a side, each tile from its own random stream
  and its own samples (``particle_sets.tile_particles``), so a brick makes its tiles'
  particles exactly as the whole volume does (a tile that straddles bricks, where ``N``
  is no multiple of the tile, is made once from its own block and its particles go to
  the brick that owns each one's cell). Lit, a particle's gradient comes from its brick's
  block (halo 2): the same float64 central differences (``block_gradients``). Each
  brick's particles are drawn as a buffer of their own into the same depth-tested
  pass; the depth test keeps the nearest sphere whatever the order, so the image is the
  single set's where no two particles on a pixel reach the same 24-bit depth (the
  order then decides; tests/test_bricks_points.py measures it).
- **Gaussian splats.** Each brick classifies the samples (at ``density``) that lie in
  the cells it owns (a shared face's to the brick after it, the volume's last face to
  the last brick), interpolated from its block with the same arithmetic (``x - o`` exact
  for a whole ``o``). The splats of all bricks are composited in one back-to-front order,
  the single texture's: by depth, ties by the sample's place in the volume (what the
  single sort's stability gives), so the blending is the same sequence of operations.
- **Tent splats.** Each brick decides which of the samples it owns are splatted (the
  corners of its occupied cells, from its block with a halo of 1) and reads their
  values; together they are the single texture's samples in the volume's order, so the
  sheets, runs and quads are the same. The gap pass and the cut pieces (clip planes,
  geometry) sample 3-D slicing's volume texture, as without bricks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import particle_sets as pbvr
from .bricks import partition, read_block


def check_grid(scene, technique):
    """Bricks take grids with finite samples: anything else is a ValueError naming it."""
    if scene.is_mesh:
        raise ValueError(f"brick_size cuts a grid into bricks; {technique} renders this TetMesh whole "
                         "(leave brick_size out)")
    if scene.volume.has_nonfinite:
        raise ValueError(f"bricked {technique} (brick_size) does not yet take non-finite samples")


def bricks_of(volume, brick_size, halo):
    return partition(volume.shape, brick_size, halo)


def block_of(volume, brick):
    """(float64 samples of the brick's block, its first sample (z, y, x))."""
    (z0, z1), (y0, y1), (x0, x1) = brick.samples
    return read_block(volume, z0, z1, y0, y1, x0, x1).astype(np.float64), (z0, y0, x0)


def block_gradients(volume, block, first, points):
    """(N, 3) float64: the contract's gradient at ``points`` (relative to the data's
    lower corner, all inside the block's owned cells; the block has a halo of 2) from the
    block alone: ``model.field.gradient``'s arithmetic on the volume's sample
    coordinates, less the block's first sample (exact), so the same bits."""
    from ..model.field import trilinear, world_to_index
    idx = world_to_index(volume, np.asarray(points, np.float64) + volume.bounds[0])
    shift = np.array(first[::-1], np.float64)          # x, y, z
    g = np.empty(idx.shape, np.float64)
    for axis in range(3):
        h = np.zeros(3)
        h[axis] = 1.0
        g[..., axis] = (trilinear(block, idx + h - shift) - trilinear(block, idx - h - shift)) \
            / (2 * volume.spacing[axis])
    return g


# ----------------------------------------------------------------------------- particles

@dataclass
class BrickedParticles:
    """One particle set made brick by brick: ``pieces`` the ParticleSet of each brick
    that has particles (``bricks`` those bricks), ``gradients`` their gradients (lit)."""
    bricks: list
    pieces: list
    gradients: list | None

    @property
    def count(self):
        return sum(p.count for p in self.pieces)

    @property
    def candidates(self):
        return sum(p.candidates for p in self.pieces)

    @property
    def cells(self):
        return sum(p.cells for p in self.pieces)

    def joined(self, tf):
        """The pieces as one ParticleSet (in brick order)."""
        return pbvr.join_sets(self.pieces, tf)


def _inside(tile, box):
    return all(b0 <= t0 and t1 <= b1 for (t0, t1), (b0, b1) in zip(tile, box))


def _owned(part, box, cell_shape):
    """The particles of a tile's ``Part`` whose cell lies in ``box``."""
    owner = np.concatenate(part.owners) if part.owners else np.zeros(0, np.int64)
    k, rem = np.divmod(owner, cell_shape[1] * cell_shape[2])
    j, i = np.divmod(rem, cell_shape[2])
    keep = np.ones(owner.size, bool)
    for c, (b0, b1) in zip((k, j, i), box):
        keep &= (b0 <= c) & (c < b1)
    pts = np.concatenate(part.points) if part.points else np.zeros((0, 3), np.float32)
    sc = np.concatenate(part.scalars) if part.scalars else np.zeros(0, np.float32)
    # the tile's candidates and emitting cells count once, with the brick owning its first cell
    first = all(b0 <= c0 < b1 for (c0, _), (b0, b1) in zip(part.tile, box))
    return pbvr.Part([pts[keep]], [sc[keep]], [owner[keep]], part.candidates if first else 0,
                      part.cells if first else 0)


def particle_bricks(volume, tf, radius, seed, repetition, sampler, brick_size, lit):
    """One particle set of ``volume`` made brick by brick (``BrickedParticles``): the
    particles ``particle_sets.generate`` makes, grouped by the brick owning their cell.
    Nothing reads the whole volume: the particle budget is checked on the candidates
    drawn so far."""
    cell_shape = [max(n - 1, 1) for n in volume.shape]
    straddling = {}       # tiles met by several bricks: made once
    bricks, pieces, gradients = [], [], []
    drawn = 0             # candidates so far: past MAX_PARTICLES, the radius is too small
    for brick in bricks_of(volume, brick_size, 2 if lit else 1):
        block, first = block_of(volume, brick)
        parts = []
        for tile in pbvr.grid_tiles(volume.shape, brick.cells):
            inside = _inside(tile, brick.cells)
            if inside:
                part = pbvr.tile_particles(block, first, tile, volume, tf, radius, seed, repetition, sampler)
            else:
                part = straddling.get(tile)
                if part is None:
                    (z0, z1), (y0, y1), (x0, x1) = tile
                    own = read_block(volume, z0, z1 + 1, y0, y1 + 1, x0, x1 + 1).astype(np.float64)
                    part = pbvr.tile_particles(own, (z0, y0, x0), tile, volume, tf, radius, seed, repetition,
                                               sampler)
                    part.tile = tile
                    straddling[tile] = part
                part = _owned(part, brick.cells, cell_shape)
            parts.append(part)
            drawn += part.candidates
            if drawn > pbvr.MAX_PARTICLES:
                pbvr.check_count(drawn, radius)
        piece = pbvr.join_sets(parts, tf)
        if piece.count == 0 and piece.candidates == 0:
            continue
        bricks.append(brick)
        pieces.append(piece)
        if lit:
            gradients.append(block_gradients(volume, block, first, piece.points).astype(np.float32))
    return BrickedParticles(bricks, pieces, gradients if lit else None)


# ----------------------------------------------------------------------------- Gaussian splats

def _owned_points(cells, last, density):
    """The sample indices (at ``density`` per spacing) in owned cells [c0, c1), with the
    closing face where ``c1`` is the volume's last cell face."""
    c0, c1 = cells
    return np.arange(c0 * density, c1 * density + (1 if c1 == last else 0))


def splat_rows(idx, s, tau, dims, spacing, tf, cell):
    """Kept splat samples at index positions ``idx`` (values ``s``, extinction ``tau``) as
    (positions, rows of colour and weighted extinction), float32. Trapezoid weights: a
    sample on a face of the box stands for half a cell along that axis, so the kernels
    carry the trapezoid rule's integral of tau over the box."""
    weight = np.prod(np.where((idx == 0) | (idx == dims - 1), 0.5, 1.0), axis=1)
    rows = np.concatenate([tf.color(s).reshape(-1, 3), (tau * weight * cell)[:, None]], axis=1)
    return (idx * spacing).astype(np.float32), rows.astype(np.float32)


def splat_bricks(volume, tf, density, brick_size):
    """(points, samples, key): the Gaussian kernel's classified samples
    (``splat.make_splats``'s, bit for bit) made brick by brick, and each one's place in
    the single texture's order (its linear index on the ``density`` grid), which breaks
    ties in depth (``splat.bricked_splats`` makes them Splats)."""
    from ..model.field import trilinear
    dims = volume.dims
    n = (dims - 1) * density + 1                       # x, y, z
    cell = float(np.prod(volume.spacing / density))
    last = [max(s - 1, 1) for s in volume.shape]       # z, y, x
    points, samples, keys = [], [], []
    for brick in bricks_of(volume, brick_size, 1):
        block, first = block_of(volume, brick)
        shift = np.array(first[::-1], np.float64)
        zs, ys, xs = (_owned_points(c, l, density) for c, l in zip(brick.cells, last))
        yy, xx = np.meshgrid(ys / density, xs / density, indexing="ij")
        gy, gx = np.meshgrid(ys, xs, indexing="ij")
        for kz in zs:
            idx = np.stack([xx.ravel(), yy.ravel(), np.full(xx.size, kz / density)], axis=1)
            s = trilinear(block, idx - shift)
            tau = pbvr.extinction(tf, s)
            keep = tau > 0
            if not keep.any():
                continue
            idx, s, tau = idx[keep], s[keep], tau[keep]
            at, rows = splat_rows(idx, s, tau, dims, volume.spacing, tf, cell)
            points.append(at)
            samples.append(rows)
            keys.append((kz * n[1] + gy.ravel()[keep]) * n[0] + gx.ravel()[keep])
    if not points:
        return np.zeros((0, 3), np.float32), np.zeros((0, 4), np.float32), np.zeros(0, np.int64)
    return np.concatenate(points), np.concatenate(samples), np.concatenate(keys).astype(np.int64)


def splat_order(scene, splats, key):
    """Back to front as ``splat.back_to_front`` sorts the single texture's splats: by the
    same float32 depth, ties by the place in the volume (``key``), as a stable sort of
    splats listed in the volume's order leaves them."""
    cam = scene.camera
    eye = (cam.eye - scene.volume.bounds[0]).astype(np.float32)
    rel = splats.points - eye
    depth = rel @ cam.forward.astype(np.float32) if cam.is_ortho else np.einsum("ij,ij->i", rel, rel)
    return np.lexsort((key, -depth)).astype(np.int32)


def splat_gradients_bricked(volume, splats, key, density, brick_size):
    """(N, 3) float32: each splat's gradient from the block of the brick owning it
    (halo 2), in the splats' order."""
    n = (volume.dims - 1) * density + 1
    at = np.stack([key % n[0], key // n[0] % n[1], key // (n[0] * n[1])], axis=1)     # x, y, z on the grid
    out = np.empty((len(key), 3), np.float32)
    for brick in bricks_of(volume, brick_size, 2):
        mine = np.ones(len(key), bool)
        last = [max(s - 1, 1) for s in volume.shape]
        for axis, ((c0, c1), l) in enumerate(zip(brick.cells, last)):
            c = at[:, 2 - axis]
            mine &= (c >= c0 * density) & ((c < c1 * density) | ((c1 == l) & (c == c1 * density)))
        if mine.any():
            block, first = block_of(volume, brick)
            out[mine] = block_gradients(volume, block, first, splats.points[mine]).astype(np.float32)
    return out


# ----------------------------------------------------------------------------- tent splats

def tent_bricks(volume, splatted, brick_size):
    """(values, at, mask) of ``splat.tent_samples`` made brick by brick: each brick marks
    which of its own samples are splatted (``splatted(block)``, a Volume of its block with
    a halo of 1, gives them: ``splat.bricked_tent_samples``; None: all) and reads their
    values; listed in the volume's order."""
    from ..model.volume import Volume
    shape = volume.shape
    mask = np.zeros(shape, bool)
    last = [max(s - 1, 1) for s in shape]
    index, values = [], []
    for brick in bricks_of(volume, brick_size, 1):
        (z0, z1), (y0, y1), (x0, x1) = brick.samples
        raw = read_block(volume, z0, z1, y0, y1, x0, x1)
        own = tuple(slice(c0 - s0, c1 - s0 + (1 if c1 == l else 0))
                    for (c0, c1), (s0, _), l in zip(brick.cells, brick.samples, last))
        if splatted is not None:
            here = splatted(Volume(raw, spacing=volume.spacing))[own]
        else:
            here = np.ones(raw[own].shape, bool)
        starts = [s.start + s0 for s, (s0, _) in zip(own, brick.samples)]
        region = tuple(slice(a, a + m) for a, m in zip(starts, here.shape))
        mask[region] = here
        local = np.argwhere(here) + starts
        index.append(np.ravel_multi_index(local.T, shape))
        values.append(raw[own][here].astype(np.float32))
    index = np.concatenate(index)
    order = np.argsort(index)
    return np.concatenate(values)[order], np.argwhere(mask)[:, ::-1].astype(np.int32), mask


def tent_gradients_bricked(samples, volume, brick_size):
    """(N, 3) float32: ``splat.tent_gradients`` (central differences at each splatted
    sample, clamped at the volume's faces) from the block of the brick owning each
    sample (halo 1: the neighbours one sample away)."""
    out = np.empty((samples.count, 3), np.float32)
    at = samples.at.astype(np.int64)            # x, y, z
    upper = np.array(volume.shape[::-1]) - 1
    last = [max(s - 1, 1) for s in volume.shape]
    for brick in bricks_of(volume, brick_size, 1):
        mine = np.ones(samples.count, bool)
        for axis, ((c0, c1), l) in enumerate(zip(brick.cells, last)):
            c = at[:, 2 - axis]
            mine &= (c >= c0) & ((c < c1) | ((c1 == l) & (c == c1)))
        if not mine.any():
            continue
        block, first = block_of(volume, brick)
        mine_at = at[mine]
        shift = np.array(first[::-1], np.int64)
        g = np.empty(mine_at.shape, np.float64)
        for axis in range(3):
            ahead, behind = mine_at.copy(), mine_at.copy()
            ahead[:, axis] = np.minimum(mine_at[:, axis] + 1, upper[axis])
            behind[:, axis] = np.maximum(mine_at[:, axis] - 1, 0)
            ahead -= shift
            behind -= shift
            g[:, axis] = (block[ahead[:, 2], ahead[:, 1], ahead[:, 0]]
                          - block[behind[:, 2], behind[:, 1], behind[:, 0]]) / (2 * volume.spacing[axis])
        out[mine] = g.astype(np.float32)
    return out
