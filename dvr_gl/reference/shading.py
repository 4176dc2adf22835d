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


def sample_gradients(volume, values):
    """The gradient at every sample, (nz, ny, nx, 3) in x, y, z order: what the
    ``gradients="texture"`` option uploads.

    Its trilinear interpolant equals ``gradient`` everywhere, not only at samples: along
    x, f(p + sx) - f(p - sx) interpolates the differences v[i+1] - v[i-1] and v[i+2] - v[i]
    of the two samples around p with the same weights as f itself, and at the edges the
    clamped points read the edge sample, as ``v[-1] -> v[0]`` does here."""
    g = np.empty(values.shape + (3,), np.float64)
    for axis in range(3):
        array_axis = 2 - axis                   # values are (z, y, x)
        n = values.shape[array_axis]
        ahead = np.take(values, np.minimum(np.arange(n) + 1, n - 1), axis=array_axis)
        behind = np.take(values, np.maximum(np.arange(n) - 1, 0), axis=array_axis)
        g[..., axis] = (ahead - behind) / (2 * volume.spacing[axis])
    return g


def phong_terms(grad, ray_dir, phong, epsilon):
    """The headlight's diffuse factor and specular term (two-sided, L = V = H = -ray_dir);
    (1, 0) where |g| <= epsilon, which leaves a sample's colour as it is."""
    ka, kd, ks, shininess = phong
    length = np.linalg.norm(grad, axis=-1)
    lit = length > epsilon
    ndotl = np.abs(np.sum(grad * np.asarray(ray_dir), axis=-1)) / np.where(lit, length, 1.0)
    diffuse = np.where(lit, ka + kd * ndotl, 1.0)
    specular = np.where(lit, ks * ndotl ** shininess, 0.0)
    return diffuse, specular


def shade_blinn_phong(color, grad, ray_dir, phong, epsilon):
    """A straight colour lit. color, grad, ray_dir: (..., 3)."""
    diffuse, specular = phong_terms(grad, ray_dir, phong, epsilon)
    return color * diffuse[..., None] + specular[..., None]


def shade_segment(segment, grad, ray_dir, phong, epsilon):
    """Premultiplied segments (..., 4), (c * alpha, alpha), lit: the lit colour associated
    with alpha (GLSL ``shadeSegment``)."""
    diffuse, specular = phong_terms(grad, ray_dir, phong, epsilon)
    out = np.array(segment, np.float64, copy=True)
    out[..., :3] = segment[..., :3] * diffuse[..., None] + (specular * segment[..., 3])[..., None]
    return out


def gradient_epsilon(volume):
    """|g| at or below this is 'below a small threshold' (contract section 6):
    1e-6 * (data range) / (min spacing). A constant volume has no range; there the scale
    is the values' magnitude instead, so that the rounding of interpolating equal values
    (about 1e-16 of them) stays unlit rather than picking a random normal."""
    lo, hi = volume.data_range
    scale = hi - lo if hi > lo else max(abs(lo), abs(hi))
    return 1e-6 * scale / volume.min_spacing


def segment_light(scene, values, origins, dirs):
    """For a lit composite scene, ``light(segments, t)``: premultiplied segments of the
    rays ``origins + t * dirs`` (box-relative, one per row) lit at ray distances ``t``;
    None when the scene's samples are unlit."""
    if not (scene.shading and scene.mode == "composite"):
        return None
    volume = scene.volume
    lo, _ = volume.bounds
    epsilon = gradient_epsilon(volume)

    def light(segments, t):
        g = gradient(volume, values, origins + np.asarray(t)[:, None] * dirs + lo)
        out = shade_segment(segments, g, dirs, scene.phong, epsilon)
        return np.where(segments[:, 3:4] > 0, out, segments)
    return light
