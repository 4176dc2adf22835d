"""Error targets: the ray caster's step chosen for a requested RMSE.

``Renderer.render(scene, "raycast", tolerance=E)`` renders with the largest step whose
image is expected to be within RMSE ``E`` of the exact image. The expectation comes from
the scene itself, measured, not assumed: a pilot of the same view at no more than
``PILOT_SIDE`` pixels is rendered at steps of 1, 1/2, 1/4 and 1/8 voxel, and Richardson's
argument turns the two finest into a reference image and an order:

- the observed order ``p = log2(|I(h) - I(h/2)| / |I(h/2) - I(h/4)|)`` (RMSE norms, ``h``
  1/2 voxel), kept in [1, 3] (the midpoint rule is second order where the integrand is
  smooth, first where the transfer function or the field has kinks the samples straddle);
- the extrapolated image ``R = I(h/4) + (I(h/4) - I(h/2)) / (2^p - 1)``, closer to the
  exact image than any pilot.

The error of each pilot step is then measured against ``R`` (not extrapolated from the
finest pair: the order seen between fine steps understates how fast coarse steps lose
accuracy, which made the first model over-predict coarse errors 1.1x to 3.2x, see
docs/guide/tolerance.md); between the pilot steps the error is interpolated on a log-log scale, beyond
them extended with the order of the nearest pair (at least 1). The step is the largest
whose predicted error is ``SAFETY * E``, between ``MIN_STEP`` and ``MAX_STEP`` voxels
(``CROSSING_MAX_STEP`` for the walk by crossings); the
pilot is then rendered at that step, its error measured and added to the model, and the
step chosen again (``verified``), since the error between the pilot's octaves is not
smooth in the step.
Unless the caller says ``preintegrate=``, ``refine=`` or ``refine_walk=``, further pilots measure
pre-integrated segments and, where the TF has detail within reach of the data, refined
pre-integrated segments (``refine=REFINE_PARTS``; and walked by crossings,
``techniques.crossing_walk``, where the values with opacity are a narrow share of the
data's): a narrow TF feature needs very short
plain steps but not pre-integrated ones, and refined ones spend their samples only where
it is crossed. Each way's choice is then rendered at up to ``TIMING_SIDE`` pixels a side
(median of ``TIMING_REPEATS``) and the fastest is taken, if it beats the one the step
estimate (``PREINTEGRATION_COST``) favours by ``TIMING_MARGIN``: what a refined segment
costs depends on how many the TF's detail touches, so it is measured rather than
assumed, and a close call stays with the estimate, since small frames time noisily.
``SAFETY`` (0.7) aims the pilot's choice below ``E``; what the pilot's pixels do not see
is then checked, not assumed (``checked``): the chosen step is rendered at the request's
own size up to ``CHECK_SIDE`` pixels a side, with the caller's options, beside a
Richardson image of that size from 1/4 and 1/8 voxel (and finer, down to
``FINEST_REFERENCE``, while its estimated error is over ``REFERENCE_SHARE`` of the
target), and its error bound must be within ``CHECK_TARGET * E``. The bound is the
measured RMSE plus the Richardson image's own estimated error and, where the check is smaller than the request, a sampling margin: the
mean of per-tile squared errors plus ``CHECK_Z`` standard errors of that mean, so that an
error held in a few tiles earns a wider margin. A step that fails is shortened by the
observed order (``CHECK_ROUNDS`` at most). Requests up to ``CHECK_SIDE`` are so checked
on the very pixels they return.

The error model, the way of sampling and its timing carry over views and sizes: they are
kept per volume, TF and options (``family_key``), so a new view or size costs only its
check (three frames at ``CHECK_SIDE``), not a pilot. Ways other than plain samples are
weighed only where plain samples would need steps under ``OTHER_WAYS_BELOW`` voxel (a
frame four times as dear as a plain one at the default half voxel): their tables (0.3 to 0.8 s
each, one per step) cost most of a first answer. What was chosen and predicted is on ``Renderer.last_choice``.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field

import numpy as np

PILOT_SIDE = 64
SAFETY = 0.7
MIN_STEP, MAX_STEP = 1.0 / 64.0, 2.0     # in voxels (the smallest spacing)
PILOT_STEPS = (1.0, 0.5, 0.25, 0.125)    # voxels
VERIFY_ROUNDS = 3                        # pilot frames at chosen steps, at most
# a pre-integrated step's cost over a plain one's (measured 1.71x to 1.87x at 512x512 on
# the CT head, chest CT, narrow spike and Marschner-Lobb at one voxel, skipping off for
# it, since plain steps go four to a loop iteration), and a refined one's at least: a way
# whose step is dearer by this estimate than 4x the cheapest is not timed
PREINTEGRATION_COST = 1.8
REFINE_PARTS = 4                         # parts of a refined pre-integrated segment
TIMING_SIDE = 256
TIMING_REPEATS = 5
TIMING_MARGIN = 0.15
CHECK_SIDE = 128                         # the check of a choice: the request's view at up to this size
CHECK_TARGET = 0.95                      # the check's error bound must be within this fraction of E
CHECK_Z = 2.0                            # standard errors of the per-tile mean in the sampling margin
CHECK_TILE = 8                           # pixels a side of a tile of the check image
CHECK_ROUNDS = 3                         # check frames at shorter steps, at most
REFERENCE_SHARE = 0.25                   # a check's reference is refined until its error is within this share
FINEST_REFERENCE = 1.0 / 32.0            # of the check's target, down to this step (voxels)
OTHER_WAYS_BELOW = 0.125                 # voxels: weigh pre-integrated ways only under this plain step
# the walk by crossings jumps empty cells whatever the step, and its error follows its
# longest piece (step / refine): its step may reach further, still measured on the pilot
CROSSING_MAX_STEP = 4.0
GROW_ROUNDS = 2                          # pilot frames at longer steps for the walk by crossings, at most


def max_step(sampling):
    """The longest step (voxels) a tolerance request may take with ``sampling``."""
    return CROSSING_MAX_STEP if sampling.get("refine_walk") == "crossings" else MAX_STEP


@dataclass(frozen=True)
class Choice:
    """What ``tolerance=`` picked: the step (world units and voxels), whether segments
    are pre-integrated, the error the model predicts, the observed order, and what the
    pilot cost."""
    tolerance: float
    step: float
    step_voxels: float
    predicted_rmse: float
    order: float
    pilot_size: tuple
    pilot_seconds: float
    preintegrate: bool = False
    refine: int = 1
    refine_walk: str = "even"      # how refined segments are cut (the ray caster's refine_walk)
    frame_seconds: float = None    # the frame time it was picked on, at TIMING_SIDE (None: not timed)
    checked_rmse: float = None     # the check's error bound at this view and step (None: not checked)
    check_size: tuple = None       # the check image's (width, height)
    reused_model: bool = False     # the error model and way came from another view or size
    interpolation: str = "exact"   # "texture_unit": its quantised weights measured within E (filtering.py)

    @property
    def sampling(self):
        """The ray caster's options for this way of sampling."""
        walk = {} if self.refine_walk == "even" else {"refine_walk": self.refine_walk}
        unit = {} if self.interpolation == "exact" else {"interpolation": self.interpolation}
        return {"preintegrate": self.preintegrate, "refine": self.refine, **walk, **unit}


