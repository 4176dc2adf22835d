"""Would per-brick adaptive steps pay? A float64 study, before any shader is written.

Each ray is marched on a lattice of the finest step h; a brick of the volume (the empty-
space skipping bricks) has a level m, and a segment starting in it is 2^m h long (kept on
the lattice: a segment starts at a multiple of its own length, and ends by the ray's last
full step), so every segment is a full step of its level and a step table per level would
keep the opacity correction exact. Levels come from the transfer function's detail over
the brick's value range times the field's variation in the brick, then the finest level
of the 26 neighbours is taken (a long segment may reach into the next brick):

- ``slope``: max |e'(s)| over the brick's range times max |grad f| in the brick, where
  e = (c tau, tau) per unit length: how fast the classified extinction and emission
  change along a ray;
- ``curvature``: the midpoint rule's own error terms: sum over the range of |delta e'|
  (the TF's kinks) times max |grad f|, plus the brick's length times max |e'| times the
  field's largest second derivative.

A brick takes the coarsest level m <= 3 with W (2^m h)^2 <= threshold. The cost is the
number of samples in non-empty bricks (what the GL ray caster pays with its empty-space
skipping on); the error is the RMSE against ``reference.exact`` at 128x128; uniform
steps are marched the same way. Samples are classified with the exact TF and exact
opacity correction, so only the sampling differs.

    python apps/adaptive_study.py [--out docs/notes/adaptive_study.md]
"""

import argparse
import math
import os
import sys

import numpy as np
from scipy.ndimage import maximum_filter, minimum_filter

import dvr_gl
from dvr_gl import metrics, reference
from dvr_gl.formats import atomic_write
from dvr_gl.util.progress import Progress
from dvr_gl.reference.common import box_rays
from dvr_gl.model.field import trilinear
from dvr_gl.techniques.raycast import BRICK, _block_reduce, brick_occupancy, brick_value_ranges
from dvr_gl.model.transfer import LookupTable

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from tolerance_vs_vtk import scenes  # noqa: E402  (the same four scenes)

MAX_LEVEL = 3
UNIFORM = (2.0, 1.0, 0.5, 0.25, 0.125)          # voxels
ADAPTIVE = ((0.25, 0.1), (0.25, 0.03), (0.125, 0.1), (0.125, 0.03))   # (finest step, threshold share)


def _per_brick_max(a):
    a = maximum_filter(a, size=3, mode="nearest")      # as brick_value_ranges: one sample of margin
    for axis in range(3):
        a = _block_reduce(a, axis, np.max)
    return a


def tf_detail(tf, lo, hi, n=4096):
    """Over a fine grid of values: |e'| per interval and |delta e'| per inner point, for
    e = (c tau, tau) per unit length (the largest component)."""
    s = np.linspace(lo, hi, n)
    alpha = np.clip(tf.opacity(s), 0.0, 1.0 - 1e-12)
    tau = -np.log1p(-alpha) / tf.unit_distance
    e = np.concatenate([tf.color(s) * tau[:, None], tau[:, None]], axis=1)
    ds = s[1] - s[0]
    slope = np.abs(np.diff(e, axis=0)).max(axis=1) / ds
    kinks = np.abs(np.diff(e, 2, axis=0)).max(axis=1) / ds
    return s, slope, kinks


def brick_weights(volume, tf, criterion):
    v = volume.values(np.float64)
    spacing = np.array(volume.spacing)[::-1]                    # z, y, x
    grads = np.gradient(v, *spacing)
    grad_max = _per_brick_max(np.sqrt(sum(g ** 2 for g in grads)))
    lo, hi = brick_value_ranges(volume)
    s, slope, kinks = tf_detail(tf, *volume.data_range)
    i0 = np.clip(np.searchsorted(s, lo) - 1, 0, len(slope) - 1).ravel()
    i1 = np.clip(np.searchsorted(s, hi), 0, len(slope) - 1).ravel()
    slope_max = np.array([slope[a:b + 1].max() for a, b in zip(i0, i1)]).reshape(lo.shape)
    if criterion == "slope":
        return slope_max * grad_max
    hessian = np.max([np.abs(np.gradient(g, spacing[k], axis=k)) for g in grads for k in range(3)], axis=0)
    curvature = _per_brick_max(hessian)        # the largest second derivative, any direction pair
    cum = np.concatenate([[0.0], np.cumsum(kinks * (s[1] - s[0]))])
    kink_sum = (cum[np.minimum(i1, len(cum) - 1)] - cum[i0]).reshape(lo.shape)
    length = BRICK * volume.min_spacing * math.sqrt(3)
    return kink_sum * grad_max + length * slope_max * curvature


def brick_levels(weights, h, threshold):
    levels = np.zeros(weights.shape, np.int64)
    for m in range(1, MAX_LEVEL + 1):
        levels[weights * (2 ** m * h) ** 2 <= threshold] = m
    return minimum_filter(levels, size=3, mode="nearest")


