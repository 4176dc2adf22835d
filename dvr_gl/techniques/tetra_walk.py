"""Projected tetrahedra without a visibility sort: each pixel's ray walked from cell to
cell on the GPU (``technique="tetra", sort="walk"``; Garrity 1990, Weiler, Kraus and
Ertl 2003, Marmitt and Slusallek 2006).

Once per mesh: the cells' planes and linear fields (``tetra.MeshTextures``, the same
textures tetra draws with: a shared face's plane stored once and negated for the second
cell, so a ray leaves one cell exactly where it enters the next). Once per mesh (and TF,
where it hides at least ``HIDDEN_FRACTION`` of the cells, ``walked_cells``): each cell's
four face neighbours (-1 on the boundary of the walked cells), the boundary faces as
triangles (``WalkTextures``) and per-cell flags (shown, zero volume, folded faces).

Per view, the CPU uploads a camera; then, per layer of depth peeling:

1. entry pass (``walk_entries``, ``walk_entry.vert/.geom/.frag``): the boundary faces are
   drawn twice, each as its triangle grown in window coordinates (or its grown bounding
   box, where a corner is too sharp to grow; so coverage is the
   fragment's test, not rasterisation's: a face seen edge-on keeps its pixels), each fragment
   finding where its pixel's ray crosses the face's plane going in, inside the face's
   triangle; the first draw keeps the nearest such t beyond where the pixel's last walk
   stopped (MIN blending, exact), the second the smallest cell at exactly that t. Between
   them a full-screen pass (``walk_mark.frag``) marks the pixels that have an entry in a
   depth buffer (``layer_depth``, falling by layer), counting them (an occlusion query):
   if none, peeling stops there, without the second draw. The layers the last frame drew
   are drawn without reading their queries (reading one waits for the GPU), so a frame
   like the last waits once. Both draws test the marks before shading (early), so later
   layers shade only the few pixels that still walk. The first layer, where no pixel is
   marked yet, takes one draw (``walk_entries.FIRST_LAYER_PICK``, walk_entry.frag's
   DEPTH_PICK): the depth test keeps the nearest t (window depth t times a power of two)
   and, among equal depths, the first face drawn, the faces being in the order of their
   cells.
2. walk pass (``walk.frag``, a full-screen triangle tested against the marks: the pixels
   with an entry in the last layer (the first: in this one); llvmpipe skips the blocks
   of pixels without one): from its entry, each pixel's ray goes from cell to cell
   through the face adjacency (the exit faces and segments: below); each cell's segment
   is cut to the clip's kept interval and at the first opaque surface, integrated
   exactly (``common/linear_segment.glsl``) and composited front to back. Leaving through a
   boundary face ends the layer for that pixel; a non-convex domain's re-entry is the
   next layer's entry. A pixel is done at the end of its kept interval or at opacity 1 -
   2^-20 (composite), and when it leaves through a face on the convex hull (not grazing
   it: ``HULL`` in the neighbours), as nothing is left to enter (81 % of the blunt fin's
   rays, 96 % of the LOX post's, under 1 % of the combustor's). In the fragment stage the
   walk reads and writes its accumulation and state in place (image load/store,
   ``IN_PLACE``): a layer shades only the pixels that have an entry in it. (Without image
   load/store it uses two targets in turn, and a layer's pass also copies the pixels that
   ended in the last; the compute stage writes its two targets in turn, every pixel.)
   After each walk a full-screen pass marks the pixels still going on
   (``walk_entries.mark_alive``), the only ones the next layer's first entry draw shades;
   their count, 0, ends the peeling without another entry pass.
   The code for zero-volume cells and folded faces is compiled in only for meshes that have them
   (``rare_paths``), and runs in an outer loop that a group of pixels enters only when
   one of them needs it: llvmpipe runs every branch's code for the whole group, taken or
   not (``capabilities.lockstep_lanes``), so in the stepping loop that code cost every
   step (15-25 % of the frame on the NASA meshes). Where lanes run in lockstep, the
   light segments are integrated inline by a straight-line rule and the others in that
   outer loop (a pixel's first waiting while it walks on, ``walk.frag``).
   ``segments="table"``: the approximate integral of ``model.segment_table``.
3. resolve: the accumulation into the image's target (composite, with the surface
   behind it) or classified (mip, minip, average: ``tetra_classify.frag``).

Exits by topology (``rare_paths``' WALK_TOPO, ``tetra/walk_topo.glsl``; every mesh
without folded faces): seen along the ray, every corner is a point of the plane across
it, and which side of an edge the ray passes is the sign of an exact 2x2 determinant of
its corners' rounded positions, the same in every cell around the edge. A cell entered
by a face that holds the ray has exactly one other face that holds it; the walk leaves
by that one, and the segment runs from where the ray came in to where it crosses that
face's plane (none where that crossing is not ahead: a sliver's crossings out of order,
a zero-volume cell, a face the ray runs in). Rays through edges and vertices are ties,
broken by a perturbation of the ray the same way in every cell (simulation of
simplicity), towards the mesh's centre (so a ray in a boundary face of a convex part
goes in, as projection leans it). So slivers, cells of zero volume and rays along faces
need no rules of their own, and the walk cannot lose its way where the planes' float32
crossings disagree (Delaunay meshes of lattice points: 0.03 to 0.15 off before). Near an
edge of a boundary face the entry pass, too, asks the signs.

Otherwise (folded faces, or an eye on a vertex of more than ``walk_entries.EYE_CELLS``
cells), the planes decide: rays through edges and vertices take the first of tied
leaving planes, the cells around the edge or vertex then passed with empty segments
(each has one leaving plane at the tie). Zero-volume cells have planes without a side:
the ray passes one through the face whose triangle holds its crossing, into a cell it
enters there; cells too thin for float32 to order their crossings are passed as
zero-volume ones (``walk_flat``). Folded cells (both cells of a face on one side of it):
the walk never steps back across the face it came in by, a folded face is an entry face
too, and a cell that offers no way on hands the ray to a folded neighbour that holds it
further; the overlap is then counted once, as the exact image counts it.

Guards (a cycle made by rounding): more steps in a layer than the mesh has cells
(``max_steps``), or 512 in a row that take the ray no further, end the ray, counted per
pixel (``walk_counts``). Entries are taken in the order of (t, cell), each layer
strictly after the last, so peeling cannot repeat an entry; it is bounded by
``MAX_PASSES`` (the pixels still having an entry then are counted in
``TetraPlan.walk_left``, with a warning).

A perspective eye inside the mesh: the cell that holds it is found on the CPU (float64,
once per view), and the first layer starts every ray there; where the eye lies on a
face, an edge or a vertex of that cell (``walk_entries.eye_clear_of_faces``), rays from
it may miss the cell, and each starts in the first of the cells around the eye
(``cells_around_eye``) that holds it by the topology's signs (none: an eye on the
boundary, the ray going out, which may enter again in the next layer). An orthographic view whose
start plane cuts the mesh: the faces of the cells it cuts (found per view,
``start_faces``) are drawn in the first entry pass too, each fragment taking t = 0 in
its cell where its ray starts inside it. Not done: meshes of 2^24 cells or more
(``WalkUnsupported``).
"""

