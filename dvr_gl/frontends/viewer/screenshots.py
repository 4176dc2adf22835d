"""Screenshots (keys s and S, ``--frames`` with ``--screenshot``).

``s`` writes the render itself, read from the renderer's float target at full quality:
no overlay, and the same PNG ``dvr-gl render`` writes of the same camera (RGB over
``--background`` if given, else un-premultiplied RGBA). ``S`` writes the window as shown,
overlay included, over the display background. Both are written atomically, to
``--screenshot`` or else to the first free ``dvr-gl-view-NNN.png``.
"""

from __future__ import annotations

import os

from ... import formats as dvr_io


def full_image(v):
    """``v``'s current view at full quality as a float image (H, W, 4), premultiplied,
    row 0 on top, from the render target (no overlay)."""
    fw, fh = v.framebuffer_size
    scene, name, step, options = v.render_arguments(fw, fh)
    with v.gl():
        fbo = v.renderer.render_target(scene, name, step, **options)
        return v.renderer.read_target(fbo, fw, fh)


def screenshot_path(settings, suffix=""):
    """Where a screenshot goes: ``settings.screenshot`` (with ``suffix`` before its
    extension), else the first ``dvr-gl-view-NNN{suffix}.png`` that does not exist."""
    path = settings.screenshot
    if path is not None:
        if suffix:
            root, ext = os.path.splitext(path)
            path = f"{root}{suffix}{ext}"
        return path
    for n in range(1, 10000):
        path = f"dvr-gl-view-{n:03d}{suffix}.png"
        if not os.path.exists(path):
            return path
    return f"dvr-gl-view{suffix}.png"


def write_screenshot(v, path=None):
    """Write ``v``'s current view at full quality, without overlays, as ``dvr-gl render``
    would (RGB over ``--background`` if given, else un-premultiplied RGBA); atomic.
    Returns the path, or None (and says why) when it cannot be written."""
    path = path or screenshot_path(v.settings)
    try:
        dvr_io.save_png(path, full_image(v), background=v.settings.background)
    except (OSError, ValueError) as e:
        v.say(f"cannot save the screenshot {path!r}: {e}")
        return None
    v.say(f"wrote {path}")
    return path


def write_window_screenshot(v, path=None):
    """Write ``v``'s window as shown (overlay included, over the display background)."""
    from PIL import Image
    import io

    path = path or screenshot_path(v.settings, "-window")
    pixels = v.frame(quality="full", grab=True)
    if pixels is None:
        return None
    buffer = io.BytesIO()
    Image.fromarray(pixels).save(buffer, format="PNG", optimize=True)
    try:
        dvr_io.atomic_write(path, buffer.getvalue())
    except OSError as e:
        v.say(f"cannot save the window screenshot {path!r}: {e}")
        return None
    v.say(f"wrote {path}")
    return path
