"""NumPy twins of the shared GLSL in ``shaders/common``: ray-box entry and exit, volume
sampling, opacity correction and compositing. Float64 unless told otherwise.

Each function here has exactly one GLSL counterpart, named in its docstring; the shader
unit tests compare the two over grids of inputs.
"""

from __future__ import annotations

import numpy as np

from ..model.clipping import clip_interval
from ..model.field import cell_is_valid, ray_box, trilinear, world_to_index
from ..model.transfer import correct_opacity


def box_rays(scene):
    """Every pixel's ray, flattened and relative to the volume box's lower corner (as the
    shaders see them): origins and unit directions (n, 3), entry and exit distances."""
    lo, hi = scene.volume.bounds
    origins, dirs = scene.camera.rays(scene.width, scene.height)
    o = (origins - lo).reshape(-1, 3)
    d = dirs.reshape(-1, 3)
    # a ray lying in a face plane is in the closed box: decided before the subtraction,
    # which can round an origin on the upper face to just outside it
    world = origins.reshape(-1, 3)
    t0, t1 = ray_box(o, d, np.zeros(3), scene.volume.extent, inside=(world >= lo) & (world <= hi))
    if scene.clips:
        planes, crop = scene.clip_in_box()
        t0, t1 = clip_interval(o, d, t0, t1, planes, crop)
    return o, d, t0, t1


def classifier(plan, lut_exact=False):
    """(classify, transparency) for a plan: its lookup table (GLSL ``applyTF`` and
    ``transparencyTF``), or with ``lut_exact`` the exact transfer function."""
    if lut_exact:
        tf = plan.scene.tf
        return (lambda s: np.concatenate([tf.color(s), tf.opacity(s)[..., None]], axis=-1),
                lambda s: 1 - tf.opacity(s))
    return plan.lut.lookup, plan.lut.lookup_transparency


def segment_of(rgba, transparency, length_over_unit, model="emission_absorption"):
    """Premultiplied RGBA (..., 4) of segments ``length_over_unit`` unit distances long of
    samples with straight colour and unit-distance opacity ``rgba`` (and the precise
    ``transparency`` 1 - alpha) under the optical ``model`` (GLSL ``segmentOf``):
    emission-absorption (c alpha, alpha) with alpha corrected for the length; absorption
    only (0, alpha); emission only (c tau L, 0)."""
    rgba = np.asarray(rgba, np.float64)
    a = rgba[..., 3]
    x = np.asarray(length_over_unit, np.float64)
    if model == "emission":
        with np.errstate(divide="ignore", invalid="ignore"):
            log_t = np.where(a <= 0.5, np.log1p(-np.minimum(a, 0.5)),
                             np.log(np.maximum(np.asarray(transparency, np.float64), 0)))
        weight = -log_t * np.maximum(x, 0)
        out = np.concatenate([rgba[..., :3] * weight[..., None], np.zeros(a.shape + (1,))], axis=-1)
    else:
        alpha = correct_opacity(a, x, transparency)
        colourless = model in ("absorption", "sabella")    # Sabella colours the ray at its end
        rgb = np.zeros(rgba[..., :3].shape) if colourless else rgba[..., :3] * alpha[..., None]
        out = np.concatenate([rgb, alpha[..., None]], axis=-1)
    out[a <= 0] = 0
    return out


def rgb_to_hsv(c):
    """(..., 3) RGB in [0, 1] to HSV, hue in [0, 1) (GLSL ``rgbToHsv``)."""
    c = np.asarray(c, np.float64)
    r, g, b = c[..., 0], c[..., 1], c[..., 2]
    mx, mn = c.max(axis=-1), c.min(axis=-1)
    delta = mx - mn
    safe = np.where(delta > 0, delta, 1.0)
    h = np.where(mx == r, (g - b) / safe, np.where(mx == g, 2.0 + (b - r) / safe, 4.0 + (r - g) / safe))
    h = np.where(delta > 0, np.mod(h / 6.0, 1.0), 0.0)
    return np.stack([h, np.where(mx > 0, delta / np.where(mx > 0, mx, 1.0), 0.0), mx], axis=-1)


def hsv_to_rgb(hsv):
    """GLSL ``hsvToRgb``."""
    hsv = np.asarray(hsv, np.float64)
    k = np.clip(np.abs(np.mod(hsv[..., :1] + np.array([0.0, 2.0, 1.0]) / 3.0, 1.0) * 6.0 - 3.0) - 1.0, 0.0, 1.0)
    return hsv[..., 2:3] * (1.0 + (k - 1.0) * hsv[..., 1:2])


