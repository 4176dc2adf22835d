"""NumPy reference of the ray caster: the same plan (rays, segments, jitter table, lookup
table, early termination) as ``shaders/raycast/raycast.frag``, in float64.

Opaque geometry: each ray's first surface hit is the exact image's own float64 test
(``exact_geometry.surface_hits``); the ray ends there and the surface's lit colour goes
behind what it gathered, as the shader does with the hit its geometry pass rasterised.

Empty-space skipping is not repeated here: it only leaves out segments whose opacity is
exactly zero, so the image is the same without it (a GL test checks that claim).
"""

from __future__ import annotations

import numpy as np

from .common import blend_under, box_rays, classified_segment, classifier, sabella_color
from .exact_geometry import surface_behind, surface_hits
from ..model.field import cell_is_valid, trilinear, world_to_index
from .shading import RayLighting, sample_terms, scene_lights, shade_blinn_phong
from ..model.field import depth_range, gradient, gradient_epsilon

ISO_BISECTION_STEPS = 16  # as ISO_BISECTION_STEPS in shaders/common/isosurface.glsl


def _jitter_per_pixel(plan, height, width):
    """The jitter table as the shader reads it: texel (x, y) = (column, row from the
    bottom) modulo the table size."""
    if plan.jitter is None:
        return np.zeros((height, width))
    size_y, size_x = plan.jitter.shape
    rows_from_bottom = (height - 1 - np.arange(height)) % size_y
    cols = np.arange(width) % size_x
    return plan.jitter[rows_from_bottom[:, None], cols[None, :]].astype(np.float64)


def refine_iso_bisection(sample, ta, tb, iso, steps=ISO_BISECTION_STEPS):
    """Twin of ``refineIsoBisection``: ``sample(t)`` gives field values at ray distances."""
    above_a = sample(ta) >= iso
    for _ in range(steps):
        tm = 0.5 * (ta + tb)
        above_m = sample(tm) >= iso
        ta = np.where(above_m == above_a, tm, ta)
        tb = np.where(above_m == above_a, tb, tm)
    return 0.5 * (ta + tb)


def _refined_segments(plan, s_front, s_back, a, length, midpoints, sample, light=None):
    """Pre-integrated segments with refinement (GLSL: raycast.frag, REFINE): those whose
    reachable values touch the TF's detail are cut at ``plan.refine - 1`` even points and
    at every cell face they cross, each part sampled, read from the fine table and lit at
    its own midpoint, composited front to back; the others are lit whole at theirs.
    ``sample(t, rows)`` samples the rows' rays at ``t``; ``light`` is the rows'
    RayLighting, or None."""
    from ..techniques.raycast import block_of, touches_detail
    volume = plan.scene.volume
    bound = plan.reach[block_of(volume, midpoints, plan.reach.shape, plan.reach_block)].astype(np.float64)
    mid = 0.5 * (s_front + s_back)
    reach = 0.5 * np.maximum(bound * length, np.abs(s_back - s_front))
    split = touches_detail(plan.detail, mid - reach, mid + reach)
    out = plan.preint.segment(s_front, s_back, length)
    if light is not None:
        out = light.segments(out, a + 0.5 * length)
    rows = np.flatnonzero(split)
    if rows.size == 0:
        return out
    a_r, len_r = a[rows], length[rows]
    if light is not None:
        light = RayLighting(light.terms, light.origins[rows], light.dirs[rows])
    b_r = a_r + len_r
    if plan.defines.get("REACH_WALK"):
        out[rows] = _reach_pieces(plan, s_front[rows], s_back[rows], a_r, b_r, bound[rows], sample, rows, light)
        return out
    cuts = [a_r[:, None] + len_r[:, None] * np.arange(1, plan.refine)[None, :] / plan.refine]
    origins, dirs = sample.rays(rows)
    spacing = np.asarray(volume.spacing, np.float64)
    for axis in range(3):
        o_, d_ = origins[:, axis], dirs[:, axis]
        n_faces = int(np.ceil(plan.step / spacing[axis])) + 1
        with np.errstate(divide="ignore", invalid="ignore"):
            index_a = (o_ + a_r * d_) / spacing[axis]
            first = np.where(d_ < 0, np.ceil(index_a) - 1, np.floor(index_a) + 1)
            faces = first[:, None] + np.sign(d_)[:, None] * np.arange(n_faces)[None, :]
            t = (faces * spacing[axis] - o_[:, None]) / d_[:, None]
        cuts.append(np.where(d_[:, None] != 0, t, np.inf))
    cuts = np.concatenate(cuts, axis=1)
    cuts = np.where((cuts > a_r[:, None]) & (cuts < b_r[:, None]), cuts, np.inf)
    cuts = np.sort(cuts, axis=1)
    t_prev = a_r.copy()
    s_prev = s_front[rows].copy()
    acc = np.zeros((rows.size, 4))
    for c in range(cuts.shape[1] + 1):
        t_next = cuts[:, c] if c < cuts.shape[1] else b_r
        inner = np.isfinite(t_next)
        if not inner.any():
            t_next = b_r
        t_next = np.where(inner, t_next, b_r)
        s_next = s_back[rows].copy()
        live = np.flatnonzero(t_next < b_r)
        if live.size:
            s_next[live] = sample(t_next[live], rows[live])
        piece = plan.preint_fine.segment(s_prev, s_next, t_next - t_prev)
        if light is not None:
            piece = light.segments(piece, 0.5 * (t_prev + t_next))
        acc = blend_under(acc, piece)
        t_prev, s_prev = t_next, s_next
        if not inner.any():
            break
    out[rows] = acc
    return out


