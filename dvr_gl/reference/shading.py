"""Gradients and Blinn-Phong headlight shading in NumPy (GLSL twin: shaders/common/shading.glsl)."""

from __future__ import annotations

import numpy as np

from .common import trilinear, world_to_index


def gradient(volume, values, points):
    """Central differences of the trilinear field one spacing apart per axis, in world
    units; sample points outside the domain are clamped to it (as clamp-to-edge
    texture sampling does) and the divisor stays 2 * spacing. points: (..., 3) world."""
    idx = world_to_index(volume, points)
    g = np.empty(idx.shape, np.float64)
    for axis in range(3):
        h = np.zeros(3)
        h[axis] = 1.0
        g[..., axis] = (trilinear(values, idx + h) - trilinear(values, idx - h)) / (2 * volume.spacing[axis])
    return g


def shade_blinn_phong(color, grad, ray_dir, phong, epsilon):
    """Two-sided headlight: L = V = H = -ray_dir. Where |g| <= epsilon the colour is
    returned unshaded. color, grad, ray_dir: (..., 3)."""
    ka, kd, ks, shininess = phong
    length = np.linalg.norm(grad, axis=-1)
    safe = np.where(length > epsilon, length, 1.0)
    n = -grad / safe[..., None]
    ndotl = np.abs(np.sum(n * -np.asarray(ray_dir), axis=-1))
    shaded = color * (ka + kd * ndotl)[..., None] + (ks * ndotl ** shininess)[..., None]
    return np.where((length > epsilon)[..., None], shaded, color)


def gradient_epsilon(volume):
    """|g| at or below this is 'below a small threshold' (contract section 6)."""
    lo, hi = volume.data_range
    return 1e-6 * (hi - lo) / volume.min_spacing
