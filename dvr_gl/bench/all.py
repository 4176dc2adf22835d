"""``dvr-gl bench --suite all``: one report for every technique, to choose between them.

Every technique is run over its quality parameter on the same scenes:

- grids (the Marschner-Lobb signal, 41^3, and the bundled CT head): ray casting at a step
  of 2, 1, 1/2 and 1/4 voxel, pre-integrated at 1 voxel, and into 16- and 8-bit targets at
  1/2 voxel; 3D slicing at 1, 1/2 and 1/4 voxel; 2D slicing with 0, 1 and 3 intermediate
  slices; PBVR with 1, 4 and 16 repetitions; splatting at density 1 and 2;
- meshes (the Delaunay ball, and the NASA blunt fin when ``../shared/data`` is there):
  projected tetrahedra with the MPVO and the centroid sort; PBVR with 1, 4 and 16
  repetitions; splatting;
- with VTK installed, VTK's GPU ray caster (1, 1/2, 1/4 voxel) and its projected
  tetrahedra join as peers.

Per point: the steady-state median frame time at ``--size`` (default 512; a new view each
frame, half a degree further round, so per-view work such as visibility sorts counts;
read-back inside; after one warm-up frame), the first frame of a new
renderer (compiling the programs, uploading the data, building the tables), the error
against ``reference.exact`` at ``--error-size`` (default 128; exact images are cached
on disk) as RMSE, largest absolute error and PSNR, and the GPU memory the renderer holds
after the frames (``Renderer.gpu_bytes``: every texture, buffer and target in its caches).

Written with ``--out DIR``: ``all.csv``, ``all.json`` (rows, machine, renderers,
``LP_NUM_THREADS``), ``all.md`` (the table), ``all.png`` (time against RMSE per scene,
one curve per technique, log-log, the Pareto front marked) and ``contact.png`` (each
technique's best image per scene beside its error map). ``--quick`` is a small run
(256 x 256 frames, 64 x 64 errors, fewer points) for a smoke test.
"""

from __future__ import annotations

import io
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from ..metrics import compare
from ..formats import atomic_write
from ..util.progress import Progress
from .common import (error_axes, figure_bytes, fmt, load_mesh_dataset, machine_info, oblique_camera, renderer_line,
                     turning_frames, vtk_version)

CSV_FIELDS = ("scene", "kind", "technique", "parameter", "value", "width", "height", "ms_median", "ms_min",
              "first_ms", "rmse", "max_abs", "psnr", "gpu_mb", "error_size")


# -- what is measured ----------------------------------------------------------------------------
def grid_points(quick):
    """(technique, parameter name, value, options) for a grid; steps in voxels."""
    if quick:
        return [("raycast", "step", 1.0, {}), ("raycast", "step", 0.5, {}),
                ("slice3d", "step", 0.5, {}), ("slice2d", "interpolate", 0, {}), ("slice2d", "interpolate", 1, {}),
                ("particles", "repetitions", 1, {}), ("particles", "repetitions", 4, {}),
                ("splat", "density", 1, {}), ("vtk raycast", "step", 1.0, {})]
    return ([("raycast", "step", s, {}) for s in (2.0, 1.0, 0.5, 0.25)]
            + [("raycast preintegrated", "step", 1.0, {"preintegrate": True}),
               ("raycast rgba16f", "step", 0.5, {"target": "rgba16f"}),
               ("raycast rgba8", "step", 0.5, {"target": "rgba8"})]
            + [("slice3d", "step", s, {}) for s in (1.0, 0.5, 0.25)]
            + [("slice2d", "interpolate", k, {}) for k in (0, 1, 3)]
            + [("particles", "repetitions", r, {}) for r in (1, 4, 16)]
            + [("splat", "density", d, {}) for d in (1, 2)]
            + [("vtk raycast", "step", s, {}) for s in (1.0, 0.5, 0.25)])


