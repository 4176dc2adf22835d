"""Bricks for 3-D texture slicing: the same proxy planes, one brick's texture at a time.

A volume wider than one 3-D texture, or a render that asks for it (``brick_size=N``), is
sliced brick by brick with the partition, texel formats and reads of ray casting's bricks
(``techniques.bricks``: ``partition``, ``texel_format``, ``read_block``). The planes are
the single texture's, ``step`` apart at the same depths; so are each fragment's segment
and its midpoint sample, computed alike in every pass. A brick's pass draws the pieces of
the planes near its cells and keeps the fragments whose sample (the midpoint of the
segment the plane stands for) lies in the cells it owns (``lo <= p < hi`` per axis, as
``bricks.ownedSample`` decides for ray samples): each (pixel, plane) sample is drawn by
exactly one brick. Bricks are drawn back to front in the reverse of ray casting's
visibility order (valid for every ray), planes far to near within each, so every pixel
blends the same fragments in the same order as in one pass: GL blends a pixel's
fragments in the order they are drawn. Only the texture coordinate differs (as for ray
casting: exact where the shader interpolates fetches, one float32 rounding through the
texture unit).

The gap pass (rays that meet no plane inside the box; ``shaders/common/slice_gap.glsl``)
integrates a whole chord in one fragment: the brick owning the chord's midpoint draws it.
Its sub-segments' samples lie within half a chord of that midpoint (a gap chord spans at
most two steps along the view: ``step / cos`` to either side, ``cos`` the smallest of the
image's rays along the view direction), so the halo grows by that many cells
(``slice_halo``) and every lookup still reads the texels the whole texture would.

Geometry, wherever it is cut: the cpu proxy cuts each plane against the brick's box grown
by half a segment along the ray (``step / (2 cos)``: a sample lies within that of its
plane's point) and by the rasteriser's snapping; the vertex proxy takes that grown box's
corners; shells and the gap pass draw the brick's box (``bricks.brick_proxy``), which
every ray with an owned sample crosses.

A brick whose texture's values all have zero opacity is neither made nor drawn: every
sample its pass could take is transparent, a fragment the single pass discards too.
"""

from __future__ import annotations

import math

import numpy as np

from . import bricks
from . import proxy as proxy_geometry
from .common import bind, box_view, grow_pixels, plane_projection
from .gpu import cull_for_proxy, empty_vao, proxy_vao, stream_vao


def unsupported(scene, preintegrate, gradients):
    """A ValueError naming the first thing bricked slicing does not do yet."""
    what = None
    if preintegrate:
        what = "preintegrate=True (its segment ends lie outside the owned cells)"
    elif scene.reads_gradient and gradients == "texture":
        what = "gradients='texture'"
    elif scene.volume.has_nonfinite:
        what = "non-finite samples"
    if what is not None:
        raise ValueError(f"bricked 3-D slicing (brick_size) does not yet take {what}")


def check_bricking(scene, brick_size, preintegrate, gradients):
    """``brick_size`` validated (None: bricks only where the volume needs them)."""
    brick_size = bricks.check_brick_size(brick_size)
    if brick_size is not None:
        unsupported(scene, preintegrate, gradients)
    return brick_size


def smallest_cos(scene):
    """The least component along the view direction of the image's unit ray directions
    (1 for orthographic cameras)."""
    cam = scene.camera
    if cam.is_ortho:
        return 1.0
    hx, hy = cam.screen_scale(scene.width, scene.height)
    return 1.0 / math.sqrt(1.0 + hx * hx + hy * hy)


def gap_reach(scene, step, shells):
    """How far (world units) a gap chord's samples can lie from the chord's midpoint:
    half the chord. A chord spanning a step or more in depth (radius, for shells) holds a
    plane, so a gap chord spans less, and its half less than ``step / (2 cos)``; this is
    twice that (the gap test's own bound, two steps), a margin for rounding."""
    return step if shells else step / smallest_cos(scene)


def slice_halo(scene, step, shells):
    """Samples of halo a brick needs: ray casting's (trilinear corners and, lit, the
    gradients' neighbours, for samples up to a cell outside the owned cells) and the whole
    cells a gap chord reaches beyond its midpoint's brick. At the default step (half a
    cell) that is ray casting's own halo."""
    return bricks.halo_for(scene) + int(math.floor(gap_reach(scene, step, shells) / scene.volume.min_spacing))


def brick_size_for(renderer, plan):
    """The plan's brick size, else the largest whose textures fit where a side of the
    volume exceeds the context's 3-D texture limit, else None (one texture)."""
    if plan.brick_size is not None:
        return plan.brick_size
    scene = plan.scene
    limit = bricks.max_3d_texture_size(renderer.ctx)
    if max(scene.volume.shape) <= limit:
        return None
    unsupported(scene, plan.preint is not None, "texture" if "GRADIENT_TEXTURE" in plan.defines else "on_the_fly")
    return limit - 1 - 2 * slice_halo(scene, plan.step, plan.shells)


