"""``dvr-gl bench --suite mesh``: projected tetrahedra beside VTK's
``vtkProjectedTetrahedraMapper`` on real CFD meshes, speed and error in one run.

Data sets: the NASA blunt fin (187,395 tets), combustor (215,040) and LOX post (513,375)
from the project's shared data folder, and the bundled Delaunay ball
(``dvr_gl.data.delaunay_ball``), each with ``dvr_gl.bench.common.mesh_tf`` and an oblique camera.

Per data set and renderer:

- frame time at ``--size`` (default 512) for a *new view each frame* (the camera turns by
  0.5 degree between frames, so both renderers sort again every frame, as a user turning
  the mesh sees it), median of ``--repeats`` frames after one warm-up; each frame ends
  with the float image read back. All renderers take their frames in turn, view by view
  (a change in the machine's load falls on all of them alike). dvr_gl's frame is split
  into its parts: the visibility sort (CPU, ``sort ms``) and projection + draw +
  read-back (GPU, ``draw ms``);
- RMSE, largest error and PSNR against ``reference.exact`` at ``--error-size`` (default
  128), with the same camera.

Per data set also: the time of Shirley and Tuchman's classification of the visible cells
in NumPy (``dvr_gl.techniques.shirley_tuchman``), the CPU alternative to the per-fragment clipping
that ``tetra`` does on the GPU (printed after the table, in the JSON info).

Renderers: dvr_gl ``tetra`` with ``sort="mpvo"``, with ``sort="centroid"`` and with
``sort="walk"`` (no sort: each pixel's ray walked cell to cell on the GPU, its ``sort ms``
is the plan's CPU time; ``passes`` its layers of depth peeling), the walk with
table-integrated segments (``segments="table"``, approximate: ``model.segment_table``), and VTK's
projected tetrahedra (its default cell-centre depth sort); VTK is left out when it is
not installed. ``t/VTK`` and ``err/VTK`` divide by VTK's row of the same data set.

With VTK, also "dvr_gl at VTK's error": ``Renderer.render(tolerance=E)`` with E VTK's
RMSE on the data set (``dvr_gl.rendering.mesh_tolerance``: the fastest way the pilot
measures within E). Its pilot runs once per data set before the timed frames (its
seconds are reported apart, ``pilot ms``); the frames then cost the chosen way's frame
(the choice is kept while the view turns). Its RMSE is that of the chosen way at
``--error-size``.
"""

from __future__ import annotations

import statistics
import sys
import time

from ..metrics import compare
from ..util.progress import Progress
from ..model.scene import Scene
from ..model.camera import default_camera
from .common import error_axes, figure_bytes, fmt, load_mesh_dataset, machine_info, renderer_line, write_results

CSV_FIELDS = ["dataset", "tets", "drawn", "renderer", "width", "sort_ms", "draw_ms", "ms_median", "ms_min",
              "error_size", "rmse", "max_abs", "psnr", "time_vs_vtk", "rmse_vs_vtk", "cycles_broken",
              "gap_constraints", "walk_passes", "tolerance", "chosen", "pilot_ms", "pilot_rmse"]
TOLERANCE_ROW = "dvr_gl at VTK's error"
# the tetra rows: key -> make_plan options
TETRA_ROWS = {"mpvo": {"sort": "mpvo"}, "centroid": {"sort": "centroid"}, "walk": {"sort": "walk"},
              "walk table": {"sort": "walk", "segments": "table"}}


def _render_choice(gl, scene, choice):
    """``scene`` rendered the way ``choice`` (a mesh_tolerance.MeshChoice) names, whatever
    the pilot would pick for this size."""
    from ..rendering import mesh_tolerance as mt
    way = mt.Way(choice.label, choice.technique, choice.options, choice.grid, choice.step_spacings)
    s, technique, step, options = mt.way_arguments(scene, way, gl.tables)
    return gl.render(s, technique=technique, step=step, **options)


def _camera(mesh, turn=0.0):
    return default_camera(mesh, azimuth=30.0 + turn, elevation=20.0)


