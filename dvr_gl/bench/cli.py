"""``dvr-gl bench``: speed and accuracy of dvr_gl's techniques, beside VTK where it is installed.

This module holds the options (joined into the ``dvr-gl`` parser by
``dvr_gl.frontends.cli``) and the dispatch over the suites:

- ``peer`` (the default): the ray caster beside VTK's (``dvr_gl.bench.raycast``);
- ``slicing``: slice2d and slice3d beside the ray caster (``dvr_gl.bench.slicing``);
- ``mesh``: projected tetrahedra beside VTK's (``dvr_gl.bench.mesh``);
- ``particles``: PBVR and splatting (``dvr_gl.bench.particles``);
- ``shading``: the cost and convergence of lighting (``dvr_gl.bench.shading``);
- ``all``: every technique over its quality parameter, one report (``dvr_gl.bench.all``).

What the suites share is in ``dvr_gl.bench.common``; the suites never import this module.
"""

from __future__ import annotations

import argparse
import math
import sys

from .common import CHEST_FILE, DEFAULT_DATA_DIR, STEPS_VOXELS


def add_arguments(parser):
    """The ``dvr-gl bench`` options, added to ``parser``; returns it."""
    parser.add_argument("--size", type=int, default=None,
                        help="image width and height in pixels (default 512; 64 with --quick)")
    parser.add_argument("--repeats", type=int, default=None,
                        help="timed frames per measurement, after one warm-up frame (default 5; 2 with --quick)")
    parser.add_argument("--quick", action="store_true",
                        help="a small, fast run for a smoke test (64x64, 2 frames)")
    parser.add_argument("--out", default=None,
                        help="write <OUT>.csv, <OUT>.json and <OUT>.png (OUT a stem or an existing folder)")
    parser.add_argument("--datasets", default=None,
                        help="comma-separated: chest (vtk.js LIDC2 CT), head (bundled CT head); default both. "
                             "Mesh suite: bluntfin, combustor, loxpost, ball; default all four")
    parser.add_argument("--steps", default=",".join(f"{s:g}" for s in STEPS_VOXELS),
                        help="comma-separated ray steps in voxels (the smallest spacing); default 1,0.5,0.25")
    parser.add_argument("--chest", default=None,
                        help=f"path of the chest CT (default $DVR_GL_DATA or {DEFAULT_DATA_DIR} / {CHEST_FILE})")
    parser.add_argument("--backend", default="auto", help="dvr_gl GL backend (auto, egl, osmesa)")
    parser.add_argument("--no-vtk", action="store_true", help="leave VTK out")
    parser.add_argument("--textures", action="store_true",
                        help="also measure trilinear sampling throughput of float32, float16 and unorm8 textures")
    parser.add_argument("--suite", choices=("peer", "slicing", "mesh", "particles", "shading", "all"), default="peer",
                        help="all: every technique over its quality parameter on generated and real "
                             "scenes, one report (--datasets ml,head,ball,bluntfin; --out DIR writes "
                             "all.csv/.json/.md/.png and contact.png); peer: the ray caster beside VTK (default); slicing: slice2d (k = 0, 1, 3), "
                             "slice3d (cpu and vertex proxies) and the ray caster at equal sample "
                             "distance, each with and without pre-integration; mesh: projected "
                             "tetrahedra (MPVO, centroid sort and the cell walk; tolerance= at VTK's error) beside VTK's on the NASA meshes "
                             "and the Delaunay ball (--datasets bluntfin,combustor,loxpost,ball); particles: "
                             "PBVR at several repetition counts beside raycast (head) and tetra (bluntfin); "
                             "shading: the cost of lighting in raycast and slice3d beside VTK's ShadeOn, "
                             "and the lit image's convergence against exact")
    parser.add_argument("--repetitions-list", default="1,4,16,64",
                        help="particles suite: the repetition counts (default 1,4,16,64)")
    parser.add_argument("--error-size", type=int, default=None,
                        help="image size of the error measurement: mesh, particles and shading suites (default 128; "
                             "32 with --quick); peer suite (default: the frame's own size)")
    parser.add_argument("--data-dir", default=None,
                        help=f"mesh suite: the shared data folder (default $DVR_GL_DATA or {DEFAULT_DATA_DIR})")
    parser.add_argument("--vtk-float", action="store_true",
                        help="give VTK the samples as float32 instead of their own type")
    return parser


def run_bench(args) -> int:
    """Fill in the defaults that depend on the suite, check the options, run the suite;
    returns the exit status (2 for a bad option)."""
    if args.size is None:
        args.size = (128 if args.suite == "all" else 64) if args.quick else 512
    if args.repeats is None:
        args.repeats = 2 if args.quick else 5
    if args.size < 1 or args.repeats < 1:
        print("dvr-gl bench: --size and --repeats must be positive", file=sys.stderr)
        return 2
    try:
        steps = [float(s) for s in args.steps.split(",") if s.strip()]
    except ValueError:
        print(f"dvr-gl bench: --steps must be numbers separated by commas, got {args.steps!r}", file=sys.stderr)
        return 2
    if not steps or any(not (s > 0 and math.isfinite(s)) for s in steps):
        print(f"dvr-gl bench: --steps must be positive, got {args.steps!r}", file=sys.stderr)
        return 2
    if args.datasets is None:
        args.datasets = {"mesh": "bluntfin,combustor,loxpost,ball", "particles": "head,bluntfin",
                         "all": "ml,ball" if args.quick else "ml,head,ball,bluntfin"}.get(args.suite, "chest,head")
    if args.suite == "all":
        from .all import run_all_bench
        return run_all_bench(args)
    if args.suite == "particles":
        from .particles import parse_repetitions, run_particles_bench
        if args.error_size is None:
            args.error_size = 32 if args.quick else 128
        try:
            args.repetitions_list = parse_repetitions(args.repetitions_list)
        except ValueError as e:
            print(f"dvr-gl bench: {e}", file=sys.stderr)
            return 2
        return run_particles_bench(args)
    if args.suite == "shading":
        from .shading import run_shading_bench
        if args.error_size is None:
            args.error_size = 32 if args.quick else 128
        if args.steps == ",".join(f"{s:g}" for s in STEPS_VOXELS):
            args.steps = "1,0.5"
        return run_shading_bench(args)
    if args.suite == "mesh":
        from .mesh import run_mesh_bench
        if args.error_size is None:
            args.error_size = 32 if args.quick else 128
        return run_mesh_bench(args)
    if args.suite == "slicing":
        from .slicing import run_slicing_bench
        return run_slicing_bench(args)
    from .raycast import run_peer_bench
    return run_peer_bench(args)


def main(argv=None) -> int:
    """``python -m dvr_gl.bench.cli``: the same as ``dvr-gl bench``."""
    parser = argparse.ArgumentParser(prog="dvr-gl bench", description=__doc__.split("\n\n")[0])
    add_arguments(parser)
    return run_bench(parser.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