from __future__ import annotations

import warnings

import numpy as np

from ..model.mesh import topology
from .common import (bind, camera_uniforms, clip_uniforms, data_projection, grow_pixels, knot_uniforms,
                     sample_term_uniforms)
from .geometry import draw_surface_behind, surface_pass
from .gpu import empty_vao, pixel_stage, rows_top_down
from . import walk_entries
from .walk_entries import (EYE_CELLS, MARK_GAP, StartFaces, WalkTargets, cells_around_eye, depth_scale, entries,
                           eye_cell, eye_clear_of_faces, first_entries, layer_depth, mark_alive, start_faces)

MAX_PASSES = 256           # layers of depth peeling (entries along one ray) at most
HIDDEN_FRACTION = 0.5      # walk only the cells the TF shows where it hides this share (walked_cells)
MAX_CELLS = 1 << 24        # cell numbers travel as float32 (MIN blending): exact below 2^24
IN_PLACE = True            # the fragment stage's walk in place (False: two targets in turn)
EXITS_BY_TOPOLOGY = True   # walk_topo.glsl's exits where the mesh and view allow (False: the planes' everywhere)


class WalkUnsupported(ValueError):
    """A scene the cell walk does not render yet (the message says what to use)."""


def check_scene(scene):
    """Raise ``WalkUnsupported`` for what the walk does not do yet."""
    mesh = scene.volume
    if mesh.n_tets >= MAX_CELLS:
        raise WalkUnsupported(f"sort='walk' takes meshes of fewer than {MAX_CELLS} tets, got {mesh.n_tets}; "
                              "use sort='centroid'")


SEGMENTS = ("exact", "table")


