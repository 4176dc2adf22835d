"""NumPy reference of particle-based volume rendering: the plan's particle sets, each
pixel-centre ray against every sphere near it (float64), the nearest entry kept (the
depth test), its colour (the exact TF's, stored with the particle), opaque; the sets
averaged.

As GL does with points, a particle whose centre lies outside the view's clip volume
(``data_projection``: beside the image, behind the near plane or beyond far) is not
drawn.
"""

from __future__ import annotations

import numpy as np

from ..techniques.common import data_projection
from ..techniques.particles import pixels_per_unit

_PAIRS = 1 << 21     # (particle, pixel) candidates per batch


def render_plan(plan, lut_exact=False):
    """(H, W, 4) float64 premultiplied RGBA, row 0 on top. ``lut_exact`` is accepted for
    the common interface: the particles carry the exact TF's colour anyway."""
    scene = plan.scene
    W, H = scene.width, scene.height
    out = np.zeros((H * W, 4))
    for particle_set in plan.sets:
        out += first_hits(scene, plan.radius, particle_set.points, particle_set.colors)
    return (out / plan.repetitions).reshape(H, W, 4)


def first_hits(scene, radius, points, colors):
    """(H * W, 4): per pixel the colour (alpha 1) of the first sphere its ray enters, or 0."""
    W, H = scene.width, scene.height
    cam = scene.camera
    lo = scene.volume.bounds[0]
    p = np.asarray(points, np.float64)
    clip = np.concatenate([p, np.ones((len(p), 1))], axis=1) @ data_projection(scene)
    w = clip[:, 3]
    inside = np.all(np.abs(clip[:, :3]) <= w[:, None], axis=1) & (w > 0)
    p, colors, clip = p[inside], np.asarray(colors, np.float64)[inside], clip[inside]
    # projected centre in pixels (x right, row down) and a square sure to hold the disc
    cx = (clip[:, 0] / clip[:, 3] + 1) * 0.5 * W
    cy = (1 - clip[:, 1] / clip[:, 3]) * 0.5 * H
    eye = cam.eye - lo
    depth = 1.0 if cam.is_ortho else np.maximum((p - eye) @ cam.forward - radius, 1e-6)
    half = np.ceil(3.0 * radius * pixels_per_unit(scene) / depth + 2.0).astype(np.int64) * np.ones(len(p), np.int64)
    x0 = np.clip(np.floor(cx).astype(np.int64) - half, 0, W - 1)
    x1 = np.clip(np.floor(cx).astype(np.int64) + half, 0, W - 1)
    y0 = np.clip(np.floor(cy).astype(np.int64) - half, 0, H - 1)
    y1 = np.clip(np.floor(cy).astype(np.int64) + half, 0, H - 1)
    origins, dirs = cam.rays(W, H)
    origins, dirs = origins.reshape(-1, 3) - lo, dirs.reshape(-1, 3)
    best = np.full(W * H, np.inf)
    owner = np.full(W * H, -1, np.int64)
    nx, ny = x1 - x0 + 1, y1 - y0 + 1
    counts = nx * ny
    start = 0
    while start < len(p):
        stop = start + max(1, int(np.searchsorted(np.cumsum(counts[start:]), _PAIRS)))
        stop = min(stop, len(p))
        ids = np.repeat(np.arange(start, stop), counts[start:stop])
        k = np.arange(ids.size) - np.repeat(np.cumsum(counts[start:stop]) - counts[start:stop], counts[start:stop])
        px = x0[ids] + k % nx[ids]
        py = y0[ids] + k // nx[ids]
        pixel = py * W + px
        v = p[ids] - origins[pixel]
        t = np.einsum("ij,ij->i", v, dirs[pixel])
        off = v - t[:, None] * dirs[pixel]
        miss = radius * radius - np.einsum("ij,ij->i", off, off)
        half_chord = np.sqrt(np.maximum(miss, 0.0))
        hit = (miss >= 0) & (t + half_chord > 0)
        t_hit = np.maximum(t - half_chord, 0.0)
        pixel, t_hit, who = pixel[hit], t_hit[hit], ids[hit]
        order = np.lexsort((t_hit, pixel))
        pixel, t_hit, who = pixel[order], t_hit[order], who[order]
        first = np.ones(pixel.size, bool)
        first[1:] = pixel[1:] != pixel[:-1]
        pixel, t_hit, who = pixel[first], t_hit[first], who[first]
        closer = t_hit < best[pixel]
        best[pixel[closer]] = t_hit[closer]
        owner[pixel[closer]] = who[closer]
        start = stop
    out = np.zeros((W * H, 4))
    hit = owner >= 0
    out[hit, :3] = colors[owner[hit]]
    out[hit, 3] = 1.0
    return out
