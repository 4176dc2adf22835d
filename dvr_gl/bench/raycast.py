"""``dvr-gl bench --suite peer`` (the default): speed and accuracy of the ray caster,
beside VTK, on real CT data.

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

import functools
import math
import sys

import numpy as np

from ..metrics import compare
from ..util.progress import Progress
from ..model.scene import Scene
from .common import (error_time_figure, fmt, interleaved_frames, load_datasets, machine_info, result_row,
                     vtk_version, write_results)

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

CSV_FIELDS = ("dataset", "width", "height", "renderer", "kind", "skip_empty", "step_voxels",
              "step_world", "ms_median", "ms_min", "ms_max", "rmse", "max_abs", "psnr",
              "time_vs_vtk", "rmse_vs_vtk", "chosen_step_voxels", "chosen_preintegrate", "chosen_refine")
STYLES = {"dvr_gl raycast": ("tab:blue", "o"), "dvr_gl raycast+skip": ("tab:green", "s"),
          "VTK GPU raycast": ("tab:red", "^"), TOLERANCE_LABEL: ("tab:purple", "D"),
          ADAPTIVE_LABEL: ("tab:orange", "v")}


# -- the suite -----------------------------------------------------------------------------
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
    from ..rendering.renderer import Renderer
    # The function, imported from its module: ``dvr_gl.reference.exact`` the attribute
    # can be shadowed by the submodule of the same name once that has been imported.
    from ..reference.exact import exact as exact_image

    size = args.size
    error_size = getattr(args, "error_size", None) or size
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

    sets = load_datasets(names, args.chest, err)

    renderers = [r for r in RENDERERS if r[1] != "vtk" or peer is not None]
    renderers.append((ADAPTIVE_LABEL, "dvr_gl", True))
    if peer is not None:
        renderers.append((TOLERANCE_LABEL, "dvr_gl", True))
    frames = 1 + args.repeats  # one warm-up frame, then the timed ones
    progress = Progress(len(sets) * (1 + len(steps) * len(renderers) * frames), stream=err)
    rows = []
    info = {}
    try:
        with Renderer(backend=args.backend) as gl:
            info["dvr_gl"] = gl.info()
            if peer is not None:
                info["vtk"] = {"renderer": peer.renderer_string(), "version": vtk_version(),
                               "data_as_float": bool(args.vtk_float)}
            for name, volume, tf, camera in sets:
                scene = Scene(volume, tf, camera, width=size, height=size)
                # the error is measured at --error-size (default: the frame's own size) on
                # the same view: an exact image of a large frame takes minutes
                error_scene = scene if error_size == size else scene.replace(width=error_size, height=error_size)
                progress.begin(f"{name}: exact image")
                exact = exact_image(error_scene)
                progress.advance(f"{name}: exact image")
                for step_vox in steps:
                    step = step_vox * volume.min_spacing
                    calls, error_images = [], {}
                    vtk_rmse = None
                    if peer is not None:
                        if error_scene is not scene:
                            peer.setup(error_scene, step)
                            error_images["vtk"] = peer.frame()
                        peer.setup(scene, step)  # the peer serves this scene only, here
                        vtk_rmse = compare(error_images.get("vtk", peer.frame()), exact)["rmse"]

                    def gl_call(label, skip, target):
                        if label == TOLERANCE_LABEL:
                            return functools.partial(gl.render, target, technique="raycast",
                                                     tolerance=max(vtk_rmse, 1e-12))
                        if label == ADAPTIVE_LABEL:
                            return functools.partial(gl.render, target, technique="raycast", step=step,
                                                     **ADAPTIVE_OPTIONS)
                        return functools.partial(gl.render, target, technique="raycast", step=step, skip_empty=skip)

                    for label, kind, skip in renderers:
                        calls.append(peer.frame if kind == "vtk" else gl_call(label, skip, scene))
                    images, times = interleaved_frames(
                        calls, args.repeats,
                        lambda k, i: progress.advance(
                            f"{name} step {step_vox:g}: {renderers[k][0]} "
                            + ("warm-up" if i < 0 else f"frame {i + 1}/{args.repeats}")))
                    for (label, kind, skip), image, ts in zip(renderers, images, times):
                        if error_scene is not scene:      # the same way, rendered at the error size
                            image = error_images["vtk"] if kind == "vtk" else gl_call(label, skip, error_scene)()
                        row = result_row(name, scene, label, kind, skip, step_vox, step, ts, compare(image, exact))
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
    info.update(machine_info(), size=size, repeats=args.repeats, steps_voxels=steps,
                datasets=[n for n, *_ in sets], vtk_note=vtk_note)
    return rows, info


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


# -- output --------------------------------------------------------------------------------
def format_table(rows):
    head = ("data", "step", "renderer", "ms/frame", "min ms", "RMSE", "max err", "PSNR dB", "t/VTK", "err/VTK")
    lines = []
    for r in rows:
        label = r["renderer"]
        if r.get("chosen_step_voxels") is not None:     # the step the tolerance chose
            label += f" (step {r['chosen_step_voxels']:.2g}" + (", pre" if r.get("chosen_preintegrate") else "") + (
                f", refine {r['chosen_refine']}" if (r.get("chosen_refine") or 1) > 1 else "") + ")"
        lines.append((r["dataset"], f"{r['step_voxels']:g}", label, fmt(r["ms_median"], ".1f"),
                      fmt(r["ms_min"], ".1f"),
                      fmt(r["rmse"], ".2e"), fmt(r["max_abs"], ".3f"), fmt(r["psnr"], ".1f"),
                      fmt(r["time_vs_vtk"], ".2f"), fmt(r["rmse_vs_vtk"], ".2f")))
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


def figure_png(rows, info) -> bytes:
    """Error (RMSE) against time per frame, log-log, one panel per data set."""
    return error_time_figure(rows, info, STYLES)


def run_peer_bench(args) -> int:
    """``dvr-gl bench --suite peer``: run, print the table and the equal-error / equal-time
    summary, write the results with ``--out``; returns the exit status."""
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
        from ..rendering.renderer import Renderer
        with Renderer(backend=args.backend) as gl:
            rates = texture_format_throughput(gl)
        print("trilinear samples per second by texture format: "
              + ", ".join(f"{k} {v / 1e6:.0f} M" for k, v in rates.items()))
    if args.out:
        paths = write_results(rows, info, args.out, fields=CSV_FIELDS, figure=figure_png)
        print("wrote " + ", ".join(str(p) for p in paths))
    return 0

