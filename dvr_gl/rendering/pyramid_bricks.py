"""A level per brick: ``tolerance=E`` on a pyramid with ``per_brick=True``.

Level 0's volume is cut into bricks (``brick_size`` cells a side, default
``BRICK_CELLS``) and each brick is drawn from a level of its own in one frame
(``techniques.brick_levels.BrickLevels``: the rays, their segments and the bricks'
ownership stay level 0's, a brick samples its level's texture of the samples around
its box). The choice, on top of the one-level choice (``pyramid.settings``) for the
same ``E``, whose level ``L*`` and step it keeps:

1. A score per brick and level (``brick_scores``): the RMS, over level 0's samples of
   the brick, of the difference between the premultiplied colour and opacity the TF
   gives level 0's sample and what it gives level ``L``'s trilinear interpolant at the
   same point (the value the frame would draw there), made monotone over levels (a
   coarser level never scores below a finer one). It says where coarse levels lose what
   the TF shows; it only orders the bricks, it is not the error.
2. Candidates: for a threshold ``t``, every brick takes the coarsest level whose score
   is at most ``t``, and never a finer one than ``L*``. A larger ``t`` is a coarser
   frame. The thresholds are the scores themselves; a bisection over them finds the
   largest whose frame, rendered at the check size of level 0's reference (the one the
   one-level choice measured against), has its error bound (``tolerance.error_bound``)
   within ``tolerance.CHECK_TARGET * E``. The error is measured on the scene, on the
   mixed frame itself: seams between levels included.
3. Where no candidate is within it (not even ``t`` = the least score), or ``L*`` is the
   coarsest level already, the frame is the one-level choice's, drawn as it draws it.

Level 0's samples are read once for the scores (a pass over the store, as its brick
summary is); the frame reads only the chosen levels' blocks. The choice is a
:class:`BrickChoice` on ``Renderer.last_choice``, kept like the one-level choice.
"""

from __future__ import annotations

import time
import weakref
from dataclasses import dataclass, field

import numpy as np

from . import tolerance as tol

BRICK_CELLS = 64      # level-0 cells a side of a brick, unless brick_size is given


@dataclass(frozen=True)
class BrickChoice:
    """What ``tolerance=E, per_brick=True`` picked: per brick index (bz, by, bx) of level
    0's partition in bricks of ``brick_size`` cells, a level (``chosen``, as pairs), the
    bricks per level (``counts``), the step (world units and level-0 voxels), the error
    bound of the mixed frame against level 0's reference at ``check_size``, every
    (threshold, bricks per level, bound) measured (``trials``), the seconds it took
    (the one-level choice's included) and the one-level :class:`LevelChoice` it started
    from (``single``). ``mixed`` False: no candidate was within E, the frame is
    ``single``'s."""
    tolerance: float
    brick_size: int
    levels: int
    chosen: tuple
    counts: tuple
    step: float
    step_voxels: float
    checked_rmse: float
    reference_error: float
    check_size: tuple
    trials: tuple
    seconds: float
    single: object
    mixed: bool
    drawer: object = field(default=None, compare=False, repr=False)    # the BrickLevels that draws it

    @property
    def sampling(self):
        return self.single.sampling

    @property
    def level(self):
        """The finest level a brick draws from."""
        return min((level for _, level in self.chosen), default=self.single.level) if self.mixed else self.single.level

    def describe(self):
        if not self.mixed:
            why = ("no mix within" if self.trials else "one level is the coarsest for")
            return f"per brick: {why} tolerance {self.tolerance:g}; " + self.single.describe()
        per = ", ".join(f"{n} at level {k}" for k, n in enumerate(self.counts) if n)
        return (f"per brick ({self.brick_size} cells): {per}; step {self.step:g} ({self.step_voxels:.3g} level-0 "
                f"voxels) for tolerance {self.tolerance:g}: error bound {self.checked_rmse:.3g} at "
                f"{self.check_size[0]}x{self.check_size[1]} against level 0's reference, choice {self.seconds:.2f} s")


def _along(block, axis, x):
    """Linear interpolation of ``block`` along ``axis`` at texel positions ``x`` (clamped
    to the block's edge, as the texture unit clamps)."""
    n = block.shape[axis]
    xc = np.clip(x, 0.0, n - 1)
    i0 = np.floor(xc).astype(np.int64)
    i1 = np.minimum(i0 + 1, n - 1)
    shape = [1, 1, 1]
    shape[axis] = -1
    f = (xc - i0).reshape(shape)
    return np.take(block, i0, axis) * (1.0 - f) + np.take(block, i1, axis) * f


def _shown(tf, values):
    """Premultiplied colour and opacity (N, 4) of the TF at ``values``."""
    alpha = tf.opacity(values)
    return np.concatenate([tf.color(values) * alpha[..., None], alpha[..., None]], axis=-1)


def brick_scores(levels, bricks, tf):
    """(bricks, levels) float64: the score of each brick at each level (module docstring,
    step 1); level 0's column is 0."""
    from ..techniques.brick_levels import level_block
    base = levels[0]
    s0 = np.asarray(base.spacing, np.float64)[::-1]
    scores = np.zeros((len(bricks), len(levels)))
    for i, brick in enumerate(bricks):
        (z0, z1), (y0, y1), (x0, x1) = [(c0, min(c1 + 1, n)) for (c0, c1), n in zip(brick.cells, base.shape)]
        v0 = np.asarray(base.read(z0, z1, y0, y1, x0, x1), np.float64)
        shown0 = _shown(tf, v0)
        for k in range(1, len(levels)):
            own = levels[k]
            samples, _ = level_block(base, own, brick, 0)
            block = np.asarray(own.read(*(b for pair in samples for b in pair)), np.float64)
            sl = np.asarray(own.spacing, np.float64)[::-1]
            shift = (np.asarray(own.origin, np.float64) - np.asarray(base.origin, np.float64))[::-1]
            vk = block
            for axis, (first, last) in enumerate(((z0, z1), (y0, y1), (x0, x1))):
                x = (np.arange(first, last) * s0[axis] - shift[axis]) / sl[axis] - samples[axis][0]
                vk = _along(vk, axis, x)
            scores[i, k] = float(np.sqrt(np.mean((_shown(tf, vk) - shown0) ** 2)))
    return np.maximum.accumulate(scores, axis=1)


