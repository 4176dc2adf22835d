"""``dvr-gl bench --suite slicing``: the slicing techniques beside the ray caster at equal
sample distance, speed and accuracy in one run.

On the peer suite's data sets and cameras (``--datasets chest,head``), for each
k = 0, 1, 3: slice2d with k intermediate slices, slice3d (cpu and vertex proxies) and the
ray caster, all at the sample distance d_k = spacing along the stack axis / (k + 1), each
with and without pre-integration. Per renderer: the median frame time (round robin, after
one warm-up frame, image read back), the error against ``reference.exact`` (RMSE, largest
absolute error, PSNR), and ``t/raycast`` and ``err/raycast``: ratios to the
post-classified ray caster at the same distance.

Results go to stdout as a table and, with ``--out``, to ``<out>.csv``, ``<out>.json`` and
``<out>.png`` (error against time, one line per technique through its distances).
"""

from __future__ import annotations

import functools
import sys

from ..metrics import compare
from ..util.progress import Progress
from ..model.scene import Scene
from .common import (error_time_figure, fmt, interleaved_frames, load_datasets, machine_info, result_row,
                     write_results)

SLICE_INTERPOLATE = (0, 1, 3)

CSV_FIELDS = ("dataset", "width", "height", "renderer", "kind", "interpolate", "preintegrate",
              "step_voxels", "step_world", "ms_median", "ms_min", "ms_max", "rmse", "max_abs",
              "psnr", "time_vs_raycast", "rmse_vs_raycast")


def slicing_configs(interpolate=SLICE_INTERPOLATE):
    """(label, technique, options, k) for each renderer of the slicing suite; every
    sample distance d_k = spacing along the stack axis / (k + 1) is shared by slice2d
    with k, both slice3d proxies and the ray caster, each with and without
    pre-integration."""
    out = []
    for k in interpolate:
        for pre in (False, True):
            tail = " +pre" if pre else ""
            opts = {"preintegrate": True} if pre else {}
            out.append((f"slice2d k={k}{tail}", "slice2d", dict(opts, interpolate=k), k))
            out.append((f"slice3d cpu{tail}", "slice3d", dict(opts, proxy="cpu"), k))
            out.append((f"slice3d vertex{tail}", "slice3d", dict(opts, proxy="vertex"), k))
            out.append((f"raycast{tail}", "raycast", dict(opts), k))
    return out


def run_slicing(args, err=None):
    """Frame time and error against exact of the slicing techniques beside the ray caster
    at equal sample distance, on the same data sets and cameras as the peer suite.
    Returns (rows, info); rows carry ``time_vs_raycast`` and ``rmse_vs_raycast`` (the
    post-classified ray caster at the same distance)."""
    err = err if err is not None else sys.stderr   # looked up now: tests swap sys.stderr
    from ..rendering.renderer import Renderer
    from ..reference.exact import exact as exact_image
    from ..techniques.slice2d import stack_axis

    size = args.size
    names = [n.strip() for n in (args.datasets or "chest,head").split(",") if n.strip()]
    sets = load_datasets(names, args.chest, err)
    configs = slicing_configs()
    ks = sorted({c[3] for c in configs})
    frames = 1 + args.repeats
    progress = Progress(len(sets) * (1 + len(configs) * frames), stream=err)
    rows, info = [], {}
    try:
        with Renderer(backend=args.backend) as gl:
            info["dvr_gl"] = gl.info()
            for name, volume, tf, camera in sets:
                scene = Scene(volume, tf, camera, width=size, height=size)
                progress.begin(f"{name}: exact image")
                exact = exact_image(scene)
                progress.advance(f"{name}: exact image")
                axis_spacing = float(volume.spacing[stack_axis(camera.forward)])
                for k in ks:
                    distance = axis_spacing / (k + 1)
                    group = [c for c in configs if c[3] == k]
                    calls = []
                    for label, technique, opts, _ in group:
                        step = {} if technique == "slice2d" else {"step": distance}
                        calls.append(functools.partial(gl.render, scene, technique=technique, **step, **opts))
                    images, times = interleaved_frames(
                        calls, args.repeats,
                        lambda j, i: progress.advance(
                            f"{name} d={distance:.3g}: {group[j][0]} "
                            + ("warm-up" if i < 0 else f"frame {i + 1}/{args.repeats}")))
                    for (label, technique, opts, _), image, ts in zip(group, images, times):
                        row = result_row(name, scene, label, technique, None, distance / volume.min_spacing,
                                         distance, ts, compare(image, exact))
                        row["interpolate"] = k
                        row["series"] = label.replace(f" k={k}", "")  # one figure line per technique
                        row["preintegrate"] = bool(opts.get("preintegrate"))
                        rows.append(row)
    finally:
        progress.close()
    base = {(r["dataset"], r["interpolate"]): r for r in rows if r["renderer"] == "raycast"}
    for r in rows:
        b = base.get((r["dataset"], r["interpolate"]))
        r["time_vs_raycast"] = r["ms_median"] / b["ms_median"] if b else None
        r["rmse_vs_raycast"] = r["rmse"] / b["rmse"] if b and b["rmse"] > 0 else None
    info.update(machine_info(), size=size, repeats=args.repeats, suite="slicing",
                datasets=[n for n, *_ in sets])
    return rows, info


def format_slicing_table(rows):
    head = ("data", "distance (voxel)", "renderer", "ms/frame", "RMSE", "max err", "PSNR dB", "t/raycast",
            "err/raycast")
    lines = [(r["dataset"], f"{r['step_voxels']:.3g}", r["renderer"], fmt(r["ms_median"], ".1f"),
              fmt(r["rmse"], ".2e"), fmt(r["max_abs"], ".3f"), fmt(r["psnr"], ".1f"),
              fmt(r["time_vs_raycast"], ".2f"), fmt(r["rmse_vs_raycast"], ".2f")) for r in rows]
    widths = [max(len(h), *(len(l[i]) for l in lines)) if lines else len(h) for i, h in enumerate(head)]

    def fmt_line(cells):
        return "  ".join(c.ljust(w) if i in (0, 2) else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths)))

    out = [fmt_line(head), fmt_line(["-" * w for w in widths])]
    prev = None
    for r, l in zip(rows, lines):
        if prev is not None and (r["dataset"], r["interpolate"]) != prev:
            out.append("")
        prev = (r["dataset"], r["interpolate"])
        out.append(fmt_line(l))
    return "\n".join(out)


def run_slicing_bench(args) -> int:
    """``dvr-gl bench --suite slicing``: run, print the table, write the results with
    ``--out``; returns the exit status."""
    rows, info = run_slicing(args)
    print(f"dvr_gl: {info['dvr_gl'].get('renderer')} ({info['dvr_gl'].get('backend')}); "
          f"{info['size']}x{info['size']}, median of {info['repeats']} frames; t/raycast and "
          f"err/raycast divide by the post-classified ray caster at the same distance")
    print(format_slicing_table(rows))
    if args.out:
        paths = write_results(rows, info, args.out, fields=CSV_FIELDS, figure=error_time_figure)
        print("wrote " + ", ".join(str(p) for p in paths))
    return 0
