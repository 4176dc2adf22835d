"""Point sprites as GL draws them, for the references of the point techniques (particles,
splat): which sprites GL keeps, and which pixel-centre rays may meet each one.

GL drops a point whose centre lies outside the view's clip volume (``data_projection``:
beside the image, behind the near plane or beyond far), whatever its size; the
references do the same. A kept sprite's candidate pixels are a square generous enough to
hold the outline of a sphere of radius ``reach`` about its centre (wider than the GL
sprite of ``shaders/common/sprite.glsl``, so the exact per-pixel test decides, not the
square).

With clip planes or a crop box, a sprite whose sphere of radius ``reach`` misses the kept
region is dropped too (``model.clipping.inside_clip`` with that margin, the vertex
shaders' ``insideClip``), and ``kept_ranges`` gives each pixel ray's kept part, which the
fragment shaders test (GLSL ``clipRange`` from the ray's start).
"""

from __future__ import annotations

import numpy as np

from ..model.clipping import clip_interval, inside_clip
from ..techniques.common import data_projection
from ..techniques.particles import pixels_per_unit

PAIRS = 1 << 21      # (sprite, pixel) candidates per chunk


def sprite_pixel_pairs(scene, centres, reach):
    """``(kept, origins, dirs, chunks)``: ``kept`` the indices of the sprites GL draws
    (``centres`` (N, 3) relative to the data's lower corner; ``reach`` a radius, one or
    per sprite; those whose sphere of that radius misses the scene's kept region are not
    kept), the pixel rays ((H * W, 3) each, origins relative to the lower corner),
    and a generator of ``(sprite, pixel)`` index arrays in chunks of at most ``PAIRS``,
    ``sprite`` indexing ``kept``."""
    W, H = scene.width, scene.height
    cam = scene.camera
    lo = scene.volume.bounds[0]
    clip = np.concatenate([centres, np.ones((len(centres), 1))], axis=1) @ data_projection(scene)
    w = clip[:, 3]
    reach = np.broadcast_to(np.asarray(reach, np.float64), (len(centres),))
    drawn = np.all(np.abs(clip[:, :3]) <= w[:, None], axis=1) & (w > 0)
    if scene.clips:
        drawn &= inside_clip(centres, *scene.clip_in_box(), margin=reach)
    kept = np.flatnonzero(drawn)
    reach = reach[kept]
    cx = (clip[kept, 0] / w[kept] + 1) * 0.5 * W
    cy = (1 - clip[kept, 1] / w[kept]) * 0.5 * H
    depth = 1.0 if cam.is_ortho else np.maximum((centres[kept] - (cam.eye - lo)) @ cam.forward - reach, 1e-6)
    half = np.ceil(3.0 * reach * pixels_per_unit(scene) / depth + 2.0).astype(np.int64)
    x0 = np.clip(np.floor(cx).astype(np.int64) - half, 0, W - 1)
    x1 = np.clip(np.floor(cx).astype(np.int64) + half, 0, W - 1)
    y0 = np.clip(np.floor(cy).astype(np.int64) - half, 0, H - 1)
    y1 = np.clip(np.floor(cy).astype(np.int64) + half, 0, H - 1)
    origins, dirs = cam.rays(W, H)
    origins, dirs = origins.reshape(-1, 3) - lo, dirs.reshape(-1, 3)
    nx = x1 - x0 + 1
    counts = nx * (y1 - y0 + 1)

    def chunks():
        start = 0
        while start < kept.size:
            stop = min(kept.size, start + max(1, int(np.searchsorted(np.cumsum(counts[start:]), PAIRS))))
            ids = np.repeat(np.arange(start, stop), counts[start:stop])
            k = np.arange(ids.size) - np.repeat(np.cumsum(counts[start:stop]) - counts[start:stop], counts[start:stop])
            yield ids, (y0[ids] + k // nx[ids]) * W + x0[ids] + k % nx[ids]
            start = stop
    return kept, origins, dirs, chunks()


def kept_ranges(scene, origins, dirs):
    """Per pixel ray the part [t0, t1] the scene's clip planes and crop box keep, from the
    ray's start (GLSL ``clipRange(origin, dir, vec2(0, inf))``); [0, inf] unclipped."""
    t0, t1 = np.zeros(len(origins)), np.full(len(origins), np.inf)
    if scene.clips:
        t0, t1 = clip_interval(origins, dirs, t0, t1, *scene.clip_in_box())
    return t0, t1
