"""The GPU objects a renderer keeps between frames, in one store, and the generic GL
builders the techniques make them with.

The store holds one LRU per kind of resource (a volume's 3-D texture, a transfer
function's table, the render targets, ...), each with its own capacity, set by the first
request of that kind. Keys are hashable: the identity of the scene objects a resource is
made from (scene objects are immutable; ``IdentityKey``) and any plain parameters. A
resource is made on its first request, kept while it stays among its kind's most recent,
and released in GL when dropped and on ``ResourceStore.release``. What the store makes
is logged in ``created``."""

from __future__ import annotations

import math

import moderngl
import numpy as np

from ..util.cache import LRU, IdentityKey
from .context import idle_framebuffer


class ResourceStore:
    """What a renderer keeps on the GPU for ``ctx``, by kind and key."""

    def __init__(self, ctx):
        self.ctx = ctx
        self.created = []  # a log of (kind, shape or detail) for every resource made
        self.idle = idle_framebuffer(ctx)  # bound before any target is released
        self._kinds = {}  # kind -> LRU

    def get(self, kind, key, make, capacity=2):
        """The ``kind`` resource under ``key``: ``make()`` on a miss. The first request of
        a kind sets how many of it are kept (``capacity``; None for no limit); the least
        recently used is released when one more is made."""
        cache = self._kinds.get(kind)
        if cache is None:
            cache = self._kinds[kind] = LRU(math.inf if capacity is None else capacity)
        return cache.get(key, make)

    def for_objects(self, kind, *objects, make, capacity=2):
        """What is kept for some scene objects (a mesh's textures, a TF's table): keyed by
        their identity (plain strings and numbers by value), logged in ``created`` as
        (kind, their type names)."""
        return self.get(kind, IdentityKey(kind, *objects),
                        lambda: self.made(kind, tuple(type(o).__name__ for o in objects), make()), capacity)

    def made(self, kind, detail, value):
        """Log ``value`` in ``created`` as (kind, detail); returns it."""
        self.created.append((kind, detail))
        return value

    def release(self):
        """Release every resource and leave the idle framebuffer bound."""
        for cache in self._kinds.values():
            cache.release()
        self._kinds.clear()
        self.idle.use()

    def gpu_bytes(self) -> int:
        """Bytes of every texture, buffer and framebuffer attachment held (the store's own
        bookkeeping; the driver's overheads are not counted)."""
        seen = set()
        return sum(_gpu_bytes(cache, seen) for cache in self._kinds.values())


def _gpu_bytes(obj, seen, depth=0):
    if obj is None or id(obj) in seen or depth > 4:
        return 0
    seen.add(id(obj))
    if isinstance(obj, (moderngl.Texture, moderngl.TextureArray, moderngl.Texture3D)):
        dims = obj.size if isinstance(obj.size, tuple) else (obj.size,)
        per = 4 if getattr(obj, "depth", False) else obj.components * int(obj.dtype[1])
        return int(np.prod(dims)) * per
    if isinstance(obj, moderngl.Buffer):
        return int(obj.size)
    if isinstance(obj, moderngl.Framebuffer):
        return (sum(_gpu_bytes(t, seen, depth + 1) for t in obj.color_attachments)
                + _gpu_bytes(obj.depth_attachment, seen, depth + 1))
    if isinstance(obj, (moderngl.Context, moderngl.Program, moderngl.VertexArray)):
        return 0
    if isinstance(obj, dict):
        return sum(_gpu_bytes(v, seen, depth + 1) for v in obj.values())
    if isinstance(obj, (list, tuple)):
        return sum(_gpu_bytes(v, seen, depth + 1) for v in obj)
    if hasattr(obj, "__dict__") and not isinstance(obj, type):   # LRUs, technique resources
        return sum(_gpu_bytes(v, seen, depth + 1) for k, v in vars(obj).items() if k != "ctx")
    return 0


# -- builders ----------------------------------------------------------------------------

def texture3d(ctx, array, components, dtype, linear):
    """A 3-D texture of ``array`` (nz, ny, nx[, components]), clamped at the edges,
    linear or nearest filtered."""
    nz, ny, nx = array.shape[:3]
    tex = ctx.texture3d((nx, ny, nz), components, np.ascontiguousarray(array).tobytes(), dtype=dtype)
    f = ctx.LINEAR if linear else ctx.NEAREST
    tex.filter = (f, f)
    tex.repeat_x = tex.repeat_y = tex.repeat_z = False
    return tex


class Target:
    """A framebuffer with one texture of ``components`` channels of ``dtype``; ``idle``
    (``context.idle_framebuffer``) is bound before it is released."""

    def __init__(self, ctx, width, height, dtype, components, idle):
        self.tex = ctx.texture((width, height), components, dtype=dtype)
        self.fbo = ctx.framebuffer([self.tex])
        self.idle = idle

    def release(self):
        self.idle.use()
        self.fbo.release()
        self.tex.release()


class VertexStream:
    """A vertex array of per-frame geometry: float32 positions (n, 3) and int32 indices
    (n,) as attributes a_position and a_slice. The buffer is rewritten each frame and
    grows (never shrinks) as needed; a new program gets a new one."""

    def __init__(self, ctx):
        self.ctx = ctx
        self.glo = None     # the program the vertex array is for
        self.vbo = None
        self.vao = None

    def vertex_array(self, prog, positions, indices):
        data = np.empty(len(positions), dtype=[("p", "f4", 3), ("i", "i4")])
        data["p"] = positions
        data["i"] = indices
        raw = data.tobytes()
        if self.vbo is not None and (self.vbo.size < len(raw) or self.glo != prog.glo):
            self.release()
        if self.vbo is None:
            self.vbo = self.ctx.buffer(reserve=max(2 * len(raw), 1 << 16), dynamic=True)
            self.vao = self.ctx.vertex_array(prog, [(self.vbo, "3f 1i", "a_position", "a_slice")])
            self.glo = prog.glo
        self.vbo.write(raw)
        self.vao.vertices = len(positions)
        return self.vao

    def release(self):
        if self.vbo is not None:
            self.vao.release()
            self.vbo.release()
            self.vbo = self.vao = self.glo = None
