"""What the viewer tells the user: messages on stdout that also show in the window's
title for a few seconds (:class:`StatusLine`), and the title itself
(:func:`window_title`: the data, the technique and mode, the step and the frame time).
"""

from __future__ import annotations

from .settings import PROG, describe_data


class StatusLine:
    """Messages said so far (``messages``, for tests and scripts) and the latest one,
    shown in the title for ``show_s`` seconds. ``clock`` is called for the time now."""

    show_s = 4.0

    def __init__(self, clock):
        self.clock = clock
        self.messages = []
        self.text = ""
        self.until = 0.0

    def say(self, message):
        """A message on stdout and, for a few seconds, in the window title."""
        self.messages.append(message)
        print(f"{PROG}: {message}", flush=True)
        self.text = message
        self.until = self.clock() + self.show_s

    def showing(self):
        """The message still shown in the title, or ""."""
        return self.text if self.text and self.clock() < self.until else ""


def window_title(viewer):
    """The title for ``viewer``'s last frame: the input and its data, the technique,
    mode and options, the step (or tolerance), the frame's size and time, and the
    message being shown."""
    f = viewer.last_frame
    options = viewer.technique_options()
    info = viewer.info
    step = f"step {f.step:.3g}" if f.step is not None else "fixed sampling"
    if viewer.tolerance is not None and viewer.technique in ("raycast", "tetra"):
        step = f"tolerance {viewer.tolerance:.3g}, {step}"
    if "interpolate" in options:
        step += f", interpolate {options['interpolate']}"
    extras = [k for k in ("preintegrate",) if options.get(k)]
    if info.accepts("sort") and info.params is not None:
        extras.append(str(options.get("sort", "auto")))
    if viewer.lit:
        extras.append("shaded")
    if viewer.layers:
        from .layers import describe_shown
        extras.append(describe_shown(viewer))
    if viewer.accumulates():
        extras.append(f"{f.accumulated} sets")
    mode = viewer.mode + (f" {viewer.iso:g}" if viewer.mode == "isosurface" else "")
    title = (f"{PROG}: {viewer.settings.input_name} ({describe_data(viewer.volume)}) | {viewer.technique} {mode}"
             + (f" ({', '.join(extras)})" if extras else "")
             + f" | {step} | {f.target_size[0]}x{f.target_size[1]} | {1e3 * f.seconds:.1f} ms"
             + (" (refining)" if f.quality == "coarse" else ""))
    message = viewer.status_line.showing()
    if message:
        title += f" | {message}"
    return title
