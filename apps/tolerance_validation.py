"""Requested against achieved error of ``Renderer.render(..., tolerance=E)`` on data the
step model never saw: what ``dvr-gl render FILE --tolerance E`` gives (the auto preset,
the first camera, lit), each against its exact image, beside the best step of a fixed
ladder (2 .. 1/64 voxel) that meets E. Writes a Markdown table.

    python apps/tolerance_validation.py [--out docs/notes/tolerance.md] [--size 128]
"""

import argparse
import os
import time

import numpy as np

import dvr_gl
from dvr_gl import metrics, reference
from dvr_gl.frontends.inputs import first_camera, load_input, resolve_tf, shading_for
from dvr_gl.formats import atomic_write
from dvr_gl.util.progress import Progress
from dvr_gl.rendering.tolerance import PILOT_STEPS, SAFETY, median_seconds

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = os.environ.get("DVR_GL_DATA", os.path.join(HERE, os.pardir, os.pardir, "shared", "data"))
FILES = ["vtk_neghip/neghip_66x66x66_uint8.raw", "vtk_hydrogen/hydrogen_64x64x64_float32.raw",
         "vtk_headmr/HeadMRVolume.mhd", "vtk_carotid/carotid.vtk", "vtk_ironprot/ironProt.vtk",
         "debian_mricron_colin27/ch2.nii.gz"]
TOLERANCES = (1e-2, 3e-3, 1e-3)
LADDER = [2.0 / 2 ** k for k in range(8)]


def scene_for(path, size):
    volume, preset = load_input(path)
    _, tf = resolve_tf(None, volume, preset)
    return dvr_gl.Scene(volume, tf, first_camera(volume), size, size, shading=shading_for("raycast"))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default=os.path.join(HERE, os.pardir, "docs", "notes", "tolerance.md"))
    p.add_argument("--size", type=int, default=128)
    args = p.parse_args(argv)
    files = [f for f in FILES if os.path.exists(os.path.join(DATA, f))]
    rows = []
    progress = Progress(len(files))
    with dvr_gl.Renderer() as r:
        for f in files:
            progress.begin(f"exact image of {f}")
            scene = scene_for(os.path.join(DATA, f), args.size)
            exact = reference.exact(scene)
            voxel = scene.volume.min_spacing
            ladder = {k: metrics.rmse(r.render(scene, step=k * voxel, ert_transmittance=0.0), exact) for k in LADDER}
            for tol in TOLERANCES:
                t = time.perf_counter()
                image = r.render(scene, tolerance=tol)
                seconds = time.perf_counter() - t
                c = r.last_choice
                meets = [k for k, e in ladder.items() if e <= tol]
                best = max(meets) if meets else float("nan")
                # frame time of the choice against the best ladder step's, at 512x512, this run
                ratio = float("nan")
                if meets:
                    big = scene.replace(width=512, height=512)
                    chosen = median_seconds(lambda: r.render(big, step=c.step, **c.sampling))
                    ratio = chosen / median_seconds(lambda: r.render(big, step=best * voxel))
                way = "" if not c.preintegrate else (", pre-int." if c.refine == 1 else f", refine {c.refine}")
                rows.append((os.path.basename(f), tol, f"{c.step_voxels:.3g}{way}", c.order, c.predicted_rmse,
                             metrics.rmse(image, exact), best, ratio, seconds))
            progress.advance(f)
    progress.close()
    lines = ["# Error targets on data the step model never saw", "",
             f"`python apps/tolerance_validation.py` ({args.size}x{args.size}, the auto preset, the first "
             "camera, lit; RMSE against `reference.exact`; the ladder is 2, 1, 1/2, ... 1/64 voxel; "
             "time / best = the chosen setting's frame time over the best ladder step's at 512x512, "
             "median of 5 each, same run; `SAFETY` "
             f"{SAFETY:g}, pilots at {', '.join(f'{k:g}' for k in PILOT_STEPS)} voxel)", "",
             "| data | requested | chosen step (voxel), sampling | order | predicted | achieved | best ladder step | "
             "time / best |", "|---|---|---|---|---|---|---|---|"]
    for name, tol, step, order, pred, got, best, ratio, _ in rows:
        lines.append(f"| {name} | {tol:g} | {step} | {order:.2f} | {pred:.2e} | {got:.2e} | {best:g} | "
                     f"{ratio:.2f} |")
    met = sum(1 for row in rows if row[5] <= row[1])
    worst = max((row[7] for row in rows if np.isfinite(row[7])), default=float("nan"))
    lines += ["", f"Achieved <= requested in {met} of {len(rows)}; at most {worst:.2f}x the best fixed "
                  "step's frame time."]
    text = "\n".join(lines) + "\n"
    atomic_write(args.out, text.encode())
    print(text)


if __name__ == "__main__":
    main()
