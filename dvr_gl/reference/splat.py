"""NumPy reference of splatting, both kernels, following the plan (float64).

The tent kernel: the plan's sheets, front to back. On each, every pixel's ray meets the
sheet at ``p``; the sheet buffer's sums there are the tent weights of the splatted
samples around ``p`` (the corners of its cell that the plan splats: no other tent reaches
it) times their values, their gradients and their non-finite flags, summed as GL's
additive blending does; the value ``sum w v / sum w`` is classified with the plan's table,
lit, given the piece of the ray the sheet stands for and blended under the image.

The Gaussian kernel: the plan's splats in the plan's order, each one's kernel integrated
along every pixel-centre ray near it (float64, the same closed form as the shader),
composited with the over operator. The over operator is associative, so the per-pixel
sequence is composited at once: with the splats of a pixel listed front to back, each
one's colour is weighted by the product of ``1 - alpha`` of those in front (a segmented
cumulative sum of ``log(1 - alpha)``). With clip planes or a crop box, each kernel's
optical depth along a ray is that of its part in the ray's kept range (``clip_fraction``,
the shader's closed form with the same erf), and kernels whose cutoff sphere misses the
kept region are dropped (``sprites``). With clips or geometry, a tent piece with an end
at a cut or at the surface (no neighbouring sheet on that side, and the kept range's end
there is not the box's) takes the field at its middle (trilinear in float64, as the
shader's texture lookup), lit with its sheet's gradient; its fragment is dropped where
that middle lies in a masked cell.

Opaque geometry: each pixel's first surface hit is the exact image's own float64 test
(``exact_geometry.surface_hits``), and the ray's kept range ends there, as at a clip. The
tent: sheets beyond it are no sheets for that ray, the piece straddling it runs to it,
and the surface's lit colour is blended under the sheets last (and under the gap pass's
chords, which end there too). The Gaussian kernel: each kernel counts by its part of the
ray in front of the surface (``clip_fraction`` up to t_hit, from the clip's start or,
unclipped, from minus infinity), and the surface is composited behind the splats
(``surface_behind``: the backmost layer GL draws first).
"""

from __future__ import annotations

import numpy as np

from ..model.field import cell_is_valid, trilinear, world_to_index
from .common import blend_under, box_rays, classifier, plane_inside, segment_of, slab_segment
from .exact_geometry import surface_behind, surface_hits
from .particles import lit_colors
from .sprites import kept_ranges, sprite_pixel_pairs


def erf_as(x):
    """erf to 1.5e-7 (Abramowitz and Stegun 7.1.26): GLSL ``erfAS`` of shaders/splat/splat.frag."""
    x = np.asarray(x, np.float64)
    t = 1.0 / (1.0 + 0.3275911 * np.abs(x))
    poly = t * (0.254829592 + t * (-0.284496736 + t * (1.421413741 + t * (-1.453152027 + t * 1.061405429))))
    with np.errstate(invalid="ignore"):
        return np.sign(x) * (1.0 - poly * np.exp(-x * x))


def clip_fraction(a, b, t0, t1):
    """The share of a kernel's integral along a ray that lies in the ray's kept range
    [t0, t1]: along the ray the kernel is a 1D Gaussian in t with mean -b / a and standard
    deviation 1 / sqrt(a) (``a``, ``b`` as in the shader)."""
    centre, k = -b / a, np.sqrt(0.5 * a)
    return 0.5 * (erf_as((t1 - centre) * k) - erf_as((t0 - centre) * k))


def render_plan(plan, lut_exact=False):
    """(H, W, 4) float64 premultiplied RGBA, row 0 on top. ``lut_exact``: the tent's
    sheets are classified with the exact TF instead of the plan's table (the Gaussian
    kernel's samples are classified with the exact TF anyway)."""
    if plan.kernel == "tent":
        return _render_tent(plan, lut_exact)
    return _render_gaussian(plan)


def sheet_sums(plan, points, values=None):
    """The sheet buffer at ``points`` (n, 3) relative to the data's lower corner: per
    point the sums over the splatted samples of ``w``, ``w v``, ``w`` of the non-finite
    ones and ``w g`` (None when unlit), ``w`` the sample's tent there. ``values``: the
    splatted samples' values in float64 (made here when not given)."""
    volume = plan.scene.volume
    samples = plan.samples
    nx, ny, nz = volume.dims
    idx = np.asarray(points, np.float64) / volume.spacing
    base = np.clip(np.floor(idx).astype(np.int64), 0, np.array([nx - 2, ny - 2, nz - 2]))
    slot = samples.slots                                      # sample -> its row in the plan
    weight = np.zeros(len(idx))
    value = np.zeros(len(idx))
    bad = np.zeros(len(idx))
    grad = None if plan.gradients is None else np.zeros((len(idx), 3))
    if values is None:
        values = volume.values(np.float64)[samples.mask]
    for corner in ((x, y, z) for z in (0, 1) for y in (0, 1) for x in (0, 1)):
        c = base + np.array(corner)
        w = np.prod(np.maximum(1.0 - np.abs(idx - c), 0.0), axis=1)
        row = slot[c[:, 2], c[:, 1], c[:, 0]]
        drawn = (row >= 0) & (w > 0)
        w, row = np.where(drawn, w, 0.0), np.maximum(row, 0)
        finite = samples.finite[row]
        weight += np.where(finite, w, 0.0)
        value += np.where(finite, w * values[row], 0.0)
        bad += np.where(finite, 0.0, w)
        if grad is not None:
            grad += np.where(finite, w, 0.0)[:, None] * plan.gradients[row].astype(np.float64)
    return weight, value, bad, grad


