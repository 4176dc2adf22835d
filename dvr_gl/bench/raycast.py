"""``dvr-gl bench``: speed and accuracy of the ray caster, beside VTK, on real CT data.

For each data set (the vtk.js LIDC2 chest CT and the bundled CT head) and each step of
1, 1/2 and 1/4 voxel (voxel = the smallest spacing), it renders the same scene with

- dvr_gl's ray caster without empty-space skipping,
- dvr_gl's ray caster with empty-space skipping,
- VTK's GPU ray caster (``dvr_gl.bench.vtk_peer``; skipped when VTK is not installed),

and reports the median steady-state frame time (after one warm-up frame; every frame
ends with the image read back, so the GL has finished; the renderers' frames are taken
round robin, so a change in the machine's load falls on all three alike; ``min ms`` is
the fastest frame) and the error against the exact
image of the contract (``dvr_gl.reference.exact``, cached on disk): RMSE, largest
absolute error and PSNR over premultiplied RGBA. The ratio columns divide each row by
VTK's row at the same data set and step: ``t/VTK`` < 1 is faster than VTK,
``err/VTK`` < 1 is more accurate.

Results go to stdout as a table and, with ``--out``, to ``<out>.csv``, ``<out>.json``
(rows plus the machine, renderers and settings) and ``<out>.png`` (error against time,
log-log, one line per renderer through its steps), each written atomically.
"""

from __future__ import annotations

import argparse
import csv
import datetime
import functools
import gzip
import io
import json
import math
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from .. import metrics
from ..formats import atomic_write
from ..util.progress import Progress
from ..model.scene import Camera, Scene, TransferFunction, Volume

STEPS_VOXELS = (1.0, 0.5, 0.25)
# the project's shared data folder beside the checkout (override with $DVR_GL_DATA)
DEFAULT_DATA_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                                "shared", "data")
CHEST_FILE = os.path.join("vtkjs_lidc2_ct", "LIDC2_256x256x133_uint8.raw.gz")

RENDERERS = (  # (label, kind, skip_empty)
    ("dvr_gl raycast", "dvr_gl", False),
    ("dvr_gl raycast+skip", "dvr_gl", True),
    ("VTK GPU raycast", "vtk", None),
)
# with VTK: dvr_gl asked for VTK's RMSE at each of VTK's steps (Renderer.render's
# tolerance=, skipping on), timed in the same round robin
TOLERANCE_LABEL = "dvr_gl tolerance=VTK's RMSE"
# adaptive sampling: pre-integrated segments refined where the TF has detail, skipping on
ADAPTIVE_LABEL = "dvr_gl refine=4 (pre-int.)"
ADAPTIVE_OPTIONS = {"preintegrate": True, "refine": 4}


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


def _load_datasets(names, chest_path, err):
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


def renderer_line(info):
    """``dvr_gl: <GL renderer> (<backend>), LP_NUM_THREADS=<n>``: how a report starts."""
    return (f"dvr_gl: {info['dvr_gl'].get('renderer')} ({info['dvr_gl'].get('backend')}), "
            f"LP_NUM_THREADS={os.environ.get('LP_NUM_THREADS', 'unset')}")


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


def _row(dataset, scene, label, kind, skip, step_vox, step_world, times, err):
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


def _add_ratios(rows):
    vtk = {(r["dataset"], r["step_voxels"]): r for r in rows if r["kind"] == "vtk"}
    for r in rows:
        ref = vtk.get((r["dataset"], r["step_voxels"]))
        if ref is not None:
            r["time_vs_vtk"] = r["ms_median"] / ref["ms_median"] if ref["ms_median"] > 0 else None
            r["rmse_vs_vtk"] = r["rmse"] / ref["rmse"] if ref["rmse"] > 0 else None


