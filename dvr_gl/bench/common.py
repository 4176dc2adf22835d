"""What the benchmark suites share: the data sets and their cameras, timing (round robin
and turning views), the machine and VTK versions, and the output (tables, result files,
figures).

Nothing here runs a suite: the suites (``raycast``, ``slicing``, ``mesh``, ``particles``,
``shading``, ``all``) import from this module, and ``dvr_gl.bench.cli`` dispatches over
them.
"""

from __future__ import annotations

import csv
import datetime
import gzip
import io
import json
import math
import os
import platform
import statistics
import time
from pathlib import Path

import numpy as np

from ..util.files import atomic_write
from ..model.camera import Camera
from ..model.mesh import TetMesh
from ..model.transfer_function import TransferFunction
from ..model.volume import Volume

STEPS_VOXELS = (1.0, 0.5, 0.25)
# the project's shared data folder beside the checkout (override with $DVR_GL_DATA)
DEFAULT_DATA_DIR = os.path.join(
    os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))), "shared", "data")
CHEST_FILE = os.path.join("vtkjs_lidc2_ct", "LIDC2_256x256x133_uint8.raw.gz")

MESHES = {  # name -> (file under the shared data folder, scalar array)
    "bluntfin": (os.path.join("nasa_bluntfin", "bluntfin_tets.npz"), "Density"),
    "combustor": (os.path.join("nasa_combustor", "comb_tets.npz"), "Density"),
    "loxpost": (os.path.join("nasa_lox_post", "post_tets.npz"), "StagnationEnergy"),
    "ball": (None, None),
}


# -- data sets -------------------------------------------------------------------------
def oblique_camera(volume, front, up, azimuth=30.0, elevation=20.0, fov=30.0):
    """A perspective camera on the volume's centre, far enough that the bounding sphere
    fits: it looks from ``front`` (a unit direction from the centre to the eye) turned
    by ``azimuth`` degrees about ``up`` and then raised by ``elevation`` towards ``up``."""
    front = np.asarray(front, float) / np.linalg.norm(front)
    up = np.asarray(up, float) / np.linalg.norm(up)
    side = np.cross(up, front)
    az, el = math.radians(azimuth), math.radians(elevation)
    horizontal = math.cos(az) * front + math.sin(az) * side
    offset = math.cos(el) * horizontal + math.sin(el) * up
    lo, hi = volume.bounds
    centre = (lo + hi) / 2
    radius = float(np.linalg.norm(hi - lo)) / 2
    distance = radius / math.sin(math.radians(fov) / 2)
    return Camera(centre + offset * distance, centre, up, fov=fov)


def chest_ct(path=None) -> Volume:
    """The vtk.js LIDC2 chest CT: (133, 256, 256) uint8 (windowed to 8 bit), spacing
    (1.40625, 1.40625, 2.5). ``path`` defaults to ``$DVR_GL_DATA`` (or the shared data
    folder) joined with ``vtkjs_lidc2_ct/LIDC2_256x256x133_uint8.raw.gz``."""
    if path is None:
        path = os.path.join(os.environ.get("DVR_GL_DATA", DEFAULT_DATA_DIR), CHEST_FILE)
    with gzip.open(path, "rb") as f:
        raw = f.read()
    if len(raw) != 133 * 256 * 256:
        raise ValueError(f"{path}: expected {133 * 256 * 256} bytes of uint8 samples, got {len(raw)}")
    data = np.frombuffer(raw, np.uint8).reshape(133, 256, 256)
    return Volume(data, spacing=(1.40625, 1.40625, 2.5))


def chest_tf(volume) -> TransferFunction:
    """Soft tissue a faint flesh-coloured haze, contrast-filled heart and vessels
    (values ~110-150) red, bone (above ~160) ivory and nearly opaque; air, lung and fat
    (0-15 after the data set's 8-bit windowing) clear. Unit distance one voxel."""
    return TransferFunction(
        color=[(20, 0.75, 0.45, 0.35), (80, 0.85, 0.55, 0.45), (115, 0.85, 0.20, 0.15),
               (140, 0.90, 0.25, 0.20), (170, 0.95, 0.90, 0.80), (255, 1.00, 1.00, 0.95)],
        opacity=[(15, 0.0), (30, 0.01), (90, 0.02), (110, 0.03), (125, 0.2), (145, 0.2),
                 (160, 0.15), (200, 0.6), (255, 0.8)],
        unit_distance=volume.min_spacing)


def _head():
    from ..data import ct_head, ct_head_tf
    return ct_head(), ct_head_tf()