PLAIN = {"preintegrate": False, "refine": 1}


def samplings(scene):
    """The ways of sampling a tolerance request weighs for ``scene``: plain midpoint
    samples; pre-integrated segments where they apply; refined ones where the TF has
    detail that the data's values can reach; and, where besides the values with opacity
    are a narrow share of the data's (``crossing_walk.narrow_opacity``), refined ones
    walked by crossings."""
    from ..techniques.common import preintegration_applies
    from ..techniques.crossing_walk import narrow_opacity
    from ..techniques.raycast import detail_knots
    ways = [dict(PLAIN)]
    if preintegration_applies(scene):
        ways.append({"preintegrate": True, "refine": 1})
        lo, hi = scene.volume.data_range
        knots = detail_knots(scene.tf)
        if np.any((knots > lo - (hi - lo)) & (knots < hi + (hi - lo))):
            ways.append({"preintegrate": True, "refine": REFINE_PARTS})
            if narrow_opacity(scene):   # the walk by crossings, measured like the others
                ways.append({"preintegrate": True, "refine": REFINE_PARTS, "refine_walk": "crossings"})
    return ways


def timing_scene(scene):
    """The view timed to compare the ways of sampling: at most TIMING_SIDE pixels a side."""
    return scaled_scene(scene, TIMING_SIDE)