def texture_ranges(volume, parts):
    """(lo, hi) float64 per brick over its texture's samples: every value its pass can
    interpolate, the gap chords' included."""
    lo = np.empty(len(parts))
    hi = np.empty(len(parts))
    for i, brick in enumerate(parts):
        block = bricks.read_block(volume, *(v for pair in brick.samples for v in pair))
        lo[i], hi[i] = float(block.min()), float(block.max())
    return lo, hi


def occupied(renderer, plan, parts, brick_size, halo):
    """Per brick, whether any value its texture holds has opacity under the 1-D transfer
    function (all True with a TransferFunction2D, which classifies by gradient too)."""
    volume, tf = plan.scene.volume, plan.scene.tf
    if plan.scene.tf_2d is not None:
        return np.ones(len(parts), bool)
    ranges = renderer.resources.for_objects(f"slice3d_brick_ranges:{brick_size}:{halo}", volume,
                                            make=lambda: texture_ranges(volume, parts), capacity=4)
    return renderer.resources.for_objects(f"slice3d_brick_occupied:{brick_size}:{halo}", volume, tf,
                                          make=lambda: bricks.brick_occupancy(ranges, plan.lut), capacity=4)


def owned_box(volume, brick, grow=0.0):
    """The world box (x, y, z; from the volume's lower corner) of the brick's cells, grown
    by ``grow`` on every side."""
    spacing = np.asarray(volume.spacing, np.float64)
    lo = np.array([brick.cells[a][0] for a in (2, 1, 0)], np.float64) * spacing - grow
    hi = np.array([brick.cells[a][1] for a in (2, 1, 0)], np.float64) * spacing + grow
    return lo, hi


def slice_range(plan, corners, eye, reach):
    """(first, count) of the plan's slices that can hold a sample in the box of
    ``corners``: planes (or shells) within ``reach`` of it in depth (radius)."""
    if plan.shells:
        lo, hi = corners.min(axis=0), corners.max(axis=0)
        gap = np.maximum(np.maximum(lo - eye, eye - hi), 0.0)
        d_min = float(np.linalg.norm(gap))
        d_max = float(np.linalg.norm(corners - eye, axis=1).max())
    else:
        depth = (corners - eye) @ np.asarray(plan.scene.camera.forward, np.float64)
        d_min, d_max = float(depth.min()), float(depth.max())
    d_min, d_max = d_min - reach, d_max + reach
    first = max(0, math.ceil((plan.far_depth - d_max) / plan.step))
    last = min(plan.count - 1, math.floor((plan.far_depth - d_min) / plan.step))
    return first, max(0, last - first + 1)


def draw(renderer, plan, prog, gap, textures, uniforms, brick_size):
    """Slice the plan brick by brick into the bound target (blending set up by the
    caller): ``prog`` the slicing program and ``gap`` the gap pass's, both compiled with
    the bricked defines; ``textures`` and ``uniforms`` theirs without the volume."""
    ctx = renderer.ctx
    scene = plan.scene
    volume = scene.volume
    cam = scene.camera
    halo = slice_halo(scene, plan.step, plan.shells)
    parts = bricks.brick_layout(renderer, volume, brick_size, halo)
    drawn = occupied(renderer, plan, parts, brick_size, halo)
    eye = np.asarray(cam.eye, np.float64) - volume.bounds[0]
    front_to_back = bricks.visibility_order(parts, volume, eye, cam.forward, cam.is_ortho)
    keep = {b.index for b, o in zip(parts, drawn) if o}
    order = [b for b in reversed(front_to_back) if b.index in keep]

    kind, view_proj, grow = box_view(scene, grow_pixels(ctx))
    # a sample lies within half a segment (step / (2 cos) along its ray) of its plane's
    # point; the plane pieces are cut from the owned box grown by that, and by the
    # rasteriser's snapping and a margin against the cut's rounding
    diagonal = float(np.linalg.norm(volume.extent))
    reach = 0.5 * plan.step / smallest_cos(scene) + grow + 1e-3 * diagonal
    unit = len(textures)
    for program in (prog, gap):
        bind(program, textures, uniforms)
        program["t_volume"].value = unit
    planes = plan.count > 0
    if planes and not plan.shells:
        prog["u_view_proj"].write(plane_projection(plan).astype("f4").tobytes())
    pieces = []
    if planes and plan.proxy == "cpu" and not plan.shells:
        pieces = cpu_pieces(renderer, plan, prog, order, eye, reach)
    elif planes and plan.proxy == "vertex":
        prog["u_normal"].value = tuple(cam.forward)
        bind(prog, {}, proxy_geometry.vertex_path_tables(cam.forward))
    textures_of = bricks.brick_textures(renderer, volume)
    try:
        for i, brick in enumerate(order):
            tex, offset = textures_of.get(brick)
            tex.use(location=unit)
            brick_inputs = bricks.brick_uniforms(volume, brick)
            for program in (prog, gap):
                if "u_brick_offset" in program:
                    program["u_brick_offset"].value = offset
                for name, value in brick_inputs.items():
                    if name in program:
                        program[name].value = value
            proxy_mvp = bricks.brick_proxy(scene, brick, kind, view_proj, grow).astype("f4").tobytes()
            if planes:
                draw_planes(renderer, plan, prog, brick, eye, reach, pieces[i] if pieces else None,
                            kind, proxy_mvp)
            gap["u_view_proj"].write(proxy_mvp)
            cull_for_proxy(ctx, kind)
            proxy_vao(renderer, gap, kind).render(instances=1)
            ctx.disable(ctx.CULL_FACE)
    finally:
        ctx.disable(ctx.CULL_FACE)


