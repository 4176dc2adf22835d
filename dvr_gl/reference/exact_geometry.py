"""Opaque geometry in the image contract ("Opaque geometry"): where each pixel's ray first
meets a scene's surfaces, the lit colour there, and the surface composited behind what
the ray gathered in front of it. Float64; shared by the exact image and the ray caster's
NumPy twin, so that the two see the same hit on every ray.

Method. Möller and Trumbore's ray-triangle test (1997), vectorised over rays x
triangles in chunks of at most ``_PAIRS`` pairs (memory stays bounded for any image and
mesh), after a slab test of each surface's bounding box that leaves out the rays that
miss it. A triangle is hit at ``t > 0`` where ``u >= 0, v >= 0, u + v <= 1`` (edges and
corners included: a ray through an edge shared by two triangles hits both, at the same
t up to rounding, and the nearer in float64 is kept); a ray parallel to a triangle's
plane (``det == 0``, a degenerate triangle included) misses it. The nearest hit over
every surface wins; on an exact tie, the first surface in ``Scene.geometry``, then the
first face.

The colour of a hit is its surface's ``color`` lit by Blinn-Phong with the face's flat
(unit) normal, two-sided, the scene's ``phong`` and lights (``shading.shade_blinn_phong``
with a gradient threshold of 0: a unit normal is always lit).
"""

from __future__ import annotations

import numpy as np

from ..model.field import ray_box
from .shading import scene_lights, shade_blinn_phong

__all__ = ["ray_triangle_hits", "surface_hits", "surface_behind"]

_PAIRS = 1 << 18         # (ray, triangle) pairs tested at a time


def ray_triangle_hits(origins, dirs, triangles, faces=None):
    """The nearest hit (t > 0) of each ray on the triangles: ``origins``, ``dirs`` (n, 3),
    ``triangles`` (m, 3, 3) corners. Returns (t (n,), inf where none; the index of the face
    hit (n,), -1 where none). ``faces``, when given, lists the candidate triangles (the
    rest are not tested)."""
    o = np.asarray(origins, np.float64).reshape(-1, 3)
    d = np.asarray(dirs, np.float64).reshape(-1, 3)
    tri = np.asarray(triangles, np.float64).reshape(-1, 3, 3)
    n = len(o)
    t_best = np.full(n, np.inf)
    f_best = np.full(n, -1, np.int64)
    idx = np.arange(len(tri)) if faces is None else np.asarray(faces, np.int64)
    if n == 0 or idx.size == 0:
        return t_best, f_best
    v0 = tri[idx, 0]
    e1 = tri[idx, 1] - v0
    e2 = tri[idx, 2] - v0
    rays_per = max(1, min(n, _PAIRS // min(idx.size, _PAIRS)))
    per = max(1, _PAIRS // rays_per)                 # faces per chunk
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for r0 in range(0, n, rays_per):
            ro, rd = o[r0:r0 + rays_per, None, :], d[r0:r0 + rays_per, None, :]
            tb, fb = t_best[r0:r0 + rays_per], f_best[r0:r0 + rays_per]
            for f0 in range(0, idx.size, per):
                a, b, c = v0[None, f0:f0 + per], e1[None, f0:f0 + per], e2[None, f0:f0 + per]
                p = np.cross(rd, c)
                det = np.einsum("rfk,rfk->rf", np.broadcast_to(b, p.shape), p)
                inv = 1.0 / det
                s = ro - a
                u = np.einsum("rfk,rfk->rf", s, p) * inv
                q = np.cross(s, b)
                v = np.einsum("rfk,rfk->rf", np.broadcast_to(rd, q.shape), q) * inv
                t = np.einsum("rfk,rfk->rf", np.broadcast_to(c, q.shape), q) * inv
                ok = (det != 0) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
                t = np.where(ok, t, np.inf)
                k = np.argmin(t, axis=1)                      # the first face on a tie
                tk = t[np.arange(len(t)), k]
                better = tk < tb
                tb[better] = tk[better]
                fb[better] = idx[f0 + k[better]]
    return t_best, f_best


def surface_hits(scene, origins=None, dirs=None):
    """Each ray's first hit on ``scene.geometry`` and the lit colour there: (t (n,), inf
    where no surface is met; colour (n, 3), 0 there). The rays default to every pixel's
    (``scene.camera.rays``, world units, row 0 on top, flattened)."""
    if origins is None:
        origins, dirs = scene.camera.rays(scene.width, scene.height)
    o = np.asarray(origins, np.float64).reshape(-1, 3)
    d = np.asarray(dirs, np.float64).reshape(-1, 3)
    t_hit = np.full(len(o), np.inf)
    color = np.zeros((len(o), 3))
    for surface in scene.geometry:
        lo, hi = surface.bounds
        t0, t1 = ray_box(o, d, lo, hi)
        near = np.flatnonzero(t1 >= t0)             # rays that meet the bounding box
        if near.size == 0:
            continue
        t, face = ray_triangle_hits(o[near], d[near], surface.triangles())
        closer = t < t_hit[near]                    # strictly: the earlier surface keeps a tie
        rows, face = near[closer], face[closer]
        if rows.size == 0:
            continue
        t_hit[rows] = t[closer]
        normals = surface.normals()[face]
        base = np.broadcast_to(surface.color, normals.shape)
        color[rows] = shade_blinn_phong(base, normals, d[rows], scene.phong, 0.0, scene_lights(scene))
    return t_hit, color


def surface_behind(pixels, t_hit, color):
    """``pixels`` (n, 4) premultiplied RGBA of what each ray gathered in front of its
    surface, with the surface behind: where ``t_hit`` is finite, ``C + (1 - A) * colour``
    and A = 1 (an opaque surface under the over operator); elsewhere as they are."""
    out = np.array(pixels, np.float64, copy=True)
    hit = np.isfinite(t_hit)
    out[hit, :3] += (1.0 - out[hit, 3:4]) * color[hit]
    out[hit, 3] = 1.0
    return out