def scaled_scene(scene, side):
    """The same view at no more than ``side`` pixels on its longer side (8 at least)."""
    scale = min(1.0, side / max(scene.width, scene.height))
    return scene.replace(width=max(8, round(scene.width * scale)), height=max(8, round(scene.height * scale)))


def median_seconds(frame, repeats=TIMING_REPEATS):
    """The median time of ``repeats`` calls of ``frame`` after one untimed call (which
    builds tables and compiles the shader); ``frame`` returns the image, read back."""
    frame()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        frame()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def estimated_cost(choice):
    """Frame cost in plain steps per voxel: a lower bound for refined segments."""
    return (PREINTEGRATION_COST if choice.preintegrate else 1.0) / choice.step_voxels


def fastest(choices, frame_seconds):
    """The Choice whose frame is fastest by ``frame_seconds(choice)``; those whose
    estimated cost is over 4x the lowest estimate of an unrefined way are not timed (a
    refined way's estimate is only a lower bound: it must not rule the others out), and
    another than the estimate's cheapest is taken only when it is at least TIMING_MARGIN
    faster (timings of small frames are noisy: the estimate decides close calls)."""
    unrefined = [estimated_cost(c) for c in choices if c.refine == 1]
    cheapest = min(unrefined or [estimated_cost(c) for c in choices])
    timed = [dataclasses.replace(c, frame_seconds=frame_seconds(c)) for c in choices
             if estimated_cost(c) <= 4 * cheapest]
    expected = min(timed, key=estimated_cost)
    best = min(timed, key=lambda c: c.frame_seconds)
    return best if best.frame_seconds < (1 - TIMING_MARGIN) * expected.frame_seconds else expected


def check_tolerance(tolerance):
    if isinstance(tolerance, bool) or not isinstance(tolerance, (int, float, np.floating)):
        raise TypeError(f"tolerance must be a number (an RMSE), got {tolerance!r}")
    if not (math.isfinite(tolerance) and tolerance > 0):
        raise ValueError(f"tolerance must be a positive RMSE, got {tolerance!r}")
    return float(tolerance)


def pilot_scene(scene):
    """The same view at no more than PILOT_SIDE pixels on its longer side."""
    return scaled_scene(scene, PILOT_SIDE)


