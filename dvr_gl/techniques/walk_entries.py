"""The cell walk's entry passes (``techniques.tetra_walk``; shaders tetra/walk_entry.*,
tetra/walk_mark.frag): per layer of depth peeling, each pixel's nearest entry into the
walked cells beyond where its last walk stopped, t and cell, and the marks of the pixels
that have one; the per-image targets they and the walk draw into; and where rays from
an eye inside the mesh start (``eye_cell``, ``cells_around_eye``)."""

from __future__ import annotations

import math

import numpy as np

from ..model.mesh import topology
from .common import bind

NO_ENTRY = 3.0e38
MARK_LEVELS = 1024         # the marks' window depths (layer_depth, alive_depth) are 1/MARK_LEVELS apart
                           # (two a layer: tetra_walk.MAX_PASSES at most half of it)
MARK_GAP = 0.5 / MARK_LEVELS   # a test depth halfway to the last mark's: rounding-proof
FIRST_LAYER_PICK = True    # the first layer's entries in one draw by the depth test (False: two, as later layers)


def layer_depth(layer):
    """The window depth of the pixels that have an entry in ``layer``: falling by layer
    (and after ``alive_depth(layer - 1)``), so that ``depth <= layer_depth(L) + MARK_GAP``
    (the depth test) keeps the pixels marked in layer L or later; while layer L is drawn,
    no pixel has a later mark yet. A pixel without an entry has none in any later layer,
    so each layer's pixels are among the last's."""
    return 1.0 - (2 * layer + 1) / MARK_LEVELS


def alive_depth(layer):
    """The window depth of the pixels whose walk in ``layer`` left the mesh without ending
    (tetra_walk.py): only they can enter it again, so only they are shaded by the next
    layer's first entry draw."""
    return 1.0 - (2 * layer + 2) / MARK_LEVELS


class WalkTargets:
    """Per image size: two (accumulation, state) RGBA32F framebuffers used in turn, and
    the entry pass's two R32F targets (nearest t, its cell)."""

    def __init__(self, ctx, width, height):
        def tex(components):
            t = ctx.texture((width, height), components, dtype="f4")
            t.filter = (ctx.NEAREST, ctx.NEAREST)
            return t
        self.acc = [tex(4), tex(4)]
        self.state = [tex(4), tex(4)]
        # the layers' marks (layer_depth): written by the entry pass, tested by the next pixel pass
        self.marks = ctx.depth_renderbuffer((width, height))
        self.layers = [ctx.framebuffer([self.acc[i], self.state[i]], self.marks) for i in range(2)]
        # the walk in place stores into acc[0] and state[0] as images, and draws into nothing
        self.in_place = ctx.framebuffer([], self.marks)
        for fbo in (*self.layers, self.in_place):
            fbo.depth_mask = False
        self.acc_only = [ctx.framebuffer([t]) for t in self.acc]
        self.state_only = [ctx.framebuffer([t]) for t in self.state]
        self.entry_t, self.entry_cell = tex(1), tex(1)
        self.entry_t_fbo = ctx.framebuffer([self.entry_t])
        self.entry_marked_fbo = ctx.framebuffer([self.entry_t], self.marks)
        self.entry_cell_marked_fbo = ctx.framebuffer([self.entry_cell], self.marks)
        self.marks_fbo = ctx.framebuffer([], self.marks)
        for fbo in (self.entry_marked_fbo, self.entry_cell_marked_fbo):
            fbo.depth_mask = False
        self.entry_cell_fbo = ctx.framebuffer([self.entry_cell])
        self.entry_pick_fbo = ctx.framebuffer([self.entry_t, self.entry_cell], self.marks)   # (DEPTH_PICK)

    def release(self):
        for fbo in (*self.layers, self.in_place, *self.acc_only, *self.state_only, self.entry_t_fbo,
                    self.entry_marked_fbo, self.entry_cell_fbo, self.entry_cell_marked_fbo, self.entry_pick_fbo,
                    self.marks_fbo):
            fbo.release()
        self.marks.release()
        for t in (*self.acc, *self.state, self.entry_t, self.entry_cell):
            t.release()


