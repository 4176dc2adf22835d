"""Bricks of several pyramid levels in one frame (``rendering.pyramid_bricks``'s per-brick
choice draws through :class:`BrickLevels`, which ``techniques.bricks.draw`` takes as a
plan's ``brick_levels``)."""

from __future__ import annotations

import numpy as np

from ..util.memory import BrickCache, parse_bytes
from .bricks import Brick, LazyBrickTextures, filter_is_exact
from .lazy_bricks import default_memory


def level_block(base, own, brick, halo):
    """(samples ((z0, z1), (y0, y1), (x0, x1)) of the level ``own``, its first sample in
    the shader's texel units, x y z) that a brick of ``base``'s partition (level 0)
    reads from ``own``: every trilinear corner of a point of the owned box, and of its
    gradient's neighbours one level spacing away where ``halo`` is 2 (``bricks.halo_for``),
    and one sample more on each side for rounding, clamped to the level."""
    s0 = np.asarray(base.spacing, np.float64)[::-1]              # z, y, x
    sl = np.asarray(own.spacing, np.float64)[::-1]
    shift = (np.asarray(own.origin, np.float64) - np.asarray(base.origin, np.float64))[::-1]
    samples, first = [], []
    for a, ((c0, c1), n) in enumerate(zip(brick.cells, own.shape)):
        lo = np.floor((c0 * s0[a] - shift[a]) / sl[a])
        hi = np.floor((c1 * s0[a] - shift[a]) / sl[a])
        # corners floor(x), floor(x) + 1, gradient neighbours one more (halo 2), one for rounding
        b0, b1 = int(max(lo - halo, 0)), int(min(hi + halo + 2, n))
        samples.append((b0, b1))
        first.append(shift[a] / sl[a] + b0)
    return tuple(samples), tuple(first[::-1])


class BrickLevels:
    """The bricks of one frame drawn from several levels of a pyramid
    (``rendering.pyramid``'s per-brick choice): the partition is level 0's (its bricks,
    their owned boxes, the rays' segments and the visibility order are level 0's, so
    each sample is still taken by exactly one brick, at the same place), and a brick of
    level ``L`` samples level ``L``'s texture of the samples around the same box.

    ``levels``: the pyramid's LazyVolumes, level 0 first, lying on each other in world
    space (``rendering.pyramid.level_volume``); ``chosen``: brick index (bz, by, bx) ->
    level (bricks not named: ``default``); ``memory``: the brick cache's budget, shared
    by the levels (``cache``: a BrickCache to share with other frames instead).

    A level-``L`` brick's texture holds the level's samples whose trilinear corners and
    gradient neighbours (one level-``L`` spacing away) any point of the owned box can
    reach, plus one for rounding, clamped to the level; its pass maps a world point to the
    level's texel ``(p - (origin_L - origin_0)) / spacing_L - first`` through the
    shader's ``u_spacing`` and a fractional ``u_brick_origin``. At a face between bricks
    of two levels the field jumps from one level's interpolant to the other's (no gap and
    no sample taken twice: ownership is level 0's); gradients near that face are the
    brick's own level's. ``drawn`` counts the passes per level and ``bytes`` the bytes of
    the blocks uploaded per level."""

    def __init__(self, levels, chosen, default=0, memory=None, cache=None):
        self.levels = tuple(levels)
        dtypes = {np.dtype(v.dtype) for v in self.levels}
        if len(dtypes) != 1:
            raise ValueError(f"the levels of one frame must share a dtype (one shader), got {sorted(map(str, dtypes))}")
        for index, level in chosen.items():
            if not 0 <= int(level) < len(self.levels):
                raise ValueError(f"brick {index}: level {level} is not one of the {len(self.levels)} levels")
        self.chosen = {tuple(int(i) for i in k): int(v) for k, v in chosen.items()}
        self.default = int(default)
        self.memory = default_memory() if memory is None else parse_bytes(memory, "memory")
        self.cache = BrickCache(self.memory) if cache is None else cache    # (one shared by frames of a store)
        self._textures = {}
        self.current = None
        self.drawn = [0] * len(self.levels)
        self.bytes = [0] * len(self.levels)

    def level_of(self, brick):
        return self.chosen.get(tuple(brick.index), self.default)

    def block(self, brick, level, halo):
        return level_block(self.levels[0], self.levels[level], brick, halo)

    def textures_for(self, ctx, level, filter_exact):
        key = (id(ctx), level, filter_exact)
        if key not in self._textures:
            self._textures[key] = LazyBrickTextures(ctx, self.levels[level], filter_exact, self.cache)
        return self._textures[key]

    def get(self, renderer, brick, halo, placement):
        """(texture, offset, uniforms) of ``brick``'s pass; ``placement`` is level 0's
        ``bricks.brick_uniforms`` of it (kept for level 0 and for the owned boxes)."""
        self.release()
        level = self.level_of(brick)
        textures = self.textures_for(renderer.ctx, level, filter_is_exact(renderer))
        uniforms = dict(placement, u_spacing=tuple(float(v) for v in self.levels[level].spacing))
        if level == 0:
            part = brick
        else:
            samples, first = self.block(brick, level, halo)
            part = Brick(brick.index, brick.cells, samples)
            uniforms["u_brick_origin"] = first
            uniforms["u_brick_texels"] = tuple(float(b1 - b0) for b0, b1 in samples[::-1])
        tex, offset = textures.get(part)
        self.current = textures
        self.drawn[level] += 1
        self.bytes[level] += int(np.prod([b1 - b0 for b0, b1 in part.samples])) * self.levels[level].dtype.itemsize
        return tex, offset, uniforms

    def release(self):
        if self.current is not None:
            self.current.release()
            self.current = None

    def counts(self):
        """Bricks per level in ``chosen`` (the default's count not included)."""
        out = [0] * len(self.levels)
        for level in self.chosen.values():
            out[level] += 1
        return out
