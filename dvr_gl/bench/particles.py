"""``dvr-gl bench --suite particles``: the point primitives (particle-based volume
rendering, splatting) against exact and beside the technique each data set has otherwise (ray casting for the CT head grid,
projected tetrahedra for the blunt fin mesh), in one run.

Per data set:

- error against ``reference.exact`` at ``--error-size`` (default 128) for R = 1, 4, 16,
  64 repetitions (``--repetitions-list``), with the fitted log-log slope (expected -0.5)
  and RMSE(64) / RMSE(1);
- at ``--size`` (default 512): particles per set, generation time per set (and particles
  generated per second), the draw of one repetition (and particles drawn per second:
  count / draw time, GL finished), and the frame time (draw of all R sets, averaging and
  read-back; particles are made once per TF, so a new view costs only this), median of
  ``--repeats`` frames after one warm-up, each frame from a new view;
- the same frame time and error for the data set's other technique (raycast at a
  half-voxel step; tetra with MPVO), and on grids for splatting (density 1 and 2, the
  default tent kernel: sheets a voxel and half a voxel apart) and VTK's GPU ray caster at a
  one-voxel step (the bar splatting is held to).
"""

from __future__ import annotations

import os
import statistics
import sys
import time

import numpy as np

from ..metrics import compare
from ..util.cache import TableCache
from ..util.progress import Progress
from ..model.scene import Scene
from ..model.camera import default_camera
from .common import (CHEST_FILE, chest_ct, chest_tf, error_axes, figure_bytes, fmt, load_mesh_dataset, machine_info,
                     renderer_line, turning_frames, write_results)

DATASETS = ("head", "chest", "bluntfin")
MARKERS = (("splat density 1", "v"), ("splat density 2", "^"), ("VTK", "D"))   # the rest: squares
VIEWS = {"head": (30.0, 15.0), "chest": (30.0, 15.0), "bluntfin": (30.0, 20.0)}     # azimuth, elevation
CSV_FIELDS = ["dataset", "renderer", "repetitions", "width", "particles", "generate_ms", "generate_per_s",
              "draw_ms", "drawn_per_s", "ms_median", "error_size", "rmse", "max_abs"]


def _scene(name, size, data_dir):
    if name == "head":
        from ..data import ct_head, ct_head_tf
        vol = ct_head()
        return Scene(vol, ct_head_tf(), _camera(vol, name), size, size), ("raycast", {"step": 0.5 * vol.min_spacing})
    if name == "chest":
        vol = chest_ct(os.path.join(data_dir, CHEST_FILE) if data_dir else None)
        return Scene(vol, chest_tf(vol), _camera(vol, name), size, size), ("raycast", {"step": 0.5 * vol.min_spacing})
    if name == "bluntfin":
        mesh, tf = load_mesh_dataset("bluntfin", data_dir)
        return Scene(mesh, tf, _camera(mesh, name), size, size), ("tetra", {})
    raise ValueError(f"unknown data set {name!r} for the particles suite; choose from {', '.join(DATASETS)}")


def _camera(data, name, turn=0.0):
    azimuth, elevation = VIEWS[name]
    return default_camera(data, azimuth=azimuth + turn, elevation=elevation)


def _timed(gl, scene, name, technique, options, repeats):
    """Median seconds of a frame (render + read-back) over ``repeats`` new views."""
    times = turning_frames(lambda s: gl.render(s, technique=technique, **options), scene,
                           lambda i: _camera(scene.volume, name, 0.5 * (i + 1)), repeats)
    return statistics.median(times)