def run(args, err=None):
    """Run the benchmark; returns (rows, info)."""
    err = err if err is not None else sys.stderr   # looked up now: tests swap sys.stderr
    import dvr_gl
    # The function, imported from its module: ``dvr_gl.reference.exact`` the attribute
    # can be shadowed by the submodule of the same name once that has been imported.
    from ..reference.exact import exact as exact_image

    size = args.size
    names = [n.strip() for n in (args.datasets or "chest,head").split(",") if n.strip()]
    steps = [float(s) for s in args.steps.split(",") if s.strip()]

    peer = None
    vtk_note = None
    if not args.no_vtk:
        try:
            from .vtk_peer import VTKPeer
            peer = VTKPeer(data_as_float=args.vtk_float)
        except ImportError as e:
            vtk_note = f"VTK not available ({e}); VTK rows skipped (pip install 'dvr-gl[bench]')"
            print(f"dvr-gl bench: {vtk_note}", file=err)

    sets = _load_datasets(names, args.chest, err)

    renderers = [r for r in RENDERERS if r[1] != "vtk" or peer is not None]
    renderers.append((ADAPTIVE_LABEL, "dvr_gl", True))
    if peer is not None:
        renderers.append((TOLERANCE_LABEL, "dvr_gl", True))
    frames = 1 + args.repeats  # one warm-up frame, then the timed ones
    progress = Progress(len(sets) * (1 + len(steps) * len(renderers) * frames), stream=err)
    rows = []
    info = {}
    try:
        with dvr_gl.Renderer(backend=args.backend) as gl:
            info["dvr_gl"] = gl.info()
            if peer is not None:
                info["vtk"] = {"renderer": peer.renderer_string(), "version": _vtk_version(),
                               "data_as_float": bool(args.vtk_float)}
            for name, volume, tf, camera in sets:
                scene = Scene(volume, tf, camera, width=size, height=size)
                progress.begin(f"{name}: exact image")
                exact = exact_image(scene)
                progress.advance(f"{name}: exact image")
                for step_vox in steps:
                    step = step_vox * volume.min_spacing
                    calls = []
                    vtk_rmse = None
                    if peer is not None:
                        peer.setup(scene, step)  # the peer serves this scene only, here
                        vtk_rmse = metrics.compare(peer.frame(), exact)["rmse"]
                    for label, kind, skip in renderers:
                        if kind == "vtk":
                            calls.append(peer.frame)
                        elif label == TOLERANCE_LABEL:
                            calls.append(functools.partial(gl.render, scene, technique="raycast",
                                                           tolerance=max(vtk_rmse, 1e-12)))
                        elif label == ADAPTIVE_LABEL:
                            calls.append(functools.partial(gl.render, scene, technique="raycast", step=step,
                                                           **ADAPTIVE_OPTIONS))
                        else:
                            calls.append(functools.partial(gl.render, scene, technique="raycast",
                                                           step=step, skip_empty=skip))
                    images, times = interleaved_frames(
                        calls, args.repeats,
                        lambda k, i: progress.advance(
                            f"{name} step {step_vox:g}: {renderers[k][0]} "
                            + ("warm-up" if i < 0 else f"frame {i + 1}/{args.repeats}")))
                    for (label, kind, skip), image, ts in zip(renderers, images, times):
                        row = _row(name, scene, label, kind, skip, step_vox, step, ts, metrics.compare(image, exact))
                        if label == TOLERANCE_LABEL:   # its own step, chosen for VTK's RMSE at this one
                            gl.render(scene, tolerance=max(vtk_rmse, 1e-12))
                            row["chosen_step_voxels"] = gl.last_choice.step_voxels
                            row["chosen_preintegrate"] = gl.last_choice.preintegrate
                            row["chosen_refine"] = gl.last_choice.refine
                        rows.append(row)
    finally:
        progress.close()
        if peer is not None:
            peer.close()
    _add_ratios(rows)
    info.update(_machine(), size=size, repeats=args.repeats, steps_voxels=steps,
                datasets=[n for n, *_ in sets], vtk_note=vtk_note)
    return rows, info


