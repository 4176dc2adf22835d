"""NumPy reference of 2D texture slicing: the same stack, slice order, per-fragment slabs
and blending as ``shaders/slice2d/slice2d.frag``, in float64, then its gap pass. With
opaque geometry each ray ends at the exact image's own first hit (``surface_rays``): a
slice point behind it is no slice, and the surface's colour is drawn first."""

from __future__ import annotations

import numpy as np

from ..techniques.slice2d import across_stack
from .common import blend_over, box_rays, surface_rays, gap_pass, classified_segment, classifier
from ..model.field import cell_is_valid, trilinear, world_to_index
from .shading import ray_lighting


def render_plan(plan, lut_exact=False):
    scene = plan.scene
    volume, cam = scene.volume, scene.camera
    H, W = scene.height, scene.width
    values = volume.values(np.float64)
    lo, _ = volume.bounds
    extent = volume.extent
    w, (u, v) = plan.axis, plan.other_axes
    o, d, t0, t1 = box_rays(scene)
    acc, t1, t_hit = surface_rays(scene, t1, plan.target)
    cos_theta = d @ cam.forward
    ahead = np.where(d[:, w] > 0, 1, -1)
    moving = d[:, w] != 0
    classify, transparency = classifier(plan, lut_exact)

    def slice_t(j):
        with np.errstate(divide="ignore", invalid="ignore"):
            return (j * plan.slice_distance - o[:, w]) / d[:, w]

    # a ray parallel to a face lies in the closed box where its origin does, decided in
    # world coordinates (as box_rays does: the subtraction may round it off the face)
    world = cam.rays(W, H)[0].reshape(-1, 3)
    in_world = (world >= volume.bounds[0]) & (world <= volume.bounds[1])

    def within(p, axis):
        return np.where(d[:, axis] == 0, in_world[:, axis], (p[:, axis] >= 0) & (p[:, axis] <= extent[axis]))

    planes, crop = scene.clip_in_box()

    def clip_keeps(j, p):
        """GLSL clipKeeps: slice j's points p kept by the plan's slice range along the
        axis, the crop box across it and the planes not parallel to the slices."""
        first, last = plan.kept_slices
        ok = (j >= first) & (j <= last)
        if crop is not None:
            ok &= (p[:, u] >= crop[0][u]) & (p[:, u] <= crop[1][u]) & (p[:, v] >= crop[0][v]) & (p[:, v] <= crop[1][v])
        for normal, offset in planes:
            if not across_stack(normal, w):
                ok &= p @ normal - offset >= 0
        return ok

    def inside(j, t):
        p = o + t[:, None] * d
        with np.errstate(invalid="ignore"):
            ok = (j >= 0) & (j < plan.count) & (t * cos_theta >= plan.min_depth) & moving
            if scene.clips:   # the point on the slice's own plane must be kept
                q = p.copy()
                q[:, w] = j * plan.slice_distance
                ok &= clip_keeps(j, q)
            ok &= within(p, u) & within(p, v)
            if scene.geometry:    # GLSL: t > t_hit is behind the pixel's surface
                ok &= ~(t > t_hit)
        return ok

    def sample(j, t):
        idx = (o + t[:, None] * d) / volume.spacing
        idx[:, w] = j / (plan.interpolate + 1)
        return trilinear(values, idx)

    for j in plan.order:  # far to near
        j_all = np.full(len(o), j)
        t = slice_t(j_all)
        here = inside(j_all, t)
        if volume.has_nonfinite:
            p = o + np.where(here, t, 0)[:, None] * d
            p[:, w] = j * plan.slice_distance
            here &= cell_is_valid(volume, world_to_index(volume, p + lo))
        rows = np.nonzero(here)[0]
        if rows.size == 0:
            continue
        j_near, j_far = j - ahead, j + ahead
        t_near, t_far = slice_t(j_near), slice_t(j_far)
        near_in, far_in = inside(j_near, t_near)[rows], inside(j_far, t_far)[rows]
        t_near, t_far, tj, r0, r1 = t_near[rows], t_far[rows], t[rows], t0[rows], t1[rows]
        s = sample(j_all, t)[rows]
        oo, dd = o[rows], d[rows]

        def sample_between(tt):
            return trilinear(values, (oo + tt[:, None] * dd) / volume.spacing)
        lighting = ray_lighting(scene, values, oo, dd)
        light = (lambda seg, t: seg) if lighting is None else lighting.segments   # noqa: E731

        if plan.preint is None:
            a = np.where(near_in, 0.5 * (t_near + tj), r0)
            b = np.where(far_in, 0.5 * (tj + t_far), r1)
            partial = ~(near_in & far_in)
            s = np.where(partial, sample_between(0.5 * (a + b)), s)
            # lit where the sample was taken: the slice point, or the partial slab's midpoint
            t_sample = np.where(partial, 0.5 * (a + b), tj)
            lit = None if lighting is None else (lambda *sample: lighting.samples(*sample, t_sample))
            src = classified_segment(classify, transparency, s, (b - a) / scene.tf.unit_distance,
                                     scene.optical_model, lit)
        else:
            t_far_all = np.where(here, slice_t(j_far), 0)
            s_back = np.where(far_in, sample(j_far, t_far_all)[rows], sample_between(r1))
            t_back = np.where(far_in, t_far, r1)
            back = light(plan.preint.segment(s, s_back, np.maximum(t_back - tj, 0)), 0.5 * (tj + t_back))
            front = light(plan.preint.segment(sample_between(r0), s, np.maximum(tj - r0, 0)), 0.5 * (r0 + tj))
            src = np.where(near_in[:, None], back, blend_over(back, front))
        drawn = np.any(src != 0, axis=1)       # GL discards all-zero fragments
        acc[rows[drawn]] = blend_over(acc[rows[drawn]], src[drawn], plan.target)

    # the gap pass: rays that meet no slice inside the box get their whole chord
    gap = t1 > t0
    wa = (o[:, w] + np.where(gap, t0, 0) * d[:, w]) / plan.slice_distance
    wb = (o[:, w] + np.where(gap, t1, 0) * d[:, w]) / plan.slice_distance
    j_lo = np.floor(np.minimum(wa, wb)).astype(np.int64)
    j_hi = np.ceil(np.maximum(wa, wb)).astype(np.int64)
    gap &= j_hi - j_lo <= 3
    for shift in range(5):
        j = j_lo + shift
        gap &= ~((j <= j_hi) & inside(j, slice_t(j)))
    gap_pass(acc, gap, (o, d, t0, t1), plan, plan.slice_distance, lut_exact)
    return acc.reshape(H, W, 4)