def march(scene, h, occupied, levels=None):
    """(image, samples in occupied bricks): the float64 midpoint marcher on the lattice
    of step h, each segment 2^level h long where ``levels`` is given."""
    volume, tf = scene.volume, scene.tf
    values = volume.values(np.float64)
    spacing = np.array(volume.spacing)
    o, d, t0, t1 = box_rays(scene)
    hit = np.flatnonzero(t1 > t0)
    o, d, t0, t1 = o[hit], d[hit], t0[hit], t1[hit]
    m = len(hit)
    n_full = np.floor((t1 - t0) / h).astype(np.int64)
    i = np.zeros(m, np.int64)
    color, alpha = np.zeros((m, 3)), np.zeros(m)
    alive = np.ones(m, bool)
    samples = 0
    bricks = np.array(occupied.shape)

    def brick_of(p):
        b = np.floor(p / spacing / BRICK).astype(np.int64)[:, ::-1]
        return tuple(np.clip(b, 0, bricks - 1).T)

    def composite(rows, t_mid, length):
        nonlocal samples
        p = o[rows] + t_mid[:, None] * d[rows]
        s = trilinear(values, p / spacing)
        samples += int(occupied[brick_of(p)].sum())
        a = 1.0 - (1.0 - np.clip(tf.opacity(s), 0, 1)) ** (length / tf.unit_distance)
        transmittance = 1.0 - alpha[rows]
        color[rows] += (transmittance * a)[:, None] * tf.color(s)
        alpha[rows] += transmittance * a

    while True:
        rows = np.flatnonzero(alive & (i < n_full))
        if rows.size == 0:
            break
        start = t0[rows] + i[rows] * h
        count = np.ones(rows.size, np.int64)
        if levels is not None:
            count = 1 << levels[brick_of(o[rows] + start[:, None] * d[rows])]
            aligned = np.where(i[rows] == 0, 1 << MAX_LEVEL, i[rows] & -i[rows])
            count = np.minimum(count, aligned)
            left = n_full[rows] - i[rows]
            while (count > left).any():
                count = np.where(count > left, count >> 1, count)
        composite(rows, start + 0.5 * count * h, count * h)
        i[rows] += count
        alive[rows[alpha[rows] >= 1.0 - 1e-3]] = False        # early termination as the GL path
    rows = np.flatnonzero(alive)
    a, b = t0[rows] + n_full[rows] * h, t1[rows]
    keep = b > a
    if keep.any():
        composite(rows[keep], 0.5 * (a[keep] + b[keep]), (b - a)[keep])
    out = np.zeros((scene.height * scene.width, 4))
    out[hit, :3], out[hit, 3] = color, alpha
    return out.reshape(scene.height, scene.width, 4), samples


def uniform_error_at(uniform, samples):
    """The uniform marcher's RMSE at ``samples``, interpolated log-log between its runs."""
    n = np.log([u[1] for u in uniform])
    e = np.log([u[2] for u in uniform])
    order = np.argsort(n)
    n, e = n[order], e[order]
    x = np.log(samples)
    k = int(np.clip(np.searchsorted(n, x) - 1, 0, len(n) - 2))      # the bracketing (or end) pair
    return float(np.exp(e[k] + (e[k + 1] - e[k]) * (x - n[k]) / (n[k + 1] - n[k])))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default=os.path.join(HERE, os.pardir, "docs", "notes", "adaptive_study.md"))
    p.add_argument("--size", type=int, default=128)
    args = p.parse_args(argv)
    sets = scenes()
    progress = Progress(len(sets) * (len(UNIFORM) + 2 * len(ADAPTIVE)))
    lines = ["# Per-brick adaptive steps: a float64 study", "",
             "`python apps/adaptive_study.py` (see its docstring for the marcher and the two criteria). "
             f"RMSE against the exact image at {args.size}x{args.size}; samples counted in non-empty bricks. "
             "'uniform at equal samples' interpolates the uniform runs log-log; a ratio above 1 means the "
             "adaptive run is more accurate than uniform steps costing the same.", "",
             "| scene | run | samples | RMSE | uniform RMSE at equal samples | ratio |", "|---|---|---|---|---|---|"]
    for name, volume, tf, camera in sets:
        scene = dvr_gl.Scene(volume, tf, camera, args.size, args.size)
        exact = reference.exact(scene)
        occupied = brick_occupancy(brick_value_ranges(volume), LookupTable(tf))
        vox = volume.min_spacing
        uniform = []
        for k in UNIFORM:
            progress.begin(f"{name}: uniform {k:g}")
            image, n = march(scene, k * vox, occupied)
            uniform.append((k, n, metrics.rmse(image, exact)))
            lines.append(f"| {name} | uniform {k:g} voxel | {n:,} | {uniform[-1][2]:.2e} | | |")
            progress.advance(f"{name}: uniform {k:g}")
        for criterion in ("slope", "curvature"):
            weights = brick_weights(volume, tf, criterion)
            top = float(weights[occupied].max()) if occupied.any() else 0.0
            for finest, share in ADAPTIVE:
                progress.begin(f"{name}: {criterion} {finest:g}")
                h = finest * vox
                levels = brick_levels(weights, h, share * top * (2 ** MAX_LEVEL * h) ** 2)
                image, n = march(scene, h, occupied, levels)
                err = metrics.rmse(image, exact)
                same = uniform_error_at(uniform, n)
                lines.append(f"| {name} | {criterion}, finest {finest:g}, threshold {share:g} | {n:,} | {err:.2e} | "
                             f"{same:.2e} | {same / err:.2f} |")
                progress.advance(f"{name}: {criterion} {finest:g}")
    text = "\n".join(lines) + "\n"
    atomic_write(os.path.abspath(args.out), text.encode())
    print(text)


if __name__ == "__main__":
    main()
