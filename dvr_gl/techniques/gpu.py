"""What the techniques keep on the GPU between frames: textures of the scene's data and
tables, render targets and vertex arrays, each made on first use by a function here and
kept in the renderer's store (``renderer.resources``, ``dvr_gl.gl.resources``) under its
kind and key, as many of each kind as its capacity says. What one technique alone uses
is made in its own module the same way."""

from __future__ import annotations

import numpy as np

from ..gl.resources import Target, VertexStream, texture3d
from ..util.cache import IdentityKey


def volume_texture(renderer, volume):
    """The samples as a float32 3-D texture in data units (exact for 8- and 16-bit
    integers), linear filtered; kept for the 2 most recent volumes."""
    store = renderer.resources

    def make():
        values = volume.values(np.float32)
        return store.made("volume", values.shape, texture3d(renderer.ctx, values, 1, "f4", linear=True))
    return store.get("volume", IdentityKey(volume), make, capacity=2)


def cell_valid_texture(renderer, volume):
    """The volume's masked cells (``Volume.cell_valid``) as a nearest-filtered 3-D texture,
    255 where a cell is valid; kept for the 2 most recent volumes."""
    store = renderer.resources

    def make():
        mask = volume.cell_valid.astype(np.uint8) * 255
        return store.made("cell_valid", mask.shape, texture3d(renderer.ctx, mask, 1, "f1", linear=False))
    return store.get("cell_valid", IdentityKey(volume), make, capacity=2)


def gradient_texture(renderer, volume):
    """The volume's sample gradients as an RGB32F 3D texture, kept with the volume."""
    from ..model.field import sample_gradients

    def make():
        g = sample_gradients(volume, volume.values(np.float64)).astype(np.float32)
        return texture3d(renderer.ctx, g, 3, "f4", linear=True)
    return renderer.resources.for_objects("gradient", volume, make=make)


def tf_texture(renderer, lut):
    """A LookupTable's rows (``texture_rows``: RGBA, then the transparency) as a
    nearest-filtered RGBA32F texture; kept for the 4 most recent tables."""
    store = renderer.resources

    def make():
        tex = renderer.ctx.texture((lut.size, 2), 4, lut.texture_rows().tobytes(), dtype="f4")
        tex.filter = (renderer.ctx.NEAREST, renderer.ctx.NEAREST)
        return store.made("tf", lut.table.shape, tex)
    return store.get("tf", IdentityKey(lut), make, capacity=4)


def tf2d_texture(renderer, tf_2d):
    """A TransferFunction2D's table and transparency rows (``texture_rows``) as an
    RGBA32F texture read with texelFetch, kept with the function."""
    def make():
        rows = tf_2d.texture_rows()
        tex = renderer.ctx.texture((rows.shape[1], rows.shape[0]), 4, rows.tobytes(), dtype="f4")
        tex.filter = (renderer.ctx.NEAREST, renderer.ctx.NEAREST)
        return tex
    return renderer.resources.for_objects("tf2d", tf_2d, make=make)


def preintegration_texture(renderer, table, fine=None):
    """The table's texture (``PreintegrationTable.texture_rows``); with ``fine`` (the
    refined parts' table, raycast), that one's rows follow below
    (``preintegratedSegmentIn``). Kept for the 2 most recent pairs."""
    store = renderer.resources

    def make():
        rows = [table.texture_rows()] + ([] if fine is None else [fine.texture_rows()])
        data = np.ascontiguousarray(np.concatenate(rows))
        tex = renderer.ctx.texture((table.size, data.shape[0]), 4, data.tobytes(), dtype="f4")
        # linear for texture() where the filter is exact; texelFetch ignores it
        tex.filter = (renderer.ctx.LINEAR, renderer.ctx.LINEAR)
        tex.repeat_x = tex.repeat_y = False
        return store.made("preintegration", (table.size, table.size), tex)
    return store.get("preintegration", IdentityKey(table, fine), make, capacity=2)


