"""Splatting against exact, beside VTK's ray caster at a one-voxel step (issue 9's bar):
for the CT head and the chest CT in the peer bench's views and in the particles suite's,
the RMSE at 128x128 against the exact image of the tent kernel at density 1 and 2, the
Gaussian kernel at density 1 and 2, dvr_gl's ray caster at 1 and 0.5 voxel and VTK's at
1 voxel; then, in the peer bench's views, frames at 512x512 of each, median of 5 taken
round robin (ratios hold within the run). Writes a Markdown table.

    LP_NUM_THREADS=2 python apps/splat_vs_vtk.py [--out docs/notes/splat_vs_vtk.md]
"""

import argparse
import functools
import os
import statistics

import dvr_gl
from dvr_gl import metrics, reference
from dvr_gl.bench.common import datasets, interleaved_frames
from dvr_gl.bench.particles import VIEWS
from dvr_gl.formats import atomic_write
from dvr_gl.util.progress import Progress
from dvr_gl.model.scene import default_camera
from dvr_gl.bench.vtk_peer import VTKPeer

HERE = os.path.dirname(os.path.abspath(__file__))
VTK_LABEL = "VTK raycast, 1 voxel"


def renderers(volume):
    """(label, technique, options) of dvr_gl's rows."""
    h = volume.min_spacing
    return [("splat, tent, density 1", "splat", {}), ("splat, tent, density 2", "splat", {"density": 2}),
            ("splat, Gaussian, density 1", "splat", {"kernel": "gaussian"}),
            ("splat, Gaussian, density 2", "splat", {"kernel": "gaussian", "density": 2}),
            ("raycast, 1 voxel", "raycast", {"step": h}), ("raycast, 0.5 voxel", "raycast", {"step": h / 2})]


def scenes(size):
    """(name, view, scene, timed): each data set in the peer bench's view (timed) and in
    the particles suite's."""
    out = []
    for name, volume, tf, camera in datasets(["head", "chest"]):
        out.append((name, "peer bench", dvr_gl.Scene(volume, tf, camera, size, size), True))
        azimuth, elevation = VIEWS[name]
        out.append((name, "particles suite", dvr_gl.Scene(volume, tf, default_camera(
            volume, azimuth=azimuth, elevation=elevation), size, size), False))
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default=os.path.join(HERE, os.pardir, "docs", "notes", "splat_vs_vtk.md"))
    p.add_argument("--size", type=int, default=512)
    p.add_argument("--error-size", type=int, default=128)
    p.add_argument("--repeats", type=int, default=5)
    args = p.parse_args(argv)
    sets = scenes(args.size)
    progress = Progress(sum(2 if timed else 1 for *_, timed in sets))
    errors, times = {}, {}
    peer = VTKPeer()
    try:
        with dvr_gl.Renderer() as gl:
            for name, view, scene, timed in sets:
                progress.begin(f"{name}, {view} view: errors")
                small = scene.replace(width=args.error_size, height=args.error_size)
                exact = reference.exact(small)
                h = scene.volume.min_spacing
                rows = {label: metrics.compare(gl.render(small, technique=t, **o), exact)
                        for label, t, o in renderers(scene.volume)}
                peer.setup(small, h)
                rows[VTK_LABEL] = metrics.compare(peer.frame(), exact)
                errors[name, view] = rows
                progress.advance(f"{name}, {view} view: errors")
                if timed:
                    peer.setup(scene, h)
                    calls = [(label, functools.partial(gl.render, scene, technique=t, **o))
                             for label, t, o in renderers(scene.volume)] + [(VTK_LABEL, peer.frame)]
                    _, seconds = interleaved_frames([c for _, c in calls], args.repeats)
                    times[name] = {label: 1e3 * statistics.median(s) for (label, _), s in zip(calls, seconds)}
                    progress.advance(f"{name}: frames")
    finally:
        progress.close()
        peer.close()
    lines = ["# Splatting beside VTK's ray caster at one voxel", "",
             f"`LP_NUM_THREADS={os.environ.get('LP_NUM_THREADS', 'unset')} python apps/splat_vs_vtk.py` (RMSE, "
             f"largest error and PSNR of premultiplied RGBA at {args.error_size}x{args.error_size} against "
             f"`reference.exact`; frames at {args.size}x{args.size} in the peer bench's views, median of "
             f"{args.repeats} taken round robin)", "",
             "| data | view | renderer | RMSE | max error | PSNR dB | RMSE / VTK's | ms/frame | time / raycast 0.5 voxel |",
             "|---|---|---|---|---|---|---|---|---|"]
    for (name, view), rows in errors.items():
        bar = rows[VTK_LABEL]["rmse"]
        for label, e in rows.items():
            ms = times.get(name, {}).get(label) if view == "peer bench" else None
            base = times.get(name, {}).get("raycast, 0.5 voxel")
            lines.append(f"| {name} | {view} | {label} | {e['rmse']:.2e} | {e['max_abs']:.2e} | {e['psnr']:.1f} | "
                         f"{e['rmse'] / bar:.2f} | {'' if ms is None else f'{ms:.0f}'} | "
                         f"{'' if ms is None else f'{ms / base:.2f}'} |")
    tent = [rows["splat, tent, density 1"]["rmse"] / rows[VTK_LABEL]["rmse"] for rows in errors.values()]
    gain = [rows["splat, tent, density 1"]["rmse"] / rows["splat, tent, density 2"]["rmse"] for rows in errors.values()]
    lines += ["", f"The tent kernel at its defaults has {min(tent):.2f} to {max(tent):.2f} times VTK's RMSE at one "
                  f"voxel; density 2 divides its error by {min(gain):.1f} to {max(gain):.1f}."]
    text = "\n".join(lines) + "\n"
    atomic_write(args.out, text.encode())
    print(text)


if __name__ == "__main__":
    main()