def cpu_pieces(renderer, plan, prog, order, eye, reach):
    """Every drawn brick's plane pieces in one vertex stream: per brick (vao, first vertex,
    vertex count). Bricks of one size are translates of one box, and a plane cut against
    ``box + v`` is the plane moved by ``-n.v`` cut against ``box``, then moved by ``v``:
    one cut per brick size (the last bricks along an axis are shorter)."""
    volume = plan.scene.volume
    normal = np.asarray(plan.scene.camera.forward, np.float64)
    runs = []                     # per brick: (lower corner, size, first slice, count)
    for brick in order:
        lo, hi = owned_box(volume, brick, reach)
        first, count = slice_range(plan, proxy_geometry.box_corners(lo, hi), eye, 0.0)
        runs.append((lo, tuple(c1 - c0 for c0, c1 in brick.cells[::-1]), first, count))
    pieces = [None] * len(order)
    sizes = {}
    for i, (lo, cells, first, count) in enumerate(runs):
        if count:
            sizes.setdefault(cells, []).append(i)
    spacing = np.asarray(volume.spacing, np.float64)
    chunks, start = [], 0
    for cells, members in sizes.items():
        size = np.asarray(cells, np.float64) * spacing + 2 * reach
        # offsets n.x of brick i's planes, less n.lo_i: the same planes against the box at 0
        per_brick = [proxy_geometry.plane_offsets(normal, eye, plan.far_depth - runs[i][2] * plan.step, plan.step,
                                                  runs[i][3]) - runs[i][0] @ normal for i in members]
        vertices, counts = proxy_geometry.plane_polygons(proxy_geometry.box_corners(np.zeros(3), size), normal,
                                                         np.concatenate(per_brick))
        at = 0
        for i, offsets in zip(members, per_brick):
            n_planes = len(offsets)
            lo, _, first, _ = runs[i]
            positions, slices = proxy_geometry.fan_triangles(vertices[at:at + n_planes] + lo, counts[at:at + n_planes])
            at += n_planes
            chunks.append((positions, slices + np.int32(first)))
            pieces[i] = (start, len(slices))
            start += len(slices)
    if start == 0:
        return [(None, 0, 0)] * len(order)
    vao = stream_vao(renderer, prog, "slice3d_bricks_cpu", np.concatenate([c[0] for c in chunks]),
                     np.concatenate([c[1] for c in chunks]))
    return [(vao, *piece) if piece is not None else (None, 0, 0) for piece in pieces]


def draw_planes(renderer, plan, prog, brick, eye, reach, piece, kind, proxy_mvp):
    """One brick's slices: its plane pieces (cpu), the vertex shader's cut of the grown
    box (vertex), or the brick's box once per shell that can reach it (shells)."""
    ctx = renderer.ctx
    if piece is not None:
        vao, first, n = piece
        if n:
            if "u_slice_base" in prog:       # (cpu pieces carry their global slice index)
                prog["u_slice_base"].value = 0
            vao.render(ctx.TRIANGLES, vertices=n, first=first)
        return
    volume = plan.scene.volume
    if plan.shells:
        lo, hi = owned_box(volume, brick)
        first, count = slice_range(plan, proxy_geometry.box_corners(lo, hi), eye, 0.5 * plan.step)
        if count:
            prog["u_slice_base"].value = first
            prog["u_view_proj"].write(proxy_mvp)
            cull_for_proxy(ctx, kind)
            proxy_vao(renderer, prog, kind).render(instances=count)
            ctx.disable(ctx.CULL_FACE)
        return
    corners = proxy_geometry.box_corners(*owned_box(volume, brick, reach))
    first, count = slice_range(plan, corners, eye, 0.0)
    if count:
        prog["u_slice_base"].value = first
        prog["u_corners"].value = [tuple(c) for c in corners]
        empty_vao(renderer, prog).render(ctx.TRIANGLES, vertices=12, instances=count)
