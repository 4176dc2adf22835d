"""The command: ``dvr-gl view INPUT [render options]`` (:func:`main`), and
:func:`open_viewer` for scripts and tests (the same arguments, a :class:`Viewer` back).
"""

from __future__ import annotations

import os
import sys

import numpy as np

from ... import formats as dvr_io
from .app import Viewer
from .settings import PROG, build_parser, describe_data, is_mesh, settings_from_args
from .window import WindowError


def open_viewer(argv) -> Viewer:
    """Parse ``argv`` (the viewer's arguments), load the input and open the window.
    Errors raise (``SystemExit`` for usage errors from argparse)."""
    args = build_parser().parse_args(list(argv))
    return Viewer(settings_from_args(args))


def main(argv=None) -> int:
    """``dvr-gl view``: returns the exit status (0; 1 no window or a failed frame; 2 bad
    input, with a one-line message; 130 interrupted). ``DVR_GL_DEBUG=1`` shows tracebacks."""
    from ..options import OPTION_OF_FIELD, UsageError

    argv = list(sys.argv[1:] if argv is None else argv)
    debug = bool(os.environ.get("DVR_GL_DEBUG"))
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as e:  # --help or a usage error (already printed)
        return e.code if isinstance(e.code, int) else (0 if e.code is None else 2)
    try:
        return _run(args)
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
    except UsageError as e:
        if debug:
            raise
        return _fail(str(e), 2)
    except dvr_io.InputError as e:
        if debug:
            raise
        option = OPTION_OF_FIELD.get(e.field)
        return _fail(f"{option}: {e.detail}" if option else f"INPUT: {e}", 2)
    except ImportError as e:
        if debug:
            raise
        return _fail(str(e), 2)
    except (ValueError, TypeError, NotImplementedError) as e:
        if debug:
            raise
        return _fail(str(e).replace("pass mask_nonfinite=True", "pass --mask-nonfinite"), 2)
    except (RuntimeError, OSError) as e:  # no window, no GL 3.3, a failed frame, a full disk
        if debug:
            raise
        return _fail(str(e) if isinstance(e, WindowError) else f"{type(e).__name__}: {e}", 1)


def _fail(message, code):
    print(f"{PROG}: error: {message}", file=sys.stderr)
    return code


def _run(args):
    settings = settings_from_args(args)
    viewer = Viewer(settings)
    glfw = viewer.glfw
    try:
        v = settings.volume
        what = (describe_data(v) if is_mesh(v) else
                f"{describe_data(v)} (x, y, z) {getattr(v, 'dtype', None) or v.data.dtype}")
        print(f"{PROG}: {settings.input_name}: {what}, values "
              f"{v.data_range[0]:g}..{v.data_range[1]:g}; transfer function {settings.tf_name}; "
              f"techniques {', '.join(viewer.available_techniques)}", flush=True)
        if args.frames:
            times = viewer.run_frames(args.frames)
            if times:
                print(f"{PROG}: {len(times)} frames at {viewer.framebuffer_size[0]}x{viewer.framebuffer_size[1]}, "
                      f"median {1e3 * float(np.median(times)):.1f} ms (first {1e3 * times[0]:.1f} ms)", flush=True)
            if settings.screenshot and viewer.save_screenshot(settings.screenshot) is None:
                return 1
            return 0
        print(f"{PROG}: press h in the window for the keys", flush=True)
        viewer.run()
        return 0
    finally:
        viewer.close()
        glfw.terminate()
