"""Projected tetrahedra: cell projection for unstructured tetrahedral meshes.

About this technique
--------------------
Per view, the cells are put in back-to-front order (``dvr_gl.techniques.cell_order``: MPVO with the
per-pixel treatment of gaps in the domain, or a centroid sort) and drawn in that order,
each as its four faces with front faces culled. A cell's back faces cover its projected
silhouette exactly once, like the 3 or 4 triangles of Shirley and Tuchman's
classification; instead of interpolating a thick vertex's depth and scalars across
those triangles, each fragment clips its own pixel ray against the cell's four planes,
which gives the exact front and back distances (under perspective too) and, from the
cell's linear field, the exact scalars there. The segment is then integrated exactly for
the piecewise-linear transfer function (``shaders/common/linear_segment.glsl``: closed-form
optical depth per piece between knots, colour by parts with 8-point Gauss-Legendre), so
the result is right for any cell size, and GL blends it with the over operator
(premultiplied, back to front) into a float target.

Classification is thus done on the GPU, per fragment, from per-cell data uploaded once per
mesh (planes, linear field, points, connectivity); the CPU's only per-view work is the
order, uploaded as one int32 per cell. The cells whose scalar range has zero opacity are
left out of the order and the draw (found once per transfer function); zero-volume cells
are sorted but never drawn.

Cracks and double counting. A shared face's plane is stored once and negated for the
second cell, so the ray leaves one cell exactly where it enters the next. Whether a ray
meets a cell is the fragment's own clipping, not rasterisation (which snaps vertices to a
grid): each cell's outline is grown by twice that snapping (``outline.frag``, one pass
per view), every fragment of a cell carries its draw slot's depth, and the depth test
keeps one fragment per cell and pixel (``tetra.vert`` has the details, and how a ray
lying exactly in a face's plane is given to one cell).

Clip planes and a crop box (``Scene.clip_planes``, ``crop_box``). Each fragment cuts its
cell's segment to the part of the pixel's ray the clip keeps (``clipRange`` in
shaders/common/clip.glsl; the kept region is convex, so that part is one interval), takes
the field's values at the cut ends, and is discarded where nothing is left. The cells
whose four points all lie outside one plane or beyond one face of the crop box are left
out of the draw (found once per mesh and clip, ``cells_kept``); the rest keep their
order, which stays back to front. Unclipped scenes compile none of this.

Opaque geometry (``Scene.geometry``). A pass before the cells finds each pixel's first
surface, its lit colour and ray parameter t (``techniques.geometry.surface_pass``). Each
fragment cuts its cell's segment at that t (``GEOMETRY`` in tetra.frag, as it cuts at the
clip's kept interval: the end value follows from the cut end), so nothing behind the
surface counts. Composite: the surface's colour is written into the target first, opaque
(``geometry.draw_surface_behind``), and the cells blend over it back to front, giving
``C + (1 - A) * lit``, ``A = 1``. mip, minip, average: the classify pass composites the
surface behind the shortened ray's classified value.

Options (same names in ``dvr_gl.reference.render``)
---------------------------------------------------
sort : "auto" (default): "walk" for meshes it takes (fewer than 2^24 tets), else "mpvo",
    so that nothing is ordered per view on the CPU; "mpvo": visibility order exact at
    every pixel centre, non-convex domains included; "centroid": cells by centroid
    distance from the eye (cheaper; its error is measured in docs/notes/tetra_vs_vtk.md);
    "walk": no order at all, each pixel's ray walked from cell to cell through the face
    adjacency on the GPU, the same exact segments composited front to back
    (``dvr_gl.techniques.tetra_walk``). The plan keeps the order taken.
target : "rgba32f" (default) | "rgba16f" | "rgba8"
    blending happens in the target.
segments : "exact" (default) | "table": with ``sort="walk"`` (composite, emission and
    absorption, no shading), each segment from a per-TF table of cumulative extinction
    (``dvr_gl.model.segment_table``): cheaper, approximate, its error measured by the
    mesh pilot (``rendering.mesh_tolerance``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..util.cache import TableCache
from ..model.mesh import LOCAL_FACES, cell_fields, topology
from .cell_order import Order, centroid_order, mpvo_order, visible_cells
from ..model.transfer import SegmentKnots
from ..model.scene import OPTICAL_MODELS, Scene
from .common import (sample_term_uniforms, cleared_target, RepeatedIndices, SizedTarget, bind, camera_uniforms,
                     check_scene, check_target, clip_defines, clip_uniforms, data_projection, grow_pixels,
                     knot_uniforms)
from .geometry import draw_surface_behind, surface_pass
from .gpu import check_stage, empty_vao, rows_top_down

MODES = ("composite", "mip", "minip", "average")
TAKES_STEP = False
DATA = "mesh"
SORTS = ("mpvo", "centroid", "walk")
TEXEL_ROW_WIDTH = 4096
MAX_KNOTS = 256            # 2 x 256 vec4 uniforms: within every desktop GL's fragment limit


@dataclass
class TetraPlan:
    scene: Scene
    knots: SegmentKnots
    visible: np.ndarray            # cells with non-zero opacity somewhere in their range
    order: object                  # mesh.Order: cells back to front, cycles, gap constraints
    draw: np.ndarray               # int32 cells to draw, back to front (no zero-volume cells)
    sort: str = "mpvo"             # the order taken ("auto" resolved)
    target: str = "rgba32f"
    defines: dict = field(default_factory=dict)
    sort_seconds: float = 0.0      # time spent ordering for this view (0 when cached)
    behind_eye: np.ndarray = None  # per draw slot: the cell reaches behind the eye's plane
    walk_passes: int = 0           # sort="walk": layers of depth peeling in the last draw
    walk_left: int = 0             # sort="walk": pixels with an entry left at the pass cap
    walk_state: object = None      # sort="walk": the last draw's per-pixel state texture
    stage: str = "auto"            # sort="walk": where the walk pass runs (gpu.pixel_stage)


def reaches_behind_eye(scene, cells):
    """Per cell: does it come within 1e-3 of the mesh's diagonal of the plane through a
    perspective eye (or behind it)? Its outline is then not finite (tetra.vert)."""
    if scene.camera.is_ortho or len(cells) == 0:
        return np.zeros(len(cells), bool)
    mesh = scene.volume
    depth = (mesh.points - scene.camera.eye) @ scene.camera.forward
    near = 1e-3 * float(np.linalg.norm(mesh.extent))
    return depth[topology(mesh).tets[cells]].min(axis=1) <= near


def cells_kept(scene, cells):
    """Per cell of ``cells``: can any of it be kept by the scene's clip planes and crop
    box? False for a cell whose four points all lie strictly outside one plane's
    half-space or beyond one face of the crop box (float64, world units): the kept region
    is convex, so every ray's kept interval misses such a cell, and leaving it out of the
    draw changes no pixel. All True when the scene does not clip."""
    keep = np.ones(len(cells), bool)
    if not scene.clips or len(cells) == 0:
        return keep
    mesh = scene.volume
    corners = mesh.points[topology(mesh).tets[cells]]           # (m, 4, 3)
    for point, normal in scene.clip_planes:
        keep &= ((corners - point) @ normal >= 0).any(axis=1)
    if scene.crop_box is not None:
        lower, upper = scene.crop_box
        keep &= ~(corners < lower).all(axis=1).any(axis=1)
        keep &= ~(corners > upper).all(axis=1).any(axis=1)
    return keep


def _clip_key(scene):
    """The scene's clip as a string (a TableCache key compares strings by value)."""
    planes = [[float(v) for v in (*p, *n)] for p, n in scene.clip_planes]
    crop = None if scene.crop_box is None else [[float(v) for v in c] for c in scene.crop_box]
    return repr((planes, crop))