def run_particles(args, err=None):
    """Run the suite; returns (rows, info)."""
    err = err if err is not None else sys.stderr   # looked up now: tests swap sys.stderr
    from ..rendering.renderer import Renderer
    from ..gl.context import current
    from ..reference.exact import exact as exact_image
    from ..techniques import particles as technique

    names = [n.strip() for n in args.datasets.split(",") if n.strip()]
    reps = args.repetitions_list
    progress = Progress(len(names) * (2 + 2 * len(reps) + 1), stream=err)
    rows, info = [], {"slopes": {}}
    try:
        with Renderer(backend=args.backend) as gl:
            info["dvr_gl"] = gl.info()
            for name in names:
                progress.begin(f"{name}: exact image")
                try:
                    scene, (peer, peer_options) = _scene(name, args.size, args.data_dir)
                except FileNotFoundError as e:
                    print(f"dvr-gl bench: skipping {name}: {e}", file=err)
                    continue
                small = scene.replace(width=args.error_size, height=args.error_size)
                exact = exact_image(small)
                progress.advance(f"{name}: exact image")
                # generation (once per TF and radius; the same for every set) and one set's draw
                gen_times, count = [], 0
                for k in range(3):
                    plan = technique.make_plan(scene, seed=k, tables=TableCache())
                    gen_times.append(plan.generate_seconds)
                    count = plan.count
                gen = statistics.median(gen_times)
                with current(gl.ctx):
                    draw_one = _draw_seconds(gl, technique.make_plan(scene, tables=gl.tables))
                errors = []
                for R in reps:
                    e = compare(gl.render(small, technique="particles", repetitions=R), exact)
                    errors.append(e["rmse"])
                    progress.advance(f"{name}: error at R={R}")
                    frame = _timed(gl, scene, name, "particles", {"repetitions": R}, args.repeats)
                    progress.advance(f"{name}: frames at R={R}")
                    rows.append(dict(dataset=name, renderer="dvr_gl particles", repetitions=R, width=args.size,
                                     particles=count, generate_ms=1e3 * gen,
                                     generate_per_s=count / gen if gen > 0 else None,
                                     draw_ms=1e3 * draw_one, drawn_per_s=count / draw_one if draw_one > 0 else None,
                                     ms_median=1e3 * frame, error_size=args.error_size, rmse=e["rmse"],
                                     max_abs=e["max_abs"]))
                slope = float(np.polyfit(np.log(reps), np.log(errors), 1)[0]) if len(reps) > 1 else None
                info["slopes"][name] = {"slope": slope, "rmse_last_over_first": errors[-1] / errors[0]}
                others = [(f"dvr_gl {peer}", peer, peer_options)]
                if not scene.is_mesh:
                    others += [(f"dvr_gl splat density {k}", "splat", {"density": k}) for k in (1, 2)]
                for label, other, options in others:
                    e = compare(gl.render(small, technique=other, **options), exact)
                    frame = _timed(gl, scene, name, other, options, args.repeats)
                    rows.append(_plain_row(name, label, args, frame, e))
                if not scene.is_mesh and not args.no_vtk:
                    row = _vtk_row(name, scene, small, exact, args, err)
                    if row is not None:
                        rows.append(row)
                progress.advance(f"{name}: {peer}, splat, VTK")
    finally:
        progress.close()
    info.update(machine_info(), size=args.size, error_size=args.error_size, repeats=args.repeats, suite="particles",
                datasets=names, repetitions=reps)
    return rows, info


def _plain_row(name, label, args, seconds, e):
    return dict(dataset=name, renderer=label, repetitions=None, width=args.size, particles=None, generate_ms=None,
                generate_per_s=None, draw_ms=None, drawn_per_s=None, ms_median=1e3 * seconds,
                error_size=args.error_size, rmse=e["rmse"], max_abs=e["max_abs"])


def _vtk_row(name, scene, small, exact, args, err):
    """VTK's GPU ray caster at a one-voxel step (the bar splatting is held to)."""
    try:
        from . import vtk_peer
        vtk_peer._import_vtk()
    except ImportError as e:
        print(f"dvr-gl bench: VTK not available ({e}); its row is left out", file=err)
        return None
    step = scene.volume.min_spacing
    image, _ = vtk_peer.render_vtk(small, step, repeats=1, warmup=0)
    _, seconds = vtk_peer.render_vtk(scene, step, repeats=args.repeats, warmup=1)
    return _plain_row(name, "VTK raycast 1 voxel", args, seconds, compare(image, exact))