def _render_tent(plan, lut_exact):
    scene = plan.scene
    H, W = scene.height, scene.width
    o, d, t0, t1 = box_rays(scene)
    box0, box1 = box_rays(scene.replace(clip_planes=(), crop_box=None))[2:] if scene.clips else (t0, t1)
    if scene.geometry:      # the kept range ends at the first surface (sheet.frag: GEOMETRY)
        t_hit, surface_color = surface_hits(scene)
        t1 = np.minimum(t1, t_hit)
    end_pieces = bool(scene.clips or scene.geometry)     # GLSL END_PIECES
    volume = scene.volume
    all_values = volume.values(np.float64)
    cos_theta = d @ scene.camera.forward
    sheets = plan.sheets
    terms = None
    if plan.gradients is not None:
        from .shading import SampleTerms
        terms = SampleTerms(scene, None)
    classify, transparency = classifier(plan, lut_exact)
    acc = np.zeros((len(o), 4))
    values = all_values[plan.samples.mask]

    def t_of(k):
        return (sheets.far_depth - k * sheets.spacing) / cos_theta

    for k in range(sheets.count - 1, -1, -1):        # front to back
        if sheets.ranges[k, 1] == 0:
            continue
        t = t_of(k)
        rows = np.nonzero(plane_inside(k, sheets.count, t, t0, t1))[0]
        if rows.size == 0:
            continue
        tk = t[rows]
        points = o[rows] + tk[:, None] * d[rows]
        weight, value, bad, grad = sheet_sums(plan, points, values)
        seen = (weight > 0) & (bad <= 0)
        rows, tk, points = rows[seen], tk[seen], points[seen]
        s = value[seen] / weight[seen]
        g = None if grad is None else grad[seen] / weight[seen][:, None]
        t_near, t_far = t_of(k + 1)[rows], t_of(k - 1)[rows]
        a, b = slab_segment(k, sheets.count, tk, t_near, t_far, t0[rows], t1[rows])
        if end_pieces:      # a piece with an end at a cut or the surface: the field at its middle
            cut = ((~plane_inside(k + 1, sheets.count, t_near, t0[rows], t1[rows]) & (t0[rows] > box0[rows]))
                   | (~plane_inside(k - 1, sheets.count, t_far, t0[rows], t1[rows]) & (t1[rows] < box1[rows])))
            middle = o[rows[cut]] + (0.5 * (a[cut] + b[cut]))[:, None] * d[rows[cut]]
            s[cut] = trilinear(all_values, middle / volume.spacing)
            if volume.has_nonfinite:     # a middle in a masked cell: its fragment is discarded
                keep = np.ones(rows.size, bool)
                keep[cut] = cell_is_valid(volume, world_to_index(volume, middle + volume.bounds[0]))
                rows, tk, points, s, a, b = (x[keep] for x in (rows, tk, points, s, a, b))
                g = None if g is None else g[keep]
        rgba, clear = classify(s), transparency(s)
        length = (b - a) / scene.tf.unit_distance
        if terms is not None:
            factor, offset, scale = terms.at(points + scene.volume.bounds[0], d[rows], grad=g)
            lit = rgba[:, 3] > 0
            rgba[:, :3] = np.where(lit[:, None], rgba[:, :3] * factor[:, None] + offset, rgba[:, :3])
            length = np.where(lit, length * scale, length)
        src = segment_of(rgba, clear, length)
        drawn = np.any(src != 0, axis=1)       # GL discards all-zero fragments
        acc[rows[drawn]] = blend_under(acc[rows[drawn]], src[drawn], plan.target)
    # rays that cross no sheet inside the box: 3D slicing's gap pass on the same planes
    from .slice3d import gap_rays_pass
    gap_rays_pass(acc, plan.gap, (o, d, t0, t1), lut_exact)
    if scene.geometry:      # the surface, opaque, blended under everything
        hit = np.isfinite(t_hit)
        surface = np.concatenate([surface_color[hit], np.ones((int(hit.sum()), 1))], axis=1)
        acc[hit] = blend_under(acc[hit], surface, plan.target)
    return acc.reshape(H, W, 4)


