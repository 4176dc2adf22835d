"""Image error metrics over premultiplied RGBA (all pixels, all channels)."""

from __future__ import annotations

import math

import numpy as np


def _diff(image, reference):
    a = np.asarray(image, dtype=np.float64)
    b = np.asarray(reference, dtype=np.float64)
    if a.shape != b.shape:
        raise ValueError(f"image shape {a.shape} differs from reference shape {b.shape}")
    return a - b


def rmse(image, reference) -> float:
    return float(np.sqrt(np.mean(_diff(image, reference) ** 2)))


def max_abs_error(image, reference) -> float:
    return float(np.abs(_diff(image, reference)).max())


def psnr(image, reference, peak=1.0) -> float:
    """Peak signal-to-noise ratio in dB; inf for identical images."""
    e = rmse(image, reference)
    return math.inf if e == 0 else 20 * math.log10(peak / e)


def compare(image, reference) -> dict:
    """All three metrics: {'rmse', 'max_abs', 'psnr'}."""
    return {"rmse": rmse(image, reference), "max_abs": max_abs_error(image, reference),
            "psnr": psnr(image, reference)}
