"""Issue 27, must-show 4: the viewer on a mesh (default the NASA LOX post) under X, while
the view turns and once it stops.

One viewer window per tolerance setting (none, and ``--tolerance E``), each opened as
``dvr-gl view`` opens a mesh (``Settings`` with the bench's transfer function,
``bench.common.mesh_tf``). In each, for each cell order (the default, then the ones
``--sorts`` names, chosen with key c as a user would): key r resets the view, one still
frame is rendered, then the left button is pressed and the cursor moves ``--steps``
times by ``--pixels`` to the right, one frame after each move (the frames the viewer
shows while the user drags: coarse ones, at half the window's resolution, and with a
tolerance rendered the fastest way within E that ``Renderer.mesh_tolerance_settings``
picks, its pilot run on the first frame);
the button is released and input settles, and the still frame follows. The viewer's
clock is the script's: each move is 10 ms after the last, so every frame while moving
is a coarse one however long it takes; the times are wall-clock (``perf_counter``)
around the viewer's own ``frame`` call, GL finished.

The error of the still frame: the window is then resized to ``--error-size`` (default
the same size; a smaller one where ``reference.exact`` is dear) and, after the same reset
and the same turn (no frames while moving: a new size would run the tolerance's pilot
again), the still frame of each setting is read back as the screenshot key does
(``render_image``: the float render target, premultiplied) and compared (RMSE, and the
largest channel error) with ``dvr_gl.reference.exact`` of the viewer's own scene.

Run it under X (Xvfb):

    LP_NUM_THREADS=2 xvfb-run -a -s "-screen 0 1024x768x24" python scripts/viewer_mesh_numbers.py
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np


def log(message):
    print(f"[{time.strftime('%H:%M:%S')}] {message}", file=sys.stderr, flush=True)


def open_mesh_viewer(mesh, tf, size, tolerance, name):
    from dvr_gl.frontends import viewer as viewer_mod
    settings = viewer_mod.Settings(volume=mesh, tf=tf, tf_name="bench", input_name=name, technique="tetra",
                                   size=size, tolerance=tolerance, vsync=False)
    return viewer_mod.Viewer(settings)


def use_sort(v, sort):
    """Key c until the viewer's cell order is ``sort`` (None: back to tetra's default,
    the order no key has chosen)."""
    from dvr_gl.frontends.viewer import PRESS, key_code
    from dvr_gl.techniques import get_technique
    if sort is None:
        if "sort" in v.options:
            v.try_change(lambda: v.options.pop("sort"), "use the default sort")
        return
    for _ in range(len(get_technique("tetra").SORTS) + 1):
        if v.options.get("sort") == sort:
            return
        v.on_key(key_code("c"), PRESS)
    raise RuntimeError(f"key c never reached sort {sort!r} ({v.messages[-1]})")


class Drive:
    """The viewer's clock, advanced by the script (see the module's notes)."""

    def __init__(self, v):
        self.v = v
        self.now = 1000.0
        v.clock = lambda: self.now

    def timed_frame(self):
        t0 = time.perf_counter()
        self.v.frame()
        return time.perf_counter() - t0, self.v.last_frame.quality, self.v.last_frame.target_size

    def reset_and_still(self):
        from dvr_gl.frontends.viewer import PRESS, key_code
        self.v.on_key(key_code("r"), PRESS)
        self.now += 1.0
        frames = []
        while self.v.needs_frame():      # with a tolerance the first frame is a coarse one (its pilot)
            frames.append(self.timed_frame())
            self.now += 1.0
        return frames

    def turn(self, steps, pixels, on_frame=None, frames=True):
        """Press, ``steps`` moves of ``pixels`` to the right with a frame after each,
        release; returns [(seconds, quality, size)] of the frames while moving and of the
        still frame after the release. ``frames=False``: no frames while moving (the
        still frame alone, as after a drag faster than one frame)."""
        from dvr_gl.frontends.viewer import MOUSE_LEFT, PRESS, RELEASE
        v = self.v
        ww, wh = v.window_size
        x, y = ww * 0.3, wh * 0.3        # over the render, above the editor panel
        assert not v.editor.contains(x, y), "the drag would start on the editor"
        v.on_mouse_button(MOUSE_LEFT, PRESS, 0, x, y)
        moving = []
        for k in range(1, steps + 1):
            self.now += 0.01
            v.on_cursor(x + k * pixels, y)
            if not frames:
                continue
            moving.append(self.timed_frame())
            if on_frame:
                on_frame(k, moving[-1])
        v.on_mouse_button(MOUSE_LEFT, RELEASE, 0)
        self.now += 1.0                  # input settled: the still frame
        still = self.timed_frame()
        assert still[1] == "full" and not v.needs_frame()
        return moving, still


def parse_size(text):
    w, h = (int(p) for p in text.lower().split("x"))
    return w, h


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh", default="loxpost", help="bench mesh (bench.common.MESHES; default loxpost)")
    parser.add_argument("--size", default="512x512", type=parse_size, help="window size (default: the viewer's, 512x512)")
    parser.add_argument("--steps", type=int, default=24, help="cursor moves (frames) while dragging")
    parser.add_argument("--pixels", type=float, default=4.0, help="pixels per move (half a turn per window height)")
    parser.add_argument("--tolerance", type=float, default=7.38e-3,
                        help="the viewer's --tolerance (default: VTK's RMSE on the LOX post, 7.38e-3); 0: none")
    parser.add_argument("--sorts", default="centroid,walk", help="cell orders besides the default, comma separated")
    parser.add_argument("--error-size", type=parse_size,
                        help="window size for the still frame's error against reference.exact "
                             "(default: --size; 0x0: skip)")
    parser.add_argument("--shots", metavar="DIR", help="also save each still frame as a screenshot (key s) there")
    args = parser.parse_args(argv)
    args.error_size = args.error_size or args.size
    if not os.environ.get("DISPLAY"):
        raise SystemExit("no DISPLAY: run under X, e.g. xvfb-run -a python scripts/viewer_mesh_numbers.py")

    from dvr_gl.bench.common import load_mesh_dataset
    from dvr_gl.reference.exact import exact
    from dvr_gl.rendering.tolerance import rmse
    from dvr_gl.frontends.viewer import PRESS, key_code

    mesh, tf = load_mesh_dataset(args.mesh)
    log(f"{args.mesh}: {mesh.n_points} points, {mesh.n_tets} tets; window {args.size[0]}x{args.size[1]}, "
        f"{args.steps} moves of {args.pixels:g} px, LP_NUM_THREADS={os.environ.get('LP_NUM_THREADS', '-')}")
    sorts = [None] + [s for s in args.sorts.split(",") if s]
    tolerances = [None] + ([args.tolerance] if args.tolerance > 0 else [])
    rows, errors = [], []
    for tolerance in tolerances:
        t0 = time.perf_counter()
        v = open_mesh_viewer(mesh, tf, args.size, tolerance, args.mesh)
        log(f"viewer open ({time.perf_counter() - t0:.1f} s), tolerance {tolerance}")
        try:
            drive = Drive(v)
            for sort in sorts:
                use_sort(v, sort)
                label = v.options.get("sort", "default") if sort else f"default ({v.render_arguments()[3].get('sort', 'auto')})"
                first = drive.reset_and_still()
                log(f"{label}, tolerance {tolerance}: first frames {[f'{s:.2f} s {q}' for s, q, _ in first]}")
                moving, still = drive.turn(args.steps, args.pixels, on_frame=lambda k, f: log(
                    f"  move {k}/{args.steps}: {f[0] * 1e3:.0f} ms {f[1]} {f[2][0]}x{f[2][1]}"))
                choice = getattr(v.renderer, "last_choice", None) if tolerance else None
                seconds = np.array([s for s, _, _ in moving])
                rows.append(dict(order=label, tolerance=tolerance, coarse=moving[0][2],
                                 qualities={q for _, q, _ in moving}, median=float(np.median(seconds)),
                                 fps=len(seconds) / float(seconds.sum()), still=still[0],
                                 first=sum(s for s, _, _ in first),
                                 way=choice.label if choice is not None else None))
                log(f"  {label}: {rows[-1]['fps']:.2f} frames/s while turning, still frame {still[0]:.2f} s")
                if args.shots:
                    os.makedirs(args.shots, exist_ok=True)
                    tag = f"{args.mesh}-{v.options.get('sort', 'default')}-{'tol' if tolerance else 'exact'}"
                    v.save_screenshot(os.path.join(args.shots, tag + ".png"))
                if choice is not None:
                    log(f"  tolerance chose {choice.label} (pilot RMSE {choice.pilot_rmse:.2e} at "
                        f"{choice.pilot_size}); measured: {choice.measured}")
            if args.error_size[0] > 0:
                if v.editor.visible:     # a small window is all editor: hide it (key e)
                    v.on_key(key_code("e"), PRESS)
                v.set_window_size(*args.error_size)
                log(f"window {v.framebuffer_size}: still-frame errors")
                reference = None
                for sort in sorts:
                    use_sort(v, sort)
                    drive.reset_and_still()
                    # the same turn (in angle); no frames while moving (the still frame is
                    # what is measured, and with a tolerance a new size would run a pilot)
                    drive.turn(args.steps, args.pixels * args.error_size[1] / args.size[1], frames=False)
                    image = v.render_image()
                    scene = v.render_arguments()[0]
                    if reference is None:
                        t1 = time.perf_counter()
                        reference = exact(scene)
                        log(f"  exact {scene.width}x{scene.height}: {time.perf_counter() - t1:.1f} s")
                        ref_scene = scene.digest()
                    assert scene.digest() == ref_scene, "the error view moved between settings"
                    label = v.options.get("sort", "default") if sort else "default"
                    errors.append(dict(order=label, tolerance=tolerance, rmse=rmse(image, reference),
                                       max=float(np.abs(image - reference).max()), size=args.error_size))
                    log(f"  {label}: RMSE {errors[-1]['rmse']:.2e}")
        finally:
            v.close()

    print(f"\n{args.mesh}, {mesh.n_tets} tets, window {args.size[0]}x{args.size[1]}: "
          f"{args.steps} frames while turning ({args.pixels:g} px each)\n")
    print("| cell order | --tolerance | frame while turning (size) | ms (median) | frames/s | way while turning | still frame s | first frame(s) s |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        size = "x".join(map(str, r["coarse"]))
        print(f"| {r['order']} | {r['tolerance'] or '-'} | {'/'.join(sorted(r['qualities']))} ({size}) | "
              f"{r['median'] * 1e3:.0f} | {r['fps']:.2f} | {r['way'] or '(the order above)'} | {r['still']:.2f} | {r['first']:.1f} |")
    if errors:
        print(f"\nStill frame against reference.exact, window {args.error_size[0]}x{args.error_size[1]}:\n")
        print("| cell order | --tolerance | RMSE | largest error |")
        print("|---|---|---|---|")
        for e in errors:
            print(f"| {e['order']} | {e['tolerance'] or '-'} | {e['rmse']:.2e} | {e['max']:.2e} |")


if __name__ == "__main__":
    main()
