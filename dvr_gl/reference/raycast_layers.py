"""NumPy twin of ray casting several volumes (``techniques.raycast_layers``,
``shaders/raycast/layers.frag``): the same rays, layer frames, cuts, equal segments per
stretch, lookup tables and label tables, blended the same way, in float64.

Opaque geometry: each ray's first surface is the exact image's own float64 hit
(``exact_geometry.surface_hits``), as in the one-volume twin.

``render_plan(plan, audit={})`` also says which pixels a float32 renderer may
legitimately render differently (``audit["ties"]``): those whose ray has a label sample
within rounding of a half-index plane across which the label changes (where the nearest
sample flips) or a stretch whose length is within rounding of a whole number of steps
(where its segment count changes). Both are choices rounding makes, not errors; the GL
test leaves such pixels to a count. Equal segments between two parallel faces of a label
box put midpoints on half-index planes by construction for some segment counts, so
such ties cluster where rays run from face to opposite face. With
``audit["sample_bound"]``, a function ``(layer index, index coordinates, values,
segment lengths)`` giving a bound on each sample's float32 error, ``audit["bound"]``
receives its sum over each pixel's composited samples (for mip, minip and average: its
largest, summed over the layers).
"""

from __future__ import annotations

import numpy as np

from ..model.clipping import clip_interval
from ..model.field import ray_box, trilinear
from ..model.transfer import LookupTable
from .exact_geometry import surface_behind, surface_hits

U32 = 2.0 ** -24
# How near counts as a tie, in float32 units of the largest magnitude in the computation
# (the coordinates, in index units; or the ray distance, in steps). GL's chain (the frame
# transform, t = a + (k + 1/2) h, the division by the spacing) rounds a few units of it.
TIE_ULPS = 16


def _rays(scene):
    """Every pixel's ray, relative to the scene's own volume's lower corner (flattened)."""
    origins, dirs = scene.camera.rays(scene.width, scene.height)
    lo = np.asarray(scene.volume.bounds[0], np.float64)
    return (origins - lo).reshape(-1, 3), dirs.reshape(-1, 3)


