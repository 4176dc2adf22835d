"""Error targets: the ray caster's step chosen for a requested RMSE.

``Renderer.render(scene, "raycast", tolerance=E)`` renders with the largest step whose
image is expected to be within RMSE ``E`` of the exact image. The expectation comes from
the scene itself, measured, not assumed: a pilot of the same view at no more than
``PILOT_SIDE`` pixels is rendered at steps of 1, 1/2, 1/4 and 1/8 voxel, and
Richardson's argument turns the two finest differences into an error model
``e(step) = K step^p``:

- the observed order ``p = log2(|I(h) - I(h/2)| / |I(h/2) - I(h/4)|)`` (RMSE norms, ``h``
  1/2 voxel), kept in [1, 3] (the midpoint rule is second order where the integrand is
  smooth, first where the transfer function or the field has kinks the samples straddle);
- the error of ``I(h/4)`` is ``|I(h/2) - I(h/4)| / (2^p - 1)``, which fixes ``K``.

The step is then ``(SAFETY * E / K)^(1/p)``, between ``MIN_STEP`` and ``MAX_STEP`` voxels.
Unless the caller says ``preintegrate=``, a second pilot measures pre-integrated segments,
and the cheaper of the two choices is taken (``PREINTEGRATION_COST``): a narrow TF
feature needs very short plain steps but not pre-integrated ones.
``SAFETY`` (0.7) covers what a pilot's pixels do not see of the full image. What was chosen
and predicted is on ``Renderer.last_choice``; the error model is kept per scene, view and
options, so another tolerance or a repeated frame costs no pilot.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

PILOT_SIDE = 64
SAFETY = 0.7
MIN_STEP, MAX_STEP = 1.0 / 64.0, 2.0     # in voxels (the smallest spacing)
PILOT_STEPS = (1.0, 0.5, 0.25, 0.125)    # voxels
# a pre-integrated step's cost over a plain one's (measured 2.05x to 2.7x at 512x512 on the
# CT head and chest CT, skipping off for it): pre-integration is chosen where its step is
# longer than that many plain steps (narrow TF features)
PREINTEGRATION_COST = 2.5


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


def check_tolerance(tolerance):
    if isinstance(tolerance, bool) or not isinstance(tolerance, (int, float, np.floating)):
        raise TypeError(f"tolerance must be a number (an RMSE), got {tolerance!r}")
    if not (math.isfinite(tolerance) and tolerance > 0):
        raise ValueError(f"tolerance must be a positive RMSE, got {tolerance!r}")
    return float(tolerance)


def pilot_scene(scene):
    """The same view at no more than PILOT_SIDE pixels on its longer side."""
    scale = min(1.0, PILOT_SIDE / max(scene.width, scene.height))
    return scene.replace(width=max(8, round(scene.width * scale)), height=max(8, round(scene.height * scale)))


def rmse(a, b):
    return float(np.sqrt(np.mean((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2)))


def error_model(d_coarse, d_fine):
    """(order p, error of the finest pilot image) from the RMSE differences of the pilot
    images at h, h/2 (``d_coarse``) and h/2, h/4 (``d_fine``)."""
    if d_fine <= 0.0:
        return 2.0, 0.0
    p = 1.0 if d_coarse <= d_fine else min(max(math.log2(d_coarse / d_fine), 1.0), 3.0)
    return p, d_fine / (2.0 ** p - 1.0)


@dataclass(frozen=True)
class ErrorModel:
    """``e(step) = finest_error * (step / finest)^order`` (steps in voxels), measured once
    per scene, view and options by ``measure``."""
    order: float
    finest_error: float
    finest: float
    pilot_size: tuple
    pilot_seconds: float


def measure(render, scene):
    """The error model of ``scene`` from its pilot: ``render(scene, step)`` renders an
    image with the caller's options."""
    t0 = time.perf_counter()
    pilot = pilot_scene(scene)
    voxel = scene.volume.min_spacing
    images = [render(pilot, k * voxel) for k in PILOT_STEPS]
    # the order from the two finest differences: the closest to the asymptotic regime
    p, finest_error = error_model(rmse(images[-3], images[-2]), rmse(images[-2], images[-1]))
    return ErrorModel(order=p, finest_error=finest_error, finest=PILOT_STEPS[-1],
                      pilot_size=(pilot.width, pilot.height), pilot_seconds=time.perf_counter() - t0)


def cheaper(plain, preintegrated):
    """The Choice whose frame costs less: plain steps against pre-integrated ones at
    PREINTEGRATION_COST each (``preintegrated`` None: not possible)."""
    if preintegrated is None or plain.step_voxels * PREINTEGRATION_COST >= preintegrated.step_voxels:
        return plain
    return preintegrated


def choose_step(model, scene, tolerance, preintegrate=False):
    """The Choice for RMSE ``tolerance`` under ``model`` (an ErrorModel of ``scene``,
    measured with or without pre-integration as ``preintegrate`` says)."""
    tolerance = check_tolerance(tolerance)
    p = model.order
    if model.finest_error == 0.0:
        steps = MAX_STEP
    else:
        steps = model.finest * (SAFETY * tolerance / model.finest_error) ** (1.0 / p)
    steps = min(max(steps, MIN_STEP), MAX_STEP)
    predicted = model.finest_error * (steps / model.finest) ** p
    return Choice(tolerance=tolerance, step=steps * scene.volume.min_spacing, step_voxels=steps,
                  predicted_rmse=predicted, order=p, pilot_size=model.pilot_size,
                  pilot_seconds=model.pilot_seconds, preintegrate=preintegrate)