def _drop_clipped(scene, cells, tables):
    """``cells`` less those the clip keeps nothing of (``cells_kept``), their order kept:
    the restriction of a back-to-front order to a subset is still one. Which cells the
    clip keeps is found once per mesh and clip."""
    if not scene.clips:
        return cells
    keep = tables.get(f"tetra_kept:{_clip_key(scene)}", scene.volume,
                      make=lambda mesh: cells_kept(scene, np.arange(mesh.n_tets)))
    return cells[keep[cells]]


def make_plan(scene, step=None, *, sort="auto", target="rgba32f", stage="auto", segments="exact", tables=None):
    """Validate the options and decide what the scene needs. ``tables`` keeps the
    visible cells (per TF) and the order (per view) between frames."""
    tables = tables or TableCache()
    check_scene(scene, "tetra", MODES, data="mesh")
    if step is not None:
        raise ValueError(f"tetra takes no step (each cell is integrated exactly), got step={step!r}")
    if sort != "auto" and sort not in SORTS:
        raise ValueError(f"sort must be auto or one of {', '.join(SORTS)}, got {sort!r}")
    if sort == "auto":
        from .tetra_walk import MAX_CELLS
        sort = "walk" if scene.volume.n_tets < MAX_CELLS else "mpvo"
    check_target(target)
    check_stage(stage)
    mesh, tf = scene.volume, scene.tf
    if sort == "walk":
        from . import tetra_walk
        tetra_walk.check_scene(scene)
    if segments != "exact":
        from .tetra_walk import check_table_segments
        check_table_segments(scene, sort, segments)
    knots = tables.get("segment_knots", tf, make=SegmentKnots)
    if scene.mode != "composite":
        # order-independent reductions of the field (not of the TF): every cell with a
        # volume counts, and nothing is sorted
        cells = np.flatnonzero(~topology(mesh).flat).astype(np.int32)
        cells = _drop_clipped(scene, cells, tables)
        defines = {"KNOT_CAPACITY": knot_capacity(knots.count), f"MODE_{scene.mode.upper()}": 1,
                   "MODE_COMPOSITE": 0, **clip_defines(scene)}
        if scene.geometry:
            defines["GEOMETRY"] = 1
        if scene.camera.is_ortho:
            defines["ORTHO"] = 1
        return TetraPlan(scene=scene, knots=knots, visible=cells, order=Order(cells, 0, 0), draw=cells,
                         sort=sort, target=target, defines=defines, behind_eye=reaches_behind_eye(scene, cells),
                         stage=stage)
    visible = tables.get("visible_cells", mesh, tf, make=visible_cells)
    timing = {}

    def order(mesh, tf, camera):
        t0 = time.perf_counter()
        fn = mpvo_order if sort == "mpvo" else centroid_order
        result = fn(mesh, visible, scene)
        timing["sort"] = time.perf_counter() - t0
        return result

    flat = topology(mesh).flat

    def drawn(result):
        return _drop_clipped(scene, result.cells[~flat[result.cells]].astype(np.int32), tables)
    if sort == "walk":      # no order (the GPU walks each ray): the cells are kept per mesh, TF and clip
        result = Order(visible, 0, 0)
        draw = tables.get(f"tetra_walk_drawn:{_clip_key(scene)}", mesh, tf, make=lambda *_: drawn(result))
    else:
        # the key's objects compare by identity, the string by value (it holds the image
        # size, on which the per-pixel gap constraints depend)
        result = tables.get(f"tetra_order:{sort}:{scene.width}x{scene.height}", mesh, tf, scene.camera, make=order)
        draw = drawn(result)
    defines = {"KNOT_CAPACITY": knot_capacity(knots.count), "SEG_OPAQUE": opaque_knots(knots), **clip_defines(scene)}
    if scene.camera.is_ortho:
        defines["ORTHO"] = 1
    if scene.geometry:
        defines["GEOMETRY"] = 1
    if scene.optical_model != "emission_absorption":     # absorption (1) or emission (2) only
        defines["OPTICAL_MODEL"] = OPTICAL_MODELS.index(scene.optical_model)
    if segments == "table":
        defines["SEGMENT_TABLE"] = 1
    if scene.shading or scene.illustration:   # terms of each cell's own (constant) gradient
        defines["SAMPLE_TERMS"] = 1
        defines.update({name.upper(): 1 for name in scene.illustration})
        if scene.shading:
            defines["SHADING"] = 1
            if not scene.headlight_only:
                defines["LIGHTS"] = 1
    return TetraPlan(scene=scene, knots=knots, visible=visible, order=result, draw=draw, sort=sort,
                     target=target, defines=defines, sort_seconds=timing.get("sort", 0.0),
                     behind_eye=None if sort == "walk" else reaches_behind_eye(scene, draw), stage=stage)