STAGES = ("auto", "fragment", "compute")


def check_stage(stage):
    """``stage``: where a per-pixel ray shader runs, one of STAGES."""
    if stage not in STAGES:
        raise ValueError(f"stage must be one of {', '.join(STAGES)}, got {stage!r}")


INTERPOLATIONS = ("exact", "texture_unit")


def check_interpolation(interpolation, bricked):
    """``interpolation``: one of INTERPOLATIONS; "texture_unit" is for one texture."""
    if interpolation not in INTERPOLATIONS:
        raise ValueError(f"interpolation must be one of {', '.join(INTERPOLATIONS)}, got {interpolation!r}")
    if interpolation == "texture_unit" and bricked:
        raise ValueError("interpolation 'texture_unit' does not yet take bricks (brick_size, or a LazyVolume)")


def pixel_stage(renderer, stage):
    """"fragment" or "compute" for a per-pixel ray shader with the option ``stage``: "auto"
    takes the one the renderer measured faster on its GPU (``Renderer.compute_stage_faster``:
    llvmpipe runs fragment shaders faster; GPUs whose graphics pipeline reaches only some
    of their cores run compute shaders far faster); "compute" needs GL 4.3."""
    if stage == "auto":
        return "compute" if renderer.compute_stage_faster else "fragment"
    if stage == "compute" and renderer.ctx.version_code < 430:
        raise ValueError(f"stage 'compute' needs OpenGL 4.3; this context has "
                         f"{renderer.ctx.version_code // 100}.{renderer.ctx.version_code % 100 // 10}")
    return stage


def target_fbo(renderer, width, height, dtype, kind="target", components=4):
    """A framebuffer with one texture of ``components`` channels of ``dtype`` (RGBA for
    images), kept per size and ``kind`` (the image's own, or a technique's auxiliary
    pass); the 6 most recent of all kinds are kept."""
    store = renderer.resources
    return store.get("target", (kind, width, height, dtype, components), lambda: store.made(
        kind, (height, width, dtype), Target(renderer.ctx, width, height, dtype, components, store.idle)),
        capacity=6).fbo


def rows_top_down(renderer, fbo):
    """Whether a pass that writes every pixel of ``fbo`` stores its rows top down: where
    the renderer reads the image back next (``Renderer._draw``), whose read then needs no
    flip. Every such pass sets its ``u_rows_top_down`` from this (its program is cached and
    shared, so a value left from another frame would flip the image)."""
    top_down = bool(getattr(renderer, "rows_top_down_wanted", False))
    renderer.top_down_target = fbo if top_down else None
    return top_down