def mesh_points(quick):
    points = [("tetra", "sort", "mpvo", {}), ("tetra", "sort", "centroid", {}),
              ("particles", "repetitions", 1, {}), ("particles", "repetitions", 4, {})]
    if not quick:
        points.append(("particles", "repetitions", 16, {}))
    return points + [("splat", "density", 1, {}), ("vtk tetra", "sort", "vtk", {})]


def render_options(technique, parameter, value, options, data):
    """(dvr_gl technique name, keyword arguments) of a point."""
    base = technique.split()[0]
    opts = dict(options)
    if parameter == "step":
        opts["step"] = value * data.min_spacing
    elif parameter in ("interpolate", "repetitions", "density"):
        opts[parameter] = value
    elif parameter == "sort":
        opts["sort"] = value
    return base, opts


def scenes(names, size, data_dir=None):
    """[(name, kind, scene, turn)] of the requested names (missing files are skipped);
    ``turn(i)`` is the camera of timed frame i, half a degree further round each time."""
    from ..data import ct_head, ct_head_tf, delaunay_ball, synthetic_tf
    from ..data.phantoms import marschner_lobb, marschner_lobb_tf
    from ..model.scene import Scene
    from ..model.camera import default_camera
    out = []

    def add(label, kind, data, tf, camera_at):
        out.append((label, kind, Scene(data, tf, camera_at(30.0), size, size),
                    lambda i: camera_at(30.0 + 0.5 * (i + 1))))

    for name in names:
        if name == "ml":
            vol = marschner_lobb()
            add("Marschner-Lobb", "grid", vol, marschner_lobb_tf(),
                lambda az, v=vol: default_camera(v, azimuth=az, elevation=20))
        elif name == "head":
            vol = ct_head()
            add("CT head", "grid", vol, ct_head_tf(),
                lambda az, v=vol: oblique_camera(v, front=(0, 1, 0), up=(0, 0, -1), azimuth=az))
        elif name == "ball":
            mesh = delaunay_ball()
            add("Delaunay ball", "mesh", mesh, synthetic_tf(),
                lambda az, m=mesh: default_camera(m, azimuth=az, elevation=20))
        elif name == "bluntfin":
            try:
                mesh, tf = load_mesh_dataset("bluntfin", data_dir)
            except FileNotFoundError as e:
                print(f"dvr-gl bench: skipping bluntfin: {e}", file=sys.stderr)
                continue
            add("blunt fin", "mesh", mesh, tf, lambda az, m=mesh: default_camera(m, azimuth=az, elevation=20))
        else:
            raise ValueError(f"unknown scene {name!r}; choose from ml, head, ball, bluntfin")
    return out


