"""The GL renderer: one headless context, its program cache, and the GPU resources
scenes need (made on first use, kept while the scene's objects live, never per frame)."""

from __future__ import annotations


import numpy as np

from .gl.context import current, describe, idle_framebuffer, shared_context
from .gl.programs import ProgramCache
from .cache import LRU, IdentityKey as _Key, TableCache
from .techniques import get_technique


class Renderer:
    """Renders scenes with GLSL techniques into float images.

    >>> with Renderer(backend="auto") as r:          # doctest: +SKIP
    ...     img = r.render(scene, technique="raycast", step=None)

    ``img`` is (H, W, 4) float32 premultiplied RGBA, row 0 on top. The first render of a
    scene compiles and uploads; later ones reuse the programs, textures and targets.
    To work in the renderer's context yourself, enter it with
    ``dvr_gl.gl.context.current(renderer.ctx)``, not ``with renderer.ctx`` (moderngl's
    does not nest with the renderer's own).
    """

    def __init__(self, backend="auto", ctx=None):
        """``backend``: "auto" (EGL, then OSMesa), "egl" or "osmesa": a headless context
        shared by the process. ``ctx``: render in this moderngl context instead (a
        window's, as the viewer does); the caller keeps it current and owns it."""
        if ctx is not None:
            self.ctx, self.backend = ctx, "window"
        else:
            self.ctx, self.backend = shared_context(backend)
        self.programs = ProgramCache(self.ctx)
        self.created = []  # a log of ("texture kind", shape) for every texture made
        self._volumes = LRU(2)
        self._tfs = LRU(4)
        self._occupancy = LRU(4)
        self._masks = LRU(2)
        self._small = {}
        self._stacks = LRU(3)
        self._preint = LRU(2)
        self._streams = {}
        self._targets = LRU(3)
        self._vbos = {}
        self._vaos = {}
        self.tables = TableCache()
        self._resources = {}  # kind -> LRU: what techniques keep on the GPU (see resource)
        self._released = False
        self._idle_fbo = idle_framebuffer(self.ctx)  # bound before any target is released

    # -- lifetime ---------------------------------------------------------------------
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()

    def release(self):
        if self._released:
            return
        self._released = True
        with current(self.ctx):
            for cache in (self._volumes, self._tfs, self._occupancy, self._masks, self._targets, self._stacks,
                          self._preint, *self._resources.values()):
                cache.release()
            streams = [obj for pair in self._streams.values() for obj in pair[1:]]
            for obj in list(self._small.values()) + list(self._vaos.values()) + list(self._vbos.values()) + streams:
                obj.release()
            self._idle_fbo.use()
            self.programs.release()
        # The context itself is shared by the process's renderers and stays (see
        # gl.context.shared_context).

    def info(self) -> dict:
        with current(self.ctx):  # another library (VTK) may have made its own context current
            return dict(describe(self.ctx), backend=self.backend)

    # -- rendering --------------------------------------------------------------------
    def render(self, scene, technique="raycast", step=None, **options):
        """Render ``scene``; see the technique's module for its options."""
        with current(self.ctx):
            fbo = self._draw(scene, technique, step, options)
            return self.read_target(fbo, scene.width, scene.height)

    def render_target(self, scene, technique="raycast", step=None, **options):
        """Render into the renderer's float target and return that framebuffer, without
        reading it back (the viewer draws its colour attachment to the window). The
        framebuffer is reused by the next render of the same size and format."""
        with current(self.ctx):
            return self._draw(scene, technique, step, options)

    def _draw(self, scene, technique, step, options):
        if self._released:
            raise RuntimeError("this Renderer has been released")
        tech = get_technique(technique)
        plan = tech.make_plan(scene, step, tables=self.tables, **options)
        return tech.draw(self, plan)

    # -- resources (used by techniques) -------------------------------------------------
    def resource(self, kind, *objects, make, capacity=2):
        """What a technique keeps on the GPU for some scene objects (a mesh's textures, a
        TF's table): ``make()`` once while those objects stay among the ``capacity``
        most recent of this kind, released (if it has ``release``) when dropped and with
        the renderer. Objects are keyed by identity (scene objects are immutable)."""
        cache = self._resources.get(kind)
        if cache is None:
            cache = self._resources[kind] = LRU(capacity)

        def logged():
            value = make()
            self.created.append((kind, tuple(type(o).__name__ for o in objects)))
            return value
        return cache.get(_Key(kind, *objects), logged)

    def _texture3d(self, kind, array, components, dtype, linear):
        nz, ny, nx = array.shape[:3]
        tex = self.ctx.texture3d((nx, ny, nz), components, np.ascontiguousarray(array).tobytes(), dtype=dtype)
        f = self.ctx.LINEAR if linear else self.ctx.NEAREST
        tex.filter = (f, f)
        tex.repeat_x = tex.repeat_y = tex.repeat_z = False
        self.created.append((kind, array.shape))
        return tex

    def volume_texture(self, volume):
        """The samples as float32 in data units: exact for 8- and 16-bit integers."""
        return self._volumes.get(_Key(volume), lambda: self._texture3d(
            "volume", volume.values(np.float32), 1, "f4", linear=True))

    def cell_valid_texture(self, volume):
        return self._masks.get(_Key(volume), lambda: self._texture3d(
            "cell_valid", volume.cell_valid.astype(np.uint8) * 255, 1, "f1", linear=False))

    def occupancy_texture(self, volume, tf, occupancy):
        return self._occupancy.get(_Key(volume, tf), lambda: self._texture3d(
            "occupancy", occupancy.astype(np.uint8) * 255, 1, "f1", linear=False))

    def tf_texture(self, lut):
        def make():
            tex = self.ctx.texture((lut.size, 2), 4, lut.texture_rows().tobytes(), dtype="f4")
            tex.filter = (self.ctx.NEAREST, self.ctx.NEAREST)
            self.created.append(("tf", lut.table.shape))
            return tex
        return self._tfs.get(_Key(lut, "texture"), make)

    def stack_texture(self, volume, axis):
        """2-D slicing's stack along ``axis`` (0 = x, 1 = y, 2 = z): a texture array with one
        float32 layer per sample plane, each layer the plane's samples with the lower of
        the other two axes varying fastest. Made when a view first needs it, then kept."""
        def make():
            values = volume.values(np.float32)  # (z, y, x)
            layers = {0: values.transpose(2, 0, 1), 1: values.transpose(1, 0, 2), 2: values}[axis]
            layers = np.ascontiguousarray(layers)  # (layer, v, u)
            n, h, w = layers.shape
            tex = self.ctx.texture_array((w, h, n), 1, layers.tobytes(), dtype="f4")
            tex.filter = (self.ctx.LINEAR, self.ctx.LINEAR)
            tex.repeat_x = tex.repeat_y = False
            self.created.append(("stack", (axis, n, h, w)))
            return tex
        return self._stacks.get(_Key(volume, axis), make)

    def preintegration_texture(self, table):
        def make():
            tex = self.ctx.texture((table.size, table.size), 4, table.texture_bytes(), dtype="f4")
            tex.filter = (self.ctx.NEAREST, self.ctx.NEAREST)
            self.created.append(("preintegration", (table.size, table.size)))
            return tex
        return self._preint.get(_Key(table), make)

    def small_texture(self, kind, table):
        """A 2-D float32 table (jitter offsets), re-uploaded only when its values change."""
        key = (kind, table.shape, table.tobytes())
        tex = self._small.get(key)
        if tex is None:
            tex = self.ctx.texture((table.shape[1], table.shape[0]), 1, table.astype("f4").tobytes(), dtype="f4")
            tex.filter = (self.ctx.NEAREST, self.ctx.NEAREST)
            self.created.append((kind, table.shape))
            self._small[key] = tex
        return tex

    def target(self, width, height, dtype):
        def make():
            tex = self.ctx.texture((width, height), 4, dtype=dtype)
            self.created.append(("target", (height, width, dtype)))
            return _Target(self.ctx.framebuffer([tex]), tex, self._idle_fbo)
        return self._targets.get((width, height, dtype), make).fbo

    def read_target(self, fbo, width, height):
        """Read back as float32 (GL finishes before this returns), row 0 on top."""
        data = fbo.read(viewport=(0, 0, width, height), components=4, dtype="f4")
        return np.frombuffer(data, np.float32).reshape(height, width, 4)[::-1].copy()

    def proxy_vao(self, prog, kind):
        from .techniques.raycast import PROXY_MESHES
        vbo = self._vbos.get(kind)
        if vbo is None:
            vbo = self._vbos[kind] = self.ctx.buffer(PROXY_MESHES[kind]().tobytes())
        key = (prog.glo, kind)
        vao = self._vaos.get(key)
        if vao is None:
            vao = self._vaos[key] = self.ctx.vertex_array(prog, [(vbo, "3f", "a_position")])
        return vao


    def empty_vao(self, prog):
        """A vertex array without attributes (vertex shaders that place vertices by
        gl_VertexID and gl_InstanceID)."""
        key = (prog.glo, "empty")
        vao = self._vaos.get(key)
        if vao is None:
            vao = self._vaos[key] = self.ctx.vertex_array(prog, [])
        return vao

    def stream_vao(self, prog, name, positions, indices):
        """A vertex array of per-frame geometry: float32 positions (n, 3) and int32 indices
        (n,) as attributes a_position and a_slice. The buffer is rewritten each frame
        and grows (never shrinks) as needed."""
        data = np.empty(len(positions), dtype=[("p", "f4", 3), ("i", "i4")])
        data["p"] = positions
        data["i"] = indices
        raw = data.tobytes()
        entry = self._streams.get(name)
        if entry is not None and (entry[1].size < len(raw) or entry[0] != prog.glo):
            entry[2].release()
            entry[1].release()
            entry = None
        if entry is None:
            vbo = self.ctx.buffer(reserve=max(2 * len(raw), 1 << 16), dynamic=True)
            vao = self.ctx.vertex_array(prog, [(vbo, "3f 1i", "a_position", "a_slice")])
            self._streams[name] = entry = (prog.glo, vbo, vao)
        entry[1].write(raw)
        entry[2].vertices = len(positions)
        return entry[2]


class _Target:
    def __init__(self, fbo, tex, idle):
        self.fbo = fbo
        self.tex = tex
        self.idle = idle

    def release(self):
        self.idle.use()
        self.fbo.release()
        self.tex.release()
