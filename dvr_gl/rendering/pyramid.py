"""Error targets on a pyramid: the level of a multiscale LazyVolume chosen for an RMSE.

``Renderer.render(scene, tolerance=E)`` on a scene whose volume has pyramid levels (an
OME-Zarr multiscale image, see :func:`dvr_gl.formats.stores.build_pyramid`) draws from
the coarsest level whose image stays within RMSE ``E`` of the exact image of the
full-resolution samples (level 0). The error is measured on the scene, with the grid
tolerance's machinery (``rendering.tolerance``):

1. The reference: level 0's Richardson image of the request's view at up to
   ``tolerance.CHECK_SIDE`` pixels a side (``tolerance.reference_for``: frames at 1/4
   and 1/8 of a level-0 voxel, finer while its own estimated error is over a quarter of
   the target), with the order of level 0's pilot (``tolerance.measure``, 64 pixels). It
   is what the grid tolerance checks level 0 against, and it is shared with it. Making it
   reads the level-0 bricks the check view's rays cross (the whole store, for a view of
   the whole volume) at a small image size; nothing else reads level 0.
2. Levels, coarsest first: each is rendered at the check size with the caller's options
   at steps of ``LEVEL_STEPS`` of its own voxels, and its error bound against the
   reference (``tolerance.error_bound``: the RMSE, the reference's estimated error and,
   where the check is smaller than the request, the per-tile sampling margin) must be
   within ``tolerance.CHECK_TARGET * E``. The first level and step that are within it
   are chosen. A halved step that lowers the bound by less than ``FLAT`` stops the
   level's steps: its error is the level's samples', which no step removes.
3. When no coarser level is within ``E``, level 0 is drawn with the step the grid
   tolerance chooses for ``E`` (``tolerance.settings``, checked against the same
   reference).

One level serves the whole image. What was chosen is a :class:`LevelChoice` on
``Renderer.last_choice``; the choice is kept per view, volume, TF, options and ``E`` in
the renderer's tolerance store, so asking again costs nothing.

A level per brick (``per_brick=True``; ``rendering.pyramid_bricks``): level
0's bricks are each drawn from a level of their own in one frame
(``techniques.brick_levels.BrickLevels``), the coarsest whose share of the error keeps
the image within ``E``, measured against the same reference.

While a view moves, the viewer and the notebook widget draw one coarse level
(:func:`moving_level`, from the levels' shapes alone) and refine to level 0, or to the
choice for their tolerance, once it is still.
"""

from __future__ import annotations

import time
import weakref
from dataclasses import dataclass

import numpy as np

from . import tolerance as tol

LEVEL_STEPS = (1.0, 0.5, 0.25)    # a candidate level's steps, in its own voxels
FLAT = 0.9                        # a halved step whose bound is over this fraction of the last: no finer


class PyramidError(ValueError):
    """A pyramid request that cannot be met; ``field`` names what was wrong."""

    def __init__(self, field, detail):
        self.field, self.detail = field, detail
        super().__init__(f"{field}: {detail}")


@dataclass(frozen=True)
class LevelChoice:
    """What ``tolerance=`` picked on a pyramid: the level (0 the finest) and its shape
    (nz, ny, nx), the step (world units and the level's voxels), the error bound measured
    against level 0's reference at ``check_size`` (``checked_rmse``; None where the grid
    tolerance drew level 0 below its reference's finest step), the reference's own
    estimated error, every (level, step in voxels, bound) measured, the seconds the choice
    took, and, for level 0, the grid tolerance's :class:`~dvr_gl.rendering.tolerance.Choice`."""
    tolerance: float
    level: int
    level_shape: tuple
    levels: int
    step: float
    step_voxels: float
    checked_rmse: float
    reference_error: float
    check_size: tuple
    trials: tuple
    seconds: float
    way: tuple = tuple(sorted(tol.PLAIN.items()))    # the ray caster's sampling options, as items
    grid: object = None

    @property
    def sampling(self):
        """The ray caster's options for the way of sampling (as ``tolerance.Choice.sampling``)."""
        return dict(self.way)

    @property
    def preintegrate(self):
        return bool(self.sampling.get("preintegrate", False))

    @property
    def refine(self):
        return int(self.sampling.get("refine", 1))

    def describe(self):
        """One line for people: the level, its shape, the step and the error measured."""
        nz, ny, nx = self.level_shape
        error = ("not measured" if self.checked_rmse is None else
                 f"error bound {self.checked_rmse:.3g} at {self.check_size[0]}x{self.check_size[1]}")
        return (f"level {self.level} of {self.levels} ({nx}x{ny}x{nz}), step {self.step:g} "
                f"({self.step_voxels:.3g} of its voxels) for tolerance {self.tolerance:g}: {error} "
                f"against level 0's reference, choice {self.seconds:.2f} s")