def _gaussian_pairs(plan, clip_terms=False, t_hit=None):
    """Every (pixel, splat) pair near each other, a chunk at a time: the pixels, the
    splats' draw ranks, the rays' directions, their distance from each centre at closest
    approach in standard deviations squared (m2), whether the centre is ahead (b < 0) and
    the kernel's opacity along the ray (the shader's closed form); with ``clip_terms`` (a
    clipped scene, or one with geometry) also a dict of what the kept range's share
    depends on. ``t_hit``: each pixel's first surface (``surface_hits``; found here when
    the scene has geometry and it is not given)."""
    order = plan.order
    centres = plan.splats.points[order].astype(np.float64)
    samples = plan.splats.samples[order].astype(np.float64)
    scales = plan.splats.scales[order].astype(np.float64)
    inv_var = 1.0 / plan.sigma ** 2
    u = plan.kernel_uniforms()
    rank, origins, dirs, chunks = sprite_pixel_pairs(plan.scene, centres, u["u_reach"] * scales)
    clips = plan.scene.clips
    ranged = bool(clips or plan.scene.geometry)      # GLSL PART_OF_RAY
    if ranged:
        keep0, keep1 = kept_ranges(plan.scene, origins, dirs)
        if not clips:
            keep0 = np.full(len(origins), -np.inf)   # unclipped, the whole kernel counts
        if plan.scene.geometry:
            keep1 = np.minimum(keep1, surface_hits(plan.scene)[0] if t_hit is None else t_hit)
    for ids, pixel in chunks:
        q = origins[pixel] - centres[rank[ids]]
        d = dirs[pixel]
        scale = scales[rank[ids]]
        iv = inv_var[None, :] / (scale * scale)[:, None]
        a = np.einsum("ij,ij->i", d * d, iv)
        b = np.einsum("ij,ij->i", d * q, iv)
        off = q - (b / a)[:, None] * d
        m2 = np.einsum("ij,ij->i", off * off, iv)
        od = samples[rank[ids], 3] * u["u_norm"] / scale ** 3 / np.sqrt(a) * np.exp(-0.5 * m2)
        ahead = b < 0
        terms = None
        if ranged:
            ahead &= keep1[pixel] > keep0[pixel]
            share = clip_fraction(a, b, keep0[pixel], keep1[pixel])
            if clip_terms:
                terms = dict(depth=od, share=share, a=a, b=b, t0=keep0[pixel], t1=keep1[pixel],
                             origin=np.linalg.norm(origins[pixel], axis=1), q=np.linalg.norm(q, axis=1), dirs=d)
            od = od * share
        if clip_terms:
            yield pixel, rank[ids], d, m2, ahead, -np.expm1(-od), terms
        else:
            yield pixel, rank[ids], d, m2, ahead, -np.expm1(-od)


def cutoff_ambiguity(plan, band):
    """(H, W): per pixel the summed opacity of the Gaussian splats whose ray passes within
    ``band`` standard deviations of the kernel's cutoff. Float32 rounding may keep or drop
    those kernels (GPUs' arithmetic does, at a few pixels), and over compositing changes
    a pixel by at most the opacity it keeps or drops."""
    scene = plan.scene
    out = np.zeros(scene.width * scene.height)
    for pixel, _, _, m2, ahead, alpha in _gaussian_pairs(plan):
        near = ahead & (np.abs(np.sqrt(m2) - plan.cutoff) <= band)
        np.add.at(out, pixel[near], alpha[near])
    return out.reshape(scene.height, scene.width)