def check_table_segments(scene, sort, segments):
    """``segments="table"`` (``model.segment_table``) is the walk's, for composite
    emission-absorption without per-cell light or illustration terms; else a clear error."""
    if segments not in SEGMENTS:
        raise ValueError(f"segments must be one of {', '.join(SEGMENTS)}, got {segments!r}")
    if segments == "exact":
        return
    if sort != "walk":
        raise ValueError(f"segments='table' is the cell walk's (sort='walk'), got sort={sort!r}")
    if scene.mode != "composite" or scene.optical_model != "emission_absorption":
        raise ValueError(f"segments='table' integrates composite emission-absorption segments, got mode="
                         f"{scene.mode!r}, optical_model={scene.optical_model!r}")
    if scene.shading or scene.illustration or scene.tf_2d is not None:
        raise ValueError("segments='table' takes a 1D TF without shading or illustration terms; use "
                         "segments='exact'")


def segment_table_texture(renderer, tf):
    """The TF's ``model.segment_table.SegmentTable`` (kept per TF) and its (ENTRIES, 2)
    RGBA32F texture, read with texelFetch."""
    from ..model.segment_table import SegmentTable
    table = renderer.tables.get("segment_table", tf, make=SegmentTable)

    def make():
        tex = renderer.ctx.texture((table.size, 2), 4, table.texture_rows().tobytes(), dtype="f4")
        tex.filter = (renderer.ctx.NEAREST, renderer.ctx.NEAREST)
        return tex
    return table, renderer.resources.for_objects("tetra_walk_segment_table", table, make=make, capacity=2)


# A cell thinner than this times the mesh's diagonal is passed as a zero-volume one. The
# walk's crossings are float32 (planes and eye relative to the mesh's corner): their t
# is rounded by some 1e-7 of the diagonal (more for rays that graze a face), so in a
# thinner cell the entry can come out behind the exit and the step take a face the ray
# never crosses (Delaunay meshes of jittered or float32-stored lattice points have such
# slivers, and lost whole rays). Passed by its triangles instead (flatExit), the cell
# adds no segment: at most its height over the TF's unit distance of opacity, where the
# ray crosses it squarely. No NASA mesh has such a cell (the thinnest: 1.9e-5).
THIN = 1e-5


def walk_flat(mesh):
    """(M,) bool: the cells the walk passes by their triangles (walk.frag's FLAT): those
    of zero volume and those thinner than ``THIN`` of the diagonal (the smallest height,
    6 |V| over twice the largest face's area)."""
    flat = mesh._derived.get("walk_flat")
    if flat is None:
        topo = topology(mesh)
        p = (mesh.points - mesh.bounds[0])[topo.tets]
        vol6 = np.abs(np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0])))
        area2 = np.zeros(len(p))
        for a, b, c in ((1, 2, 3), (0, 2, 3), (0, 1, 3), (0, 1, 2)):
            area2 = np.maximum(area2, np.linalg.norm(np.cross(p[:, b] - p[:, a], p[:, c] - p[:, a]), axis=1))
        height = vol6 / np.maximum(area2, 1e-300)
        flat = mesh._derived["walk_flat"] = topo.flat | (height <= THIN * float(np.linalg.norm(mesh.extent)))
    return flat


def rare_paths(mesh):
    """walk.frag's switches for the rare cells this mesh has: WALK_FLAT (zero-volume or
    too thin: ``walk_flat``) and WALK_FOLDS (folded faces), each 0 where it has none; and
    WALK_TOPO, the exits by topology (tetra/walk_topo.glsl), for every mesh without folded
    faces (a folded pair covers part of space twice, which the topology cannot tell)."""
    folds = int(folded_faces(mesh).any())
    return {"WALK_FLAT": int(walk_flat(mesh).any()), "WALK_FOLDS": folds,
            "WALK_TOPO": int(EXITS_BY_TOPOLOGY and not folds)}


def exact_products(ctx):
    """Whether the GL keeps `precise` arithmetic (GL_ARB_gpu_shader5, core in 4.0): the
    topology's exact products (walk_topo.glsl) split floats in a way a compiler free to
    fold and fuse would undo. Without it the walk takes the planes' rule."""
    return ctx.version_code >= 400 or "GL_ARB_gpu_shader5" in ctx.extensions


def max_steps(mesh):
    """The step guard of one layer's walk: a walk that makes progress meets each cell at
    most once, so more steps than cells can only be a cycle made by rounding."""
    return int(mesh.n_tets) + 4


