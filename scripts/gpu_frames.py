"""Frame times on this machine's GL, as docs/notes/gpu.md and docs/notes/tetra_vs_vtk.md
report them for a lent GPU: the cell walk (exact segments and table segments), several
volumes in each pixel stage, and the ray caster at VTK's one-voxel error, each at
SIZE x SIZE with a new view each frame and the image read back (medians, after a warm-up;
GPU time of one draw from a timer query). Writes JSON to --out and the 96x96 walk images
beside it; each walk row has their RMSE against ``reference.exact`` (float64, on the CPU),
so that one run gives the exact mode's frames with their error.

    DVR_GL_DATA=../shared/data python scripts/gpu_frames.py [--size 1024] [--out gpu_frames.json] [--walk-only]

The walk is also timed in the other stage and, where the GL's lanes are not found in
lockstep, built as for lanes in lockstep (``LOCKSTEP_LANES``), each with its images.
"""

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import dvr_gl  # noqa: E402
from dvr_gl.bench.common import datasets, load_mesh_dataset  # noqa: E402
from dvr_gl.gl.context import current  # noqa: E402
from dvr_gl.techniques import get_technique, raycast  # noqa: E402
from test_raycast_layers import channels_scene, head_and_field  # noqa: E402

VTK_ONE_VOXEL_STEP = {"head": 1.41, "chest": 1.09}   # voxels (docs/tolerance_vs_vtk.md)


def gpu_ms(ctx, fn, repeats=7):
    """Median GPU time of fn() in ms (a timer query), after two warm-up calls."""
    fn(), fn()
    ctx.finish()
    query, times = ctx.query(time=True), []
    for _ in range(repeats):
        with query:
            fn()
        times.append(query.elapsed / 1e6)
    return round(float(np.median(times)), 3)


def median_ms(fn, args, warm=4):
    """Median wall time in ms of fn(a) over args after ``warm`` of them (fn reads back: GL has finished)."""
    for a in args[:warm]:
        fn(a)
    times = []
    for a in args[warm:]:
        start = time.perf_counter()
        fn(a)
        times.append(time.perf_counter() - start)
    return round(1000 * float(np.median(times)), 2)


def walk_rows(r, size, out, name, mesh, tf, cams, stage, lockstep, exact96):
    """The cell walk on one mesh in ``stage`` ("auto": the renderer's choice), built with
    ``LOCKSTEP_LANES`` ``lockstep`` (None: the GL's own): exact segments, and table ones
    for the default way; the 96x96 images saved beside ``out``, their RMSE against
    ``exact96`` (the exact image of the first view) in the rows."""
    rows = []
    tetra = get_technique("tetra")
    default = stage == "auto" and lockstep is None
    for segments in ("exact", "table") if default else ("exact",):
        scenes = [dvr_gl.Scene(mesh, tf, c, size, size) for c in cams]
        frame = median_ms(lambda s: r.render(s, "tetra", segments=segments, stage=stage), scenes)
        plan = tetra.make_plan(scenes[0], None, tables=r.tables, segments=segments, stage=stage)
        small = dvr_gl.Scene(mesh, tf, cams[0], 96, 96)
        label = segments + ("" if default else f"_{stage}" + ("" if lockstep is None else f"_lockstep{lockstep}"))
        image96 = r.render(small, "tetra", segments=segments, stage=stage)
        np.save(out.with_name(f"walk96_{name}_{label}.npy"), image96)
        with current(r.ctx):
            rows.append(dict(mesh=name, segments=segments, stage=stage, lockstep=lockstep, size=size, frame_ms=frame,
                             draw_gpu_ms=gpu_ms(r.ctx, lambda: tetra.draw(r, plan), 5),
                             rmse_96=float(f"{dvr_gl.metrics.rmse(image96, exact96):.3g}")))
        print(rows[-1], flush=True)
    return rows


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--size", type=int, default=1024)
    parser.add_argument("--out", default="gpu_frames.json")
    parser.add_argument("--walk-only", action="store_true", help="only the cell walk's rows (a shorter run)")
    args = parser.parse_args()
    size, out = args.size, Path(args.out)
    results = {}
    # the walk's other ways, measured beside the default: the other stage, and the walk
    # built for lanes in lockstep (light segments inline, the rest in the outer loop)
    lockstep = dvr_gl.Renderer()
    lockstep.programs.context_defines["LOCKSTEP_LANES"] = 1
    with dvr_gl.Renderer() as r, lockstep, current(r.ctx):
        ctx = r.ctx
        results["renderer"] = [ctx.info["GL_RENDERER"], r.compute_stage_faster]
        print(results["renderer"], flush=True)
        other_stage = "fragment" if r.compute_stage_faster else "compute"
        rows = results["walk"] = []
        for name in ("bluntfin", "combustor", "loxpost"):
            mesh, tf = load_mesh_dataset(name)
            cams = [dvr_gl.default_camera(mesh, azimuth=30 + 7 * k, elevation=20) for k in range(29)]
            exact96 = dvr_gl.reference.exact(dvr_gl.Scene(mesh, tf, cams[0], 96, 96))
            rows += walk_rows(r, size, out, name, mesh, tf, cams, "auto", None, exact96)
            rows += walk_rows(r, size, out, name, mesh, tf, cams, other_stage, None, exact96)
            if not r.programs.context_defines["LOCKSTEP_LANES"]:
                rows += walk_rows(lockstep, size, out, name, mesh, tf, cams, "auto", 1, exact96)
        if args.walk_only:
            write_json(out, results)
            return
        rows = results["layers"] = []
        for name, make in (("head+field", head_and_field), ("channels", channels_scene)):
            scene = make(size, "mix")
            for stage in ("fragment", "compute"):
                plan = raycast.make_plan(scene, None, tables=r.tables, stage=stage)
                rows.append(dict(scene=name, size=size, stage=stage, gpu_ms=gpu_ms(ctx, lambda: raycast.draw(r, plan), 5),
                                 frame_ms=median_ms(lambda s: r.render(s, stage=stage), [scene] * 9)))
                print(rows[-1], flush=True)
        rows = results["raycast"] = []
        for name, volume, tf, camera in datasets(["head", "chest"]):
            step = VTK_ONE_VOXEL_STEP[name] * volume.min_spacing
            scenes = [dvr_gl.Scene(volume, tf, dvr_gl.default_camera(volume, azimuth=30 + 3 * k, elevation=20), size, size)
                      for k in range(24)]
            plan = raycast.make_plan(scenes[0], step, tables=r.tables)
            rows.append(dict(data=name, size=size, frame_ms=median_ms(lambda s: r.render(s, step=step), scenes),
                             gpu_ms=gpu_ms(ctx, lambda: raycast.draw(r, plan))))
            print(rows[-1], flush=True)
    write_json(out, results)


def write_json(out, results):
    partial = out.with_name(out.name + ".partial")
    partial.write_text(json.dumps(results, indent=1))
    os.replace(partial, out)


if __name__ == "__main__":
    main()