def draw_ray_compute(renderer, prog, scene, dtype):
    """Run the compute build of a per-pixel ray shader (``ProgramCache.compute``) once per
    pixel of the renderer's target for this size and ``dtype`` (f4, f2, f1), which it writes whole;
    returns the framebuffer. Rows are stored top down where the renderer reads the image
    back next (``Renderer.read_target`` then copies no rows: a 1024x1024 float image's
    flip cost more than its ray casting on a GPU)."""
    ctx = renderer.ctx
    width, height = scene.target_size
    fbo = target_fbo(renderer, width, height, dtype)
    fbo.color_attachments[0].bind_to_image(0, read=False, write=True)
    prog["u_target_size"].value = (width, height)
    prog["u_rows_top_down"].value = int(rows_top_down(renderer, fbo))
    prog.run((width + 7) // 8, (height + 7) // 8)
    ctx.memory_barrier()
    return fbo


def proxy_vao(renderer, prog, kind):
    """``prog``'s vertex array over a proxy mesh (``PROXY_MESHES``) as attribute a_position."""
    store, ctx = renderer.resources, renderer.ctx
    vbo = store.get("proxy_vbo", kind, lambda: ctx.buffer(PROXY_MESHES[kind]().tobytes()), capacity=None)
    return store.get("vao", (prog.glo, kind), lambda: ctx.vertex_array(prog, [(vbo, "3f", "a_position")]),
                     capacity=None)


def empty_vao(renderer, prog):
    """A vertex array without attributes (vertex shaders that place vertices by
    gl_VertexID and gl_InstanceID)."""
    return renderer.resources.get("vao", (prog.glo, "empty"), lambda: renderer.ctx.vertex_array(prog, []),
                                  capacity=None)


def stream_vao(renderer, prog, name, positions, indices):
    """The vertex array of per-frame geometry ``name`` (``gl.resources.VertexStream``):
    float32 positions (n, 3) and int32 indices (n,) as attributes a_position and
    a_slice, written into a buffer that is kept and grows as needed."""
    stream = renderer.resources.get("stream", name, lambda: VertexStream(renderer.ctx), capacity=None)
    return stream.vertex_array(prog, positions, indices)


def _unit_cube_back_face_mesh():
    """36 vertices of the unit cube, every triangle wound counter-clockwise seen from
    outside (so culling front faces leaves the back faces)."""
    corners = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], np.float64)
    faces = [(0, 2, 6, 4), (1, 5, 7, 3), (0, 4, 5, 1), (2, 3, 7, 6), (0, 1, 3, 2), (4, 6, 7, 5)]
    tris = []
    centre = np.full(3, 0.5)
    for a, b, c, d in faces:
        for tri in ((a, b, c), (a, c, d)):
            p = corners[list(tri)]
            normal = np.cross(p[1] - p[0], p[2] - p[0])
            if np.dot(normal, p.mean(axis=0) - centre) < 0:
                p = p[::-1]
            tris.append(p)
    return np.array(tris, np.float32).reshape(-1, 3)


_FULLSCREEN = np.array([[-1, -1, 0], [3, -1, 0], [-1, 3, 0]], np.float32)

# the proxies of ``box_proxy``: the unit box's back faces, or one full-screen triangle
PROXY_MESHES = {"box": _unit_cube_back_face_mesh, "fullscreen": lambda: _FULLSCREEN}


def cull_for_proxy(ctx, kind):
    """A box proxy draws its back faces only (one fragment a pixel); a full-screen
    triangle is drawn whole."""
    if kind == "box":
        ctx.enable(ctx.CULL_FACE)
        ctx.cull_face = "front"
    else:
        ctx.disable(ctx.CULL_FACE)


def table_texture(ctx, rows):
    """An (n, 4) float32 table as an (n, 1) RGBA32F texture read with texelFetch."""
    tex = ctx.texture((len(rows), 1), 4, np.ascontiguousarray(rows, np.float32).tobytes(), dtype="f4")
    tex.filter = (ctx.NEAREST, ctx.NEAREST)
    return tex


def occupancy_texture(renderer, volume, tf, occupancy):
    """The bricks' occupancy for the volume and its TF (``brick_occupancy``) as a
    nearest-filtered 3-D texture, 255 where occupied; kept for the 4 most recent pairs."""
    store = renderer.resources

    def make():
        mask = occupancy.astype(np.uint8) * 255
        return store.made("occupancy", mask.shape, texture3d(renderer.ctx, mask, 1, "f1", linear=False))
    return store.get("occupancy", IdentityKey(volume, tf), make, capacity=4)


def jitter_texture(renderer, table):
    """The jitter offsets (a 2-D float32 table) as a texture, made again only for new values."""
    store = renderer.resources

    def make():
        tex = renderer.ctx.texture((table.shape[1], table.shape[0]), 1, table.astype("f4").tobytes(), dtype="f4")
        tex.filter = (renderer.ctx.NEAREST, renderer.ctx.NEAREST)
        return store.made("jitter", table.shape, tex)
    return store.get("jitter", (table.shape, table.tobytes()), make, capacity=None)
