"""The one place GL contexts are made.

``backend="auto"`` tries EGL (moderngl's ``egl`` backend, Mesa's llvmpipe or a GPU driver)
and then OSMesa (libOSMesa through the small ctypes loader below); ``"egl"`` and
``"osmesa"`` force one. A failure says what was tried, why each failed, and what to
install. Contexts are OpenGL 3.3 core or newer.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util

import moderngl

BACKENDS = ("egl", "osmesa")
REQUIRED_GL = 330
COMPUTE_GL = 430      # compute shaders

INSTALL_HINT = {
    "egl": "install Mesa's EGL (Debian/Ubuntu: apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri)",
    "osmesa": "install OSMesa (Debian/Ubuntu: apt-get install libosmesa6)",
}


class BackendUnavailable(RuntimeError):
    """No requested GL backend could make a context."""


class _OSMesaLoader:
    """A moderngl context loader over libOSMesa: makes a core-profile context current on
    a 1x1 RGBA buffer (dvr_gl always renders into its own framebuffer objects) and
    resolves GL entry points with OSMesaGetProcAddress."""

    OSMESA_RGBA = 0x1908
    OSMESA_FORMAT = 0x22
    OSMESA_DEPTH_BITS = 0x30
    OSMESA_STENCIL_BITS = 0x31
    OSMESA_ACCUM_BITS = 0x32
    OSMESA_PROFILE = 0x33
    OSMESA_CORE_PROFILE = 0x34
    OSMESA_CONTEXT_MAJOR_VERSION = 0x36
    OSMESA_CONTEXT_MINOR_VERSION = 0x37
    GL_UNSIGNED_BYTE = 0x1401

    _LIB_NAMES = ("libOSMesa.so.8", "libOSMesa.so.6", "libOSMesa.so")

    def __init__(self):
        lib = None
        errors = []
        names = list(self._LIB_NAMES)
        found = ctypes.util.find_library("OSMesa")
        if found:
            names.insert(0, found)
        for name in names:
            try:
                lib = ctypes.CDLL(name)
                break
            except OSError as e:
                errors.append(str(e))
        if lib is None:
            raise OSError("libOSMesa not found (" + "; ".join(errors[-1:]) + ")")
        self._lib = lib
        lib.OSMesaCreateContextAttribs.restype = ctypes.c_void_p
        lib.OSMesaCreateContextAttribs.argtypes = [ctypes.POINTER(ctypes.c_int), ctypes.c_void_p]
        lib.OSMesaMakeCurrent.restype = ctypes.c_ubyte
        lib.OSMesaMakeCurrent.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_uint,
                                          ctypes.c_int, ctypes.c_int]
        lib.OSMesaGetProcAddress.restype = ctypes.c_void_p
        lib.OSMesaGetProcAddress.argtypes = [ctypes.c_char_p]
        lib.OSMesaGetCurrentContext.restype = ctypes.c_void_p
        lib.OSMesaDestroyContext.argtypes = [ctypes.c_void_p]
        attribs = [self.OSMESA_FORMAT, self.OSMESA_RGBA, self.OSMESA_DEPTH_BITS, 24,
                   self.OSMESA_STENCIL_BITS, 8, self.OSMESA_ACCUM_BITS, 0,
                   self.OSMESA_PROFILE, self.OSMESA_CORE_PROFILE,
                   self.OSMESA_CONTEXT_MAJOR_VERSION, REQUIRED_GL // 100,
                   self.OSMESA_CONTEXT_MINOR_VERSION, (REQUIRED_GL // 10) % 10, 0]
        arr = (ctypes.c_int * len(attribs))(*attribs)
        self._ctx = lib.OSMesaCreateContextAttribs(arr, None)
        if not self._ctx:
            raise OSError(f"OSMesaCreateContextAttribs failed for a {REQUIRED_GL / 100:.1f} core profile")
        self._buffer = (ctypes.c_ubyte * 4)()
        self._make_current()

    def _make_current(self):
        if not self._lib.OSMesaMakeCurrent(self._ctx, self._buffer, self.GL_UNSIGNED_BYTE, 1, 1):
            raise OSError("OSMesaMakeCurrent failed")

    # -- the interface moderngl expects of a loader ----------------------------------
    def load_opengl_function(self, name):
        return self._lib.OSMesaGetProcAddress(name.encode()) or 0

    def __enter__(self):
        self._make_current()

    def __exit__(self, *exc):
        pass

    def release(self):
        if self._ctx:
            self._lib.OSMesaDestroyContext(self._ctx)
            self._ctx = None


_LIBEGL = []  # [the library or None], loaded on first use
EGL_CONTEXT_CLIENT_TYPE = 0x3097


def egl_library():
    """libEGL through ctypes, for the few calls moderngl does not make (None without it)."""
    if not _LIBEGL:
        try:
            egl = ctypes.CDLL("libEGL.so.1")
            for name in ("eglGetCurrentContext", "eglGetCurrentDisplay"):
                getattr(egl, name).restype = ctypes.c_void_p
                getattr(egl, name).argtypes = []
            egl.eglGetCurrentSurface.restype = ctypes.c_void_p
            egl.eglGetCurrentSurface.argtypes = [ctypes.c_int]
            egl.eglMakeCurrent.restype = ctypes.c_uint
            egl.eglMakeCurrent.argtypes = [ctypes.c_void_p] * 4
            egl.eglQueryContext.restype = ctypes.c_uint
            egl.eglQueryContext.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int,
                                            ctypes.POINTER(ctypes.c_int)]
        except (OSError, AttributeError):
            egl = None
        _LIBEGL.append(egl)
    return _LIBEGL[0]


def _create_egl():
    # 4.3 where the driver has it (compute shaders: techniques.gpu.pixel_stage); EGL
    # drivers may give exactly the version asked for, so ask for it first
    try:
        ctx = moderngl.create_context(standalone=True, backend="egl", require=COMPUTE_GL)
    except Exception:
        ctx = moderngl.create_context(standalone=True, backend="egl", require=REQUIRED_GL)
    egl = egl_library()
    if egl is not None:
        with ctx:  # moderngl makes it current: note which EGL display and context it is
            ctx.extra = {"egl_handles": (egl.eglGetCurrentDisplay(), egl.eglGetCurrentContext())}
    return ctx


def context_lost(ctx):
    """True when ``ctx``'s EGL context no longer exists. EGL keeps one display per device
    in a process, and another library that terminates it (VTK does when one of its
    offscreen windows is finalised; pyvista's ``close()`` does that) destroys every
    context on it: GL calls then fail or, worse, return garbage. Contexts of other kinds
    are never lost this way."""
    handles = (ctx.extra or {}).get("egl_handles") if isinstance(ctx.extra, dict) else None
    egl = egl_library()
    if not handles or egl is None:
        return False
    value = ctypes.c_int()
    return not egl.eglQueryContext(handles[0], handles[1], EGL_CONTEXT_CLIENT_TYPE, ctypes.byref(value))


def _create_osmesa():
    loader = _OSMesaLoader()
    ctx = moderngl.Context.__new__(moderngl.Context)
    ctx.mglo, ctx.version_code = moderngl.mgl.create_context(context=loader)
    ctx._info = None
    ctx._extensions = None
    ctx.extra = None
    ctx._gc_mode = None
    ctx._objects = __import__("collections").deque()
    ctx._screen = None
    ctx.fbo = None
    if ctx.version_code < REQUIRED_GL:
        raise OSError(f"OSMesa gave OpenGL {ctx.version_code}, dvr_gl needs {REQUIRED_GL} or newer")
    ctx.extra = {"osmesa_loader": loader}
    return ctx


_CREATORS = {"egl": _create_egl, "osmesa": _create_osmesa}


def create_context(backend="auto"):
    """A headless moderngl context and the name of the backend that made it."""
    if backend == "auto":
        order = BACKENDS
    elif backend in BACKENDS:
        order = (backend,)
    else:
        raise ValueError(f"backend must be 'auto', 'egl' or 'osmesa', got {backend!r}")
    failures = []
    for name in order:
        try:
            ctx = _CREATORS[name]()
        except Exception as e:  # each backend fails in its own way; report them all
            failures.append(f"  {name}: {type(e).__name__}: {e}\n    fix: {INSTALL_HINT[name]}")
            continue
        return ctx, name
    raise BackendUnavailable("no OpenGL 3.3 core context could be created; tried:\n" + "\n".join(failures))


_SHARED = {}


def shared_context(backend="auto"):
    """The process's context for ``backend`` (made on first use, kept until exit) and the
    name of the backend behind it. Renderers share it and release only their own objects:
    tearing down an EGL context can invalidate the other contexts on the same display
    once another library (VTK) has used it, so contexts are never destroyed mid-process.
    A context another library destroyed (see ``context_lost``) is replaced by a new one."""
    key = backend
    for ctx in {id(c): c for c, _ in _SHARED.values()}.values():
        if context_lost(ctx):
            _forget(ctx)
    if key not in _SHARED:
        if backend == "auto":
            for name in BACKENDS:  # reuse a backend already made before trying to make one
                if name in _SHARED:
                    _SHARED[key] = _SHARED[name]
                    return _SHARED[key]
        ctx, name = create_context(backend)
        _SHARED[key] = _SHARED.setdefault(name, (ctx, name))
    return _SHARED[key]


def _forget(lost):
    """Drop every record of a lost context, so that the next request makes a new one (its
    objects died with it: nothing is released)."""
    for key in [k for k, (ctx, _) in _SHARED.items() if ctx is lost]:
        del _SHARED[key]
    _IDLE_FRAMEBUFFERS.pop(id(lost), None)
    _CURRENT_DEPTH.pop(id(lost), None)
    LOST_CONTEXTS.append(lost.extra["egl_handles"])


LOST_CONTEXTS = []  # EGL handles of the contexts found lost and replaced, for the record

_CURRENT_DEPTH = {}


@contextlib.contextmanager
def current(ctx):
    """Make ``ctx`` current for the block, re-entrantly. moderngl's own ``with ctx`` must
    not be nested: leaving the inner block restores what was current before the *outer*
    one (often nothing), and a read-back then silently returns uninitialised memory."""
    key = id(ctx)
    depth = _CURRENT_DEPTH.get(key, 0)
    if depth:
        _CURRENT_DEPTH[key] = depth + 1
        try:
            yield ctx
        finally:
            _CURRENT_DEPTH[key] -= 1
        return
    with ctx:
        _CURRENT_DEPTH[key] = 1
        try:
            yield ctx
        finally:
            _CURRENT_DEPTH[key] = 0


_IDLE_FRAMEBUFFERS = {}


def idle_framebuffer(ctx):
    """A 1x1 framebuffer kept for the context's life. moderngl re-binds the last bound
    framebuffer when it makes a new one, so that one must never have been released: bind
    this before releasing any other. It also gives transform feedback a framebuffer (a
    context with none bound refuses to draw even with rasterisation off)."""
    fbo = _IDLE_FRAMEBUFFERS.get(id(ctx))
    if fbo is None:
        with current(ctx):
            fbo = _IDLE_FRAMEBUFFERS[id(ctx)] = ctx.framebuffer([ctx.texture((1, 1), 4, dtype="f1")])
    return fbo


def describe(ctx) -> dict:
    """Renderer strings, GL version and the limits dvr_gl cares about. The context is made
    current first: an EGL context is not current after it is made, and GL answers queries
    on no context with empty strings and zeros."""
    with current(ctx):
        info = ctx.info
    return {
        "vendor": info.get("GL_VENDOR"),
        "renderer": info.get("GL_RENDERER"),
        "version": info.get("GL_VERSION"),
        "version_code": ctx.version_code,
        "max_texture_size": info.get("GL_MAX_TEXTURE_SIZE"),
        "max_3d_texture_size": info.get("GL_MAX_3D_TEXTURE_SIZE"),
        "max_viewport_dims": info.get("GL_MAX_VIEWPORT_DIMS"),
    }
