"""The viewer's window: glfw, an OpenGL 3.3 core window and a moderngl context for it.

glfw is imported inside functions only (:func:`import_glfw`), so the viewer package
imports without it and without a display.

Two GL libraries meet in a process that renders both headless and in a window: a
headless :class:`dvr_gl.Renderer` uses EGL (or OSMesa), the window GLX. libglvnd refuses
to make a GLX context current on a thread where an EGL context is current (an X error
that ends the process), and the other way round (silently: a headless Renderer's calls
would go into the window's context). So the window's context is current only inside
:func:`gl_current` blocks, each of which first drops any current EGL context
(:func:`release_current_egl`).
"""

from __future__ import annotations

import contextlib
import os
import sys
import time

from ...gl.context import current


class WindowError(RuntimeError):
    """No window could be opened (no display, no OpenGL 3.3)."""


def import_glfw():
    try:
        import glfw
    except ImportError as e:
        raise ImportError(f"the interactive viewer needs glfw (pip install glfw): {e}") from None
    return glfw


def no_display_message(detail):
    if sys.platform.startswith("linux") and not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        return ("cannot open a window: no display (DISPLAY is not set). The viewer needs a screen; "
                "off-screen, run it under xvfb-run (xvfb-run -a dvr-gl view INPUT --screenshot out.png "
                "--frames 5) or use dvr-gl render")
    return f"cannot open a window: {detail}"


def open_window(size, title, visible=True, vsync=True):
    """Open a window of ``size`` (width, height) with an OpenGL 3.3 core context, make
    that context current and return ``(glfw, window, ctx)``: the glfw module, the window
    and a moderngl context for it. :class:`WindowError` when none can be opened."""
    glfw = import_glfw()
    import moderngl

    width, height = size
    old = glfw.ERROR_REPORTING
    glfw.ERROR_REPORTING = "raise"
    if (sys.platform.startswith("linux") and os.environ.get("DISPLAY") and hasattr(glfw, "PLATFORM_X11")
            and hasattr(glfw, "init_hint")):
        # moderngl's Linux windows are GLX: ask for an X11 window (XWayland under Wayland)
        try:
            glfw.init_hint(glfw.PLATFORM, glfw.PLATFORM_X11)
        except glfw.GLFWError:  # a glfw older than 3.4 has only X11 anyway
            pass
    try:
        try:
            ok = glfw.init()
        except glfw.GLFWError as e:
            raise WindowError(no_display_message(str(e))) from None
        if not ok:
            raise WindowError(no_display_message("glfw could not be initialised"))
        # 4.3 where the driver has it (compute shaders: techniques.gpu.pixel_stage), else 3.3
        window, failure = None, None
        for minor_4_3 in (True, False):
            glfw.default_window_hints()
            glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, 4 if minor_4_3 else 3)
            glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, 3)
            glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
            glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, True)
            glfw.window_hint(glfw.VISIBLE, bool(visible))
            release_current_egl()  # glfw makes its new context current to test it
            try:
                window = glfw.create_window(width, height, title, None, None)
            except glfw.GLFWError as e:
                failure = e
            if window:
                break
        if not window:
            raise WindowError("cannot open an OpenGL 3.3 core window" + (f": {failure}" if failure else ""))
    finally:
        glfw.ERROR_REPORTING = old
    glfw.make_context_current(window)
    glfw.swap_interval(1 if vsync else 0)
    return glfw, window, window_context(moderngl)


def window_context(moderngl):
    """A moderngl context for the GL context current now (the window's). On Linux it
    is made through glcontext's "detect" mode with an explicit GLX library, so that
    entering it makes the window's context current again: without settings,
    ``moderngl.create_context()`` in a process that has no context yet returns one whose
    enter and exit do nothing, and the first such context is also handed to every later
    caller."""
    settings = {}
    if sys.platform.startswith("linux"):
        import ctypes.util
        settings["libgl"] = ctypes.util.find_library("GL") or "libGL.so.1"
    return moderngl.create_context(require=330, **settings)


@contextlib.contextmanager
def gl_current(glfw, window, ctx):
    """Make the window's context current for a block of GL work, and current to nothing
    afterwards; any current EGL context is dropped first (see the module's notes)."""
    release_current_egl()
    glfw.make_context_current(window)
    try:
        with current(ctx):
            yield ctx
    finally:
        glfw.make_context_current(None)


def resize_window(glfw, window, width, height):
    """Resize the window (as a user would) and process the events that follow."""
    glfw.set_window_size(window, int(width), int(height))
    for _ in range(50):
        glfw.poll_events()
        if tuple(glfw.get_window_size(window)) == (width, height):
            break
        time.sleep(0.005)
    glfw.poll_events()


def destroy_window(glfw, window, ctx):
    """Destroy the window; its GL resources must have been released."""
    glfw.destroy_window(window)
    # dvr_gl.gl.context keys per-context state by id(ctx); keep this context object
    # alive so that a later context cannot reuse its id.
    _CLOSED_CONTEXTS.append(ctx)


_CLOSED_CONTEXTS = []


def release_current_egl():
    """Make no EGL context current on this thread, if libEGL is loaded at all. A headless
    context may be left current (``gl.context.create_context`` leaves a new EGL context
    current, even after it is released), and libglvnd then refuses glXMakeCurrent."""
    if not sys.platform.startswith("linux"):
        return
    egl = _EGL.get("lib")
    if egl is None:
        import ctypes

        try:  # RTLD_NOLOAD: only a libEGL the process has already loaded
            egl = ctypes.CDLL("libEGL.so.1", mode=os.RTLD_NOLOAD | os.RTLD_LAZY)
        except (OSError, AttributeError):
            return
        egl.eglGetCurrentContext.restype = ctypes.c_void_p
        egl.eglGetCurrentDisplay.restype = ctypes.c_void_p
        egl.eglMakeCurrent.argtypes = [ctypes.c_void_p] * 4
        egl.eglMakeCurrent.restype = ctypes.c_uint
        _EGL["lib"] = egl
    if egl.eglGetCurrentContext():
        egl.eglMakeCurrent(egl.eglGetCurrentDisplay(), None, None, None)


_EGL = {}
