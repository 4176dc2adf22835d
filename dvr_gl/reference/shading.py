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


def scene_lights(scene):
    """The scene's lights as (unit world direction towards the light, or None for the
    headlight; intensity) pairs, or None for the contract's default headlight (whose
    simpler formula both twins keep)."""
    if scene.headlight_only:
        return None
    return [(light.world_direction(scene.camera), light.intensity) for light in scene.lights]


def phong_terms(grad, ray_dir, phong, epsilon, lights=None):
    """The lights' diffuse factor and specular term at samples with gradients ``grad``
    seen along ``ray_dir``; (1, 0) where |g| <= epsilon, which leaves a sample's colour
    as it is (GLSL ``phongTerms``).

    Default (``lights`` None): the headlight, two-sided, L = V = H = -ray_dir:
    ``ka + kd |N.L|`` and ``ks |N.L|^n``. With ``lights`` (see ``scene_lights``): the
    contract's two-sided formula for each light, ``kd I |N.L|`` and ``ks I |N.H|^n`` with H
    the unit half vector of L and V (none where L = -V); a headlight has L = V, which is
    the default's formula. Being symmetric in N, it is continuous in the gradient."""
    ka, kd, ks, shininess = phong
    grad = np.asarray(grad, np.float64)
    ray_dir = np.asarray(ray_dir, np.float64)
    length = np.linalg.norm(grad, axis=-1)
    lit = length > epsilon
    safe = np.where(lit, length, 1.0)
    if lights is None:
        ndotl = np.abs(np.sum(grad * ray_dir, axis=-1)) / safe
        diffuse = ka + kd * ndotl
        specular = ks * ndotl ** shininess
    else:
        v = -np.broadcast_to(ray_dir, grad.shape)
        n = grad / safe[..., None]          # the sign of N does not matter under |.|
        diffuse = np.full(length.shape, float(ka))
        specular = np.zeros(length.shape)
        for direction, intensity in lights:
            l = v if direction is None else np.broadcast_to(direction, grad.shape)
            h = l + v
            hl = np.linalg.norm(h, axis=-1)
            ndh = np.abs(np.sum(n * h, axis=-1)) / np.where(hl > 0, hl, 1.0)
            diffuse = diffuse + kd * intensity * np.abs(np.sum(n * l, axis=-1))
            specular = specular + np.where(hl > 0, ks * intensity * ndh ** shininess, 0.0)
    return np.where(lit, diffuse, 1.0), np.where(lit, specular, 0.0)


def shade_blinn_phong(color, grad, ray_dir, phong, epsilon, lights=None):
    """A straight colour lit. color, grad, ray_dir: (..., 3)."""
    diffuse, specular = phong_terms(grad, ray_dir, phong, epsilon, lights)
    return color * diffuse[..., None] + specular[..., None]


def shade_segment(segment, grad, ray_dir, phong, epsilon, lights=None):
    """Premultiplied segments (..., 4), (c * alpha, alpha), lit: the lit colour associated
    with alpha (GLSL ``shadeSegment``)."""
    diffuse, specular = phong_terms(grad, ray_dir, phong, epsilon, lights)
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


class RayLighting:
    """The lighting of a lit composite scene along some rays ``origins + t * dirs``
    (box-relative, one per row): ``colors(rgb, t)`` lights straight colours of samples at
    ray distances ``t`` (GLSL ``litColor``), ``segments(seg, t)`` lights premultiplied
    (pre-integrated) segments there (GLSL ``shadeSegment``)."""

    def __init__(self, scene, values, origins, dirs):
        self.scene, self.values, self.origins, self.dirs = scene, values, origins, dirs
        self.lo, _ = scene.volume.bounds
        self.epsilon = gradient_epsilon(scene.volume)
        self.lights = scene_lights(scene)

    def terms(self, t):
        g = gradient(self.scene.volume, self.values, self.origins + np.asarray(t)[:, None] * self.dirs + self.lo)
        return phong_terms(g, self.dirs, self.scene.phong, self.epsilon, self.lights)

    def colors(self, rgb, t):
        diffuse, specular = self.terms(t)
        return rgb * diffuse[:, None] + specular[:, None]

    def segments(self, seg, t):
        diffuse, specular = self.terms(t)
        out = np.array(seg, np.float64, copy=True)
        out[:, :3] = seg[:, :3] * diffuse[:, None] + (specular * seg[:, 3])[:, None]
        return np.where(seg[:, 3:4] > 0, out, seg)


def ray_lighting(scene, values, origins, dirs):
    """A ``RayLighting`` for a lit composite scene, None when its samples are unlit."""
    if not (scene.shading and scene.mode == "composite"):
        return None
    return RayLighting(scene, values, origins, dirs)