def _time_interleaved(gl, scene, sorts, repeats, on_frame, tolerance=None, vtk=None):
    """Median (sort, draw + read-back) seconds and every frame's total, for frames each
    from a new view, the renderers taking their frames in turn (each view drawn by every
    sort, then at ``tolerance`` (an RMSE, if given: ``Renderer.render(tolerance=)``, whose
    pilot has run before) and by VTK (``vtk``, the peer module, if given) before the
    camera turns on), so that a change in the machine's load falls on all of them alike:
    {sort: (last plan, sort s, draw s, totals)}, {"tolerance": totals, "vtk": totals}."""
    from ..techniques import tetra
    parts = {sort: ([], [], []) for sort in sorts}
    others = {key: [] for key, on in (("tolerance", tolerance is not None), ("vtk", vtk is not None)) if on}
    plans = {}
    for i in range(-1, repeats):
        s = scene.replace(camera=_camera(scene.volume, 0.5 * (i + 1)))
        for sort in sorts:
            t0 = time.perf_counter()
            plans[sort] = plan = tetra.make_plan(s, tables=gl.tables, **TETRA_ROWS[sort])
            t1 = time.perf_counter()
            with _current(gl):
                gl.read_target(tetra.draw(gl, plan), s.width, s.height)
            t2 = time.perf_counter()
            if i >= 0:
                for part, value in zip(parts[sort], (t1 - t0, t2 - t1, t2 - t0)):
                    part.append(value)
            on_frame(sort)
        if tolerance is not None:
            t0 = time.perf_counter()
            gl.render(s, technique="tetra", tolerance=tolerance)     # the choice is kept per view family
            if i >= 0:
                others["tolerance"].append(time.perf_counter() - t0)
            on_frame("at VTK's error")
        if vtk is not None:
            _, (seconds,) = vtk.render_vtk_mesh(s, repeats=1, warmup=0)  # frame() and read-back, timed inside
            if i >= 0:
                others["vtk"].append(seconds)
            on_frame("VTK")
    return ({sort: (plans[sort], statistics.median(p[0]), statistics.median(p[1]), p[2])
             for sort, p in parts.items()}, others)


def _time_cpu_classification(scene, repeats=3):
    """Median seconds of Shirley-Tuchman's classification of the visible cells in NumPy
    (``dvr_gl.techniques.shirley_tuchman``): the CPU alternative to tetra's per-fragment clipping."""
    from ..techniques import shirley_tuchman
    from ..model.mesh import topology
    from ..techniques.cell_order import visible_cells
    mesh = scene.volume
    cells = visible_cells(mesh, scene.tf)
    cells = cells[~topology(mesh).flat[cells]]
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        shirley_tuchman.classify(mesh, cells, scene)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def _current(gl):
    from ..gl.context import current
    return current(gl.ctx)


