"""Gradients and Blinn-Phong headlight shading in NumPy (GLSL twin: shaders/common/shading.glsl)."""

from __future__ import annotations

import numpy as np

from ..model.field import depth_range, gradient, gradient_epsilon, gradient_max


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


class SampleTerms:
    """Everything a composite sample's position changes (GLSL ``sampleTerms`` in
    shaders/common/shading.glsl): the lights' diffuse factor and specular term (when
    lit), the illustration terms' tone (an added colour) and depth cue (a factor on the
    colour), and the opacity scale of boundary and silhouette enhancement (a factor on
    the extinction). ``at(points, dirs)`` gives (factor, offset RGB, opacity scale): the
    sample's colour becomes ``c * factor + offset``, its extinction ``tau * scale``."""

    def __init__(self, scene, values):
        self.scene, self.values = scene, values
        self.volume = scene.volume
        self.terms = scene.illustration
        self.lit = scene.shading
        self.epsilon = gradient_epsilon(scene.volume)
        self.lights = scene_lights(scene)
        first = scene.lights[0]
        self.tone_light = first.world_direction(scene.camera)
        self.needs_gradient = scene.reads_gradient
        self.g_max = gradient_max(self.volume, values) if "boundary" in self.terms else 1.0
        self.depths = depth_range(scene) if "depth_cue" in self.terms else None
        # a lower bound of the extinction scale: the constant terms (at most 1 each)
        self.scale_floor = float(np.prod([min(self.terms[name][0], 1.0) for name in ("boundary", "silhouette")
                                          if name in self.terms]))

    def at(self, points, dirs, grad=None, depth_cue=True):
        """(factor, offset, scale) at ``points`` seen along ``dirs``; ``grad`` gives the
        gradients instead of reading them (a mesh's cells); ``depth_cue=False`` leaves the
        depth cue out (projected tetrahedra integrate it along the segment)."""
        points = np.asarray(points, np.float64)
        if grad is not None:
            g = np.broadcast_to(grad, points.shape)
        else:
            g = gradient(self.volume, self.values, points) if self.needs_gradient else None
        return self._terms(points, np.broadcast_to(dirs, points.shape), g, depth_cue)

    def cue(self, points):
        """The depth cue's colour factor at world ``points`` (GLSL ``depthCue``)."""
        near, far = self.depths
        cam = self.scene.camera
        u = np.clip(((np.asarray(points, np.float64) - cam.eye) @ cam.forward - near) / (far - near), 0, 1)
        return 1 - self.terms["depth_cue"][0] * u

    def classify(self, points, dirs, s):
        """A scene with a 2D transfer function: (rgba, transparency) of the values ``s`` at
        ``points`` from the table at their gradient magnitude (GLSL ``lookupTF2D``), and
        (factor, offset, scale) there, the gradient read once."""
        points = np.asarray(points, np.float64)
        g = gradient(self.volume, self.values, points)
        rgba, transparency = self.scene.tf_2d.lookup(s, np.linalg.norm(g, axis=-1))
        return (rgba, transparency) + self._terms(points, np.broadcast_to(dirs, points.shape), g)

    def _terms(self, points, dirs, g, depth_cue=True):
        shape = points.shape[:-1]
        factor = np.ones(shape)
        offset = np.zeros(shape + (3,))
        scale = np.ones(shape)
        if g is not None:
            length = np.linalg.norm(g, axis=-1)
            ok = length > self.epsilon
            n = g / np.where(ok, length, 1.0)[..., None]
        if self.lit:
            diffuse, specular = phong_terms(g, dirs, self.scene.phong, self.epsilon, self.lights)
            factor = diffuse
            offset = np.repeat(specular[..., None], 3, axis=-1)
        if "tone" in self.terms:
            warm, cool = (np.asarray(c) for c in self.terms["tone"])
            light = -dirs if self.tone_light is None else np.broadcast_to(self.tone_light, points.shape)
            t = np.abs(np.sum(n * light, axis=-1))
            offset = offset + np.where(ok[..., None], t[..., None] * warm + (1 - t[..., None]) * cool, 0.0)
        if "boundary" in self.terms:
            kc, ks, ke = self.terms["boundary"]
            scale = scale * (kc + ks * (length / self.g_max if self.g_max > 0 else 0 * length) ** ke)
        if "silhouette" in self.terms:
            kc, ks, ke = self.terms["silhouette"]
            facing = np.abs(np.sum(n * dirs, axis=-1))
            scale = scale * np.where(ok, kc + ks * np.maximum(1 - facing, 0) ** ke, 1.0)
        if self.depths is not None and depth_cue:
            cue = self.cue(points)
            factor = factor * cue
            offset = offset * cue[..., None]
        return factor, offset, scale


def sample_terms(scene, values):
    """The scene's ``SampleTerms``, or None when its composite samples are plain (lit by
    nothing, no illustration term, a 1D transfer function)."""
    if scene.mode != "composite" or not (scene.shading or scene.illustration or scene.tf_2d is not None):
        return None
    return SampleTerms(scene, values)


class RayLighting:
    """A scene's ``SampleTerms`` along some rays ``origins + t * dirs`` (box-relative, one
    per row): ``samples(s, rgba, transparency, t)`` for classified samples at ray distances ``t``
    (GLSL ``sampleTerms``), ``segments(seg, t)`` for premultiplied (pre-integrated)
    segments there (GLSL ``litSegment``)."""

    def __init__(self, terms, origins, dirs):
        self.terms, self.origins, self.dirs = terms, origins, dirs
        self.lo, _ = terms.volume.bounds

    def at(self, t):
        return self.terms.at(self.origins + np.asarray(t)[:, None] * self.dirs + self.lo, self.dirs)

    def samples(self, s, rgba, transparency, t):
        """Samples of values ``s`` at ``t`` classified as ``rgba`` (straight colour, and
        ``transparency``) by the 1D TF: (their rgba with the terms applied, their
        transparency, their extinction scale). With a 2D TF, ``rgba`` only gates (it is the
        envelope): the table at the sample's gradient magnitude classifies where it is
        non-zero (GLSL ``sampleSegmentOf``)."""
        if self.terms.scene.tf_2d is not None:
            p = self.origins + np.asarray(t)[:, None] * self.dirs + self.lo
            rgba2, transparency2, factor, offset, scale = self.terms.classify(p, self.dirs, s)
            visible = rgba[..., 3] > 0
            rgba = np.where(visible[:, None], rgba2, 0.0)
            transparency = np.where(visible, transparency2, 1.0)
        else:
            factor, offset, scale = self.at(t)
            rgba = np.array(rgba, np.float64, copy=True)
        rgba[:, :3] = rgba[:, :3] * factor[:, None] + offset
        return rgba, transparency, scale

    def segments(self, seg, t):
        factor, offset, _ = self.at(t)
        out = np.array(seg, np.float64, copy=True)
        out[:, :3] = seg[:, :3] * factor[:, None] + offset * seg[:, 3:4]
        return np.where(seg[:, 3:4] > 0, out, seg)


def ray_lighting(scene, values, origins, dirs):
    """A ``RayLighting`` for a scene with sample terms, None when its samples are plain."""
    terms = sample_terms(scene, values)
    return None if terms is None else RayLighting(terms, origins, dirs)
