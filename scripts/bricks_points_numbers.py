"""The point techniques' numbers of docs/guide/bricks.md: bricked against whole-volume
particles and splats (tent and Gaussian kernels), the largest difference, the time to make
the primitives and the frame time.

    LP_NUM_THREADS=2 python scripts/bricks_points_numbers.py [--size 512] [--repeats 3] [--data DIR]

The bench's CT head and chest CT with their transfer functions and oblique views
(``dvr_gl.bench.common.datasets``), each technique's defaults. Per technique, the whole
volume and bricks of 32 and 64 cells are rendered in turn: first with nothing cached
(``make``: the primitives made, then one frame), then ``repeats`` frames with them
cached (the median). The largest difference is of any channel of any pixel against the
whole volume's image."""

import argparse
import os
import statistics
import time

import numpy as np

import dvr_gl
from dvr_gl.bench.common import CHEST_FILE, datasets
from dvr_gl.techniques import particle_sets
from dvr_gl.util.cache import TableCache

TECHNIQUES = [("particles", {}), ("splat tent", {"kernel": "tent"}), ("splat Gaussian", {"kernel": "gaussian"})]
BRICKS = (None, 32, 64)


def cold(renderer, scene, technique, options):
    """(image, seconds) of a frame with nothing made yet (no tables, no cell cache)."""
    renderer.tables = TableCache()
    particle_sets._CELLS.clear()
    start = time.perf_counter()
    image = renderer.render(scene, technique, **options)
    return image, time.perf_counter() - start


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--data", default=os.path.join("..", "shared", "data"))
    parser.add_argument("--names", default="head,chest")
    args = parser.parse_args()
    renderer = dvr_gl.Renderer()
    rows = []
    for name, volume, tf, camera in datasets(args.names.split(","), os.path.join(args.data, CHEST_FILE)):
        scene = dvr_gl.Scene(volume, tf, camera, width=args.size, height=args.size)
        label = f"{name} {'x'.join(map(str, volume.shape[::-1]))} {volume.data.dtype}"
        for title, options in TECHNIQUES:
            technique = title.split()[0]
            configs = [dict(options) if b is None else dict(options, brick_size=b) for b in BRICKS]
            renderer.render(scene, technique, **options)      # (the shaders compiled before any timing)
            made = [cold(renderer, scene, technique, o) for o in configs]
            # cached frames: the primitives of every config kept (a table each)
            tables = []
            for o in configs:
                renderer.tables = TableCache()
                renderer.render(scene, technique, **o)
                tables.append(renderer.tables)
            times = [[] for _ in configs]
            for _ in range(args.repeats):
                for o, t, out in zip(configs, tables, times):
                    renderer.tables = t
                    start = time.perf_counter()
                    renderer.render(scene, technique, **o)
                    out.append(time.perf_counter() - start)
            frames = [statistics.median(t) for t in times]
            single = made[0][0]
            for b, (image, make), frame in zip(BRICKS, made, frames):
                diff = "" if b is None else f"{float(np.abs(image - single).max()):.1e}"
                rows.append((label, title, "whole volume" if b is None else f"{b}^3", make, frame, frame / frames[0],
                             diff))
                print(" | ".join([label, title, rows[-1][2], f"make {make:.2f} s", f"frame {frame * 1e3:.0f} ms",
                                  f"{frame / frames[0]:.2f}x", diff]), flush=True)
    print()
    print("| data | technique | bricks | first frame (made) | frame | against whole | largest difference |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for label, title, bricks, make, frame, ratio, diff in rows:
        print(f"| {label} | {title} | {bricks} | {make:.2f} s | {frame * 1e3:.0f} ms | "
              f"{'' if bricks == 'whole volume' else f'{ratio:.2f}x'} | {diff} |")


if __name__ == "__main__":
    main()