HULL = -2                  # neighbours(hull=True): across a boundary face on the convex hull
# After a walk through flat cells alone (no progress), the hull faces next to flat cells
# are tried again within this share of the diagonal of its t (walk_entry.frag)
HULL_WINDOW = 1e-4


def neighbours(mesh, walked=None, hull=False):
    """(M, 4) int32: the cell across each cell's local face k (the face opposite corner
    k), -1 on the boundary and where that cell is not in ``walked`` (a bool mask; None:
    every cell). ``hull``: ``HULL`` instead across the boundary faces that lie in a
    supporting plane of all the mesh's points (``Topology.on_hull``): a ray that leaves
    there has nothing left to enter (walk.frag)."""
    topo = topology(mesh)
    cells = topo.face_cells[topo.tet_faces]                  # (M, 4, 2)
    own = np.arange(mesh.n_tets)[:, None]
    across = np.where(cells[..., 0] == own, cells[..., 1], cells[..., 0])
    if walked is not None:
        across = np.where((across >= 0) & walked[np.maximum(across, 0)], across, -1)
    if hull:
        across = np.where(topo.on_hull[topo.tet_faces], HULL, across)
    return across.astype(np.int32)


def boundary_faces(mesh, walked=None):
    """The boundary faces of the walked cells (``walked``: a bool mask, None for all) as
    vertices of triangles, a structured array of position (float32, relative to the mesh's
    lower corner) and slot 4 * cell + local face: each walked cell's faces across which
    lies the boundary or a cell not walked, and the faces of folded cells (both cells of
    a face on one side of it, as some curvilinear grids have: the union of the two is then
    entered there, and neither cell's plane says the ray crosses into the other)."""
    topo = topology(mesh)
    cell, local = boundary_slots(mesh, walked)
    vertex = np.dtype([("position", "f4", 3), ("slot", "i4")])
    out = np.zeros((len(cell), 3), vertex)
    out["position"] = (mesh.points - mesh.bounds[0])[topo.faces[topo.tet_faces[cell, local]]]
    out["slot"] = (4 * cell + local)[:, None]
    return out.reshape(-1)


def boundary_slots(mesh, walked=None):
    """(cells, local faces) of ``boundary_faces``, in its order (by cell)."""
    cell, local = np.nonzero((neighbours(mesh, walked) < 0) | folded_faces(mesh))
    if walked is not None:
        keep = walked[cell]
        cell, local = cell[keep], local[keep]
    return cell, local


def reentry_faces(mesh, walked=None):
    """int32 indices of the vertices of ``boundary_faces`` that are not on the convex hull
    (``Topology.on_hull``): after the first layer, a ray enters again only through them (it
    was inside every supporting plane and left one, which it cannot cross back). And those
    that share a point with a boundary face of a flat cell (``walk_flat``), where the walk
    is by topology (``rare_paths``): a walk through flat cells alone that leaves by the
    boundary is no progress (walk.frag), and the next layer tries the other entries at its
    t, on the hull too."""
    topo = topology(mesh)
    cell, local = boundary_slots(mesh, walked)
    face = topo.tet_faces[cell, local]
    keep = ~topo.on_hull[face]
    flat = walk_flat(mesh)[cell]
    if flat.any() and rare_paths(mesh)["WALK_TOPO"]:     # (the planes' rule never takes them)
        near_flat = np.zeros(mesh.n_points, bool)
        near_flat[topo.faces[face[flat]].ravel()] = True
        keep |= near_flat[topo.faces[face]].any(axis=1)
    keep = np.flatnonzero(keep)
    return (3 * keep[:, None] + np.arange(3)).astype(np.int32).reshape(-1)


def folded_faces(mesh):
    """(M, 4) bool: the cell's local face is shared with a cell on the same side of it
    (their planes there point the same way rather than opposite ways), both with a volume."""
    topo = topology(mesh)
    own = np.arange(mesh.n_tets)[:, None]
    is_first = topo.face_cells[topo.tet_faces, 0] == own
    sign = np.zeros((len(topo.faces), 2))      # per face: each of its cells' sign
    sign[topo.tet_faces[is_first], 0] = topo.tet_face_sign[is_first]
    sign[topo.tet_faces[~is_first], 1] = topo.tet_face_sign[~is_first]
    a, b = topo.face_cells[:, 0], topo.face_cells[:, 1]
    # a zero-volume cell's planes have no side (walk.frag passes such cells by their triangles)
    flat = walk_flat(mesh)
    solid = (b >= 0) & ~flat[a] & ~flat[np.maximum(b, 0)]
    folded = solid & (sign[:, 0] == sign[:, 1])
    return folded[topo.tet_faces]


