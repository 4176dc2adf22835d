"""Issue 27, must-show 5: memory per tet on the GPU side and the largest mesh the cell walk
renders on this machine.

For each point count, a Delaunay mesh of uniform random points in the unit cube (scalars:
a smooth function of position) is built with ``TetMesh.from_points``, rendered with
``sort="walk"`` at the given size (the first frame, which makes the per-mesh tables, and
the median of later frames, each a new view), and the renderer's GPU bytes
(``Renderer.gpu_bytes``: textures and targets it holds) divided by the tet count.
Prints one line per mesh and a PNG of the largest; stops at the first count that fails
(memory) and says why.

    LP_NUM_THREADS=2 python scripts/largest_mesh.py --points 100000,400000,1000000 --size 512
"""

from __future__ import annotations

import argparse
import resource
import sys
import time

import numpy as np

import dvr_gl
from dvr_gl.bench.common import mesh_tf


def random_mesh(n, seed=0):
    rng = np.random.default_rng(seed)
    p = rng.random((n, 3))
    scalars = np.sin(6 * p[:, 0]) * np.cos(5 * p[:, 1]) + p[:, 2]
    return dvr_gl.TetMesh.from_points(p, scalars)


def peak_rss_gib():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2 ** 20


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", default="100000,400000,1000000")
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--frames", type=int, default=3)
    parser.add_argument("--png", default=None, help="write the largest mesh's picture here")
    args = parser.parse_args(argv)
    counts = [int(v) for v in args.points.split(",")]
    print(f"{'points':>9} {'tets':>10} {'build s':>8} {'first frame s':>14} {'frame s':>8} "
          f"{'GPU MB':>8} {'GPU B/tet':>9} {'peak RSS GiB':>12}", flush=True)
    last = None
    for n in counts:
        try:
            t = time.perf_counter()
            mesh = random_mesh(n)
            built = time.perf_counter() - t
            tf = mesh_tf(mesh)
            with dvr_gl.Renderer() as r:
                scene = dvr_gl.Scene(mesh, tf, dvr_gl.default_camera(mesh, azimuth=30, elevation=20),
                                     args.size, args.size)
                t = time.perf_counter()
                image = r.render(scene, "tetra", sort="walk")
                first = time.perf_counter() - t
                frames = []
                for k in range(args.frames):
                    s = dvr_gl.Scene(mesh, tf, dvr_gl.default_camera(mesh, azimuth=40 + 9 * k, elevation=20),
                                     args.size, args.size)
                    t = time.perf_counter()
                    r.render(s, "tetra", sort="walk")
                    frames.append(time.perf_counter() - t)
                gpu = r.gpu_bytes()
        except MemoryError as e:
            print(f"{n:>9}: out of memory ({e})", flush=True)
            break
        print(f"{n:>9} {mesh.n_tets:>10} {built:>8.1f} {first:>14.2f} {float(np.median(frames)):>8.2f} "
              f"{gpu / 2**20:>8.1f} {gpu / mesh.n_tets:>9.1f} {peak_rss_gib():>12.2f}", flush=True)
        last = image
    if args.png and last is not None:
        from dvr_gl.formats.images import save_png
        save_png(args.png, last)
        print(f"wrote {args.png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