def start_faces(mesh, camera, walked, flat):
    """Orthographic: the faces of the (walked, not ``flat``: passed by their triangles) cells that the rays'
    start plane cuts, as ``boundary_faces`` lays them out, or None when it cuts none: a
    ray starting inside one of them starts its walk there (walk_entry.frag, START_FACES)."""
    if not camera.is_ortho:
        return None
    topo = topology(mesh)
    depth = (mesh.points - camera.eye) @ camera.forward
    if not depth.min() < 0.0 < depth.max():
        return None
    d = depth[topo.tets]
    cut = (d.min(axis=1) < 0.0) & (d.max(axis=1) > 0.0) & ~flat
    if walked is not None:
        cut &= walked
    cell = np.repeat(np.flatnonzero(cut), 4)
    local = np.tile(np.arange(4), len(cell) // 4)
    vertex = np.dtype([("position", "f4", 3), ("slot", "i4")])
    out = np.zeros((len(cell), 3), vertex)
    out["position"] = (mesh.points - mesh.bounds[0])[topo.faces[topo.tet_faces[cell, local]]]
    out["slot"] = (4 * cell + local)[:, None]
    return out.reshape(-1)


class StartFaces:
    """The start faces' vertex buffer, rewritten per view, grown (never shrunk) as needed."""

    def __init__(self, ctx):
        self.ctx = ctx
        self.buffer = None
        self.vaos = {}

    def vao(self, prog, faces):
        if self.buffer is None or self.buffer.size < faces.nbytes:
            self.release()
            self.buffer = self.ctx.buffer(reserve=max(faces.nbytes, 1 << 16))
        self.buffer.write(faces.tobytes())
        vao = self.vaos.get(prog.glo)
        if vao is None:
            vao = self.vaos[prog.glo] = self.ctx.vertex_array(prog, [(self.buffer, "3f 1i", "a_position", "a_slot")])
        return vao

    def release(self):
        for vao in self.vaos.values():
            vao.release()
        self.vaos = {}
        if self.buffer is not None:
            self.buffer.release()
            self.buffer = None


def entries(ctx, prog, faces, data, flags, targets, src, query, start, count, layer, marker, neighbours,
            tie_window=0.0, hull_window=-1.0, touch_window=0.0):
    """The entry pass of ``layer``: each pixel's nearest eligible entry (t, then the
    smallest cell at that t) into ``targets.entry_t`` and ``entry_cell``, and the pixels
    that have one marked at ``layer_depth(layer)`` in ``targets.marks`` (``marker``: the
    marking program and its vertex array). ``faces``: (vertex array, vertices) of the
    boundary faces. ``query`` counts the pixels with an entry (the marking pass); ``count``:
    returns that count (0: none, and the second draw is then not made; a count waits for
    the GPU), else None.
    After the first layer both draws test the marks early (walk_entry.frag), so that only
    the pixels marked alive after the last layer's walk (the first draw; ``mark_alive``)
    or marked in this one (the second) are shaded. ``start``: (program, vertex array,
    vertices) of the start faces (orthographic rays that start inside the mesh; the
    program built with START_FACES), drawn too. ``neighbours``: the walk's texture
    (``HULL`` across hull faces). The windows (walk_entry.frag): ``tie_window``, in the
    layer after ``first_entries``, how close in t its depth test ties entries (the
    function ``tie_window``), else 0; ``hull_window``, in the re-entry layers, how near a
    stop of no progress a hull face among ``faces`` is tried again (-1: the first layer,
    every face); ``touch_window``, how far before a stop another part's entry is taken
    (the function ``touch_window``)."""

    def render(pick, textures, uniforms):
        for p, vao, vertices in ((prog, *faces), start) if start is not None else ((prog, *faces),):
            bind(p, textures, {**uniforms, "u_pick_cell": pick, "u_tie_window": tie_window,
                               "u_hull_window": hull_window, "u_touch_window": touch_window})
            vao.render(ctx.TRIANGLES, vertices=vertices)

    def entry_blending():
        ctx.enable(ctx.BLEND)
        ctx.blend_func = ctx.ONE, ctx.ONE
        ctx.blend_equation = ctx.MIN

    def depth_test(func):
        ctx.enable(ctx.DEPTH_TEST)
        ctx.depth_func = func

    entry_blending()
    textures = {"t_planes": data.planes, "t_flags": flags, "t_state": targets.state[src],
                "t_nearest": targets.entry_t, "t_tets": data.tets, "t_points": data.points,
                "t_neighbours": neighbours}
    try:
        targets.entry_t_fbo.use()
        targets.entry_t_fbo.clear(NO_ENTRY, NO_ENTRY, NO_ENTRY, NO_ENTRY)
        if layer > 0:
            depth_test(">=")      # the pixels marked in the last layer
        targets.entry_marked_fbo.use()
        # t_nearest is not read in this draw; bound to a texture not drawn into
        render(False, dict(textures, t_nearest=targets.entry_cell),
               {"u_test_depth": alive_depth(layer - 1) + MARK_GAP if layer > 0 else 0.5})
        ctx.disable(ctx.BLEND)
        if mark(ctx, targets, marker, layer, query, count) == 0:
            return 0
        entry_blending()
        targets.entry_cell_fbo.use()
        targets.entry_cell_fbo.clear(NO_ENTRY, NO_ENTRY, NO_ENTRY, NO_ENTRY)
        depth_test(">=")          # the pixels just marked
        targets.entry_cell_marked_fbo.use()
        render(True, textures, {"u_test_depth": layer_depth(layer) + MARK_GAP})
    finally:
        ctx.disable(ctx.BLEND | ctx.DEPTH_TEST)
        ctx.depth_func = "<"
        ctx.blend_equation = ctx.FUNC_ADD
        ctx.blend_func = ctx.ONE, ctx.ONE_MINUS_SRC_ALPHA
    return query.samples if count else None


def mark(ctx, targets, marker, layer, query, count, depth=None, state=None):
    """After a layer's entries, mark the pixels that have one at ``layer_depth(layer)`` in
    ``targets.marks`` (``marker``: the marking program and its vertex array), counted by
    ``query`` (an occlusion query); returns the count with ``count`` (which waits for the
    GPU), else None. ``depth`` and ``state`` (``mark_alive``): that depth instead, for the
    pixels among them whose ``state`` says the ray goes on. Leaves the depth test on."""
    ctx.enable(ctx.DEPTH_TEST)
    ctx.depth_func = "1"
    mark_prog, mark_vao = marker
    targets.marks_fbo.use()
    bind(mark_prog, {"t_entry_t": targets.entry_t, "t_state": state if state is not None else targets.entry_t},
         {"u_layer_depth": layer_depth(layer) if depth is None else depth, "u_alive": state is not None})
    with query:
        mark_vao.render(ctx.TRIANGLES, vertices=3)
    return query.samples if count else None


def mark_alive(ctx, targets, marker, layer, state, query, count):
    """After the walk of ``layer``: the pixels it walked whose ray left the mesh
    without ending, marked at ``alive_depth(layer)``, so that the next layer's first entry
    draw shades only them (``entries``). Returns their count with
    ``count`` (0: no later layer can have an entry), else None."""
    try:
        return mark(ctx, targets, marker, layer, query, count, alive_depth(layer), state)
    finally:
        ctx.disable(ctx.DEPTH_TEST)
        ctx.depth_func = "<"


def depth_scale(scene):
    """DEPTH_PICK's scale of t to window depth: a power of two (exact) that keeps every
    t along a ray through the mesh's box below 1 (t: distance from the eye, or from the
    orthographic rays' start plane)."""
    lo, hi = scene.volume.bounds
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    farthest = float(np.linalg.norm(corners - np.asarray(scene.camera.eye), axis=1).max())
    return 2.0 ** -math.frexp(max(farthest, 1e-30) * 1.01)[1]


def touch_window(scale):
    """How far before where the last walk left (t) another part's entry is still taken
    (walk_entry.frag): 2^-21 of the farthest t (``scale``: ``depth_scale``), 4 to 8 ulps there."""
    return 2.0 ** -21 / scale


def tie_window(scale):
    """How close in t ``first_entries``' depth test (window depth t * ``scale``, at least
    24 bits) may tie two entries: eight steps of its depth, for any rounding."""
    return 8.0 / (2.0 ** 24 * scale)


def first_entries(ctx, prog, faces, data, flags, targets, src, query, count, marker, scale):
    """The first layer's entry pass in one draw (walk_entry.frag, DEPTH_PICK): each
    pixel's nearest entry t and its cell by the depth test, then the marks (``mark``).
    ``faces``: (vertex array, vertices) of the boundary faces in the order of their cells.
    Returns the pixels with an entry with ``count``, else None."""
    try:
        ctx.disable(ctx.BLEND)
        ctx.enable(ctx.DEPTH_TEST)
        ctx.depth_func = "<"
        targets.entry_pick_fbo.use()
        targets.entry_pick_fbo.clear(NO_ENTRY, NO_ENTRY, NO_ENTRY, NO_ENTRY, depth=1.0)
        # t_nearest is not read in this draw; bound to a texture not drawn into
        bind(prog, {"t_planes": data.planes, "t_flags": flags, "t_state": targets.state[src],
                    "t_nearest": targets.acc[src], "t_tets": data.tets, "t_points": data.points},
             {"u_test_depth": 0.5, "u_depth_scale": scale, "u_pick_cell": False})
        faces[0].render(ctx.TRIANGLES, vertices=faces[1])
        return mark(ctx, targets, marker, 0, query, count)
    finally:
        ctx.disable(ctx.DEPTH_TEST)
        ctx.depth_func = "<"


EYE_CLEAR = 1e-5           # the eye this share of the diagonal inside its cell's faces: it holds every ray


def eye_clear_of_faces(mesh, camera, planes, cell):
    """Whether a perspective eye in ``cell`` lies at least ``EYE_CLEAR`` of the mesh's
    diagonal inside each of its face planes (``planes``: topology.cell_planes()): every
    line through it then crosses the cell, so the topology's signs hold each ray in the
    cell (walk_topo.glsl). Rays from an eye on a face, an edge or a vertex may, by the
    signs, miss the cell that holds the eye (those in the plane of that face, for one)."""
    eye = camera.eye - mesh.bounds[0]
    room = planes[cell, :, 3] - planes[cell, :, :3] @ eye
    return bool(room.min() >= EYE_CLEAR * float(np.linalg.norm(mesh.extent)))


EYE_CELLS = 64             # the cells around an eye on an edge or a vertex at most (tetra/walk.frag: u_start_cells)


def cells_around_eye(mesh, camera, planes, cell, flat):
    """int32 array: the cells (not ``flat``: tetra_walk.walk_flat, whose planes are one)
    that hold a perspective eye to within ``EYE_CLEAR`` of the mesh's diagonal (those
    around the face, edge or vertex it lies on), ``cell`` first; None where they are more
    than ``EYE_CELLS``. Each ray from the eye starts in the first of them that holds it
    by the topology's signs (walk.frag)."""
    margin = EYE_CLEAR * float(np.linalg.norm(mesh.extent))
    cells = np.concatenate([[cell], *_cells_holding(mesh, camera, planes, flat, margin)])
    cells = cells[np.sort(np.unique(cells, return_index=True)[1])]
    return cells.astype(np.int32) if len(cells) <= EYE_CELLS else None


def eye_cell(mesh, camera, planes, flat):
    """The first cell (not ``flat``: tetra_walk.walk_flat) that holds a perspective eye,
    or -1: float64, the cells' own planes (``planes``: topology.cell_planes())."""
    lo, hi = mesh.bounds
    if camera.is_ortho or np.any(camera.eye < lo) or np.any(camera.eye > hi):
        return -1
    for cells in _cells_holding(mesh, camera, planes, flat, 0.0):
        if len(cells):
            return int(cells[0])
    return -1


def _cells_holding(mesh, camera, planes, flat, margin):
    """The cells, not ``flat``, inside each of whose planes the eye lies to within
    ``margin``: one array per chunk of cells, in order (memory stays bounded)."""
    eye = camera.eye - mesh.bounds[0]
    for start in range(0, len(planes), 1 << 18):
        chunk = planes[start:start + (1 << 18)]
        hold = ((chunk[..., 3] - chunk[..., :3] @ eye) >= -margin).all(axis=1) & ~flat[start:start + len(chunk)]
        yield start + np.flatnonzero(hold)
