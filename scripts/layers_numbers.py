"""The numbers of docs/guide/layers.md: error against the exact image per step, and the
frame time of several volumes beside one, on this machine's GL.

    LP_NUM_THREADS=2 python scripts/layers_numbers.py [--size 128] [--frame 512] [--frames-only]

The scenes are those of tests/test_raycast_layers.py (the CT head with a rotated
Marschner-Lobb field on its own grid; three channels of one grid)."""

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import dvr_gl  # noqa: E402
from dvr_gl import metrics, reference  # noqa: E402
from dvr_gl.gl.context import current  # noqa: E402
from test_raycast_layers import channels_scene, head_and_field  # noqa: E402


def median_frames(renderer, scenes, repeats=5):
    """The median frame time of each (scene, options), their frames taken in turn (so
    that a load on the machine falls on all alike); the first frame of each (compiling,
    uploading) apart."""
    for scene, options in scenes:
        renderer.render(scene, **options)
    times = [[] for _ in scenes]
    for _ in range(repeats):
        for (scene, options), kept in zip(scenes, times):
            start = time.perf_counter()
            renderer.render(scene, **options)          # reads back: GL has finished
            kept.append(time.perf_counter() - start)
    return [statistics.median(kept) for kept in times]


SCENES = (("head + rotated field", head_and_field, "mix"),
          ("head + rotated field", head_and_field, "add"),
          ("three channels", channels_scene, "add"),
          ("three channels", channels_scene, "mix"))


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--size", type=int, default=128, help="image side for the errors")
    parser.add_argument("--frame", type=int, default=512, help="image side for the frame times")
    parser.add_argument("--frames-only", action="store_true", help="leave out the errors against exact")
    args = parser.parse_args()
    with dvr_gl.Renderer() as renderer:
        with current(renderer.ctx):
            print(renderer.ctx.info.get("GL_RENDERER"), "load average", os.getloadavg())
        if not args.frames_only:
            print("error against exact (RMSE, max abs, PSNR) per step:")
        for name, make, blend in (() if args.frames_only else SCENES):
            scene = make(args.size, blend)
            start = time.perf_counter()
            exact = reference.exact(scene)
            exact_s = time.perf_counter() - start
            voxel = min(layer.volume.min_spacing for layer in scene.all_layers)
            for fraction in (1.0, 0.5, 0.25):
                image = renderer.render(scene, step=fraction * voxel, ert_transmittance=0.0)
                print(f"  {name:22s} {blend:3s} step {fraction:<5} voxel ({fraction * voxel:.3f}): "
                      f"RMSE {metrics.rmse(image, exact):.2e}  max {metrics.max_abs_error(image, exact):.2e}  "
                      f"PSNR {metrics.psnr(image, exact):.1f} dB   (exact {exact_s:.1f} s)")
        print(f"median of 5 frames at {args.frame}x{args.frame}, default step and options "
              f"(and the layers without empty-space skipping):")
        for name, make, blend in SCENES:
            scene = make(args.frame, blend)
            alone = scene.replace(layers=())
            several, unskipped, one = median_frames(renderer, [(scene, {}), (scene, {"skip_empty": False}),
                                                               (alone, {})])
            print(f"  {name:22s} {blend:3s}: {len(scene.all_layers)} volumes {several * 1e3:7.1f} ms "
                  f"(skip_empty=False {unskipped * 1e3:7.1f} ms), first volume alone {one * 1e3:7.1f} ms  "
                  f"({several / one:.2f}x, unskipped {unskipped / one:.2f}x)")
        print("load average", os.getloadavg())


if __name__ == "__main__":
    main()
