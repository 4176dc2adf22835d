"""NumPy reference of splatting: the plan's splats in the plan's order, each one's
kernel integrated along every pixel-centre ray near it (float64, the same closed form
as the shader), composited with the over operator.

The over operator is associative, so the per-pixel sequence is composited at once: with
the splats of a pixel listed front to back, each one's colour is weighted by the product
of ``1 - alpha`` of those in front (a segmented cumulative sum of ``log(1 - alpha)``).
"""

from __future__ import annotations

import numpy as np

from .particles import lit_colors
from .sprites import sprite_pixel_pairs


def render_plan(plan, lut_exact=False):
    """(H, W, 4) float64 premultiplied RGBA, row 0 on top. ``lut_exact`` is accepted for
    the common interface: the samples are classified with the exact TF anyway."""
    scene = plan.scene
    W, H = scene.width, scene.height
    order = plan.order
    centres = plan.splats.points[order].astype(np.float64)
    samples = plan.splats.samples[order].astype(np.float64)
    scales = plan.splats.scales[order].astype(np.float64)
    gradients = None if plan.gradients is None else plan.gradients[order].astype(np.float64)
    inv_var = 1.0 / plan.sigma ** 2
    u = plan.kernel_uniforms()
    # draw position in the plan's order of each splat GL keeps
    rank, origins, dirs, chunks = sprite_pixel_pairs(scene, centres, u["u_reach"] * scales)
    pixels, ranks, alphas, colors = [], [], [], []
    for ids, pixel in chunks:
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
        rgb = samples[rank[ids][hit], :3]
        if gradients is not None:          # lit along each pixel's own ray
            rgb = lit_colors(scene, rgb, gradients[rank[ids][hit]], d[hit])
        colors.append(rgb * alpha[hit, None])
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