def _draw_seconds(gl, plan, repeats=3):
    """Median seconds to draw one particle set and finish (no read-back)."""
    from ..techniques import particles as technique
    times = []
    for _ in range(repeats + 1):
        t0 = time.perf_counter()
        technique.draw(gl, plan)
        gl.ctx.finish()
        times.append(time.perf_counter() - t0)
    return statistics.median(times[1:])


def format_particles_table(rows):
    head = ("data", "renderer", "R", "particles", "gen ms", "gen/s", "draw ms", "drawn/s", "ms/frame", "RMSE")
    lines = [(r["dataset"], r["renderer"], fmt(r["repetitions"], "d"), fmt(r["particles"], ",d"),
              fmt(r["generate_ms"], ".0f"),
              fmt(r["generate_per_s"] / 1e6, ".2f") + "M" if r["generate_per_s"] else "-", fmt(r["draw_ms"], ".1f"),
              fmt(r["drawn_per_s"] / 1e6, ".1f") + "M" if r["drawn_per_s"] else "-",
              fmt(r["ms_median"], ".0f"), fmt(r["rmse"], ".2e")) for r in rows]
    widths = [max(len(h), *(len(l[i]) for l in lines)) if lines else len(h) for i, h in enumerate(head)]

    def fmt_line(cells):
        return "  ".join(c.ljust(w) if i in (0, 1) else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths)))

    return "\n".join([fmt_line(head), fmt_line(["-" * w for w in widths])] + [fmt_line(l) for l in lines])


def figure_png(rows, info) -> bytes:
    """Error against frame time, log-log: each data set's particle series (R marked) and
    its other technique."""
    import matplotlib
    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure
    fig = Figure(figsize=(6.5, 4.5), constrained_layout=True)
    ax = fig.subplots()
    for k, name in enumerate(info.get("datasets", [])):
        color = f"C{k}"
        series = [r for r in rows if r["dataset"] == name and r["renderer"] == "dvr_gl particles"]
        if series:
            ax.plot([r["ms_median"] for r in series], [r["rmse"] for r in series], "o-", color=color,
                    label=f"{name}: particles")
            for r in series:
                ax.annotate(f"R={r['repetitions']}", (r["ms_median"], r["rmse"]), textcoords="offset points",
                            xytext=(4, 4), fontsize=7, color=color)
        for r in rows:
            if r["dataset"] == name and r["renderer"] != "dvr_gl particles":
                label = r["renderer"].replace("dvr_gl ", "")
                marker = next((m for key, m in MARKERS if key in label), "s")
                ax.scatter([r["ms_median"]], [max(r["rmse"], 1e-12)], marker=marker, color=color,
                           label=f"{name}: {label}")
    error_axes(ax, f"median time per frame (ms, {info.get('size')}x{info.get('size')})",
               f"RMSE against exact ({info.get('error_size')}x{info.get('error_size')})")
    return figure_bytes(fig)


def run_particles_bench(args) -> int:
    rows, info = run_particles(args)
    print(renderer_line(info) + f"; frames at {info['size']}x{info['size']} "
          f"(median of {info['repeats']}, a new view each); error at {info['error_size']}x{info['error_size']} "
          "against reference.exact; gen: per particle set, once per transfer function")
    print(format_particles_table(rows))
    for name, s in info["slopes"].items():
        slope = "-" if s["slope"] is None else f"{s['slope']:.2f}"
        print(f"{name}: RMSE falls with R at a log-log slope of {slope}; "
              f"RMSE(R={info['repetitions'][-1]}) / RMSE(R={info['repetitions'][0]}) = "
              f"{s['rmse_last_over_first']:.3f}")
    if args.out:
        paths = write_results(rows, info, args.out, fields=CSV_FIELDS, figure=figure_png)
        print("wrote " + ", ".join(str(p) for p in paths))
    return 0


def parse_repetitions(text):
    try:
        values = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise ValueError(f"--repetitions-list must be whole numbers separated by commas, got {text!r}") from None
    if not values or any(v < 1 for v in values):
        raise ValueError(f"--repetitions-list must be positive, got {text!r}")
    return values

