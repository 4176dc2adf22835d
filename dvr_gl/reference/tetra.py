"""NumPy reference of projected tetrahedra: the plan's cells, in the plan's draw order,
each pixel's segment through each cell found in float64 (``mesh_rays``), integrated with
the twin of the shader's segment integral (``linear_segment``), blended back to front
with the over operator into the plan's target (rounded per blend as the target would).

What the GL path leaves to rasterisation is decided here as GL decides it: a pixel whose
ray lies in a face shared by two cells is covered once (GL's rule gives such a pixel to
one of the two triangles; both give the same segment), so overlapping coverage of a ray
is counted once.

Clip planes and a crop box: each (cell, pixel) segment is cut to the pixel ray's kept
interval (box coordinates, as the shader's ``clipRange``), its end values interpolated
linearly, before anything else; empty ones are dropped, as the shader discards them.

``sort="walk"`` (``techniques.tetra_walk``): the same segments, composited per pixel in
the order of their distance along the ray (the walk's front-to-back order; a ray meets
cells in this order whatever the mesh), in float64, the target's rounding applied once
at the end (the walk accumulates in float32 and writes the target once). Folded cells
(both cells of a face on one side of it) are the exception: here, as in projection, each
cell's own segment counts, so their overlap twice; the walk counts it once, as the exact
image does (tests/test_tetra_walk.py compares those with exact).

Opaque geometry: each pixel's first surface hit is the exact image's own float64 test
(``exact_geometry.surface_hits``); every segment is cut at it as at a clip (``clip_segments``
with the interval [0, t_hit]). Composite: the surface's lit colour, opaque, is the
target's backmost layer, the cells blended over it; mip, minip, average: the surface goes
behind the shortened ray's classified value (``surface_behind``).
"""

from __future__ import annotations

import numpy as np

from .common import blend_over, round_to_target
from .exact_geometry import surface_behind, surface_hits
from .linear_segment import linear_segment
from .mesh_rays import clip_segments, kept_intervals, ray_tet_segments, union_segments
from .shading import sample_terms


def render_plan(plan, lut_exact=False):
    """(H, W, 4) float64 premultiplied RGBA, row 0 on top. ``lut_exact`` is accepted for
    the common interface: this technique classifies with the exact TF (its knots) anyway."""
    scene = plan.scene
    W, H = scene.width, scene.height
    out = np.zeros((H * W, 4))
    t_surface = None
    if scene.geometry:      # the surface, opaque, as the backmost layer (tetra.frag: GEOMETRY)
        t_surface, surface_color = surface_hits(scene)
        if scene.mode == "composite":
            hit = np.isfinite(t_surface)
            out[hit, :3] = surface_color[hit]
            out[hit, 3] = 1.0
            if plan.target != "rgba32f" and plan.sort != "walk":   # the walk writes the target once
                out = round_to_target(out, plan.target)
    if plan.draw.size == 0:
        if t_surface is not None and scene.mode != "composite":
            out = surface_behind(out, t_surface, surface_color)
        return out.reshape(H, W, 4)
    seg = ray_tet_segments(scene, tets=plan.draw)
    if scene.clips:     # each fragment's segment cut to its ray's kept interval (tetra.frag)
        seg = clip_segments(seg, *kept_intervals(scene, box_coordinates=True))
    if t_surface is not None:    # and at its pixel's first surface
        seg = clip_segments(seg, np.zeros_like(t_surface), t_surface)
    seg = union_segments(seg)
    if scene.mode != "composite":
        out = _reduce(scene, seg, out)
        if t_surface is not None:
            out = surface_behind(out, t_surface, surface_color)
        return out.reshape(H, W, 4)
    if plan.sort == "walk":      # back to front along each ray: farthest entry first
        r = -seg["t0"]
    else:
        rank = np.full(len(scene.volume.tets), -1, np.int64)
        rank[plan.draw] = np.arange(plan.draw.size)
        r = rank[seg["tet"]]
    order = np.lexsort((r, seg["pixel"]))              # per pixel, in draw order (back first)
    pix = seg["pixel"][order]
    length = (seg["t1"] - seg["t0"])[order]
    terms = sample_terms(scene, None)
    model = scene.optical_model
    if plan.defines.get("SEGMENT_TABLE"):     # segments="table": the walk's approximate integral
        from ..model.segment_table import SegmentTable, table_segment
        rgba = table_segment(SegmentTable(scene.tf), seg["s0"][order], seg["s1"][order], length)
    elif terms is None:
        rgba = linear_segment(plan.knots, seg["s0"][order], seg["s1"][order], length, model)
    else:   # each cell's terms are constant (its gradient is): see shaders/tetra/tetra.frag
        from ..model.mesh import cell_fields
        grads = cell_fields(scene.volume)[seg["tet"][order], 0, :3]
        dirs = scene.camera.rays(W, H)[1].reshape(-1, 3)[pix]
        factor, offset, scale = terms.at(np.zeros_like(dirs), dirs, grad=grads, depth_cue=False)
        cue = None
        if "depth_cue" in scene.illustration:     # linear along each segment: integrated with it
            lo = scene.volume.bounds[0]
            origins = scene.camera.rays(W, H)[0].reshape(-1, 3)[pix] - lo
            cue = tuple(terms.cue(origins + seg[t][order][:, None] * dirs + lo) for t in ("t0", "t1"))
        rgba, weight = linear_segment(plan.knots, seg["s0"][order], seg["s1"][order], length * scale, model,
                                      weights=True, cue=cue)
        rgba[:, :3] = rgba[:, :3] * factor[:, None] + offset * weight[:, None]
    # layer k of a pixel is its k-th fragment in draw order; blend layer by layer
    if pix.size == 0:       # every segment cut away (behind a surface, or clipped)
        return out.reshape(H, W, 4)
    first = np.concatenate([[0], np.flatnonzero(pix[1:] != pix[:-1]) + 1])
    counts = np.diff(np.concatenate([first, [pix.size]]))
    layer = np.arange(pix.size) - np.repeat(first, counts)
    by_layer = np.argsort(layer, kind="stable")
    bounds = np.searchsorted(layer[by_layer], np.arange(int(counts.max()) + 1))
    for k in range(int(counts.max())):
        at = by_layer[bounds[k]:bounds[k + 1]]
        p = pix[at]
        out[p] = blend_over(out[p], rgba[at], "rgba32f" if plan.sort == "walk" else plan.target)
    return out.reshape(H, W, 4)


def _reduce(scene, seg, out):
    """mip, minip, average: the field's extreme or mean over each pixel's segments,
    classified with the TF (float64)."""
    pix = seg["pixel"]
    n = len(out)
    if scene.mode == "average":
        length = seg["t1"] - seg["t0"]
        total = np.bincount(pix, length, n)
        integral = np.bincount(pix, 0.5 * (seg["s0"] + seg["s1"]) * length, n)
        hit = total > 0
        s = np.where(hit, integral / np.where(hit, total, 1.0), 0.0)
    else:
        sign = 1.0 if scene.mode == "mip" else -1.0
        v = sign * np.maximum(sign * seg["s0"], sign * seg["s1"])
        best = np.full(n, -np.inf)
        np.maximum.at(best, pix, sign * v)
        hit = np.isfinite(best)
        s = np.where(hit, sign * best, 0.0)
    a = scene.tf.opacity(s[hit])
    out[hit, :3] = scene.tf.color(s[hit]) * a[:, None]
    out[hit, 3] = a
    return out
