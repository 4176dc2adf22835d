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
whose predicted error is ``SAFETY * E``, between ``MIN_STEP`` and ``MAX_STEP`` voxels; the
pilot is then rendered at that step, its error measured and added to the model, and the
step chosen again (``verified``), since the error between the pilot's octaves is not
smooth in the step.
Unless the caller says ``preintegrate=`` or ``refine=``, further pilots measure
pre-integrated segments and, where the TF has detail within reach of the data, refined
pre-integrated segments (``refine=REFINE_PARTS``): a narrow TF feature needs very short
plain steps but not pre-integrated ones, and refined ones spend their samples only where
it is crossed. Each way's choice is then rendered at up to ``TIMING_SIDE`` pixels a side
(median of ``TIMING_REPEATS``) and the fastest is taken, if it beats the one the step
estimate (``PREINTEGRATION_COST``) favours by ``TIMING_MARGIN``: what a refined segment
costs depends on how many the TF's detail touches, so it is measured rather than
assumed, and a close call stays with the estimate, since small frames time noisily.
``SAFETY`` (0.7) covers what a pilot's pixels do not see of the full image. What was chosen
and predicted is on ``Renderer.last_choice``; the error model is kept per scene, view and
options, so another tolerance or a repeated frame costs no pilot.
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
    frame_seconds: float = None    # the frame time it was picked on, at TIMING_SIDE (None: not timed)

    @property
    def sampling(self):
        """The ray caster's options for this way of sampling."""
        return {"preintegrate": self.preintegrate, "refine": self.refine}


PLAIN = {"preintegrate": False, "refine": 1}


def samplings(scene):
    """The ways of sampling a tolerance request weighs for ``scene``: plain midpoint
    samples; pre-integrated segments where they apply; and refined ones where the TF has
    detail that the data's values can reach."""
    from ..techniques.common import preintegration_applies
    from ..techniques.raycast import detail_knots
    ways = [dict(PLAIN)]
    if preintegration_applies(scene):
        ways.append({"preintegrate": True, "refine": 1})
        lo, hi = scene.volume.data_range
        knots = detail_knots(scene.tf)
        if np.any((knots > lo - (hi - lo)) & (knots < hi + (hi - lo))):
            ways.append({"preintegrate": True, "refine": REFINE_PARTS})
    return ways


def timing_scene(scene):
    """The view timed to compare the ways of sampling: at most TIMING_SIDE pixels a side."""
    return scaled_scene(scene, TIMING_SIDE)


def scaled_scene(scene, side):
    """The same view at no more than ``side`` pixels on its longer side (8 at least)."""
    scale = min(1.0, side / max(scene.width, scene.height))
    return scene.replace(width=max(8, round(scene.width * scale)), height=max(8, round(scene.height * scale)))


def median_seconds(frame):
    """The median time of TIMING_REPEATS calls of ``frame`` after one untimed call (which
    builds tables and compiles the shader); ``frame`` returns the image, read back."""
    frame()
    times = []
    for _ in range(TIMING_REPEATS):
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
    choices: dict = field(default_factory=dict)   # (tolerance, preintegrate) -> the verified Choice

    def with_point(self, step, error, seconds=0.0):
        """The model with one more measured (step, error)."""
        points = sorted(zip(self.steps + (step,), self.errors + (error,)), reverse=True)
        return ErrorModel(order=self.order, steps=tuple(p[0] for p in points), errors=tuple(p[1] for p in points),
                          pilot_size=self.pilot_size, pilot_seconds=self.pilot_seconds + seconds,
                          reference=self.reference, choices=dict(self.choices))

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
    p, _ = error_model(rmse(images[-3], images[-2]), rmse(images[-2], images[-1]))
    reference = richardson(images, p)
    return ErrorModel(order=p, steps=PILOT_STEPS, errors=tuple(rmse(im, reference) for im in images),
                      pilot_size=(pilot.width, pilot.height), pilot_seconds=time.perf_counter() - t0,
                      reference=reference)


def verified(model, render, scene, tolerance, sampling=PLAIN):
    """(model, Choice): the step for ``tolerance``, checked on the pilot. The error is not
    a smooth function of the step between the pilot's octaves (samples fall elsewhere on
    the features), so an interpolated step is rendered on the pilot, its error measured
    against the Richardson image and added to the model; a step over ``SAFETY * E`` is
    chosen again from the model so corrected (at most VERIFY_ROUNDS pilot frames). The
    step returned is one whose pilot error was measured within ``SAFETY * E`` where any
    was; the answer is kept, so asking again costs nothing and gives the same step."""
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
            error = rmse(render(pilot_scene(scene), choice.step), model.reference)
            model = model.with_point(choice.step_voxels, error, time.perf_counter() - t0)
            if error <= target:
                break
            choice = choose_step(model, scene, tolerance, sampling)
            if choice.step_voxels < min(PILOT_STEPS):
                break
        error = measured(choice.step_voxels)
        within = [s for s, e in zip(model.steps, model.errors) if e <= target and MIN_STEP <= s <= MAX_STEP]
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
    if max(model.errors) == 0.0:
        steps = MAX_STEP
    else:
        steps = model.largest_step(SAFETY * tolerance)
    steps = min(max(steps, MIN_STEP), MAX_STEP)
    return Choice(tolerance=tolerance, step=steps * scene.volume.min_spacing, step_voxels=steps,
                  predicted_rmse=model.predict(steps), order=model.order, pilot_size=model.pilot_size,
                  pilot_seconds=model.pilot_seconds, **dict(PLAIN, **sampling))
