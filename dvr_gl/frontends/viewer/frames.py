"""Frames: the view rendered into the renderer's float target, then shown in the window.

Every frame is rendered by the very same technique modules and shader programs as
headless rendering, into the renderer's float target at the window's framebuffer size
(a fraction of it for coarse frames). That texture is then drawn to the window with one
full-screen triangle, composited over a background colour (``C + (1 - A) * B``), and the
transfer-function editor (:mod:`.overlay`) is drawn over it. The render is redone only
when something that changes the picture changed (the viewer's version counter, the
size, the quality); a background or overlay change only composes again.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ...gl.context import idle_framebuffer
from .overlay import OverlayDrawer


@dataclass
class FrameInfo:
    quality: str                 # "full" or "coarse"
    target_size: tuple           # (width, height) rendered
    framebuffer_size: tuple      # (width, height) of the window's framebuffer
    step: float | None
    seconds: float               # render + present, GL finished
    key: tuple = field(default=(), repr=False)
    render_key: tuple = field(default=(), repr=False)
    accumulated: int = 1         # particle sets averaged (particles only)


class Presenter:
    """Draws a viewer's frames. Its GL resources (the present program, the overlay's
    buffers) live in the window's context: make it inside the viewer's GL block and
    :meth:`release` it there."""

    def __init__(self, viewer):
        self.viewer = viewer
        self.ctx = viewer.ctx
        self.program = viewer.renderer.programs.get("viewer/present.vert", "viewer/present.frag")
        self.vao = self.ctx.vertex_array(self.program, [])
        self.overlay = OverlayDrawer(viewer.renderer)
        self.target = None              # the framebuffer the view was last rendered into
        self.rendered = None            # what it holds: (width, height, quality, step)
        self.good_state = None          # the last rendering choices that rendered
        self.uploaded_overlay = None    # what the overlay's buffer was made from

    def release(self):
        self.overlay.release()
        self.vao.release()
        self.target = None

    def frame(self, quality, force=False, grab=False):
        """Render the viewer's view at ``quality`` (when something changed, or
        ``force``) and show it; record the viewer's ``last_frame`` and title. Returns
        the window's pixels ((H, W, 3) uint8, row 0 on top, overlay included) when
        ``grab``; None when the window is minimised."""
        v = self.viewer
        fw, fh = v.framebuffer_size
        if fw < 1 or fh < 1:  # minimised
            return None
        scale = v.coarse_scale if quality == "coarse" else 1.0
        tw, th = max(1, round(fw * scale)), max(1, round(fh * scale))
        key = (quality, (tw, th, fw, fh), v.version, v.accumulated)
        render = force or self.target is None or v.last_frame is None or v.last_frame.render_key != key
        t0 = time.perf_counter()
        ctx = self.ctx
        with v.gl():
            if render:
                self._render(tw, th, quality)
            pixels = None
            if grab:  # the same drawing into an 8-bit framebuffer of our own, read back
                texture = ctx.texture((fw, fh), 4, dtype="f1")
                fbo = ctx.framebuffer([texture])
                fbo.use()
                self.compose(fw, fh)
                raw = fbo.read(viewport=(0, 0, fw, fh), components=3, alignment=1)
                pixels = np.frombuffer(raw, np.uint8).reshape(fh, fw, 3)[::-1].copy()
                idle_framebuffer(ctx).use()  # never leave a released framebuffer bound
                fbo.release()
                texture.release()
            ctx.screen.use()
            self.compose(fw, fh)
            ctx.finish()
            v.glfw.swap_buffers(v.window)
        seconds = time.perf_counter() - t0
        tw, th, q, step = self.rendered
        if render:
            v.frame_times.append(seconds)
        v.last_frame = FrameInfo(q, (tw, th), (fw, fh), step, seconds if render else
                                 (v.last_frame.seconds if v.last_frame else seconds),
                                 key=(q, (tw, th, fw, fh), v.version, v.overlay_version, v.background),
                                 render_key=key, accumulated=v.accumulated if q == "full" else 1)
        v.update_title()
        return pixels

    def _render(self, tw, th, quality):
        """Render the view into the target; if that fails (a shader that fails to build,
        a plan the GPU refuses), go back to the last choices that rendered and say so."""
        v = self.viewer
        scene, name, step, options = v.render_arguments(tw, th, coarse=quality == "coarse")
        try:
            self.target = v.renderer.render_target(scene, name, step, **options)
        except Exception as e:
            if self.good_state is None:
                raise
            v.restore(self.good_state)
            v.say(f"rendering {name} failed, back to the last state that worked: {first_error(e)}")
            scene, name, step, options = v.render_arguments(tw, th, coarse=quality == "coarse")
            self.target = v.renderer.render_target(scene, name, step, **options)
        self.good_state = v.state()
        self.rendered = (tw, th, quality, step)

    def compose(self, fw, fh):
        """Draw the render target (over the background) and the overlay into the bound
        framebuffer of size ``fw`` x ``fh``."""
        v = self.viewer
        ctx = self.ctx
        ctx.viewport = (0, 0, fw, fh)
        ctx.disable(ctx.BLEND | ctx.DEPTH_TEST | ctx.CULL_FACE)
        self.target.color_attachments[0].use(location=0)
        tw, th = self.rendered[:2]
        prog = self.program
        prog["t_image"].value = 0
        prog["u_ratio"].value = (tw / fw, th / fh)
        prog["u_background"].value = v.background
        self.vao.render(vertices=3)
        if v.editor.visible:
            iso = v.iso_shown()
            overlay_key = (v.overlay_version, v.window_size, iso)
            if self.uploaded_overlay != overlay_key:
                self.overlay.upload(v.editor.geometry(iso_value=iso))
                self.uploaded_overlay = overlay_key
            self.overlay.draw(v.window_size)


def first_error(exc):
    """The telling line of an exception's message (a GLSL log's first error)."""
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    errors = [line for line in lines if "error" in line.lower()]
    return f"{type(exc).__name__}: {(errors or lines or [''])[0]}"