def _reach_pieces(plan, s_front, s_back, a, b, bound, sample, rows, light):
    """Twin of the walk by reach (``shaders/common/reach_walk.glsl``, REACH_WALK): from
    each piece's front value, a piece as long as the field cannot reach the TF's detail
    (value distance / gradient bound), at least ``(b - a) / refine``, cut at the next
    cell face only where shorter; pieces read from the fine table, lit at their
    midpoints and composited front to back. Returns (n, 4)."""
    volume = plan.scene.volume
    spacing = np.asarray(volume.spacing, np.float64)
    origins, dirs = sample.rays(rows)
    part = (b - a) / plan.refine
    lo, hi = plan.detail[:, 0], plan.detail[:, 1]
    acc = np.zeros((len(a), 4))
    t, s = a.copy(), s_front.copy()
    live = np.flatnonzero(t < b)
    while live.size:
        distance = np.maximum(np.maximum(lo[None, :] - s[live, None], s[live, None] - hi[None, :]), 0.0).min(axis=1) \
            if len(lo) else np.full(live.size, np.inf)
        with np.errstate(divide="ignore", invalid="ignore"):
            free = distance / np.maximum(bound[live], 1e-30)
            index = (origins[live] + t[live, None] * dirs[live]) / spacing
            face = np.where(dirs[live] < 0, np.ceil(index - 1e-4) - 1, np.floor(index + 1e-4) + 1)
            t_face = np.where(dirs[live] != 0, (face * spacing - origins[live]) / dirs[live], np.inf).min(axis=1)
        t_next = np.minimum(t[live] + np.maximum(free, part[live]), b[live])
        t_next = np.where(free < part[live], np.minimum(t_next, t_face), t_next)
        done = t_next >= b[live]
        s_next = s_back[live].copy()
        if (~done).any():
            s_next[~done] = sample(t_next[~done], rows[live[~done]])
        piece = plan.preint_fine.segment(s[live], s_next, t_next - t[live])
        if light is not None:
            piece = RayLighting(light.terms, light.origins[live], light.dirs[live]).segments(
                piece, 0.5 * (t[live] + t_next))
        acc[live] = blend_under(acc[live], piece)
        t[live], s[live] = t_next, s_next
        live = live[~done]
    return acc


class _RowSampler:
    """``sample(t, sub)``: the field at ``t`` on the rays ``rows[sub]``; ``rays(sub)``:
    their box-relative origins and directions."""

    def __init__(self, sample, origins, dirs, rows):
        self.sample, self.origins, self.dirs, self.rows = sample, origins, dirs, rows

    def __call__(self, t, sub):
        return self.sample(t, self.rows[sub])

    def rays(self, sub):
        return self.origins[self.rows[sub]], self.dirs[self.rows[sub]]