# -- running ---------------------------------------------------------------------------------------------
def run_all(args, err=None):
    """Run the suite; returns (rows, info, images) with images[(scene, label)] = (image,
    exact) at the error size, for the contact sheet."""
    err = err if err is not None else sys.stderr
    from ..rendering.renderer import Renderer
    from ..reference.exact import exact as exact_image
    from . import vtk_peer

    names = [n.strip() for n in args.datasets.split(",") if n.strip()]
    sets = scenes(names, args.size, args.data_dir)
    peer = None
    if not args.no_vtk and vtk_peer.available():
        peer = vtk_peer.VTKPeer()
    plan = [(name, kind, scene, turn, point) for name, kind, scene, turn in sets
            for point in (grid_points if kind == "grid" else mesh_points)(args.quick)
            if peer is not None or not point[0].startswith("vtk")]
    progress = Progress(len(plan) + len(sets), stream=err)
    exact = {}
    for name, kind, scene, _ in sets:
        small = scene.replace(width=args.error_size, height=args.error_size)
        progress.begin(f"{name}: exact image")
        exact[name] = exact_image(small)
        progress.advance(f"{name}: exact image")
    rows, images = [], {}
    for name, kind, scene, turn, (technique, parameter, value, options) in plan:
        label = f"{name}: {technique} {parameter} {value}"
        progress.begin(label)
        small = scene.replace(width=args.error_size, height=args.error_size)
        if technique.startswith("vtk"):
            step = value * scene.volume.min_spacing if parameter == "step" else None

            def vtk_frame(s):
                return peer.render(s, step=step, repeats=1, warmup=0)[0]
            t0 = time.perf_counter()
            vtk_frame(scene)
            first = time.perf_counter() - t0
            times = turning_frames(vtk_frame, scene, turn, args.repeats)
            image = vtk_frame(small)
            memory = None
        else:
            base, opts = render_options(technique, parameter, value, options, scene.volume)
            renderer = Renderer(backend=args.backend)
            try:
                def frame(s):
                    return renderer.render(s, technique=base, **opts)
                t0 = time.perf_counter()
                frame(scene)
                first = time.perf_counter() - t0
                times = turning_frames(frame, scene, turn, args.repeats)
                memory = renderer.gpu_bytes()
                image = frame(small)
            finally:
                renderer.release()
        e = compare(image, exact[name])
        rows.append({"scene": name, "kind": kind, "technique": technique, "parameter": parameter,
                     "value": value, "width": scene.width, "height": scene.height,
                     "ms_median": 1e3 * statistics.median(times), "ms_min": 1e3 * min(times),
                     "first_ms": 1e3 * first, "rmse": e["rmse"], "max_abs": e["max_abs"], "psnr": e["psnr"],
                     "gpu_mb": None if memory is None else memory / 2 ** 20, "error_size": args.error_size})
        images[(name, technique, parameter, value)] = image
        progress.advance(label)
    progress.close()
    info = {"suite": "all", "size": args.size, "error_size": args.error_size, "repeats": args.repeats,
            "quick": bool(args.quick), **machine_info()}
    with Renderer(backend=args.backend) as r:
        info["dvr_gl"] = r.info()
    if peer is not None:
        info["vtk"] = {"version": vtk_version(), "renderer": peer.renderer_string()}
        peer.close()
    return rows, info, (images, exact)


# -- reporting ------------------------------------------------------------------------------------------
def pareto(rows):
    """The rows no other row of the same scene beats in both time and RMSE."""
    front = []
    for r in rows:
        if not any(o is not r and o["scene"] == r["scene"] and o["ms_median"] <= r["ms_median"]
                   and o["rmse"] <= r["rmse"] and (o["ms_median"] < r["ms_median"] or o["rmse"] < r["rmse"])
                   for o in rows):
            front.append(r)
    return front


def markdown_table(rows):
    front = {id(r) for r in pareto(rows)}
    lines = ["| scene | technique | parameter | ms/frame | first frame ms | RMSE | max err | PSNR | GPU MB | Pareto |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['scene']} | {r['technique']} | {r['parameter']} {r['value']} | "
                     f"{r['ms_median']:.1f} | {r['first_ms']:.0f} | {r['rmse']:.2e} | {r['max_abs']:.3f} | "
                     f"{fmt(r['psnr'], '.1f')} | {fmt(r['gpu_mb'], '.1f')} | {'yes' if id(r) in front else ''} |")
    return "\n".join(lines) + "\n"


STYLES = {"raycast": ("tab:blue", "o"), "raycast preintegrated": ("tab:cyan", "P"),
          "raycast rgba16f": ("tab:blue", "1"), "raycast rgba8": ("tab:blue", "2"),
          "slice3d": ("tab:green", "s"), "slice2d": ("tab:olive", "D"), "particles": ("tab:purple", "v"),
          "splat": ("tab:pink", "*"), "tetra": ("tab:brown", "h"), "vtk raycast": ("tab:red", "^"),
          "vtk tetra": ("tab:red", "^")}


