"""NumPy reference of splatting: the plan's splats in the plan's order, each one's
kernel integrated along every pixel-centre ray near it (float64, the same closed form
as the shader), composited with the over operator.

The over operator is associative, so the per-pixel sequence is composited at once: with
the splats of a pixel listed front to back, each one's colour is weighted by the product
of ``1 - alpha`` of those in front (a segmented cumulative sum of ``log(1 - alpha)``).
"""

from __future__ import annotations

import numpy as np

from ..techniques.common import data_projection
from ..techniques.particles import pixels_per_unit

_PAIRS = 1 << 21     # (splat, pixel) candidates per batch


def render_plan(plan, lut_exact=False):
    """(H, W, 4) float64 premultiplied RGBA, row 0 on top. ``lut_exact`` is accepted for
    the common interface: the samples are classified with the exact TF anyway."""
    scene = plan.scene
    W, H = scene.width, scene.height
    cam = scene.camera
    lo = scene.volume.bounds[0]
    order = plan.order
    centres = plan.splats.points[order].astype(np.float64)
    samples = plan.splats.samples[order].astype(np.float64)
    scales = plan.splats.scales[order].astype(np.float64)
    sigma = plan.sigma
    inv_var = 1.0 / sigma ** 2
    u = plan.kernel_uniforms()
    clip = np.concatenate([centres, np.ones((len(centres), 1))], axis=1) @ data_projection(scene)
    w = clip[:, 3]
    inside = np.all(np.abs(clip[:, :3]) <= w[:, None], axis=1) & (w > 0)   # GL clips points by centre
    rank = np.flatnonzero(inside)                                           # draw position
    cx = (clip[rank, 0] / w[rank] + 1) * 0.5 * W
    cy = (1 - clip[rank, 1] / w[rank]) * 0.5 * H
    reach = plan.cutoff * float(sigma.max()) * scales[rank]
    eye = cam.eye - lo
    depth = 1.0 if cam.is_ortho else np.maximum((centres[rank] - eye) @ cam.forward - reach, 1e-6)
    half = np.ceil(3.0 * reach * pixels_per_unit(scene) / depth + 2.0).astype(np.int64) * np.ones(rank.size, np.int64)
    x0 = np.clip(np.floor(cx).astype(np.int64) - half, 0, W - 1)
    x1 = np.clip(np.floor(cx).astype(np.int64) + half, 0, W - 1)
    y0 = np.clip(np.floor(cy).astype(np.int64) - half, 0, H - 1)
    y1 = np.clip(np.floor(cy).astype(np.int64) + half, 0, H - 1)
    origins, dirs = cam.rays(W, H)
    origins, dirs = origins.reshape(-1, 3) - lo, dirs.reshape(-1, 3)
    nx, ny = x1 - x0 + 1, y1 - y0 + 1
    counts = nx * ny
    pixels, ranks, alphas, colors = [], [], [], []
    start = 0
    while start < rank.size:
        stop = min(rank.size, start + max(1, int(np.searchsorted(np.cumsum(counts[start:]), _PAIRS))))
        ids = np.repeat(np.arange(start, stop), counts[start:stop])
        k = np.arange(ids.size) - np.repeat(np.cumsum(counts[start:stop]) - counts[start:stop], counts[start:stop])
        pixel = (y0[ids] + k // nx[ids]) * W + x0[ids] + k % nx[ids]
        q = origins[pixel] - centres[rank[ids]]
        d = dirs[pixel]
        scale = scales[rank[ids]]
        iv = inv_var[None, :] / (scale * scale)[:, None]
        a = np.einsum("ij,ij->i", d * d, iv)
        b = np.einsum("ij,ij->i", d * q, iv)
        off = q - (b / a)[:, None] * d
        m2 = np.einsum("ij,ij->i", off * off, iv)
        hit = (b < 0) & (m2 <= u["u_cutoff2"])
        od = samples[rank[ids], 3] * u["u_norm"] / scale ** 3 / np.sqrt(a) * np.exp(-0.5 * m2)
        alpha = -np.expm1(-od)
        pixels.append(pixel[hit])
        ranks.append(rank[ids][hit])
        alphas.append(alpha[hit])
        colors.append(samples[rank[ids][hit], :3] * alpha[hit, None])
        start = stop
    out = np.zeros((H * W, 4))
    if not pixels:
        return out.reshape(H, W, 4)
    pixel, rnk, alpha, color = (np.concatenate(x) for x in (pixels, ranks, alphas, colors))
    # front to back per pixel: the last drawn is the nearest
    sequence = np.lexsort((-rnk, pixel))
    pixel, alpha, color = pixel[sequence], alpha[sequence], color[sequence]
    log_t = np.log1p(-np.minimum(alpha, 1.0 - 1e-16))
    total = np.cumsum(log_t)
    first = np.ones(pixel.size, bool)
    first[1:] = pixel[1:] != pixel[:-1]
    base = np.maximum.accumulate(np.where(first, np.arange(pixel.size), 0))
    before = total - log_t - (total[base] - log_t[base])     # sum over the pixel's splats in front
    weight = np.exp(before)
    np.add.at(out[:, :3], pixel, color * weight[:, None])
    np.add.at(out[:, 3], pixel, alpha * weight)
    return out.reshape(H, W, 4)