def _extinction(alpha, transparency, unit_distance):
    """(tau, opaque) as GLSL ``extinction``: -log(1 - alpha) / u, log1p up to alpha 0.5 and
    the stored transparency above; opaque where alpha reaches 1."""
    a = np.asarray(alpha, np.float64)
    b = np.asarray(transparency, np.float64)
    opaque = (a >= 1) | (b <= 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        log_t = np.where(a <= 0.5, np.log1p(-np.minimum(a, 0.5)), np.log(np.maximum(b, 1e-300)))
    tau = np.where(opaque | (a <= 0), 0.0, -log_t / unit_distance)
    return tau, opaque


class _Layer:
    """One layer's rays in its own frame and its classification."""

    def __init__(self, layer, frame, table, o, d, lut_exact):
        self.layer, self.table = layer, table
        m, offset = frame
        self.o = o @ m.T + offset
        self.d = d @ m.T
        volume = layer.volume
        self.spacing = np.asarray(volume.spacing, np.float64)
        self.dims = np.asarray(volume.dims, np.int64)
        self.values = volume.values(np.float64)
        self.labels = layer.is_labels
        self.lut_exact = lut_exact
        t0, t1 = ray_box(self.o, self.d, np.zeros(3), np.asarray(volume.extent, np.float64))
        self.hit = t1 > t0
        self.span = np.stack([t0, t1], axis=1)

    def index(self, rows, t):
        return (self.o[rows] + t[:, None] * self.d[rows]) / self.spacing

    def value(self, rows, t):
        """The layer's value at distance t on the rays ``rows``: trilinear, or the nearest label."""
        x = self.index(rows, t)
        if not self.labels:
            return trilinear(self.values, x)
        idx = np.clip(np.floor(x + 0.5).astype(np.int64), 0, self.dims - 1)
        return self.values[idx[:, 2], idx[:, 1], idx[:, 0]]

    def label_ties(self, rows, t):
        """Rows whose label sample lies within rounding of a half-index plane across which
        the label changes (there a float32 position may pick the other sample)."""
        x = self.index(rows, t) + 0.5
        scale = (np.abs(self.o[rows]).max(axis=1)[:, None] + np.abs(t)[:, None]) / self.spacing + np.abs(x)
        near = np.abs(x - np.round(x)) <= TIE_ULPS * U32 * scale
        tie = np.zeros(len(rows), bool)
        base = np.floor(x).astype(np.int64)
        for axis in range(3):
            upper, lower = base.copy(), base.copy()
            upper[:, axis] = np.round(x[:, axis])
            lower[:, axis] = upper[:, axis] - 1
            upper, lower = np.clip(upper, 0, self.dims - 1), np.clip(lower, 0, self.dims - 1)
            a = self.values[upper[:, 2], upper[:, 1], upper[:, 0]]
            b = self.values[lower[:, 2], lower[:, 1], lower[:, 0]]
            tie |= near[:, axis] & (a != b)
        return tie

    def classify(self, s):
        """(straight rgba, transparency) of values s (GLSL ``layerClass``)."""
        if self.labels:
            label = np.floor(s + 0.5).astype(np.int64)
            rgba = self.table.rgba(label)
            clear = np.where((label >= 0) & (label < len(self.table.table)),
                             (1.0 - self.table.table[:, 3]).astype(np.float32)[np.clip(label, 0, len(self.table.table) - 1)],
                             1.0)
            rgba = rgba.astype(np.float32).astype(np.float64)
            return rgba, clear.astype(np.float64)
        if self.lut_exact:
            tf = self.layer.tf
            rgba = np.concatenate([tf.color(s), tf.opacity(s)[..., None]], axis=-1)
            return rgba, 1 - rgba[..., 3]
        lut: LookupTable = self.table
        rgba = lut.lookup(s)
        clear = np.where(rgba[:, 3] > 0.5, lut.lookup_transparency(s), 1 - rgba[:, 3])
        return rgba, clear


def _cuts(layers, t0, t1):
    """(n, 2 L) sorted cuts: each layer's entry and exit clamped to [t0, t1] (t1 for a layer
    the ray misses)."""
    cols = []
    for lay in layers:
        cols.append(np.where(lay.hit, np.clip(lay.span[:, 0], t0, t1), t1))
        cols.append(np.where(lay.hit, np.clip(lay.span[:, 1], t0, t1), t1))
    return np.sort(np.stack(cols, axis=1), axis=1)


def render_plan(plan, lut_exact=False, audit=None):
    """The reference image of a ``raycast_layers.LayersPlan``, (H, W, 4) float64.
    ``lut_exact`` classifies scans with their exact transfer functions (the ideal float64
    marcher); ``audit``, a dict, receives ``"ties"`` (an (H, W) bool array of the pixels
    whose label sample or segment count sits within rounding of a change) and, when it
    holds ``"sample_bound"``, ``"bound"`` (module doc)."""
    from ..techniques.raycast_layers import layer_frames
    scene = plan.scene
    H, W = scene.height, scene.width
    mode, add = scene.mode, scene.blend == "add"
    o, d = _rays(scene)
    n_rays = len(o)
    layers = [_Layer(layer, frame, table, o, d, lut_exact)
              for layer, frame, table in zip(plan.layers, layer_frames(scene), plan.tables)]
    hit_any = np.zeros(n_rays, bool)
    t0 = np.full(n_rays, np.inf)
    t1 = np.full(n_rays, -np.inf)
    for lay in layers:
        t0 = np.where(lay.hit, np.minimum(t0, lay.span[:, 0]), t0)
        t1 = np.where(lay.hit, np.maximum(t1, lay.span[:, 1]), t1)
        hit_any |= lay.hit
    if scene.clips:
        planes, crop = scene.clip_in_box()
        t0, t1 = clip_interval(o, d, t0, t1, planes, crop)
    if scene.geometry:
        t_surface, surface_color = surface_hits(scene)
        t1 = np.minimum(t1, t_surface)
    live = hit_any & (t1 > t0)
    cuts = _cuts(layers, t0, t1)
    tie = np.zeros(n_rays, bool)
    n_layers = len(layers)
    sample_bound = None if audit is None else audit.get("sample_bound")
    bound = np.zeros((n_layers, n_rays))

    color = np.zeros((n_rays, 3))
    alpha = np.zeros(n_rays)
    acc = np.zeros((n_layers, n_rays, 4))
    done = np.zeros((n_layers, n_rays), bool)
    best = np.full((n_layers, n_rays), -np.inf if mode == "mip" else (np.inf if mode == "minip" else 0.0))
    len_sum = np.zeros((n_layers, n_rays))
    ended = np.zeros(n_rays, bool)
    budget = np.full(n_rays, plan.max_segments)
    ert = plan.ert_transmittance

    for j in range(cuts.shape[1] - 1):
        a, b = cuts[:, j], cuts[:, j + 1]
        middle = 0.5 * (a + b)
        held = np.zeros(n_rays, bool)
        for lay in layers:
            held |= lay.hit & (lay.span[:, 0] <= middle) & (middle <= lay.span[:, 1])
        go = live & (b > a) & held & ~ended
        rows = np.flatnonzero(go)
        if rows.size == 0:
            continue
        length = b[rows] - a[rows]
        ratio = length / plan.step
        n = np.ceil(ratio).astype(np.int64)
        near = np.abs(ratio - np.round(ratio)) <= TIE_ULPS * U32 * (np.abs(b[rows]) / plan.step + 1)
        tie[rows[near & (np.round(ratio) >= 1)]] = True
        h = length / n
        for k in range(int(n.max())):
            sel = (k < n) & ~ended[rows] & (budget[rows] > 0)
            r = rows[sel]
            if r.size == 0:
                break
            budget[r] -= 1
            hk = h[sel]
            t = a[r] + (k + 0.5) * hk
            samples = []
            for i, lay in enumerate(layers):
                inside = lay.hit[r] & (lay.span[r, 0] <= t) & (t <= lay.span[r, 1])
                ri = np.flatnonzero(inside)
                s = np.zeros(r.size)
                if ri.size:
                    s[ri] = lay.value(r[ri], t[ri])
                    if lay.labels and audit is not None:
                        tie[r[ri[lay.label_ties(r[ri], t[ri])]]] = True
                    if sample_bound is not None:
                        e = sample_bound(i, lay.index(r[ri], t[ri]), s[ri], hk[ri])
                        if mode == "composite":
                            bound[i, r[ri]] += e
                        else:
                            bound[i, r[ri]] = np.maximum(bound[i, r[ri]], e)
                rgb = np.zeros((r.size, 3))
                tau = np.zeros(r.size)
                opaque = np.zeros(r.size, bool)
                if mode == "composite" and ri.size:
                    rgba, clear = lay.classify(s[ri])
                    rgb[ri] = rgba[:, :3]
                    tau[ri], opaque[ri] = _extinction(rgba[:, 3], clear, lay.layer.tf.unit_distance)
                samples.append((inside, s, rgb, tau, opaque))
            if add:
                all_done = np.ones(r.size, bool)
                for i, (inside, s, rgb, tau, opaque) in enumerate(samples):
                    if mode == "composite":
                        step_alpha = np.where(opaque, 1.0, -np.expm1(-hk * tau))
                        piece = np.concatenate([rgb * step_alpha[:, None], step_alpha[:, None]], axis=1)
                        piece[~opaque & (tau <= 0)] = 0
                        use = inside & ~done[i, r]
                        ru = r[use]
                        acc[i, ru] += (1 - acc[i, ru, 3:4]) * piece[use]
                        stop = acc[i, ru, 3] >= 1
                        if ert > 0:
                            stop |= 1 - acc[i, ru, 3] < ert
                        done[i, ru] = stop
                        all_done &= done[i, r]
                    else:                  # each layer's extreme or mean: no early end
                        ri, si = r[inside], s[inside]
                        if mode == "mip":
                            best[i, ri] = np.maximum(best[i, ri], si)
                        elif mode == "minip":
                            best[i, ri] = np.minimum(best[i, ri], si)
                        else:
                            best[i, ri] += si * hk[inside]
                            len_sum[i, ri] += hk[inside]
                        all_done[:] = False
                ended[r] = all_done if mode == "composite" else False
            else:
                tau = sum(x[3] for x in samples)
                emission = sum(x[2] * x[3][:, None] for x in samples)
                n_opaque = sum(x[4].astype(np.float64) for x in samples)
                opaque_rgb = sum(x[2] * x[4][:, None] for x in samples)
                piece = np.zeros((r.size, 4))
                clear = tau > 0
                step_alpha = -np.expm1(-hk[clear] * tau[clear])
                piece[clear, :3] = emission[clear] / tau[clear, None] * step_alpha[:, None]
                piece[clear, 3] = step_alpha
                op = n_opaque > 0
                piece[op, :3] = opaque_rgb[op] / n_opaque[op, None]
                piece[op, 3] = 1.0
                transmittance = 1 - alpha[r]
                color[r] += transmittance[:, None] * piece[:, :3]
                alpha[r] += transmittance * piece[:, 3]
                stop = alpha[r] >= 1
                if ert > 0:
                    stop |= 1 - alpha[r] < ert
                ended[r] = stop

    out = np.zeros((n_rays, 4))
    if add:
        if mode != "composite":
            for i, lay in enumerate(layers):
                if mode == "average":
                    ok = len_sum[i] > 0
                    s = np.where(ok, best[i], 0.0) / np.where(ok, len_sum[i], 1.0)
                else:
                    ok = np.isfinite(best[i])
                    s = np.where(ok, best[i], 0.0)
                rgba, _ = lay.classify(s)
                acc[i, :, :3] = rgba[:, :3] * rgba[:, 3:4]
                acc[i, :, 3] = rgba[:, 3]
                acc[i, ~ok] = 0
        out[:, :3] = acc[:, :, :3].sum(axis=0)
        out[:, 3] = 1 - np.prod(1 - acc[:, :, 3], axis=0)
    else:
        out[:, :3] = color
        out[:, 3] = alpha
    out[~live] = 0
    if scene.geometry:
        out = surface_behind(out, t_surface, surface_color)
    if audit is not None:
        audit["ties"] = tie.reshape(H, W)
        if sample_bound is not None:
            audit["bound"] = bound.sum(axis=0).reshape(H, W)
    return out.reshape(H, W, 4)