def datasets(names, chest_path=None):
    """[(name, volume, tf, camera)] for the requested names; both data sets have the
    face or chest towards +y and the head towards -z, so both get a front view turned
    30 degrees and raised 20."""
    out = []
    for name in names:
        if name == "chest":
            volume = chest_ct(chest_path)
            tf = chest_tf(volume)
        elif name == "head":
            volume, tf = _head()
        else:
            raise ValueError(f"unknown data set {name!r}; choose from chest, head")
        camera = oblique_camera(volume, front=(0, 1, 0), up=(0, 0, -1))
        out.append((name, volume, tf, camera))
    return out


def load_datasets(names, chest_path, err):
    """``datasets`` for each name, skipping (with a message) those whose file is missing."""
    sets = []
    for name in names:
        try:
            sets.extend(datasets([name], chest_path=chest_path))
        except FileNotFoundError as e:
            print(f"dvr-gl bench: skipping {name}: {e}", file=err)
    if not sets:
        raise SystemExit("dvr-gl bench: no data set could be loaded")
    return sets


def load_mesh_dataset(name, data_dir=None):
    """(mesh, tf) of a named mesh data set (``MESHES``): the Delaunay ball is bundled, the
    others are read from ``data_dir`` (default ``$DVR_GL_DATA`` or the shared data folder)."""
    if name not in MESHES:
        raise ValueError(f"unknown mesh data set {name!r}; choose from {', '.join(MESHES)}")
    if name == "ball":
        from ..data import delaunay_ball, synthetic_tf
        return delaunay_ball(), synthetic_tf()
    path, scalars = MESHES[name]
    directory = data_dir or os.environ.get("DVR_GL_DATA") or DEFAULT_DATA_DIR
    full = os.path.join(directory, path)
    if not os.path.exists(full):
        raise FileNotFoundError(f"{full} not found (set $DVR_GL_DATA to the shared data folder)")
    z = np.load(full)
    mesh = TetMesh(z["points"], z["tets"], z[scalars])
    return mesh, mesh_tf(mesh)


def mesh_tf(mesh):
    """Blue to green to red over the 2nd to 98th percentile of the scalars, opacity rising
    from 0 with a band at two thirds; unit distance 1/40 of the bounding-box diagonal, so
    that the whole mesh is semi-transparent."""
    lo, hi = (float(v) for v in np.percentile(mesh.scalars, [2, 98]))
    if hi <= lo:
        hi = lo + 1.0
    at = lambda f: lo + f * (hi - lo)   # noqa: E731
    return TransferFunction(
        color=[(at(0.0), 0.15, 0.3, 0.9), (at(0.5), 0.2, 0.85, 0.3), (at(1.0), 0.95, 0.25, 0.1)],
        opacity=[(at(0.0), 0.0), (at(0.55), 0.15), (at(0.67), 0.6), (at(0.8), 0.2), (at(1.0), 0.5)],
        unit_distance=float(np.linalg.norm(mesh.extent)) / 40)


# -- measuring -----------------------------------------------------------------------------
def interleaved_frames(calls, repeats, on_frame=None):
    """Time several renderers on one scene, round robin: one untimed warm-up frame each
    (compiling, uploading), then ``repeats`` rounds of one timed frame each, so that a
    change in the machine's load falls on all of them alike. Each call must return its
    image read back (so the GL has finished). Returns (last images, [seconds] per call);
    ``on_frame(k, i)`` is called after each frame (i = -1 for the warm-up)."""
    images = [None] * len(calls)
    times = [[] for _ in calls]
    for k, call in enumerate(calls):
        images[k] = call()
        if on_frame:
            on_frame(k, -1)
    for i in range(max(1, repeats)):
        for k, call in enumerate(calls):
            t0 = time.perf_counter()
            images[k] = call()
            times[k].append(time.perf_counter() - t0)
            if on_frame:
                on_frame(k, i)
    return images, times


def turning_frames(frame, scene, turn, repeats):
    """One untimed frame of ``scene``, then ``repeats`` timed frames, frame i of the view
    ``turn(i)``, as an orbiting user sees them: per-view work (visibility sorts, depth
    orders) is inside the time. ``frame(scene)`` must read its image back (so the GL has
    finished). Returns the seconds of each timed frame."""
    frame(scene)
    times = []
    for i in range(repeats):
        turned = scene.replace(camera=turn(i))
        t0 = time.perf_counter()
        frame(turned)
        times.append(time.perf_counter() - t0)
    return times


def result_row(dataset, scene, label, kind, skip, step_vox, step_world, times, err):
    """A row of the peer and slicing suites: frame times (ms) and errors against exact."""
    return {
        "dataset": dataset, "width": scene.width, "height": scene.height,
        "renderer": label, "kind": kind, "skip_empty": skip,
        "step_voxels": step_vox, "step_world": step_world,
        "ms_median": 1e3 * statistics.median(times), "ms_min": 1e3 * min(times),
        "ms_max": 1e3 * max(times), "frames_ms": [1e3 * t for t in times],
        "rmse": err["rmse"], "max_abs": err["max_abs"], "psnr": err["psnr"],
        "time_vs_vtk": None, "rmse_vs_vtk": None, "chosen_step_voxels": None, "chosen_preintegrate": None,
        "chosen_refine": None,
    }