def run_mesh(args, err=None):
    """Run the suite; returns (rows, info)."""
    err = err if err is not None else sys.stderr   # looked up now: tests swap sys.stderr
    from ..rendering.renderer import Renderer
    from ..reference.exact import exact as exact_image

    names = [n.strip() for n in args.datasets.split(",") if n.strip()]
    peer, vtk_note = None, None
    if not args.no_vtk:
        try:
            from . import vtk_peer
            peer = vtk_peer
            vtk_peer._import_vtk()
        except ImportError as e:
            peer = None
            vtk_note = f"VTK not available ({e}); VTK rows skipped"
            print(f"dvr-gl bench: {vtk_note}", file=err)
    renderers = [("dvr_gl tetra mpvo", "mpvo"), ("dvr_gl tetra centroid", "centroid"), ("dvr_gl tetra walk", "walk"),
                 ("dvr_gl tetra walk, table segments", "walk table")]
    if peer is not None:
        renderers += [(TOLERANCE_ROW, "tolerance"), ("VTK projected tetrahedra", "vtk")]
    frames = 1 + args.repeats
    progress = Progress(len(names) * (4 + len(renderers) * (frames + 1)), stream=err)
    rows, info = [], {"cpu_classify_ms": {}, "tolerance_first_call_ms": {}, "tolerance_measured": {}}
    try:
        with Renderer(backend=args.backend) as gl:
            info["dvr_gl"] = gl.info()
            for name in names:
                progress.begin(f"{name}: loading")
                try:
                    mesh, tf = load_mesh_dataset(name, args.data_dir)
                except FileNotFoundError as e:
                    print(f"dvr-gl bench: skipping {name}: {e}", file=err)
                    continue
                progress.advance(f"{name}: loaded")
                scene = Scene(mesh, tf, _camera(mesh), args.size, args.size)
                small = scene.replace(width=args.error_size, height=args.error_size)
                progress.begin(f"{name}: exact image")
                exact = exact_image(small)
                progress.advance(f"{name}: exact image")
                info["cpu_classify_ms"][name] = 1e3 * _time_cpu_classification(scene)
                progress.advance(f"{name}: CPU classification")
                sorts = [sort for _, sort in renderers if sort not in ("vtk", "tolerance")]
                images, vtk_rmse, choice = {}, None, None
                if peer is not None:
                    images["vtk"], _ = peer.render_vtk_mesh(small, repeats=1, warmup=0)
                    vtk_rmse = compare(images["vtk"], exact)["rmse"]
                    t0 = time.perf_counter()
                    gl.render(scene, technique="tetra", tolerance=vtk_rmse)   # the pilot, once per mesh
                    choice = gl.last_choice
                    info["tolerance_first_call_ms"][name] = 1e3 * (time.perf_counter() - t0)
                    info["tolerance_measured"][name] = [
                        dict(way=label, pilot_rmse=e, frame_ms=None if t is None else 1e3 * t)
                        for label, e, t in choice.measured]
                    images["tolerance"] = _render_choice(gl, small, choice)   # the frames' way, at the error size
                    progress.advance(f"{name}: pilot at VTK's error")
                timed, others = _time_interleaved(gl, scene, sorts, args.repeats,
                                                  lambda label: progress.advance(f"{name}: {label}"),
                                                  tolerance=vtk_rmse, vtk=peer)
                for label, sort in renderers:
                    row = dict(sort_ms=None, draw_ms=None, cycles_broken=None, gap_constraints=None,
                               drawn=None, walk_passes=None, tolerance=None, chosen=None, pilot_ms=None,
                               pilot_rmse=None)
                    if sort in others:
                        image, times = images[sort], others[sort]
                        if sort == "tolerance":
                            row.update(tolerance=vtk_rmse, chosen=choice.label, pilot_ms=1e3 * choice.pilot_seconds,
                                       pilot_rmse=choice.pilot_rmse)
                    else:
                        last, ts, td, times = timed[sort]
                        image = gl.render(small, technique="tetra", **TETRA_ROWS[sort])
                        from ..techniques import tetra
                        plan = tetra.make_plan(scene, tables=gl.tables, **TETRA_ROWS[sort])
                        row.update(sort_ms=1e3 * ts, draw_ms=1e3 * td, cycles_broken=plan.order.cycles_broken,
                                   gap_constraints=plan.order.gap_constraints, drawn=int(plan.draw.size),
                                   walk_passes=last.walk_passes if last.sort == "walk" else None)
                    e = compare(image, exact)
                    progress.advance(f"{name}: {label} error")
                    row.update(dataset=name, tets=mesh.n_tets, renderer=label, width=args.size,
                               ms_median=1e3 * statistics.median(times), ms_min=1e3 * min(times),
                               error_size=args.error_size, rmse=e["rmse"], max_abs=e["max_abs"],
                               psnr=e["psnr"], time_vs_vtk=None, rmse_vs_vtk=None)
                    rows.append(row)
    finally:
        progress.close()
    vtk = {r["dataset"]: r for r in rows if r["renderer"].startswith("VTK")}
    for r in rows:
        v = vtk.get(r["dataset"])
        if v is not None:
            r["time_vs_vtk"] = r["ms_median"] / v["ms_median"]
            r["rmse_vs_vtk"] = r["rmse"] / v["rmse"] if v["rmse"] > 0 else None
    info.update(machine_info(), size=args.size, error_size=args.error_size, repeats=args.repeats, suite="mesh",
                datasets=names, vtk_note=vtk_note)
    return rows, info