# -- the slicing suite ---------------------------------------------------------------------
SLICE_INTERPOLATE = (0, 1, 3)


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
    import dvr_gl
    from ..reference.exact import exact as exact_image
    from ..techniques.slice2d import stack_axis

    size = args.size
    names = [n.strip() for n in (args.datasets or "chest,head").split(",") if n.strip()]
    sets = _load_datasets(names, args.chest, err)
    configs = slicing_configs()
    ks = sorted({c[3] for c in configs})
    frames = 1 + args.repeats
    progress = Progress(len(sets) * (1 + len(configs) * frames), stream=err)
    rows, info = [], {}
    try:
        with dvr_gl.Renderer(backend=args.backend) as gl:
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
                        row = _row(name, scene, label, technique, None, distance / volume.min_spacing,
                                   distance, ts, metrics.compare(image, exact))
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
    info.update(_machine(), size=size, repeats=args.repeats, suite="slicing",
                datasets=[n for n, *_ in sets])
    return rows, info


def format_slicing_table(rows):
    head = ("data", "distance (voxel)", "renderer", "ms/frame", "RMSE", "max err", "PSNR dB", "t/raycast",
            "err/raycast")
    lines = [(r["dataset"], f"{r['step_voxels']:.3g}", r["renderer"], _fmt(r["ms_median"], ".1f"),
              _fmt(r["rmse"], ".2e"), _fmt(r["max_abs"], ".3f"), _fmt(r["psnr"], ".1f"),
              _fmt(r["time_vs_raycast"], ".2f"), _fmt(r["rmse_vs_raycast"], ".2f")) for r in rows]
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


def equal_error_and_time(rows):
    """For each VTK row: dvr_gl's (skipping on) frame time at VTK's error, and its error at
    VTK's frame time, interpolated log-log between dvr_gl's steps (None outside their
    range). Returns rows of dicts with the two ratios (dvr_gl / VTK; below 1 is better)."""
    out = []
    for v in (r for r in rows if r["kind"] == "vtk"):
        mine = sorted((r for r in rows if r["dataset"] == v["dataset"] and r["renderer"] == "dvr_gl raycast+skip"),
                      key=lambda r: r["rmse"])
        if len(mine) < 2:
            continue
        err = np.log([r["rmse"] for r in mine])
        ms = np.log([r["ms_median"] for r in mine])
        t_at_err = _interp(math.log(v["rmse"]), err, ms)
        order = np.argsort(ms)
        e_at_t = _interp(math.log(v["ms_median"]), ms[order], err[order])
        out.append({"dataset": v["dataset"], "vtk_step_voxels": v["step_voxels"],
                    "vtk_ms": v["ms_median"], "vtk_rmse": v["rmse"],
                    "time_ratio_at_equal_error": None if t_at_err is None else math.exp(t_at_err) / v["ms_median"],
                    "error_ratio_at_equal_time": None if e_at_t is None else math.exp(e_at_t) / v["rmse"]})
    return out


def _interp(x, xs, ys):
    if not xs[0] <= x <= xs[-1]:
        return None
    return float(np.interp(x, xs, ys))


def texture_format_throughput(renderer, size=256, samples=64, repeats=5):
    """Trilinear samples per second from a 3-D texture stored as float32, float16 and
    unorm8: every pixel of a size x size target sums ``samples`` lookups along a line."""
    import time
    from ..gl.context import current
    ctx = renderer.ctx
    vs = "#version 330 core\nin vec2 a_pos; void main() { gl_Position = vec4(a_pos, 0.0, 1.0); }"
    fs = f"""#version 330 core
uniform sampler3D t_volume;
out vec4 f_color;
void main() {{
    vec2 uv = gl_FragCoord.xy / {size}.0;
    float acc = 0.0;
    for (int i = 0; i < {samples}; ++i)
        acc += texture(t_volume, vec3(uv, (float(i) + 0.37) / {samples}.0)).r;
    f_color = vec4(acc);
}}"""
    rng = np.random.default_rng(0)
    data = rng.random((128, 128, 128)).astype(np.float32)
    result = {}
    with current(ctx):
        prog = ctx.program(vertex_shader=vs, fragment_shader=fs)
        vbo = ctx.buffer(np.array([-1, -1, 3, -1, -1, 3], "f4").tobytes())
        vao = ctx.vertex_array(prog, [(vbo, "2f", "a_pos")])
        target = ctx.texture((size, size), 4, dtype="f4")
        fbo = ctx.framebuffer([target])
        for dtype, array in (("f4", data), ("f2", data.astype(np.float16)), ("f1", (data * 255).astype(np.uint8))):
            tex = ctx.texture3d((128, 128, 128), 1, array.tobytes(), dtype=dtype)
            tex.filter = (ctx.LINEAR, ctx.LINEAR)
            tex.use(0)
            fbo.use()
            times = []
            for i in range(repeats + 1):
                t = time.perf_counter()
                vao.render()
                fbo.read(components=1, dtype="f4")  # GL has finished
                if i:
                    times.append(time.perf_counter() - t)
            result[{"f4": "float32", "f2": "float16", "f1": "unorm8"}[dtype]] = size * size * samples / float(np.median(times))
            tex.release()
        for obj in (vao, vbo, prog):
            obj.release()
    return result