# -- the machine ---------------------------------------------------------------------------
def renderer_line(info):
    """``dvr_gl: <GL renderer> (<backend>), LP_NUM_THREADS=<n>``: how a report starts."""
    return (f"dvr_gl: {info['dvr_gl'].get('renderer')} ({info['dvr_gl'].get('backend')}), "
            f"LP_NUM_THREADS={os.environ.get('LP_NUM_THREADS', 'unset')}")


def vtk_version():
    """VTK's version string, or None when VTK is not installed."""
    try:
        from vtkmodules.vtkCommonCore import vtkVersion
        return vtkVersion.GetVTKVersion()
    except ImportError:
        return None


def machine_info():
    """The date, Python, platform, CPU count and LP_NUM_THREADS, for a report's info."""
    return {"date": datetime.datetime.now().isoformat(timespec="seconds"),
            "python": platform.python_version(), "platform": platform.platform(),
            "cpu_count": os.cpu_count(), "LP_NUM_THREADS": os.environ.get("LP_NUM_THREADS")}


# -- output --------------------------------------------------------------------------------
def fmt(v, spec):
    """``v`` formatted by ``spec``, or ``-`` for None."""
    return "-" if v is None else format(v, spec)


def output_paths(out):
    """``out`` names a stem (a suffix .csv/.json/.png is dropped) or an existing folder
    (then ``<folder>/bench``); returns the three paths."""
    p = Path(out)
    if p.is_dir():
        p = p / "bench"
    elif p.suffix.lower() in (".csv", ".json", ".png"):
        p = p.with_suffix("")
    return p.with_suffix(".csv"), p.with_suffix(".json"), p.with_suffix(".png")


def write_results(rows, info, out, fields, figure):
    """``rows`` as ``<out>.csv`` (the columns ``fields``), ``rows`` and ``info`` as
    ``<out>.json``, and ``figure(rows, info)`` (PNG bytes) as ``<out>.png``, each written
    atomically; returns the three paths."""
    csv_path, json_path, png_path = output_paths(out)
    csv_path.parent.mkdir(parents=True, exist_ok=True)
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=fields, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if r[k] is None else r[k]) for k in fields})
    atomic_write(csv_path, buf.getvalue().encode())

    def clean(v):
        return None if isinstance(v, float) and not math.isfinite(v) else v

    doc = {"info": info, "rows": [{k: clean(v) for k, v in r.items()} for r in rows]}
    atomic_write(json_path, json.dumps(doc, indent=1, default=str).encode())
    atomic_write(png_path, figure(rows, info))
    return csv_path, json_path, png_path


def error_time_figure(rows, info, styles=None) -> bytes:
    """Error (RMSE) against time per frame, log-log, one panel per data set, one line per
    renderer (or per ``series``) through its steps; ``styles`` maps a label to its
    (colour, marker)."""
    import matplotlib
    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    names = list(dict.fromkeys(r["dataset"] for r in rows))
    fig = Figure(figsize=(5.5 * len(names), 4.5), constrained_layout=True)
    axes = fig.subplots(1, len(names), squeeze=False)[0]
    styles = styles or {}
    for ax, name in zip(axes, names):
        for label in dict.fromkeys(r.get("series", r["renderer"]) for r in rows):
            pts = sorted(((r["ms_median"], r["rmse"], r["step_voxels"]) for r in rows
                          if r["dataset"] == name and r.get("series", r["renderer"]) == label),
                         key=lambda p: -p[2])
            if not pts:
                continue
            color, marker = styles.get(label, (None, "x"))
            ax.plot([p[0] for p in pts], [p[1] for p in pts], marker=marker, color=color, label=label)
            for t, e, s in pts:
                ax.annotate(f"{s:.3g}", (t, e), textcoords="offset points", xytext=(4, 4), fontsize=7, color=color)
        error_axes(ax, "median time per frame (ms)", "RMSE against exact (premultiplied RGBA)")
        ax.set_title(f"{name}, {info.get('size')}x{info.get('size')}, step in voxels")
    return figure_bytes(fig)


def error_axes(ax, xlabel, ylabel):
    """Log-log axes of error against time, gridded, with a legend. Times are labelled
    at 1, 2 and 5 per decade as plain numbers (matplotlib's default labels the minor
    ticks of an axis spanning less than a decade, where they overlap)."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.xaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
    ax.xaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)


def figure_bytes(fig):
    """A matplotlib figure as PNG bytes."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    return buf.getvalue()