def walked_cells(mesh, visible):
    """Composite: the cells a ray is walked through, a bool mask, or None for all. A cell
    the TF hides adds nothing, so where the TF hides at least ``HIDDEN_FRACTION`` of the
    cells, only those it shows (``visible``, found once per TF) and the zero-volume ones
    (they join shown cells) are walked: the walked region's boundary is then where rays
    enter and leave, as the mesh's is. Fewer cells are walked, but the region has more
    holes, and each re-entry costs a layer of depth peeling (two draws of the entry faces
    and a full-screen pass): scattered hidden cells are cheaper to walk through."""
    if len(visible) > (1.0 - HIDDEN_FRACTION) * mesh.n_tets:
        return None
    walked = walk_flat(mesh).copy()
    walked[visible] = True
    return walked


class WalkTextures:
    """The walk's data beyond tetra's, per mesh and set of walked cells: the face
    neighbours (RGBA32I texture, one texel per cell; ``HULL`` across hull faces), the
    boundary faces (a vertex buffer) and those off the convex hull (an index buffer)."""

    def __init__(self, ctx, mesh, texture, walked=None):
        self.neighbours = texture(ctx, neighbours(mesh, walked, hull=True), "i4")
        faces = boundary_faces(mesh, walked)
        self.face_vertices = len(faces)
        self.faces = ctx.buffer(faces.tobytes())
        reentry = reentry_faces(mesh, walked)
        self.reentry_vertices = len(reentry)
        self.reentry = ctx.buffer(reentry.tobytes()) if len(reentry) else None
        self.vaos = {}
        self.layers_drawn = 0       # layers the last draw found entries in (draw: drawn without waiting)

    def vao(self, ctx, prog, reentry=False):
        """(vertex array, vertices): the boundary faces, or (``reentry``) those that are
        not on the convex hull (``reentry_faces``; None where there are none)."""
        if reentry and self.reentry is None:
            return None
        vao = self.vaos.get((prog.glo, reentry))
        if vao is None:
            content = [(self.faces, "3f 1i", "a_position", "a_slot")]
            vao = self.vaos[prog.glo, reentry] = (ctx.vertex_array(prog, content, self.reentry, 4) if reentry
                                                  else ctx.vertex_array(prog, content))
        return vao, self.reentry_vertices if reentry else self.face_vertices

    def release(self):
        for vao in self.vaos.values():
            vao.release()
        self.neighbours.release()
        self.faces.release()
        if self.reentry is not None:
            self.reentry.release()