def figure_png(rows, info):
    import matplotlib
    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure
    names = list(dict.fromkeys(r["scene"] for r in rows))
    cols = min(2, len(names))
    nrows = -(-len(names) // cols)
    fig = Figure(figsize=(6.5 * cols, 5.0 * nrows), constrained_layout=True)
    axes = fig.subplots(nrows, cols, squeeze=False).ravel()
    front = pareto(rows)
    for ax, name in zip(axes, names):
        mine = [r for r in rows if r["scene"] == name]
        for technique in dict.fromkeys(r["technique"] for r in mine):
            pts = sorted((r["ms_median"], r["rmse"], r["value"]) for r in mine if r["technique"] == technique)
            color, marker = STYLES.get(technique, (None, "x"))
            ax.plot([p[0] for p in pts], [p[1] for p in pts], marker=marker, color=color, label=technique,
                    linestyle="-" if len(pts) > 1 else "none")
            for t, e, v in pts:
                ax.annotate(f"{v}", (t, e), textcoords="offset points", xytext=(4, 3), fontsize=6, color=color)
        best = sorted((r["ms_median"], r["rmse"]) for r in front if r["scene"] == name)
        ax.plot([p[0] for p in best], [p[1] for p in best], color="black", linewidth=4, alpha=0.15,
                label="Pareto front")
        error_axes(ax, "median time per frame (ms)", "RMSE against exact")
        ax.set_title(f"{name}, {info['size']}x{info['size']} frames", fontsize=10)
    for ax in axes[len(names):]:
        ax.set_visible(False)
    return figure_bytes(fig)


def contact_sheet_png(rows, images, exact):
    """Per scene, each technique's most accurate point: the image over black and its
    error map (largest channel error, scaled so that 0.05 is white)."""
    from PIL import Image, ImageDraw
    names = list(dict.fromkeys(r["scene"] for r in rows))
    best = {}
    for r in rows:
        key = (r["scene"], r["technique"])
        if key not in best or r["rmse"] < best[key]["rmse"]:
            best[key] = r
    size = next(iter(exact.values())).shape[0]
    cols = max(sum(1 for k in best if k[0] == n) for n in names)
    tile = size + 4
    sheet = Image.new("RGB", (cols * tile, len(names) * (2 * tile + 14)), (40, 40, 40))
    draw = ImageDraw.Draw(sheet)
    for j, name in enumerate(names):
        y = j * (2 * tile + 14)
        for i, ((scene, technique), r) in enumerate((k, v) for k, v in best.items() if k[0] == name):
            img = images[(scene, technique, r["parameter"], r["value"])]
            rgb = np.clip(img[..., :3], 0, 1)
            err = np.clip(np.abs(img - exact[name]).max(axis=-1) / 0.05, 0, 1)
            sheet.paste(Image.fromarray((rgb * 255).astype(np.uint8)), (i * tile, y + 12))
            sheet.paste(Image.fromarray((err * 255).astype(np.uint8)).convert("RGB"), (i * tile, y + 12 + tile))
            draw.text((i * tile + 2, y), f"{technique[:14]}", fill=(230, 230, 230))
    buf = io.BytesIO()
    sheet.save(buf, format="PNG")
    return buf.getvalue()


def write_all(rows, info, images, exact, out):
    import csv
    import json
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=CSV_FIELDS, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if r[k] is None else r[k]) for k in CSV_FIELDS})
    paths = [out / "all.csv", out / "all.json", out / "all.md", out / "all.png", out / "contact.png"]
    atomic_write(paths[0], buf.getvalue().encode())
    clean = [{k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in r.items()} for r in rows]
    atomic_write(paths[1], json.dumps({"info": info, "rows": clean}, indent=1, default=str).encode())
    atomic_write(paths[2], markdown_table(rows).encode())
    atomic_write(paths[3], figure_png(rows, info))
    atomic_write(paths[4], contact_sheet_png(rows, images, exact))
    return paths


def run_all_bench(args) -> int:
    if args.quick:
        args.size = min(args.size, 256)
        args.error_size = args.error_size or 64
    args.error_size = args.error_size or 128
    rows, info, (images, exact) = run_all(args)
    print(renderer_line(info) + f"; {info['size']}x{info['size']} frames, median of {info['repeats']}; "
          f"error at {info['error_size']}x{info['error_size']} against reference.exact")
    print(markdown_table(rows))
    if args.out:
        paths = write_all(rows, info, images, exact, args.out)
        print("wrote " + ", ".join(str(p) for p in paths))
    return 0
