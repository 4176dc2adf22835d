"""Generated test volumes with known structure, for the tests, the hard-case suite and
the bench.

``marschner_lobb`` is the signal of Marschner and Lobb (1994), the standard test of
reconstruction and sampling in volume rendering: a slow fall along z with a radial
cosine of high frequency on top, sampled near its Nyquist limit, so that every filter
and every sampling error shows.
"""

from __future__ import annotations

import numpy as np

from ..model.transfer_function import TransferFunction
from ..model.volume import Volume


def marschner_lobb(n=41, f_m=6.0, alpha=0.25):
    """The Marschner-Lobb signal on [-1, 1]^3 sampled at n^3 points (values in [0, 1])."""
    if int(n) != n or n < 2:
        raise ValueError(f"n must be an integer >= 2, got {n!r}")
    n = int(n)
    x = np.linspace(-1.0, 1.0, n)
    z, y, x = np.meshgrid(x, x, x, indexing="ij")
    radial = np.cos(2 * np.pi * f_m * np.cos(np.pi * np.hypot(x, y) / 2))
    values = (1 - np.sin(np.pi * z / 2) + alpha * (1 + radial)) / (2 * (1 + alpha))
    spacing = 2.0 / (n - 1)
    return Volume(values.astype(np.float32), spacing=(spacing,) * 3, origin=(-1.0, -1.0, -1.0))


def marschner_lobb_tf(unit_distance=0.05):
    """A transfer function that shows the signal's shells: opaque-ish around 0.5, colour
    across the range."""
    return TransferFunction(color=[(0.0, 0.1, 0.2, 0.8), (0.5, 0.9, 0.8, 0.3), (1.0, 1.0, 0.3, 0.1)],
                            opacity=[(0.0, 0.0), (0.35, 0.0), (0.5, 0.6), (0.65, 0.0), (1.0, 0.0)],
                            unit_distance=unit_distance)