def sabella_color(peak_color, intensity, depth):
    """Sabella (1988) pixels (..., 4) from the TF colour at each ray's peak value, its
    integrated intensity and the peak's depth in [0, 1] (GLSL ``sabellaColor``)."""
    hsv = rgb_to_hsv(peak_color)
    hsv[..., 1] *= 1.0 - np.clip(depth, 0.0, 1.0)
    hsv[..., 2] = 1.0
    intensity = np.asarray(intensity, np.float64)
    return np.concatenate([hsv_to_rgb(hsv) * intensity[..., None], intensity[..., None]], axis=-1)


def classified_segment(classify, transparency, s, length_over_unit, model="emission_absorption", lit=None):
    """Premultiplied RGBA (..., 4) of segments with field value ``s`` (GLSL
    ``classifiedSegment``; ``sampleSegment`` with ``lit``, a function of (s, rgba,
    transparency) giving the samples' (rgba with their terms, transparency, extinction
    scale): ``shading.RayLighting.samples``)."""
    rgba, clear = classify(s), transparency(s)
    if lit is not None:
        rgba, clear, scale = lit(s, rgba, clear)
        length_over_unit = length_over_unit * scale
    return segment_of(rgba, clear, length_over_unit, model)


def composite_front_to_back(color_acc, alpha_acc, rgb, alpha):
    """One over-operator step on associated colour (GLSL ``compositeFrontToBack``):
    returns the new (colour, accumulated opacity)."""
    weight = (1 - alpha_acc) * alpha
    return color_acc + weight[..., None] * rgb, alpha_acc + weight


def blend_over(dst, src, target="rgba32f"):
    """Fixed-function blending ``ONE, ONE_MINUS_SRC_ALPHA`` of premultiplied ``src``
    (..., 4) onto ``dst`` drawn behind it, as a render target of format ``target`` stores
    it (the slicing techniques' twin of GL blending). A float32 target is modelled in
    float64; lower-precision targets round the fragment's output and the blended result
    to their format each time, which is where slicing's banding comes from."""
    if target == "rgba32f":
        return src + (1 - src[..., 3:4]) * dst
    src = round_to_target(src, target)
    return round_to_target(src + (1 - src[..., 3:4]) * dst, target)


def blend_under(dst, src, target="rgba32f"):
    """Fixed-function blending ``ONE_MINUS_DST_ALPHA, ONE`` of premultiplied ``src``
    (..., 4) onto ``dst`` drawn in front of it (front to back: the over operator with
    the new fragment behind), rounded to the target's format as ``blend_over`` does."""
    if target == "rgba32f":
        return dst + (1 - dst[..., 3:4]) * src
    src = round_to_target(src, target)
    return round_to_target(dst + (1 - dst[..., 3:4]) * src, target)


def plane_inside(k, count, t, t0, t1):
    """Whether plane ``k`` of ``count`` (met at ray distances ``t``) exists and meets the
    rays inside the box [t0, t1], in front of their start (GLSL ``sliceInside``)."""
    t = np.asarray(t, np.float64)
    if k < 0 or k >= count:
        return np.zeros(t.shape, bool)
    return (t > 0) & (t >= t0) & (t <= t1)


def slab_segment(k, count, t, t_near, t_far, t0, t1):
    """The piece [a, b] of each ray that plane ``k`` (met at ``t``) stands for: from
    halfway to plane k + 1 (met at ``t_near``) to halfway to plane k - 1 (``t_far``), or
    to the box's entry ``t0`` or exit ``t1`` where that neighbour does not meet the ray
    inside it (GLSL ``slabSegment``)."""
    a = np.where(plane_inside(k + 1, count, t_near, t0, t1), 0.5 * (t_near + t), t0)
    b = np.where(plane_inside(k - 1, count, t_far, t0, t1), 0.5 * (t + t_far), t1)
    return a, b


MAX_CHORD_SEGMENTS = 4096  # as shaders/common/slice_gap.glsl


def chord_color(segment, a, b, max_step):
    """Premultiplied RGBA of whole chords [a, b] in equal sub-segments of at most
    ``max_step``, front to back (GLSL ``chordColor``, the slicing techniques' gap
    fragments). ``segment(rows, a, b)`` gives the colours of segments [a, b] of the rays
    ``rows`` (indices into ``a`` and ``b``)."""
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    n = np.clip(np.ceil((b - a) / max_step), 1, MAX_CHORD_SEGMENTS).astype(np.int64)
    h = (b - a) / n
    acc = np.zeros((len(a), 4))
    for i in range(int(n.max(initial=0))):
        rows = np.nonzero(i < n)[0]
        start = a[rows] + i * h[rows]
        end = np.where(i == n[rows] - 1, b[rows], a[rows] + (i + 1) * h[rows])
        acc[rows] = blend_over(segment(rows, start, end), acc[rows])
    return acc