def _vtk_version():
    try:
        from vtkmodules.vtkCommonCore import vtkVersion
        return vtkVersion.GetVTKVersion()
    except ImportError:
        return None


def _machine():
    return {"date": datetime.datetime.now().isoformat(timespec="seconds"),
            "python": platform.python_version(), "platform": platform.platform(),
            "cpu_count": os.cpu_count(), "LP_NUM_THREADS": os.environ.get("LP_NUM_THREADS")}


# -- output --------------------------------------------------------------------------------
def _fmt(v, spec):
    return "-" if v is None else format(v, spec)


def format_table(rows):
    head = ("data", "step", "renderer", "ms/frame", "min ms", "RMSE", "max err", "PSNR dB", "t/VTK", "err/VTK")
    lines = []
    for r in rows:
        label = r["renderer"]
        if r.get("chosen_step_voxels") is not None:     # the step the tolerance chose
            label += f" (step {r['chosen_step_voxels']:.2g}" + (", pre" if r.get("chosen_preintegrate") else "") + (
                f", refine {r['chosen_refine']}" if (r.get("chosen_refine") or 1) > 1 else "") + ")"
        lines.append((r["dataset"], f"{r['step_voxels']:g}", label, _fmt(r["ms_median"], ".1f"),
                      _fmt(r["ms_min"], ".1f"),
                      _fmt(r["rmse"], ".2e"), _fmt(r["max_abs"], ".3f"), _fmt(r["psnr"], ".1f"),
                      _fmt(r["time_vs_vtk"], ".2f"), _fmt(r["rmse_vs_vtk"], ".2f")))
    widths = [max(len(h), *(len(l[i]) for l in lines)) if lines else len(h) for i, h in enumerate(head)]
    left = {0, 2}

    def fmt_line(cells):
        return "  ".join(c.ljust(w) if i in left else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths)))

    out = [fmt_line(head), fmt_line(["-" * w for w in widths])]
    prev = None
    for r, l in zip(rows, lines):
        if prev is not None and (r["dataset"], r["step_voxels"]) != prev:
            out.append("")
        prev = (r["dataset"], r["step_voxels"])
        out.append(fmt_line(l))
    return "\n".join(out)


CSV_FIELDS = ("dataset", "width", "height", "renderer", "kind", "skip_empty", "step_voxels",
              "step_world", "ms_median", "ms_min", "ms_max", "rmse", "max_abs", "psnr",
              "time_vs_vtk", "rmse_vs_vtk", "chosen_step_voxels", "chosen_preintegrate", "chosen_refine")


def output_paths(out):
    """``out`` names a stem (a suffix .csv/.json/.png is dropped) or an existing folder
    (then ``<folder>/bench``); returns the three paths."""
    p = Path(out)
    if p.is_dir():
        p = p / "bench"
    elif p.suffix.lower() in (".csv", ".json", ".png"):
        p = p.with_suffix("")
    return p.with_suffix(".csv"), p.with_suffix(".json"), p.with_suffix(".png")


SLICING_CSV_FIELDS = ("dataset", "width", "height", "renderer", "kind", "interpolate", "preintegrate",
                      "step_voxels", "step_world", "ms_median", "ms_min", "ms_max", "rmse", "max_abs",
                      "psnr", "time_vs_raycast", "rmse_vs_raycast")