def knot_capacity(count):
    """The uniform arrays' size for a TF of ``count`` knots: the next power of two (at
    least 4), so that editing a TF rarely compiles a new variant."""
    if count > MAX_KNOTS:
        raise ValueError(f"tf has {count} control-point positions; tetra takes at most {MAX_KNOTS}")
    return max(4, 1 << (count - 1).bit_length())


def opaque_knots(knots):
    """SEG_OPAQUE of common/linear_segment.glsl: 1 where a knot of ``knots`` (a
    SegmentKnots) has opacity 1 (its float32 transparency 0, as the shader reads it), else
    0 and the segment integral leaves out the code for opacity 1."""
    return int(bool((knots.texture_rows()[1, :, 1] <= 0.0).any()))


# ---------------------------------------------------------------------------------------
# GL path

def texture_rows(array):
    """(n, k) values laid out TEXEL_ROW_WIDTH texels per row (shaders/common/texel_rows.glsl):
    a (rows, TEXEL_ROW_WIDTH, k) array, the tail padded with zeros."""
    n, k = array.shape
    rows = max(1, -(-n // TEXEL_ROW_WIDTH))
    out = np.zeros((rows * TEXEL_ROW_WIDTH, k), array.dtype)
    out[:n] = array
    return out.reshape(rows, TEXEL_ROW_WIDTH, k)


def _texture(ctx, array, dtype):
    rows = texture_rows(np.ascontiguousarray(array))
    tex = ctx.texture((TEXEL_ROW_WIDTH, rows.shape[0]), rows.shape[2], rows.tobytes(), dtype=dtype)
    tex.filter = (ctx.NEAREST, ctx.NEAREST)
    return tex


class MeshTextures:
    """Per-mesh GPU data, uploaded once: points, cells, planes and linear fields."""

    def __init__(self, ctx, mesh):
        topo = topology(mesh)
        lo = mesh.bounds[0]
        pts = np.zeros((mesh.n_points, 4), np.float32)
        pts[:, :3] = mesh.points - lo
        planes = topo.cell_planes().reshape(-1, 4).astype(np.float32)
        field = cell_fields(mesh).reshape(-1, 4).astype(np.float32)
        self.centre = tuple(mesh.points.mean(axis=0) - lo)   # where rays in a face's plane lean (tetra.frag)
        self.points = _texture(ctx, pts, "f4")
        self.tets = _texture(ctx, topo.tets.astype(np.int32), "i4")
        self.planes = _texture(ctx, planes, "f4")
        self.field = _texture(ctx, field, "f4")
        self.bytes = sum(t.width * t.height * t.components * 4 for t in
                         (self.points, self.tets, self.planes, self.field))

    def release(self):
        for tex in (self.points, self.tets, self.planes, self.field):
            tex.release()


class _OrderTexture:
    """The per-view draw order: one int32 texel per slot, rewritten each frame, grown
    (never shrunk) as needed."""

    def __init__(self):
        self.tex = None

    def write(self, ctx, cells):
        rows = texture_rows(cells.reshape(-1, 1))
        if self.tex is None or self.tex.height < rows.shape[0]:
            if self.tex is not None:
                self.tex.release()
            self.tex = ctx.texture((TEXEL_ROW_WIDTH, rows.shape[0]), 1, dtype="i4")
            self.tex.filter = (ctx.NEAREST, ctx.NEAREST)
        self.tex.write(rows.tobytes(), viewport=(0, 0, TEXEL_ROW_WIDTH, rows.shape[0]))
        return self.tex

    def release(self):
        if self.tex is not None:
            self.tex.release()


def draw(renderer, plan):
    """Render the plan into the renderer's target; returns that framebuffer."""
    if plan.sort == "walk":     # the cell walk draws with this module's per-mesh textures
        from . import tetra_walk
        mesh = plan.scene.volume
        data = renderer.resources.for_objects("tetra_mesh", mesh, make=lambda: MeshTextures(renderer.ctx, mesh),
                                              capacity=1)
        return tetra_walk.draw(renderer, plan, data, _texture)
    ctx = renderer.ctx
    scene = plan.scene
    mesh = scene.volume
    composite = scene.mode == "composite"
    fbo = cleared_target(renderer, scene, plan.target)
    surfaces = surface_pass(renderer, scene) if scene.geometry else None   # each pixel's first surface
    if plan.draw.size == 0:
        if surfaces is not None:      # the surfaces alone (an empty ray classifies to 0)
            fbo.use()
            draw_surface_behind(renderer, surfaces)
        return fbo
    prog = renderer.programs.get("tetra/tetra.vert", "tetra/tetra.frag", plan.defines)
    data = renderer.resources.for_objects("tetra_mesh", mesh, make=lambda: MeshTextures(ctx, mesh), capacity=1)
    order = renderer.resources.for_objects("tetra_order", make=_OrderTexture, capacity=1).write(ctx, plan.draw)
    # tetra's own depths are slot numbers; its projection only places the faces of cells
    # that reach behind the eye, clipped just in front of it
    view_proj = data_projection(scene, near=None if scene.camera.is_ortho else
                                1e-6 * float(np.linalg.norm(mesh.extent))).astype("f4").tobytes()

    # the outline pass: every cell's grown outline in window coordinates (outline.frag)
    outline = renderer.resources.for_objects("tetra_outline", make=lambda: _OutlineTarget(ctx), capacity=1).get(
        int(plan.draw.size))
    outline_prog = renderer.programs.get("tetra/fullscreen.vert", "tetra/outline.frag")
    bind(outline_prog, {"t_order": order, "t_tets": data.tets, "t_points": data.points},
         {"u_target_size": scene.target_size, "u_inflate": grow_pixels(ctx), "u_slots": int(plan.draw.size)})
    outline_prog["u_view_proj"].write(view_proj)
    outline.use()
    empty_vao(renderer, outline_prog).render(ctx.TRIANGLES, vertices=3)

    if composite:
        color = fbo.color_attachments[0]
        drawn = renderer.resources.for_objects("tetra_depth", color, make=lambda: _DepthFramebuffer(ctx, color),
                                               capacity=2).fbo
    else:
        # the reduction needs float precision whatever the output target is
        drawn = reduced = renderer.resources.for_objects("tetra_reduced", make=lambda: SizedTarget(ctx, depth=True),
                                                         capacity=1).get(*scene.target_size)
    drawn.use()
    drawn.clear(-3.0e38 if scene.mode in ("mip", "minip") else 0.0, 0.0, 0.0, 0.0, depth=0.0)
    if surfaces is not None and composite:    # the surface as the backmost layer
        draw_surface_behind(renderer, surfaces)
    textures = {"t_order": order, "t_tets": data.tets, "t_points": data.points, "t_planes": data.planes,
                "t_field": data.field, "t_outline01": outline.color_attachments[0],
                "t_outline23": outline.color_attachments[1]}
    uniforms = {**camera_uniforms(scene), "u_knot_count": plan.knots.count, "u_inv_unit": plan.knots.inv_unit,
                "u_target_size": scene.target_size,
                "u_centre": data.centre, **clip_uniforms(scene)}
    if surfaces is not None:
        textures["t_surface"] = surfaces
    if scene.shading or scene.illustration:
        uniforms.update(sample_term_uniforms(renderer, scene, plan.defines))
    bind(prog, textures, uniforms)
    knot_uniforms(prog, plan.knots, plan.defines["KNOT_CAPACITY"])
    prog["u_view_proj"].write(view_proj)
    # the four faces of every drawn cell from its four vertices 4k .. 4k + 3 (tetra.vert)
    vao = renderer.resources.for_objects("tetra_faces", make=lambda: RepeatedIndices(ctx, LOCAL_FACES), capacity=1).vao(
        prog, plan.draw.size)
    ctx.enable(ctx.BLEND | ctx.CULL_FACE)
    ctx.depth_func = ">"
    ctx.cull_face = "front"
    if composite:
        ctx.blend_func = ctx.ONE, ctx.ONE_MINUS_SRC_ALPHA
        ctx.blend_equation = ctx.FUNC_ADD
    else:
        ctx.blend_func = ctx.ONE, ctx.ONE
        ctx.blend_equation = ctx.FUNC_ADD if scene.mode == "average" else ctx.MAX
    depth_range = 0
    for first, count, exact in draw_calls(plan):
        if first // SLOTS_PER_DEPTH_RANGE != depth_range:   # depths restart: clear them only
            depth_range = first // SLOTS_PER_DEPTH_RANGE
            depth_only = ctx.framebuffer(depth_attachment=drawn.depth_attachment)
            depth_only.clear(depth=0.0)
            drawn.use()
            depth_only.release()
        if exact:   # cells behind the eye's plane: their faces as they are (tetra.vert)
            ctx.disable(ctx.DEPTH_TEST)
        else:       # grown outlines, one fragment per cell by the depth test
            ctx.enable(ctx.DEPTH_TEST)
        bind(prog, {}, {"u_first_slot": depth_range * SLOTS_PER_DEPTH_RANGE, "u_exact_faces": exact})
        vao.render(ctx.TRIANGLES, vertices=12 * count, first=12 * first)
    ctx.disable(ctx.BLEND | ctx.CULL_FACE | ctx.DEPTH_TEST)
    ctx.depth_func = "<"
    ctx.blend_equation = ctx.FUNC_ADD
    if not composite:
        classify = renderer.programs.get("tetra/fullscreen.vert", "tetra/tetra_classify.frag",
                                         {k: v for k, v in plan.defines.items()
                                          if k in ("KNOT_CAPACITY", "MODE_MINIP", "MODE_AVERAGE", "GEOMETRY")})
        fbo.use()
        classify_textures = {"t_reduced": reduced.color_attachments[0]}
        if surfaces is not None:
            classify_textures["t_surface"] = surfaces
        bind(classify, classify_textures, {"u_knot_count": plan.knots.count,
                                           "u_rows_top_down": rows_top_down(renderer, fbo)})
        knot_uniforms(classify, plan.knots, plan.defines["KNOT_CAPACITY"])
        empty_vao(renderer, classify).render(ctx.TRIANGLES, vertices=3)
    return fbo


SLOTS_PER_DEPTH_RANGE = (1 << 22) - 1  # cells with distinct depths (k + 1) / 2^22 (tetra.vert)


def draw_calls(plan):
    """(first slot, count, exact) per draw call: runs of cells in drawing order, split
    where cells start or stop reaching behind the eye's plane (``exact``: drawn with
    their faces as they are, see tetra.vert) and where depths restart (every
    SLOTS_PER_DEPTH_RANGE slots)."""
    n = int(plan.draw.size)
    if n == 0:
        return []
    exact = plan.behind_eye
    cuts = set(range(0, n, SLOTS_PER_DEPTH_RANGE)) | set((np.flatnonzero(np.diff(exact)) + 1).tolist())
    bounds = sorted(cuts) + [n]
    return [(a, b - a, bool(exact[a])) for a, b in zip(bounds[:-1], bounds[1:])]


class _OutlineTarget:
    """The outline pass's two RGBA32F targets, TEXEL_ROW_WIDTH texels wide, one texel per
    cell and pair of its corners; grown (never shrunk) as needed."""

    def __init__(self, ctx):
        self.ctx = ctx
        self.fbo = None

    def get(self, texels):
        rows = max(1, -(-texels // TEXEL_ROW_WIDTH))
        if self.fbo is None or self.fbo.size[1] < rows:
            rows = max(rows, 2 * self.fbo.size[1]) if self.fbo is not None else rows
            self.release()
            textures = [self.ctx.texture((TEXEL_ROW_WIDTH, rows), 4, dtype="f4") for _ in range(2)]
            for tex in textures:
                tex.filter = (self.ctx.NEAREST, self.ctx.NEAREST)
            self.fbo = self.ctx.framebuffer(textures)
        return self.fbo

    def release(self):
        if self.fbo is not None:
            for tex in self.fbo.color_attachments:
                tex.release()
            self.fbo.release()
            self.fbo = None


class _DepthFramebuffer:
    """A framebuffer over a target's colour texture with a 24-bit depth texture of its
    own, for the depth test that keeps one fragment per cell and pixel (tetra.vert)."""

    def __init__(self, ctx, color):
        self.depth = ctx.depth_texture(color.size)
        self.fbo = ctx.framebuffer([color], self.depth)

    def release(self):
        self.fbo.release()
        self.depth.release()
