"""NumPy reference of 3D texture slicing: the same slices, per-fragment segments and
blending order as ``shaders/slice3d/slice3d.frag``, in float64 (per-target rounding of
the blending as ``common.blend_over`` models it). The polygons only decide which pixels
a slice may cover; the shader's per-fragment test decides which it does, so the
reference applies that test to every pixel (and the gap pass's test after the slices).
With clip planes or a crop box the rays' intervals (``box_rays``) are the kept ones; with
opaque geometry they end at the exact image's own first hit (``surface_rays``), and the
surface's lit colour is the target's content before the first slice."""

from __future__ import annotations

import numpy as np

from .common import blend_over, box_rays, surface_rays, gap_pass, plane_inside, segment_colors, slab_segment
from ..model.field import cell_is_valid, trilinear, world_to_index
from .shading import ray_lighting


def render_plan(plan, lut_exact=False):
    scene = plan.scene
    volume, cam = scene.volume, scene.camera
    H, W = scene.height, scene.width
    values = volume.values(np.float64)
    lo, _ = volume.bounds
    o, d, t0, t1 = box_rays(scene)
    acc, t1, _ = surface_rays(scene, t1, plan.target)
    cos_theta = d @ cam.forward

    def slice_t(k):
        depth = plan.far_depth - k * plan.step
        return np.full(len(o), depth) if plan.shells else depth / cos_theta

    def inside(k, t):
        return plane_inside(k, plan.count, t, t0, t1)

    for k in range(plan.count):  # far to near
        t = slice_t(k)
        here = inside(k, t)
        if not here.any():
            continue
        rows = np.nonzero(here)[0]
        t_near, t_far = slice_t(k + 1)[rows], slice_t(k - 1)[rows]
        near_in, far_in = inside(k + 1, slice_t(k + 1))[rows], inside(k - 1, slice_t(k - 1))[rows]
        tk, r0, r1 = t[rows], t0[rows], t1[rows]
        oo, dd = o[rows], d[rows]

        def sample(tt):
            return trilinear(values, (oo + tt[:, None] * dd) / volume.spacing)

        def valid_cells(tt):
            return cell_is_valid(volume, world_to_index(volume, oo + tt[:, None] * dd + lo))
        valid = valid_cells if volume.has_nonfinite else None
        light = ray_lighting(scene, values, oo, dd)

        if plan.preint is None:
            a, b = slab_segment(k, plan.count, tk, t_near, t_far, r0, r1)
            src = segment_colors(plan, sample, valid, a, b, lut_exact, light)
        else:
            src = segment_colors(plan, sample, valid, tk, np.where(far_in, t_far, r1), light=light)
            front = segment_colors(plan, sample, valid, r0, tk, light=light)
            src = np.where(near_in[:, None], src, blend_over(src, front))
        drawn = np.any(src != 0, axis=1)       # GL discards all-zero fragments
        acc[rows[drawn]] = blend_over(acc[rows[drawn]], src[drawn], plan.target)

    gap_rays_pass(acc, plan, (o, d, t0, t1), lut_exact)
    return acc.reshape(H, W, 4)


def gap_rays_pass(acc, plan, rays, lut_exact=False):
    """The gap pass (GLSL slice3d.frag with GAP): the rays that meet no slice inside the
    box get their whole chord, blended into ``acc``. Sheet-buffer splatting's too."""
    o, d, t0, t1 = rays
    cos_theta = d @ plan.scene.camera.forward
    per_t = np.ones(len(o)) if plan.shells else cos_theta
    gap = (t1 > t0) & ((t1 - t0) * per_t <= 2 * plan.step)
    k_far = np.ceil((plan.far_depth - np.where(gap, t1, 0) * per_t) / plan.step).astype(np.int64)
    for shift in range(-1, 3):
        k = k_far + shift
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (plan.far_depth - k * plan.step) / per_t
        gap &= ~((k >= 0) & (k < plan.count) & (t > 0) & (t >= t0) & (t <= t1))
    gap_pass(acc, gap, (o, d, t0, t1), plan, plan.step, lut_exact)