def clip_rounding(plan, eps=2.0 ** -23):
    """(H, W): per pixel a bound on how much float32 rounding of the clipped share moves
    the Gaussian splats' opacities (zero unclipped). A splat's opacity is ``1 - exp(-D f)``
    with ``f = (erf(z1) - erf(z0)) / 2``, ``z = (t_end - c) sqrt(a / 2)``, ``c = -b / a`` its
    centre along the ray and ``t_end`` the kept range's ends; so it moves by at most
    ``D exp(-D f) |df|``, ``|df| <= sum over the ends of exp(-z^2) |dz| / sqrt(pi)``. The
    centre along the ray rounds by ``8 eps |q|`` (as the cutoff's band: ``|q|`` the eye's
    distance from the centre); an end, where the ray meets a plane or a crop face, by
    ``8 eps (|o| + t + max |offset|)`` across that surface, so ``/ g`` along the ray, ``g``
    the smallest non-zero ``|n . d|`` over the planes and the crop box's axes; and the erf's own
    float32 evaluation by ``8 eps`` each. Over compositing, a pixel moves by at most the
    sum over its splats."""
    scene = plan.scene
    out = np.zeros(scene.width * scene.height)
    if not scene.clips:
        return out.reshape(scene.height, scene.width)
    planes, crop = scene.clip_in_box()
    normals = [np.asarray(n, np.float64) for n, _ in planes] + ([] if crop is None else list(np.eye(3)))
    offsets = [abs(o) for _, o in planes] + ([] if crop is None else [float(np.abs(np.concatenate(crop)).max())])
    reach = max(offsets)
    for pixel, _, _, _, ahead, _, t in _gaussian_pairs(plan, clip_terms=True):
        k = np.sqrt(0.5 * t["a"])
        centre = -t["b"] / t["a"]
        cosines = np.abs(np.stack([t["dirs"] @ n for n in normals]))
        g = np.min(np.where(cosines > 0, cosines, np.inf), axis=0)      # a parallel surface ends no ray
        moved = np.zeros(pixel.size)
        for end in (t["t0"], t["t1"]):
            finite = np.isfinite(end)
            z = np.where(finite, (np.where(finite, end, 0.0) - centre) * k, np.inf)
            with np.errstate(divide="ignore", invalid="ignore"):
                dt = 8 * eps * (t["origin"] + np.abs(np.where(finite, end, 0.0)) + reach) / g
            dz = k * (dt + 8 * eps * t["q"]) + 8 * eps
            moved += np.where(finite, np.exp(-np.minimum(z * z, 700.0)) * dz / np.sqrt(np.pi), 0.0)
        sensitivity = t["depth"] * np.exp(-t["depth"] * t["share"]) * moved
        np.add.at(out, pixel[ahead], sensitivity[ahead])
    return out.reshape(scene.height, scene.width)


def surface_rounding(plan, dt, eps=2.0 ** -23):
    """(H, W): per pixel a bound on how much GL's t_hit, off the float64 hit by ``dt``
    (per pixel, (H, W)), moves the Gaussian splats' opacities (zero without geometry):
    ``clip_rounding``'s bound at the kept range's far end where that end is the surface,
    ``D exp(-D f) exp(-z^2) |dz| / sqrt(pi)`` per splat, ``dz = sqrt(a / 2) (dt + 8 eps |q|)
    + 8 eps`` (the end, the kernel's centre along the ray, the erf's own rounding)."""
    scene = plan.scene
    out = np.zeros(scene.width * scene.height)
    if not scene.geometry:
        return out.reshape(scene.height, scene.width)
    t_hit = surface_hits(scene)[0]
    dt = np.asarray(dt, np.float64).reshape(-1)
    for pixel, _, _, _, ahead, _, t in _gaussian_pairs(plan, clip_terms=True, t_hit=t_hit):
        k = np.sqrt(0.5 * t["a"])
        at_surface = ahead & np.isfinite(t["t1"]) & (t["t1"] == t_hit[pixel])
        z = (np.where(at_surface, t["t1"], 0.0) + t["b"] / t["a"]) * k
        dz = k * (dt[pixel] + 8 * eps * t["q"]) + 8 * eps
        moved = np.exp(-np.minimum(z * z, 700.0)) * dz / np.sqrt(np.pi)
        sensitivity = t["depth"] * np.exp(-t["depth"] * t["share"]) * moved
        np.add.at(out, pixel[at_surface], sensitivity[at_surface])
    return out.reshape(scene.height, scene.width)


def _render_gaussian(plan):
    scene = plan.scene
    W, H = scene.width, scene.height
    samples = plan.splats.samples[plan.order].astype(np.float64)
    gradients = None if plan.gradients is None else plan.gradients[plan.order].astype(np.float64)
    cutoff2 = plan.kernel_uniforms()["u_cutoff2"]
    t_hit = surface_color = None
    if scene.geometry:
        t_hit, surface_color = surface_hits(scene)
    pixels, ranks, alphas, colors = [], [], [], []
    for pixel, rank, d, m2, ahead, alpha in _gaussian_pairs(plan, t_hit=t_hit):
        hit = ahead & (m2 <= cutoff2)
        pixels.append(pixel[hit])
        ranks.append(rank[hit])
        alphas.append(alpha[hit])
        rgb = samples[rank[hit], :3]
        if gradients is not None:          # lit along each pixel's own ray
            rgb = lit_colors(scene, rgb, gradients[rank[hit]], d[hit])
        colors.append(rgb * alpha[hit, None])
    out = np.zeros((H * W, 4))
    if not pixels:
        return out.reshape(H, W, 4) if t_hit is None else surface_behind(out, t_hit, surface_color).reshape(H, W, 4)
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
    if t_hit is not None:      # the surface behind the splats (GL draws it first)
        out = surface_behind(out, t_hit, surface_color)
    return out.reshape(H, W, 4)