def draw(renderer, plan, data, texture):
    """Render a ``sort="walk"`` plan into the renderer's target; returns that framebuffer.
    ``data``: tetra's per-mesh textures (``tetra.MeshTextures``: planes, field, points,
    cells), ``texture``: tetra's maker of long tables as textures (``tetra._texture``).
    Sets ``plan.walk_passes`` (layers walked, with or without entries) and ``plan.walk_left`` (pixels still having
    an entry after ``MAX_PASSES``; 0 unless the cap was reached)."""
    from .common import cleared_target
    ctx = renderer.ctx
    scene = plan.scene
    mesh = scene.volume
    composite = scene.mode == "composite"
    fbo = cleared_target(renderer, scene, plan.target)
    surfaces = surface_pass(renderer, scene) if scene.geometry else None
    plan.walk_passes, plan.walk_left = 0, 0
    if plan.draw.size == 0:
        if surfaces is not None:
            fbo.use()
            draw_surface_behind(renderer, surfaces)
        return fbo
    width, height = scene.target_size
    # composite walks the cells the TF shows (found once per mesh and TF); the reductions
    # count every cell
    shown = (scene.tf,) if composite else ("every cell",)
    walked = renderer.tables.get("tetra_walk_cells", mesh, *shown, make=lambda m, *_: walked_cells(
        m, plan.visible) if composite else None)
    walk = renderer.resources.for_objects("tetra_walk_mesh", mesh, *(shown if walked is not None else ()),
                                          make=lambda: WalkTextures(ctx, mesh, texture, walked), capacity=1)
    flags = renderer.resources.for_objects("tetra_walk_flags", mesh, *shown, make=lambda: texture(
        ctx, cell_flags(mesh, plan.visible if composite else None), "u1"), capacity=1)
    targets = renderer.resources.get("tetra_walk_targets", (width, height),
                                     lambda: WalkTargets(ctx, width, height), capacity=1)
    start = -1
    if not scene.camera.is_ortho:
        planes = renderer.tables.get("tetra_walk_planes", mesh, make=lambda m: topology(m).cell_planes())
        start = renderer.tables.get("tetra_walk_eye_cell", mesh, scene.camera,
                                    make=lambda m, cam: eye_cell(m, cam, planes, walk_flat(m)))
        if walked is not None and start >= 0 and not walked[start]:
            start = -1       # the eye in a cell not walked: rays start at their first entry
    rare = dict(renderer.tables.get(f"tetra_walk_rare_paths:{EXITS_BY_TOPOLOGY}", mesh, make=rare_paths))
    if not exact_products(ctx):
        rare["WALK_TOPO"] = 0    # the topology's signs need arithmetic the compiler leaves as written
    around = None                        # the cells around an eye on a face, an edge or a vertex
    if start >= 0 and rare["WALK_TOPO"] and not eye_clear_of_faces(mesh, scene.camera, planes, start):
        around = renderer.tables.get("tetra_walk_eye_cells", mesh, scene.camera,
                                     make=lambda m, cam: cells_around_eye(m, cam, planes, start, walk_flat(m)))
        if around is None:
            rare["WALK_TOPO"] = 0        # more than walk.frag takes: the planes' rule
    around = np.zeros(0, np.int32) if around is None else around
    start_cells = np.resize(np.append(around, 0), EYE_CELLS).astype("i4").tobytes()
    view = {**({"ORTHO": 1} if scene.camera.is_ortho else {}), "WALK_TOPO": rare["WALK_TOPO"]}
    compute = pixel_stage(renderer, plan.stage) == "compute"
    # the fragment stage's walk in place where the GL has image load/store (4.2)
    in_place = not compute and IN_PLACE and ctx.version_code >= 420
    entry_prog = renderer.programs.get("tetra/walk_entry.vert", "tetra/walk_entry.frag", view,
                                       geometry="tetra/walk_entry.geom")
    # the first layer's entries in one draw (DEPTH_PICK) where no start faces are drawn
    pick_prog = None
    if walk_entries.FIRST_LAYER_PICK:
        pick_prog = renderer.programs.get("tetra/walk_entry.vert", "tetra/walk_entry.frag", dict(view, DEPTH_PICK=1),
                                          geometry="tetra/walk_entry.geom")
    mark_prog = renderer.programs.get("tetra/walk_layer.vert", "tetra/walk_mark.frag")
    walk_defines = {**plan.defines, **rare,
                    **({"IN_PLACE": 1} if in_place else {})}
    walk_prog = (renderer.programs.compute("tetra/walk.frag", walk_defines) if compute else
                 renderer.programs.get("tetra/walk_layer.vert", "tetra/walk.frag", walk_defines))
    diagonal = float(np.linalg.norm(mesh.extent))
    scale = depth_scale(scene)         # t to window depth (DEPTH_PICK), and the entry passes' windows
    view_proj = data_projection(scene, near=None if scene.camera.is_ortho else
                                1e-6 * diagonal).astype("f4").tobytes()
    cam = camera_uniforms(scene)
    starts = start_faces(mesh, scene.camera, walked, walk_flat(mesh))
    start_prog = None if starts is None else renderer.programs.get(
        "tetra/walk_entry.vert", "tetra/walk_entry.frag", dict(view, START_FACES=1), geometry="tetra/walk_entry.geom")
    for prog in (p for p in (entry_prog, pick_prog, start_prog) if p is not None):
        bind(prog, {}, {**cam, "u_target_size": scene.target_size, "u_inflate": grow_pixels(ctx),
                        "u_centre": data.centre, "u_start_margin": 1e-6 * diagonal})
        prog["u_view_proj"].write(view_proj)
    walk_uniforms = {**cam, "u_centre": data.centre, "u_reach": diagonal, "u_knot_count": plan.knots.count,
                     "u_inv_unit": plan.knots.inv_unit, "u_max_steps": max_steps(mesh), **clip_uniforms(scene)}
    if scene.shading or scene.illustration:
        walk_uniforms.update(sample_term_uniforms(renderer, scene, plan.defines))
    knot_uniforms(walk_prog, plan.knots, plan.defines["KNOT_CAPACITY"])
    extra_textures = {}
    if plan.defines.get("SEGMENT_TABLE"):
        table, extra_textures["t_segment_table"] = segment_table_texture(renderer, scene.tf)
        walk_uniforms.update(u_table_lo=table.lo, u_table_hi=table.hi, u_table_scale=table.scale,
                             u_table_size=table.size)
    faces = walk.vao(ctx, entry_prog)
    reentry = walk.vao(ctx, entry_prog, reentry=True)
    start_vao = None
    if starts is not None:
        start_vao = (start_prog, renderer.resources.for_objects(
            "tetra_walk_start", make=lambda: StartFaces(ctx), capacity=1).vao(start_prog, starts), len(starts))
    # one occlusion query a layer: read after the frame's one wait, they say how many
    # layers had entries without waiting again
    queries = renderer.resources.get("tetra_walk_queries", ("samples", MAX_PASSES), lambda: [
        ctx.query(samples=True) for _ in range(MAX_PASSES + 1)], capacity=None)

    ctx.disable(ctx.DEPTH_TEST | ctx.CULL_FACE | ctx.BLEND)
    for i in range(1 if in_place else 2):      # a pixel without an entry is never walked (not even copied)
        targets.acc_only[i].use()
        targets.acc_only[i].clear(-3.0e38 if scene.mode in ("mip", "minip") else 0.0, 0.0, 0.0, 0.0)
        targets.state_only[i].use()
        targets.state_only[i].clear(0.0, -1.0, 0.0, 0.0)     # stopped at t = 0, no entry yet
    # every pixel walks in the first layer from the eye's cell
    targets.marks_fbo.clear(depth=layer_depth(0) if start >= 0 else 1.0)
    # the marks: the entry passes' early depth test (both stages), and the fragment stage's walk's
    marker = (mark_prog, empty_vao(renderer, mark_prog))
    src = 0
    # as many layers as the last frame found entries in are drawn without waiting for
    # their entry counts (a layer without entries leaves every pixel as it was): one wait
    # a frame
    counted_from = min(walk.layers_drawn, MAX_PASSES)
    entered = []            # the layers' queries, each counting the pixels with an entry
    ties = 0.0              # the next entry pass's u_tie_window (after first_entries)
    hull_window = HULL_WINDOW * diagonal
    touch = walk_entries.touch_window(scale)
    for layer in range(MAX_PASSES + 1):
        first_from_eye = layer == 0 and start >= 0
        if first_from_eye:
            entered.append(None)
        elif layer > 0 and reentry is None:     # convex: nothing to enter again
            break
        else:
            starting = layer == 0 and start_vao is not None
            count = "pixels" if layer == MAX_PASSES else layer >= counted_from
            query = queries[layer]
            entered.append(query)
            if layer == 0 and pick_prog is not None and start_vao is None:
                found = first_entries(ctx, pick_prog, walk.vao(ctx, pick_prog), data, flags, targets, src, query,
                                      count, marker, scale)
                ties = walk_entries.tie_window(scale)
            else:
                found = entries(ctx, entry_prog, faces if layer == 0 else reentry, data, flags, targets, src,
                                query, start_vao if starting else None, count, layer, marker, walk.neighbours,
                                ties, -1.0 if layer == 0 else hull_window, touch)
                ties = 0.0
            if found == 0 and count:
                break
            if layer == MAX_PASSES:         # the cap: what is left is counted, not walked
                plan.walk_left = int(query.samples)
                warnings.warn(f"tetra walk: {plan.walk_left} pixels still had an entry after {MAX_PASSES} layers "
                              "of depth peeling, and their rays were cut there (sort='mpvo' has no such cap)",
                              RuntimeWarning, stacklevel=2)
                break
        dst = src if in_place else 1 - src
        (targets.in_place if in_place else targets.layers[dst]).use()
        textures = {"t_planes": data.planes, "t_field": data.field, "t_neighbours": walk.neighbours, "t_flags": flags,
                    "t_tets": data.tets, "t_points": data.points, "t_entry_t": targets.entry_t,
                    "t_entry_cell": targets.entry_cell, **extra_textures}
        if surfaces is not None:
            textures["t_surface"] = surfaces
        if not in_place:    # in place the images are read and written; no sampler reads them
            textures.update(t_acc=targets.acc[src], t_state=targets.state[src])
        else:
            targets.acc[src].bind_to_image(0, read=True, write=True)
            targets.state[src].bind_to_image(1, read=True, write=True)
        bind(walk_prog, textures, {**walk_uniforms, "u_start_cell": start if first_from_eye else -1,
                                   "u_start_count": len(around) if first_from_eye else 0,
                                   "u_start_cells": start_cells,
                                   "u_acc_image": 0, "u_state_image": 1})
        if compute:
            targets.acc[dst].bind_to_image(0, read=False, write=True)
            targets.state[dst].bind_to_image(1, read=False, write=True)
            walk_prog["u_target_size"].value = (width, height)
            walk_prog.run((width + 7) // 8, (height + 7) // 8)
        elif first_from_eye:
            empty_vao(renderer, walk_prog).render(ctx.TRIANGLES, vertices=3)
        else:
            # in place: only the pixels that have an entry in this layer; else also those
            # whose walk ended in the last layer (their result is copied into this layer's
            # targets, as the layer after skips them). The test is early (walk.frag neither
            # discards nor writes depth; in place, it says so): llvmpipe then skips the
            # blocks without such pixels, and runs the walk's loops for those it has only.
            ctx.enable(ctx.DEPTH_TEST)
            ctx.depth_func = ">="
            walk_prog["u_layer_depth"].value = layer_depth(layer if in_place else max(layer - 1, 0)) + MARK_GAP
            empty_vao(renderer, walk_prog).render(ctx.TRIANGLES, vertices=3)
            ctx.disable(ctx.DEPTH_TEST)
            ctx.depth_func = "<"
        if compute or in_place:
            ctx.memory_barrier()        # the images' stores, before the next pass reads them
        alive = None
        if layer < MAX_PASSES and reentry is not None:
            if first_from_eye:          # every pixel walked: as if each had an entry
                targets.entry_t_fbo.use()
                targets.entry_t_fbo.clear(0.0, 0.0, 0.0, 0.0)
            # the pixels whose ray goes on, the only ones the next layer's first entry draw
            # shades; counted where the next layer's entries would be: none, no next layer
            alive = mark_alive(ctx, targets, marker, layer, targets.state[dst], queries[MAX_PASSES],
                               layer + 1 >= counted_from)
        src = dst
        plan.walk_passes += 1
        if alive == 0:
            break
    # the layers with entries (their counts are ready: a later layer's count was waited for)
    walk.layers_drawn = 1 if reentry is None else sum(1 for q in entered if q is None or q.samples > 0)
    ctx.disable(ctx.BLEND)
    fbo.use()
    if composite:
        resolve = renderer.programs.get("tetra/fullscreen.vert", "tetra/walk_resolve.frag",
                                        {"GEOMETRY": 1} if surfaces is not None else {})
        textures = {"t_acc": targets.acc[src]}
    else:
        resolve = renderer.programs.get("tetra/fullscreen.vert", "tetra/tetra_classify.frag",
                                        {k: v for k, v in plan.defines.items()
                                         if k in ("KNOT_CAPACITY", "MODE_MINIP", "MODE_AVERAGE", "GEOMETRY")})
        textures = {"t_reduced": targets.acc[src]}
        bind(resolve, {}, {"u_knot_count": plan.knots.count})
        knot_uniforms(resolve, plan.knots, plan.defines["KNOT_CAPACITY"])
    if surfaces is not None:
        textures["t_surface"] = surfaces
    bind(resolve, textures, {"u_rows_top_down": rows_top_down(renderer, fbo)})
    empty_vao(renderer, resolve).render(ctx.TRIANGLES, vertices=3)
    plan.walk_state = targets.state[src]
    return fbo


def cell_flags(mesh, visible):
    """(M, 1) uint8 per cell: 1 (SHOWN in walk.frag) for the cells in ``visible`` (all
    cells when None), plus 2 (FLAT) for the cells ``walk_flat`` gives, plus 4 << k where local face k
    is folded (``folded_faces``)."""
    flags = np.zeros((mesh.n_tets, 1), np.uint8)
    flags[visible if visible is not None else slice(None)] = 1
    flags[walk_flat(mesh), 0] |= 2
    flags[:, 0] |= (folded_faces(mesh) * (4 << np.arange(4))).sum(axis=1).astype(np.uint8)
    return flags


def walk_counts(renderer, plan):
    """(cells visited per pixel, pixels whose walk hit the step guard) in the last
    ``draw`` of ``plan``, read back from the state texture: a test and diagnostic helper,
    not on the frame's path. Cells visited counts one more per layer (the step that ends it)."""
    from ..gl.context import current
    with current(renderer.ctx):
        state = np.frombuffer(plan.walk_state.read(), np.float32).reshape(-1, 4)
    return state[:, 2].astype(np.int64), int((state[:, 3] > 0).sum())