def segment_colors(plan, sample, valid, a, b, lut_exact=False, light=None):
    """Premultiplied RGBA of the segments [a, b] of the rays: a midpoint sample with
    opacity corrected for the length, or the pre-integrated table. ``sample(t)`` and
    ``valid(t)`` (None without masking) evaluate the field and the masked-cell test at
    ray distances ``t``; ``light`` (a ``shading.RayLighting`` of the same rays, None when
    unlit) lights them at their midpoints."""
    tm = 0.5 * (a + b)
    if plan.preint is not None:
        out = plan.preint.segment(sample(a), sample(b), b - a)
        if light is not None:
            out = light.segments(out, tm)
    else:
        lit = None if light is None else (lambda *sample: light.samples(*sample, tm))
        out = classified_segment(*classifier(plan, lut_exact), sample(tm), (b - a) / plan.scene.tf.unit_distance,
                                 plan.scene.optical_model, lit)
    if valid is not None:
        out[~valid(tm)] = 0
    return out


def gap_pass(acc, gap, rays, plan, max_step, lut_exact=False):
    """The slicing techniques' gap pass (GLSL ``slice_gap.glsl`` and its callers): the
    rays where ``gap`` is set get their whole chord, in pieces of at most ``max_step``,
    blended into ``acc`` as the target stores it. ``rays`` is ``box_rays(scene)``."""
    o, d, t0, t1 = rays
    rows = np.nonzero(gap)[0]
    if rows.size == 0:
        return
    from .shading import ray_lighting
    volume = plan.scene.volume
    values = volume.values(np.float64)
    lo, _ = volume.bounds

    def segment(sub, a, b):
        oo, dd = o[rows[sub]], d[rows[sub]]
        light = ray_lighting(plan.scene, values, oo, dd)

        def sample(tt):
            return trilinear(values, (oo + tt[:, None] * dd) / volume.spacing)

        def valid(tt):
            return cell_is_valid(volume, world_to_index(volume, oo + tt[:, None] * dd + lo))
        return segment_colors(plan, sample, valid if volume.has_nonfinite else None, a, b, lut_exact, light)

    src = chord_color(segment, t0[rows], t1[rows], max_step)
    drawn = np.any(src != 0, axis=1)           # GL discards all-zero fragments
    acc[rows[drawn]] = blend_over(acc[rows[drawn]], src[drawn], plan.target)


def surface_rays(scene, t1, target="rgba32f"):
    """The slicing techniques' opaque geometry (GLSL ``GEOMETRY`` in slice2d.frag and
    slice3d.frag, and ``geometry/surface_behind.frag``): (the target's content before the
    first slice, (n, 4): each ray's first surface's lit colour with opacity 1, 0 where no
    surface; the exits ``t1`` ended at the surface; the hits t, inf where none). The hit
    is the exact image's own (``exact_geometry.surface_hits``). Without geometry: zeros,
    ``t1`` as it is and no hits."""
    n = len(t1)
    if not scene.geometry:
        return np.zeros((n, 4)), t1, np.full(n, np.inf)
    from .exact_geometry import surface_hits
    t_hit, color = surface_hits(scene)
    hit = np.isfinite(t_hit)
    acc = np.zeros((n, 4))
    acc[hit, :3] = color[hit]
    acc[hit, 3] = 1.0
    return round_to_target(acc, target), np.minimum(t1, t_hit), t_hit


def round_to_target(x, target):
    """What a render target of format ``target`` stores for the float values ``x``.

    unorm8: clamp to [0, 1], round to the nearest multiple of 1/255. float16: llvmpipe
    converts by truncation toward zero (not to nearest), so this does the same."""
    x = np.asarray(x, np.float64)
    if target == "rgba8":
        return np.round(np.clip(x, 0, 1) * 255) / 255
    if target == "rgba16f":
        h = x.astype(np.float32).astype(np.float16)
        over = np.abs(h.astype(np.float64)) > np.abs(x.astype(np.float32).astype(np.float64))
        h = np.where(over, np.nextafter(h, np.float16(0)), h)
        return h.astype(np.float64)
    return x