_CACHES = weakref.WeakKeyDictionary()      # level 0's volume -> {budget: BrickCache}


def shared_cache(volume, memory):
    """One BrickCache per store (its level-0 volume) and budget, for every frame the
    per-brick choice draws (its trials and its frames), so they hold one budget."""
    from ..techniques.lazy_bricks import default_memory
    from ..util.memory import BrickCache, parse_bytes
    budget = default_memory() if memory is None else parse_bytes(memory, "memory")
    caches = _CACHES.setdefault(volume, {})
    if budget not in caches:
        caches[budget] = BrickCache(budget)
    return caches[budget]


def assignment(scores, threshold, floor):
    """Per brick the coarsest level whose score is within ``threshold``, at least ``floor``."""
    within = scores <= threshold
    coarsest = np.where(within.all(axis=1), scores.shape[1] - 1, np.argmin(within, axis=1) - 1)
    return np.maximum(coarsest, floor)


def brick_settings(renderer, scene, tolerance, technique, options):
    """(level 0's scene, step, options with ``brick_levels`` and ``brick_size``,
    BrickChoice) for ``tolerance`` (the module's docstring); where no mix is within it,
    the one-level choice's (scene, step, options, BrickChoice with ``mixed`` False)."""
    from ..techniques.bricks import check_brick_size
    from . import pyramid
    t0 = time.perf_counter()
    tolerance = pyramid.check_request(scene, tolerance, technique)
    options = dict(options)
    brick_size = check_brick_size(options.pop("brick_size", None)) or BRICK_CELLS
    level_scene, step, level_options, single = pyramid.settings(renderer, scene, tolerance, technique, options)
    volume = scene.volume
    levels = [pyramid.level_volume(volume, k) for k in range(len(volume.levels))]
    scene0 = scene.replace(volume=levels[0])
    sampling = single.sampling
    key = ("pyramid per brick", tol.check_scene(scene0).digest(), (scene.width, scene.height), brick_size) + \
        tol.family_key(scene0, options)[1:] + (tuple(sorted(sampling.items())), tolerance)
    models = renderer._error_models
    chosen = models.items.get(key)
    if chosen is None:
        chosen = _choose(renderer, scene0, levels, tolerance, technique, options, single, brick_size, t0)
        models.put(key, chosen)
    if not chosen.mixed:
        return level_scene, step, level_options, chosen
    return scene0, chosen.step, dict(options, **sampling, brick_size=brick_size, brick_levels=chosen.drawer), chosen


def _choose(renderer, scene0, levels, tolerance, technique, options, single, brick_size, t0):
    from ..techniques.bricks import partition
    from ..techniques.brick_levels import BrickLevels
    from . import pyramid
    sampling = single.sampling
    reference, sampled = pyramid._reference(renderer, scene0, tolerance, technique, options, sampling)
    check = reference.scene
    target = tol.CHECK_TARGET * tolerance
    bricks = partition(levels[0].shape, brick_size, 0)
    scores = renderer._error_models.get(
        ("pyramid brick scores", levels[0].digest(), scene0.tf.key(), brick_size),
        lambda: brick_scores(levels, bricks, scene0.tf))
    floor = single.level
    step = single.step
    cache = shared_cache(levels[0], options.get("memory"))
    thresholds = np.unique(scores[:, floor + 1:]) if floor + 1 < len(levels) else np.array([])
    trials, measured = [], {}

    def bound_at(i):
        if i not in measured:
            levels_of = assignment(scores, thresholds[i], floor)
            drawer = BrickLevels(levels, {b.index: int(k) for b, k in zip(bricks, levels_of)}, cache=cache)
            image = renderer.render(check, technique, step=step, brick_size=brick_size, brick_levels=drawer,
                                    **dict(options, **sampling))
            bound = tol.error_bound(image, reference.image, reference.error, sampled)
            counts = tuple(int(n) for n in np.bincount(levels_of, minlength=len(levels)))
            trials.append((float(thresholds[i]), counts, bound))
            measured[i] = (bound, drawer, counts)
        return measured[i][0]

    best = None
    if len(thresholds):
        lo, hi = -1, len(thresholds) - 1       # the largest index within the target, if any
        if bound_at(hi) <= target:
            best = hi
        else:
            while hi - lo > 1:
                mid = (lo + hi) // 2
                if bound_at(mid) <= target:
                    lo = mid
                else:
                    hi = mid
            best = lo if lo >= 0 else None
    if best is None:
        return BrickChoice(tolerance, brick_size, len(levels), (), (), step, step / levels[0].min_spacing,
                           single.checked_rmse, reference.error, (check.width, check.height), tuple(trials),
                           time.perf_counter() - t0, single, False)
    bound, drawer, counts = measured[best]
    return BrickChoice(tolerance, brick_size, len(levels), tuple(sorted(drawer.chosen.items())), counts, step,
                       step / levels[0].min_spacing, bound, reference.error, (check.width, check.height),
                       tuple(trials), time.perf_counter() - t0, single, True, drawer)