def has_pyramid(scene):
    """True for a one-volume scene whose volume has more than one level."""
    return not getattr(scene, "layers", ()) and len(getattr(scene.volume, "levels", ()) or ()) > 1


_LEVELS = weakref.WeakKeyDictionary()     # volume -> {index: its level's LazyVolume}, opened once


def level_volume(volume, index):
    """Level ``index`` of ``volume`` (a LazyVolume from :func:`dvr_gl.formats.stores.open_store`)
    as a LazyVolume, opened once per volume. Where ``volume``'s spacing or origin were
    given in place of the store's (``open_store(spacing=...)``), every level is scaled
    and moved the same way, so the levels keep lying on each other."""
    from ..formats.stores import open_level
    from ..model.lazy_volume import LazyVolume
    opened = _LEVELS.setdefault(volume, {})
    if index in opened:
        return opened[index]
    levels = volume.levels
    if not 0 <= index < len(levels):
        raise PyramidError("level", f"{index} is not a level of {volume.describe()} (it has {len(levels)})")
    key = volume.source[1] if volume.source is not None else None
    own = next((i for i, level in enumerate(levels) if level.key == key), 0)     # the level volume is
    if index == own:
        opened[index] = volume
        return volume
    level, base = open_level(volume, index), levels[own]
    ratio = np.asarray(volume.spacing, float) / np.asarray(base.spacing, float)
    origin = np.asarray(volume.origin, float) + (np.asarray(level.origin, float) - base.origin) * ratio
    if not (np.allclose(ratio, 1.0) and np.allclose(origin, level.origin)):
        moved = LazyVolume(level.array, spacing=np.asarray(level.spacing) * ratio, origin=origin, source=level.source)
        moved.levels, moved.store_format = level.levels, level.store_format
        moved._level_arrays = level._level_arrays
        level = moved
    opened[index] = level
    return level


def check_request(scene, tolerance, technique):
    """The tolerance as a float, or a named error: a scene without levels, another
    technique than the ray caster, a tolerance that is not a positive number."""
    if technique != "raycast":
        raise PyramidError("technique", f"a pyramid's level is chosen for the ray caster; got {technique!r}")
    if not has_pyramid(scene):
        what = getattr(scene.volume, "describe", lambda: type(scene.volume).__name__)()
        raise PyramidError("levels", f"{what} has one level: no pyramid to choose from; build one with "
                                     "dvr_gl.formats.stores.build_pyramid(path) (dvr-gl render --build-pyramid)")
    try:
        return tol.check_tolerance(tolerance)
    except (TypeError, ValueError) as e:
        raise PyramidError("tolerance", str(e)) from None