def rmse(a, b):
    return float(np.sqrt(np.mean((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2)))


def error_model(d_coarse, d_fine):
    """(order p, error of the finest pilot image) from the RMSE differences of the pilot
    images at h, h/2 (``d_coarse``) and h/2, h/4 (``d_fine``)."""
    if d_fine <= 0.0:
        return 2.0, 0.0
    p = 1.0 if d_coarse <= d_fine else min(max(math.log2(d_coarse / d_fine), 1.0), 3.0)
    return p, d_fine / (2.0 ** p - 1.0)


@dataclass(frozen=True, eq=False)
class ErrorModel:
    """The measured error of each pilot step (``steps`` in voxels, coarsest first) against
    the Richardson image ``reference``, and the order of the finest pair; measured once
    per scene, view and options by ``measure`` (and at each step chosen, by ``verified``).
    ``predict(step)`` interpolates it."""
    order: float
    steps: tuple
    errors: tuple
    pilot_size: tuple
    pilot_seconds: float
    reference: object = None       # the Richardson image of the pilot, float64
    pilot: object = None           # the pilot Scene the model was measured on
    reference_error: float = 0.0   # the estimated RMSE of the finest pilot image (bounds the reference's)
    choices: dict = field(default_factory=dict)   # (tolerance, preintegrate) -> the verified Choice

    def with_point(self, step, error, seconds=0.0):
        """The model with one more measured (step, error)."""
        points = sorted(zip(self.steps + (step,), self.errors + (error,)), reverse=True)
        return ErrorModel(order=self.order, steps=tuple(p[0] for p in points), errors=tuple(p[1] for p in points),
                          pilot_size=self.pilot_size, pilot_seconds=self.pilot_seconds + seconds,
                          reference=self.reference, pilot=self.pilot, reference_error=self.reference_error,
                          choices=dict(self.choices))

    def _curve(self):
        """(log steps, log errors) ascending in step, errors made non-decreasing with the
        step (a coarser step is never predicted better than a finer one)."""
        steps = np.array(self.steps[::-1], np.float64)
        errors = np.maximum.accumulate(np.array(self.errors[::-1], np.float64))
        return np.log(steps), np.log(np.maximum(errors, 1e-300))

    def _slopes(self):
        x, y = self._curve()
        coarse = float(np.clip((y[-1] - y[-2]) / (x[-1] - x[-2]), 1.0, 3.0))
        return x, y, coarse

    def predict(self, step):
        """The expected RMSE at ``step`` voxels."""
        if max(self.errors) == 0.0:
            return 0.0
        x, y, coarse = self._slopes()
        t = math.log(step)
        if t <= x[0]:
            return float(math.exp(y[0] + self.order * (t - x[0])))
        if t >= x[-1]:
            return float(math.exp(y[-1] + coarse * (t - x[-1])))
        return float(math.exp(np.interp(t, x, y)))

    def largest_step(self, error):
        """The largest step (voxels, unclamped) whose predicted RMSE is ``error``."""
        x, y, coarse = self._slopes()
        g = math.log(error)
        if g >= y[-1]:
            return math.exp(x[-1] + (g - y[-1]) / coarse)
        if g <= y[0]:
            return math.exp(x[0] + (g - y[0]) / self.order)
        k = int(np.searchsorted(y, g, side="right")) - 1     # y[k] <= g < y[k + 1]
        while y[k + 1] == y[k]:
            k += 1
        return math.exp(x[k] + (g - y[k]) * (x[k + 1] - x[k]) / (y[k + 1] - y[k]))


def richardson(images, order):
    """The extrapolated image from the two finest pilot images (float64)."""
    fine, coarser = np.asarray(images[-1], np.float64), np.asarray(images[-2], np.float64)
    return fine + (fine - coarser) / (2.0 ** order - 1.0)


def measure(render, scene):
    """The error model of ``scene`` from its pilot: ``render(scene, step)`` renders an
    image with the caller's options."""
    t0 = time.perf_counter()
    pilot = pilot_scene(scene)
    voxel = scene.volume.min_spacing
    images = [render(pilot, k * voxel) for k in PILOT_STEPS]
    # the order from the two finest differences: the closest to the asymptotic regime
    p, finest = error_model(rmse(images[-3], images[-2]), rmse(images[-2], images[-1]))
    reference = richardson(images, p)
    return ErrorModel(order=p, steps=PILOT_STEPS, errors=tuple(rmse(im, reference) for im in images),
                      pilot_size=(pilot.width, pilot.height), pilot_seconds=time.perf_counter() - t0,
                      reference=reference, pilot=pilot, reference_error=finest)


def verified(model, render, scene, tolerance, sampling=PLAIN):
    """(model, Choice): the step for ``tolerance``, checked on the pilot. The error is not
    a smooth function of the step between the pilot's octaves (samples fall elsewhere on
    the features), so an interpolated step is rendered on the pilot, its error measured
    against the Richardson image and added to the model; a step over ``SAFETY * E`` is
    chosen again from the model so corrected (at most VERIFY_ROUNDS pilot frames). The
    step returned is one whose pilot error was measured within ``SAFETY * E`` where any
    was; the answer is kept, so asking again costs nothing and gives the same step. For
    the walk by crossings a step so measured is lengthened while the model, with that
    point, gives a longer one measured within too (GROW_ROUNDS pilot frames at most)."""
    tolerance = check_tolerance(tolerance)
    sampling = dict(PLAIN, **sampling)
    key = (tolerance, tuple(sorted(sampling.items())))
    if key in model.choices:
        return model, model.choices[key]
    target = SAFETY * tolerance
    choice = choose_step(model, scene, tolerance, sampling)

    def measured(k):
        return next((e for s, e in zip(model.steps, model.errors) if abs(k - s) <= 1e-9 * k), None)

    # below the finest pilot step the Richardson image is no better than the step itself:
    # there the model's extrapolation stands unchecked
    if model.reference is not None and max(model.errors) > 0.0 and choice.step_voxels >= min(PILOT_STEPS):
        for _ in range(VERIFY_ROUNDS):
            error = measured(choice.step_voxels)
            if error is not None:
                break
            t0 = time.perf_counter()
            pilot = model.pilot if model.pilot is not None else pilot_scene(scene)
            error = rmse(render(pilot, choice.step), model.reference)
            model = model.with_point(choice.step_voxels, error, time.perf_counter() - t0)
            if error <= target:
                break
            choice = choose_step(model, scene, tolerance, sampling)
            if choice.step_voxels < min(PILOT_STEPS):
                break
        error = measured(choice.step_voxels)
        if sampling.get("refine_walk") == "crossings" and error is not None and error <= target:
            # the walk's error grows slower past the pilot's steps than their order says (its
            # pieces are cut at crossings): a longer step is taken only where measured within
            for _ in range(GROW_ROUNDS):
                longer = choose_step(model, scene, tolerance, sampling)
                if longer.step_voxels <= choice.step_voxels * (1 + 1e-6):
                    break
                t0 = time.perf_counter()
                pilot = model.pilot if model.pilot is not None else pilot_scene(scene)
                grown = rmse(render(pilot, longer.step), model.reference)
                model = model.with_point(longer.step_voxels, grown, time.perf_counter() - t0)
                if grown > target:
                    break
                choice, error = longer, grown
        within = [s for s, e in zip(model.steps, model.errors) if e <= target and MIN_STEP <= s <= max_step(sampling)]
        if (error is None or error > target) and within and choice.step_voxels >= min(PILOT_STEPS):
            k = max(within)
            choice = Choice(tolerance=tolerance, step=k * scene.volume.min_spacing, step_voxels=k,
                            predicted_rmse=model.predict(k), order=model.order, pilot_size=model.pilot_size,
                            pilot_seconds=model.pilot_seconds, **sampling)
    choice = dataclasses.replace(choice, pilot_seconds=model.pilot_seconds)
    model.choices[key] = choice
    return model, choice


def choose_step(model, scene, tolerance, sampling=PLAIN):
    """The Choice for RMSE ``tolerance`` under ``model`` (an ErrorModel of ``scene``,
    measured with the ray caster's ``sampling`` options)."""
    tolerance = check_tolerance(tolerance)
    longest = max_step(sampling)
    if max(model.errors) == 0.0:
        steps = longest
    else:
        steps = model.largest_step(SAFETY * tolerance)
    steps = min(max(steps, MIN_STEP), longest)
    return Choice(tolerance=tolerance, step=steps * scene.volume.min_spacing, step_voxels=steps,
                  predicted_rmse=model.predict(steps), order=model.order, pilot_size=model.pilot_size,
                  pilot_seconds=model.pilot_seconds, **dict(PLAIN, **sampling))


def family_key(scene, options):
    """What the error model and the way of sampling are kept under: the scene with its
    camera and size left out (volume, TF, mode, lighting, clipping ...) and the caller's
    options. The step's error per voxel depends on the data and TF far more than on the
    view; each view is checked on its own (``checked``)."""
    from ..model.camera import default_camera
    neutral = scene.replace(camera=default_camera(scene.volume), width=8, height=8)
    return (neutral.digest(), repr(sorted(options.items())))


def check_scene(scene):
    """The view a choice is checked on: the request itself up to CHECK_SIDE pixels a side."""
    return scaled_scene(scene, CHECK_SIDE)


def error_bound(image, reference, reference_error=0.0, sampled=False):
    """An upper bound of the RMSE of the image this check stands for: the RMSE of
    ``image`` against ``reference`` plus the reference's own estimated error and, when
    the check image is a smaller sample of the request (``sampled``), CHECK_Z standard
    errors of the mean of its tiles' squared errors (tiles, not pixels: neighbouring
    pixels' errors go together); an error held in a few tiles widens the margin."""
    squared = np.mean((np.asarray(image, np.float64) - reference) ** 2, axis=-1)   # per pixel, channels averaged
    mse = float(squared.mean())
    if sampled:
        rows = np.array_split(squared, max(1, squared.shape[0] // CHECK_TILE), axis=0)
        tiles = np.array([t.mean() for r in rows for t in np.array_split(r, max(1, r.shape[1] // CHECK_TILE), axis=1)])
        if tiles.size > 1:
            mse += CHECK_Z * float(tiles.std(ddof=1)) / math.sqrt(tiles.size)
    return math.sqrt(mse) + reference_error


@dataclass(frozen=True, eq=False)
class ViewReference:
    """The Richardson image of one check view (``scene``) from its frames at ``steps``
    (voxels, the finest frame kept in ``finest``) and its estimated error (the finest
    frame's: the extrapolated image is better still); the error bounds measured against
    it are kept by step (voxels) and whether the check is a sample of a larger request in
    ``bounds``."""
    scene: object
    image: object
    error: float
    steps: tuple
    finest: object
    bounds: dict = field(default_factory=dict)


def view_reference(render, check, order, steps=PILOT_STEPS[-2:]):
    """The Richardson image of ``check`` from its frames at ``steps`` (voxels, the
    coarser first) with the model's ``order``."""
    voxel = check.volume.min_spacing
    images = [np.asarray(render(check, k * voxel), np.float64) for k in steps]
    return ViewReference(check, richardson(images, order), rmse(images[0], images[1]) / (2.0 ** order - 1.0),
                         tuple(steps), images[-1])


def finer_reference(reference, render, order):
    """``reference`` with one more frame at half its finest step."""
    voxel = reference.scene.volume.min_spacing
    step = reference.steps[-1] / 2
    images = [reference.finest, np.asarray(render(reference.scene, step * voxel), np.float64)]
    return ViewReference(reference.scene, richardson(images, order), rmse(*images) / (2.0 ** order - 1.0),
                         reference.steps + (step,), images[-1])


def checked(choice, reference, render, scene, tolerance, model, sampled):
    """``choice`` checked on the request's view: its step rendered by ``render`` (the
    caller's own options) at the check size, and its error bound (``error_bound``) kept
    within CHECK_TARGET * ``tolerance``; a step that fails is shortened by the model's
    order (with a tenth more) and rendered again, CHECK_ROUNDS times at most. A step
    under the reference's finest is not checked (the reference is no better than it):
    ``checked_rmse`` is None then."""
    target = CHECK_TARGET * tolerance
    voxel = scene.volume.min_spacing
    k = choice.step_voxels
    bound = None
    for _ in range(CHECK_ROUNDS + 1):
        if k < reference.steps[-1] * (1 - 1e-9):
            bound = None
            break
        bound = reference.bounds.get((k, sampled))     # a request larger than the check adds a margin
        if bound is None:
            bound = error_bound(render(reference.scene, k * voxel), reference.image, reference.error, sampled)
            reference.bounds[k, sampled] = bound
        if bound <= target:
            break
        k = max(k * 0.9 * (target / bound) ** (1.0 / model.order), MIN_STEP)
    else:
        bound = None
    return dataclasses.replace(choice, step=k * voxel, step_voxels=k, predicted_rmse=min(choice.predicted_rmse,
                               model.predict(k)), checked_rmse=bound,
                               check_size=(reference.scene.width, reference.scene.height))


def pilot_renderer(renderer, technique, options, sampling=PLAIN, **extra):
    """``render(scene, step)`` with the caller's ``options`` and ``sampling`` (and ``extra``)."""
    opts = dict(options, **sampling, **extra)
    return lambda s, h: renderer.render(s, technique, step=h, **opts)


def model_key(scene, options, sampling=PLAIN):
    """What ``settings`` keeps a way's error model under in ``renderer._error_models``."""
    return ("model",) + family_key(scene, options) + (tuple(sorted(sampling.items())),)


def reference_for(renderer, scene, tolerance, technique, options, order, sampling=PLAIN):
    """The Richardson image of ``scene``'s check view (``check_scene``) with the caller's
    ``options`` and ``sampling`` and no early termination, made finer while its estimated
    error is over REFERENCE_SHARE of the check's target for ``tolerance`` (down to
    FINEST_REFERENCE); kept in ``renderer._error_models`` per check view, volume, TF and
    options, so ``settings`` and the pyramid's level choice share it."""
    check = check_scene(scene)
    pilot = pilot_renderer(renderer, technique, options, sampling, ert_transmittance=0.0)
    view_key = ("view", check.digest()) + family_key(scene, options)[1:] + (tuple(sorted(sampling.items())),)
    models = renderer._error_models
    reference = models.get(view_key, lambda: view_reference(pilot, check, order))
    # the reference's own error counts against the request: made finer where it is a large share
    while (reference.error > REFERENCE_SHARE * CHECK_TARGET * tolerance
           and reference.steps[-1] > FINEST_REFERENCE * (1 + 1e-9)):
        reference = finer_reference(reference, pilot, order)
        models.put(view_key, reference)
    return reference


def settings(renderer, scene, tolerance, technique, options):
    """The Choice for ``renderer.render(scene, tolerance=...)``: the error model of each
    way of sampling, measured once per ``family_key`` (on the first view asked) and kept
    in ``renderer._error_models``; the way picked per family and tolerance, kept in
    ``renderer._tolerance_picks``; and each view's check (``checked``)."""
    from ..techniques import check_options
    if technique != "raycast":
        raise ValueError(f"tolerance chooses the ray caster's step; technique {technique!r} takes its "
                         f"own options (use technique='raycast')")
    check_options(technique, options)
    tolerance = check_tolerance(tolerance)
    options = dict(options)
    fixed = None
    if "preintegrate" in options or "refine" in options or "refine_walk" in options:   # the caller's say is kept
        fixed = {"preintegrate": bool(options.pop("preintegrate", False)), "refine": options.pop("refine", 1)}
        if "refine_walk" in options:
            fixed["refine_walk"] = options.pop("refine_walk")
    family = family_key(scene, options)
    check = check_scene(scene)
    sampled = (check.width, check.height) != (scene.width, scene.height)
    pilot_digest = pilot_scene(scene).digest()
    models = renderer._error_models

    def view_choice(sampling, on_view=True):
        key = model_key(scene, options, sampling)
        # the pilot and the references measure the step's error alone (no early termination)
        pilot = pilot_renderer(renderer, technique, options, sampling, ert_transmittance=0.0)
        model = models.get(key, lambda: measure(pilot, scene))
        model, chosen = verified(model, pilot, scene, tolerance, sampling)
        models.put(key, model)
        if not on_view:
            return chosen
        reference = reference_for(renderer, scene, tolerance, technique, options, model.order, sampling)
        chosen = checked(chosen, reference, pilot_renderer(renderer, technique, options, sampling), scene,
                         tolerance, model, sampled)
        return dataclasses.replace(chosen, reused_model=model.pilot is not None and model.pilot.digest() != pilot_digest)

    if fixed is not None:
        return view_choice(fixed)
    pick_key = family + (tolerance,)
    picked = renderer._tolerance_picks.items.get(pick_key)
    if picked is not None:        # the way picked on another view or size
        renderer._tolerance_picks.items.move_to_end(pick_key)
        return dataclasses.replace(view_choice(picked.sampling), frame_seconds=picked.frame_seconds)
    plain = view_choice(PLAIN)
    ways = samplings(scene)
    if len(ways) == 1 or plain.step_voxels >= OTHER_WAYS_BELOW:
        picked = plain
    else:
        timed = timing_scene(scene)

        def frame_seconds(chosen):
            return median_seconds(lambda: renderer.render(timed, technique, step=chosen.step,
                                                          **dict(options, **chosen.sampling)))
        # the other ways are timed at their pilot's step and only the one picked is checked:
        # each way's check needs tables of its own for the reference's steps
        picked = fastest([plain] + [view_choice(way, on_view=False) for way in ways[1:]], frame_seconds)
        if picked.sampling != plain.sampling:
            picked = dataclasses.replace(view_choice(picked.sampling), frame_seconds=picked.frame_seconds)
    renderer._tolerance_picks.put(pick_key, picked)
    return picked