def format_mesh_table(rows):
    head = ("data", "tets", "renderer", "sort ms", "draw ms", "ms/frame", "RMSE", "max err", "t/VTK", "err/VTK",
            "passes", "way (pilot ms)")
    lines = [(r["dataset"], str(r["tets"]), r["renderer"], fmt(r["sort_ms"], ".0f"), fmt(r["draw_ms"], ".0f"),
              fmt(r["ms_median"], ".0f"), fmt(r["rmse"], ".2e"), fmt(r["max_abs"], ".3f"),
              fmt(r["time_vs_vtk"], ".2f"), fmt(r["rmse_vs_vtk"], ".3f"), fmt(r.get("walk_passes"), "d"),
              f"{r['chosen']} ({r['pilot_ms']:.0f})" if r.get("chosen") else "")
             for r in rows]
    widths = [max(len(h), *(len(l[i]) for l in lines)) if lines else len(h) for i, h in enumerate(head)]

    def fmt_line(cells):
        return "  ".join(c.ljust(w) if i in (0, 2) else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths)))

    return "\n".join([fmt_line(head), fmt_line(["-" * w for w in widths])] + [fmt_line(l) for l in lines])


def figure_png(rows, info) -> bytes:
    """Error against new-view frame time, log-log, one point per renderer and data set."""
    import matplotlib
    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure
    fig = Figure(figsize=(6.5, 4.5), constrained_layout=True)
    ax = fig.subplots()
    markers = {"dvr_gl tetra mpvo": ("tab:blue", "o"), "dvr_gl tetra centroid": ("tab:green", "s"),
               "dvr_gl tetra walk": ("tab:purple", "D"), "dvr_gl tetra walk, table segments": ("tab:pink", "d"),
               TOLERANCE_ROW: ("tab:orange", "*"),
               "VTK projected tetrahedra": ("tab:red", "^")}
    for label, (color, marker) in markers.items():
        pts = [(r["ms_median"], r["rmse"], r["dataset"]) for r in rows if r["renderer"] == label]
        if not pts:
            continue
        ax.scatter([p[0] for p in pts], [max(p[1], 1e-12) for p in pts], color=color, marker=marker, label=label)
        for t, e, name in pts:
            ax.annotate(name, (t, max(e, 1e-12)), textcoords="offset points", xytext=(4, 4), fontsize=7, color=color)
    error_axes(ax, f"median time per frame, new view each frame (ms, {info.get('size')}x{info.get('size')})",
               f"RMSE against exact ({info.get('error_size')}x{info.get('error_size')})")
    return figure_bytes(fig)


def run_mesh_bench(args) -> int:
    rows, info = run_mesh(args)
    print(renderer_line(info) + f"; frames at {info['size']}x{info['size']} "
          f"(a new view each frame, median of {info['repeats']}); error at {info['error_size']}x{info['error_size']} "
          "against reference.exact")
    print(format_mesh_table(rows))
    for r in rows:
        if r["renderer"] == TOLERANCE_ROW:
            print(f"{r['dataset']}: tolerance={r['tolerance']:.3g} (VTK's RMSE) chose {r['chosen']} "
                  f"(pilot RMSE {r['pilot_rmse']:.2e}); the pilot took {r['pilot_ms']:.0f} ms once "
                  f"(first call at {info['size']}x{info['size']}, pilot and frame: "
                  f"{info['tolerance_first_call_ms'][r['dataset']]:.0f} ms); pilot's ways, RMSE (ms at "
                  f"up to 256 px): " + ", ".join(f"{m['way']} {m['pilot_rmse']:.1e}" + (
                      f" ({m['frame_ms']:.0f})" if m["frame_ms"] is not None else "")
                      for m in info["tolerance_measured"][r["dataset"]]))
    if info["cpu_classify_ms"]:
        print("Shirley-Tuchman classification on the CPU (NumPy; tetra clips per fragment instead), ms per view: "
              + ", ".join(f"{k} {v:.0f}" for k, v in info["cpu_classify_ms"].items()))
    if args.out:
        paths = write_results(rows, info, args.out, fields=CSV_FIELDS, figure=figure_png)
        print("wrote " + ", ".join(str(p) for p in paths))
    return 0