def settings(renderer, scene, tolerance, technique="raycast", options=None):
    """(scene of the chosen level, step, options, LevelChoice) for ``tolerance`` (see the
    module's docstring). ``options`` are the ray caster's; ``preintegrate``/``refine``
    given are kept for every level."""
    from ..techniques import check_options
    tolerance = check_request(scene, tolerance, technique)
    options = dict(options or {})
    check_options(technique, options)
    sampling = dict(tol.PLAIN)
    fixed = "preintegrate" in options or "refine" in options
    if fixed:
        sampling = {"preintegrate": bool(options.pop("preintegrate", False)), "refine": options.pop("refine", 1)}
    volume = scene.volume
    scene0 = scene.replace(volume=level_volume(volume, 0))
    key = ("pyramid", tol.check_scene(scene0).digest(), (scene.width, scene.height)) + \
        tol.family_key(scene0, options)[1:] + (tuple(sorted(sampling.items())), tolerance)
    cached = renderer._error_models.items.get(key)
    if cached is None:
        cached = _choose(renderer, scene0, tolerance, technique, options, sampling, fixed)
        renderer._error_models.put(key, cached)
    chosen = cached
    level_scene = scene.replace(volume=level_volume(volume, chosen.level))
    return level_scene, chosen.step, dict(options, **chosen.sampling), chosen


def _reference(renderer, scene0, tolerance, technique, options, sampling):
    """(level 0's reference of the check view, whether the check samples the request)."""
    pilot = tol.pilot_renderer(renderer, technique, options, sampling, ert_transmittance=0.0)
    model = renderer._error_models.get(tol.model_key(scene0, options, sampling), lambda: tol.measure(pilot, scene0))
    reference = tol.reference_for(renderer, scene0, tolerance, technique, options, model.order, sampling)
    check = reference.scene
    return reference, (check.width, check.height) != (scene0.width, scene0.height)


def _choose(renderer, scene0, tolerance, technique, options, sampling, fixed):
    t0 = time.perf_counter()
    volume = scene0.volume
    reference, sampled = _reference(renderer, scene0, tolerance, technique, options, sampling)
    check = reference.scene
    target = tol.CHECK_TARGET * tolerance
    render = tol.pilot_renderer(renderer, technique, options, sampling)
    trials = []
    levels = volume.levels
    for index in range(len(levels) - 1, 0, -1):
        level = level_volume(volume, index)
        previous = None
        for k in LEVEL_STEPS:
            image = render(check.replace(volume=level), k * level.min_spacing)
            bound = tol.error_bound(image, reference.image, reference.error, sampled)
            trials.append((index, k, bound))
            if bound <= target:
                return LevelChoice(tolerance, index, level.shape, len(levels), k * level.min_spacing, k, bound,
                                   reference.error, (check.width, check.height), tuple(trials),
                                   time.perf_counter() - t0, tuple(sorted(sampling.items())))
            if previous is not None and bound > FLAT * previous:
                break
            previous = bound
    grid_options = dict(options, **sampling) if fixed else options
    grid = tol.settings(renderer, scene0, tolerance, technique, grid_options)
    return LevelChoice(tolerance, 0, volume.shape, len(levels), grid.step, grid.step_voxels, grid.checked_rmse,
                       reference.error, (check.width, check.height), tuple(trials), time.perf_counter() - t0,
                       tuple(sorted(grid.sampling.items())), grid=grid)


def render(renderer, scene, tolerance, technique="raycast", **options):
    """The image of ``scene`` drawn from the level chosen for ``tolerance``
    (:func:`settings`); the :class:`LevelChoice` is on ``renderer.last_choice``."""
    level_scene, step, options, chosen = settings(renderer, scene, tolerance, technique, options)
    image = renderer.render(level_scene, technique, step=step, **options)
    renderer.last_choice = chosen
    return image


MOVING_SAMPLES = 2 ** 21     # samples (128^3) of the level a moving view draws from


def moving_level(volume, samples=MOVING_SAMPLES):
    """The level the viewer and the notebook widget draw while the view moves: the finest
    with at most ``samples`` samples (the coarsest where none is so small), chosen once
    from the levels' shapes alone; 0 for a volume without levels."""
    levels = getattr(volume, "levels", ()) or ()
    if len(levels) < 2:
        return 0
    small = [k for k, level in enumerate(levels) if int(np.prod(level.shape, dtype=np.int64)) <= samples]
    return small[0] if small else len(levels) - 1


def moving_volume(volume, samples=MOVING_SAMPLES):
    """``volume``'s level :func:`moving_level` as a volume (``volume`` itself without levels)."""
    index = moving_level(volume, samples)
    return volume if index == 0 else level_volume(volume, index)