def render_plan(plan, lut_exact=False):
    """The reference image of a ray-casting plan, (H, W, 4) float64.

    ``lut_exact=True`` classifies with the exact piecewise-linear transfer function
    instead of the lookup table (the ideal float64 midpoint marcher)."""
    from ..techniques.raycast_layers import LayersPlan
    if isinstance(plan, LayersPlan):      # several volumes: their own twin
        from .raycast_layers import render_plan as render_layers
        return render_layers(plan, lut_exact=lut_exact)
    if getattr(plan, "crossings", None) is not None:      # refine_walk="crossings": its own twin
        from .crossing_walk import render_plan as render_crossings
        return render_crossings(plan)
    scene = plan.scene
    volume, tf = scene.volume, scene.tf
    H, W = scene.height, scene.width
    values = volume.values(np.float64)
    lo, _ = volume.bounds
    classify, transparency = classifier(plan, lut_exact)
    origins, dirs, t0, t1 = box_rays(scene)
    if scene.geometry:     # the ray ends at its first surface (GLSL: GEOMETRY; the exact image's own hit)
        t_surface, surface_color = surface_hits(scene)
        t1 = np.minimum(t1, t_surface)
    jitter = _jitter_per_pixel(plan, H, W).reshape(-1)
    n = origins.shape[0]
    out = np.zeros((n, 4))
    hit = np.nonzero(t1 > t0)[0]
    o, d, t0, t1, jitter = origins[hit], dirs[hit], t0[hit], t1[hit], jitter[hit]
    step, inv_unit = plan.step, 1.0 / tf.unit_distance

    def sample(t, rows=slice(None)):
        p = o[rows] + np.asarray(t)[..., None] * d[rows]
        return trilinear(values, p / volume.spacing)

    def valid(t, rows=slice(None)):
        p = o[rows] + t[..., None] * d[rows]
        return cell_is_valid(volume, world_to_index(volume, p + lo))

    m = len(hit)
    mode = scene.mode
    terms = sample_terms(scene, values)       # lighting and illustration of composite samples
    sabella = mode == "composite" and scene.optical_model == "sabella"
    t_peak = np.zeros(m)
    epsilon = gradient_epsilon(volume)
    lights = scene_lights(scene)

    color = np.zeros((m, 3))
    alpha_acc = np.zeros(m)
    s_best = np.full(m, -np.inf if mode == "mip" or sabella else np.inf)
    s_sum = np.zeros(m)
    len_sum = np.zeros(m)
    alive = np.ones(m, bool)
    have_prev = np.zeros(m, bool)
    above_prev = np.zeros(m, bool)
    t_prev = t0.copy()
    t_hit = np.full(m, -1.0)
    s_front = np.zeros(m)          # pre-integration: the field at each ray's segment start
    have_front = np.zeros(m, bool)

    step_rows = None if lut_exact else plan.step_rows      # GLSL lookupStepTF
    # the full segments, k = 0 .. n_full - 1 (the shader's count; the rest are partial)
    n_full = np.maximum(np.floor((t1 - t0) / step - jitter), 0)
    for k in range(-1, plan.max_segments):
        a = np.maximum(t0 + (jitter + k) * step, t0)
        b = np.minimum(t0 + (jitter + k + 1) * step, t1)
        alive &= a < t1
        if not alive.any():
            break
        active = alive & (b - a > 0)
        if volume.has_nonfinite:
            ok = valid(0.5 * (a + b))
            have_front[active & ~ok] = False
            active &= ok
        rows = np.nonzero(active)[0]
        if rows.size == 0:
            continue
        a, b = a[rows], b[rows]
        full = (k >= 0) & (k < n_full[rows])
        length = b - a
        tm = 0.5 * (a + b)
        if mode == "composite" and plan.preint is not None:
            start = rows[~have_front[rows]]
            s_front[start] = sample(a[~have_front[rows]], start)
            s_back = sample(b, rows)
            light = None if terms is None else RayLighting(terms, o[rows], d[rows])
            if plan.refine > 1:
                segment = _refined_segments(plan, s_front[rows], s_back, a, length, o[rows] + tm[:, None] * d[rows],
                                            _RowSampler(sample, o, d, rows), light)
            else:
                segment = plan.preint.segment(s_front[rows], s_back, length)
                if light is not None:
                    segment = light.segments(segment, tm)
            s_front[rows] = s_back
            have_front[rows] = True
            transmittance = 1 - alpha_acc[rows]  # the over operator on an associated segment
            color[rows] += transmittance[:, None] * segment[:, :3]
            alpha_acc[rows] += transmittance * segment[:, 3]
            stop = alpha_acc[rows] >= 1
            if plan.ert_transmittance > 0:
                stop |= 1 - alpha_acc[rows] < plan.ert_transmittance
            alive[rows[stop]] = False
            continue
        s = sample(tm, rows)
        if mode == "composite":
            light = None
            if terms is not None:
                light = RayLighting(terms, o[rows], d[rows])
            piece = classified_segment(classify, transparency, s, length * inv_unit, scene.optical_model,
                                       None if light is None else (lambda *sample: light.samples(*sample, tm)))
            if step_rows is not None and full.any():    # full segments: the step table
                table = plan.lut.interpolate(step_rows, s[full])
                if light is not None:
                    table = RayLighting(terms, o[rows[full]], d[rows[full]]).segments(table, tm[full])
                piece[full] = table
            transmittance = 1 - alpha_acc[rows]
            color[rows] += transmittance[:, None] * piece[:, :3]
            alpha_acc[rows] += transmittance * piece[:, 3]
            if sabella:   # the peak over every sample (the first one met on ties); no early end
                higher = s > s_best[rows]
                s_best[rows[higher]] = s[higher]
                t_peak[rows[higher]] = tm[higher]
                continue
            stop = alpha_acc[rows] >= 1
            if plan.ert_transmittance > 0:
                stop |= 1 - alpha_acc[rows] < plan.ert_transmittance
            alive[rows[stop]] = False
        elif mode == "mip":
            s_best[rows] = np.maximum(s_best[rows], s)
        elif mode == "minip":
            s_best[rows] = np.minimum(s_best[rows], s)
        elif mode == "average":
            s_sum[rows] += s * length
            len_sum[rows] += length
        else:  # isosurface
            first = ~have_prev[rows]
            if first.any():
                r = rows[first]
                above_prev[r] = sample(a[first], r) >= scene.iso_value
                t_prev[r] = a[first]
                have_prev[r] = True
            above = s >= scene.iso_value
            crossed = above != above_prev[rows]
            if crossed.any():
                r = rows[crossed]
                t_hit[r] = refine_iso_bisection(lambda t: sample(t, r), t_prev[r], tm[crossed], scene.iso_value)
                alive[r] = False
            t_prev[rows[~crossed]] = tm[~crossed]

    result = np.zeros((m, 4))
    if sabella:
        ok = np.isfinite(s_best) & (alpha_acc > 0)
        cam = scene.camera
        near, far = depth_range(scene)
        depth = ((o + t_peak[:, None] * d + lo - cam.eye) @ cam.forward - near) / (far - near)
        peak = classify(np.where(ok, s_best, 0.0))[:, :3]
        result[ok] = sabella_color(peak[ok], alpha_acc[ok], depth[ok])
    elif mode == "composite":
        result[:, :3] = color
        result[:, 3] = alpha_acc
    elif mode in ("mip", "minip", "average"):
        if mode == "average":
            ok = len_sum > 0
            s_final = np.where(ok, s_sum / np.where(ok, len_sum, 1), 0)
        else:
            ok = np.isfinite(s_best)
            s_final = np.where(ok, s_best, 0)
        rgba = classify(s_final)
        result[:, :3] = rgba[:, :3] * rgba[:, 3:4]
        result[:, 3] = rgba[:, 3]
        result[~ok] = 0
    else:
        ok = t_hit >= 0
        if ok.any():
            p = o[ok] + t_hit[ok, None] * d[ok] + lo
            rgb = np.broadcast_to(classify(np.array([scene.iso_value]))[0, :3], (ok.sum(), 3))
            g = gradient(volume, values, p)
            result[ok, :3] = shade_blinn_phong(rgb, g, d[ok], scene.phong, epsilon, lights)
            result[ok, 3] = 1.0
    out[hit] = result
    if scene.geometry:     # the surface behind what the ray gathered
        out = surface_behind(out, t_surface, surface_color)
    return out.reshape(H, W, 4)