def write_results(rows, info, out, fields=CSV_FIELDS, figure=None):
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
    atomic_write(png_path, (figure or figure_png)(rows, info))
    return csv_path, json_path, png_path


def figure_png(rows, info) -> bytes:
    """Error (RMSE) against time per frame, log-log, one panel per data set."""
    import matplotlib
    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    names = list(dict.fromkeys(r["dataset"] for r in rows))
    fig = Figure(figsize=(5.5 * len(names), 4.5), constrained_layout=True)
    axes = fig.subplots(1, len(names), squeeze=False)[0]
    styles = {"dvr_gl raycast": ("tab:blue", "o"), "dvr_gl raycast+skip": ("tab:green", "s"),
              "VTK GPU raycast": ("tab:red", "^"), TOLERANCE_LABEL: ("tab:purple", "D"),
              ADAPTIVE_LABEL: ("tab:orange", "v")}
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


# -- command line ----------------------------------------------------------------------------
def add_arguments(parser):
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
                             "tetrahedra (MPVO and centroid sort) beside VTK's on the NASA meshes "
                             "and the Delaunay ball (--datasets bluntfin,combustor,loxpost,ball); particles: "
                             "PBVR at several repetition counts beside raycast (head) and tetra (bluntfin); "
                             "shading: the cost of lighting in raycast and slice3d beside VTK's ShadeOn, "
                             "and the lit image's convergence against exact")
    parser.add_argument("--repetitions-list", default="1,4,16,64",
                        help="particles suite: the repetition counts (default 1,4,16,64)")
    parser.add_argument("--error-size", type=int, default=None,
                        help="mesh, particles and shading suites: image size of the error measurement (default 128; "
                             "32 with --quick)")
    parser.add_argument("--data-dir", default=None,
                        help=f"mesh suite: the shared data folder (default $DVR_GL_DATA or {DEFAULT_DATA_DIR})")
    parser.add_argument("--vtk-float", action="store_true",
                        help="give VTK the samples as float32 instead of their own type")
    return parser


def run_bench(args) -> int:
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
        rows, info = run_slicing(args)
        print(f"dvr_gl: {info['dvr_gl'].get('renderer')} ({info['dvr_gl'].get('backend')}); "
              f"{info['size']}x{info['size']}, median of {info['repeats']} frames; t/raycast and "
              f"err/raycast divide by the post-classified ray caster at the same distance")
        print(format_slicing_table(rows))
        if args.out:
            paths = write_results(rows, info, args.out, fields=SLICING_CSV_FIELDS)
            print("wrote " + ", ".join(str(p) for p in paths))
        return 0
    rows, info = run(args)
    print(f"dvr_gl: {info['dvr_gl'].get('renderer')} ({info['dvr_gl'].get('backend')}); "
          f"VTK: {info['vtk']['renderer'] + ' (VTK ' + str(info['vtk']['version']) + ')' if 'vtk' in info else 'not run'}; "
          f"{info['size']}x{info['size']}, median of {info['repeats']} frames; "
          f"t/VTK and err/VTK divide by VTK's row at the same step")
    print(format_table(rows))
    summary = equal_error_and_time(rows)
    if summary:
        print("at equal error / equal time (dvr_gl with skipping, interpolated log-log across its steps):")
        for r in summary:
            t = r["time_ratio_at_equal_error"]
            e = r["error_ratio_at_equal_time"]
            print(f"  {r['dataset']:6s} vs VTK at {r['vtk_step_voxels']:g} voxel: time ratio at equal error "
                  f"{'n/a' if t is None else f'{t:.2f}'}, error ratio at equal time {'n/a' if e is None else f'{e:.2f}'}")
    if args.textures:
        import dvr_gl
        with dvr_gl.Renderer(backend=args.backend) as gl:
            rates = texture_format_throughput(gl)
        print("trilinear samples per second by texture format: "
              + ", ".join(f"{k} {v / 1e6:.0f} M" for k, v in rates.items()))
    if args.out:
        paths = write_results(rows, info, args.out)
        print("wrote " + ", ".join(str(p) for p in paths))
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="dvr-gl bench", description=__doc__.split("\n\n")[0])
    add_arguments(parser)
    return run_bench(parser.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
