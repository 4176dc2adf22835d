"""``dvr-gl bench --suite shading``: what lighting costs, beside VTK's shaded ray caster,
and how accurate the lit image is.

Speed, per data set (the chest CT and the CT head, as in the peer suite) and step (1 and
1/2 voxel by default, ``--steps``): the median frame time at ``--size`` (512) of

- dvr_gl ``raycast`` and ``slice3d`` unlit, lit with gradients on the fly (six field
  lookups per lit sample) and lit from the gradient texture (one lookup);
- ``raycast`` with each illustration term alone (boundary, silhouette, tone, depth cue)
  and lit with all four;
- ``raycast`` and ``slice3d`` classified by a 2D transfer function (the data set's TF
  with Levoy's gradient-magnitude opacity modulation, ``transfer2d.gradient_modulated``),
  unlit and lit;
- VTK's GPU ray caster unlit and with ``ShadeOn()`` (same ka, kd, ks, shininess), at the
  same step,

all taken round robin within one data set and step (``bench.interleaved_frames``), each
frame read back. ``cost`` divides a row by the same renderer's plain row. RMSE
against the exact image (lit or unlit, as the row) at ``--error-size`` (128).

Accuracy: the lit Marschner-Lobb phantom (41^3, ``--error-size``), ``raycast`` and
``slice3d`` at 1, 1/2, 1/4, 1/8 and 1/16 voxel against ``reference.exact`` (which lights
every quadrature node with the contract's gradient), the observed convergence order per
halving, and the float64 midpoint marcher (``reference.render(..., lut_exact=True)``,
same gradient rule) at 1/4 voxel.
"""

from __future__ import annotations

import functools
import math
import sys

import numpy as np

from ..metrics import compare, rmse
from ..util.progress import Progress
from ..model.scene import Scene
from .common import (error_axes, figure_bytes, fmt, interleaved_frames, load_datasets, machine_info, renderer_line,
                     write_results)

ALL_TERMS = ("boundary", "silhouette", "tone", "depth_cue")
# a variant: (lit, illustration terms, classified by the 2D TF gradient_modulated makes)
PLAIN, LIT, TF2D, TF2D_LIT = (False, (), False), (True, (), False), (False, (), True), (True, (), True)
CONFIGS = (  # (label, kind, technique, variant, options, the row its cost divides by)
    ("raycast", "dvr_gl", "raycast", PLAIN, {}, None),
    ("raycast lit", "dvr_gl", "raycast", LIT, {}, "raycast"),
    ("raycast lit texture", "dvr_gl", "raycast", LIT, {"gradients": "texture"}, "raycast"),
    ("raycast +boundary", "dvr_gl", "raycast", (False, ("boundary",), False), {}, "raycast"),
    ("raycast +silhouette", "dvr_gl", "raycast", (False, ("silhouette",), False), {}, "raycast"),
    ("raycast +tone", "dvr_gl", "raycast", (False, ("tone",), False), {}, "raycast"),
    ("raycast +depth_cue", "dvr_gl", "raycast", (False, ("depth_cue",), False), {}, "raycast"),
    ("raycast lit +all four", "dvr_gl", "raycast", (True, ALL_TERMS, False), {}, "raycast"),
    ("raycast lit +all four texture", "dvr_gl", "raycast", (True, ALL_TERMS, False), {"gradients": "texture"},
     "raycast"),
    ("raycast 2D TF", "dvr_gl", "raycast", TF2D, {}, "raycast"),
    ("raycast 2D TF texture", "dvr_gl", "raycast", TF2D, {"gradients": "texture"}, "raycast"),
    ("raycast 2D TF lit texture", "dvr_gl", "raycast", TF2D_LIT, {"gradients": "texture"}, "raycast"),
    ("slice3d", "dvr_gl", "slice3d", PLAIN, {}, None),
    ("slice3d lit", "dvr_gl", "slice3d", LIT, {}, "slice3d"),
    ("slice3d lit texture", "dvr_gl", "slice3d", LIT, {"gradients": "texture"}, "slice3d"),
    ("slice3d 2D TF texture", "dvr_gl", "slice3d", TF2D, {"gradients": "texture"}, "slice3d"),
    ("VTK GPU raycast", "vtk", None, PLAIN, {}, None),
    ("VTK GPU raycast ShadeOn", "vtk", None, LIT, {}, "VTK GPU raycast"),
)
VARIANTS = sorted({c[3] for c in CONFIGS})
CONVERGENCE_STEPS = (1.0, 0.5, 0.25, 0.125, 0.0625)
CSV_FIELDS = ["dataset", "step_voxels", "renderer", "lit", "terms", "width", "ms_median", "ms_min", "cost",
              "time_vs_vtk", "error_size", "rmse", "max_abs", "psnr"]


def variant(scene, lit_terms):
    lit, terms, tf2d = lit_terms
    scene = scene.replace(shading=lit, illustration=terms)
    return scene.replace(tf=modulated_tf(scene.volume, scene.tf)) if tf2d else scene


@functools.lru_cache(maxsize=4)
def modulated_tf(volume, tf):
    """The data set's TF with Levoy's gradient-magnitude opacity modulation, as a 2D TF
    over the volume's gradient magnitudes (made once per volume and TF)."""
    from ..model.field import gradient_max
    from ..model.transfer2d import gradient_modulated
    return gradient_modulated(tf, (0.0, gradient_max(volume)))


def _timed_rows(gl, peers, name, scene, step_vox, repeats, progress, exact_images):
    """Rows for one data set and step: every configuration timed round robin. ``peers``
    maps lit (False, True) to its own VTK pipeline (switching one pipeline's lighting
    every frame would time VTK's rebuilds), or is empty."""
    step = step_vox * scene.volume.min_spacing
    configs = [c for c in CONFIGS if c[1] != "vtk" or peers]
    calls = []
    for label, kind, technique, lit_terms, opts, _ in configs:
        s = variant(scene, lit_terms)
        if kind == "vtk":
            peers[lit_terms[0]].setup(s, step)
            calls.append(peers[lit_terms[0]].frame)
        else:
            calls.append(functools.partial(gl.render, s, technique=technique, step=step, **opts))
    _, times = interleaved_frames(calls, repeats, lambda k, i: progress.advance(
        f"{name} step {step_vox:g}: {configs[k][0]} " + ("warm-up" if i < 0 else f"frame {i + 1}/{repeats}")))
    rows = []
    for (label, kind, technique, lit_terms, opts, base), ts in zip(configs, times):
        small, exact = exact_images[lit_terms]
        if kind == "vtk":
            peers[lit_terms[0]].setup(small, step)
            image = peers[lit_terms[0]].frame()
        else:
            image = gl.render(small, technique=technique, step=step, **opts)
        err = compare(image, exact)
        rows.append({"dataset": name, "step_voxels": step_vox, "renderer": label, "lit": lit_terms[0],
                     "terms": "+".join(lit_terms[1] + (("tf2d",) if lit_terms[2] else ())), "base": base,
                     "width": scene.width, "ms_median": 1e3 * float(np.median(ts)), "ms_min": 1e3 * min(ts),
                     "error_size": small.width, "rmse": err["rmse"], "max_abs": err["max_abs"],
                     "psnr": err["psnr"], "cost": None, "time_vs_vtk": None})
    by_label = {r["renderer"]: r for r in rows}
    vtk = {r["lit"]: r for r in rows if r["renderer"].startswith("VTK")}
    for r in rows:
        base = by_label.get(r.pop("base"))
        if base is not None:
            r["cost"] = r["ms_median"] / base["ms_median"]
        if not r["terms"] and r["lit"] in vtk and not r["renderer"].startswith("VTK"):
            r["time_vs_vtk"] = r["ms_median"] / vtk[r["lit"]]["ms_median"]
    return rows


def convergence(gl, size):
    """Lit Marschner-Lobb: RMSE against exact per step for raycast and slice3d, the
    order per halving, and the float64 marcher at 1/4 voxel."""
    from ..data.phantoms import marschner_lobb, marschner_lobb_tf
    from ..reference import render as reference_render
    from ..reference.exact import exact as exact_image
    from ..model.camera import default_camera
    volume = marschner_lobb(41)
    scene = Scene(volume, marschner_lobb_tf(), default_camera(volume, azimuth=30, elevation=20),
                  width=size, height=size, shading=True)
    exact = exact_image(scene)
    h = volume.min_spacing
    out = {"steps_voxels": list(CONVERGENCE_STEPS)}
    for technique in ("raycast", "slice3d"):
        opts = {"ert_transmittance": 0.0} if technique == "raycast" else {}
        errors = [rmse(gl.render(scene, technique=technique, step=k * h, **opts), exact)
                  for k in CONVERGENCE_STEPS]
        out[technique] = errors
        out[technique + "_orders"] = [math.log2(a / b) for a, b in zip(errors, errors[1:])]
    out["marcher_quarter"] = rmse(
        reference_render(scene, "raycast", step=0.25 * h, lut_exact=True, ert_transmittance=0.0), exact)
    return out


def run_shading(args, err=None):
    err = err if err is not None else sys.stderr
    from ..rendering.renderer import Renderer
    from ..reference.exact import exact as exact_image
    names = [n.strip() for n in args.datasets.split(",") if n.strip()]
    steps = [float(s) for s in args.steps.split(",") if s.strip()]
    peers = {}
    if not args.no_vtk:
        try:
            from .vtk_peer import VTKPeer
            peers = {False: VTKPeer(), True: VTKPeer()}
        except ImportError as e:
            print(f"dvr-gl bench: VTK not available ({e}); VTK rows skipped", file=err)
    sets = load_datasets(names, args.chest, err)
    n_configs = sum(1 for c in CONFIGS if c[1] != "vtk" or peers)
    progress = Progress(len(sets) * (len(VARIANTS) + len(steps) * n_configs * (1 + args.repeats)) + 1, stream=err)
    rows, info = [], {}
    try:
        with Renderer(backend=args.backend) as gl:
            info["dvr_gl"] = gl.info()
            for name, volume, tf, camera in sets:
                scene = Scene(volume, tf, camera, width=args.size, height=args.size)
                exact_images = {}
                for lit_terms in VARIANTS:
                    small = variant(Scene(volume, tf, camera, width=args.error_size, height=args.error_size),
                                    lit_terms)
                    what = (f"{name}: exact image, {'lit' if lit_terms[0] else 'unlit'} {'+'.join(lit_terms[1])}"
                            + (" 2D TF" if lit_terms[2] else ""))
                    progress.begin(what)
                    exact_images[lit_terms] = (small, exact_image(small))
                    progress.advance(what)
                for step_vox in steps:
                    rows.extend(_timed_rows(gl, peers, name, scene, step_vox, args.repeats, progress, exact_images))
            progress.begin("lit Marschner-Lobb convergence")
            info["convergence"] = convergence(gl, args.error_size)
            progress.advance("lit Marschner-Lobb convergence")
    finally:
        progress.close()
        if peers:
            info["vtk"] = {"renderer": peers[False].renderer_string()}
        for peer in peers.values():
            peer.close()
    info.update(machine_info(), size=args.size, error_size=args.error_size, repeats=args.repeats, suite="shading",
                datasets=[n for n, *_ in sets], steps_voxels=steps)
    return rows, info


def format_shading_table(rows):
    head = ("data", "step (voxel)", "renderer", "ms/frame", "cost", "t/VTK", "RMSE", "max err")
    lines = [(r["dataset"], f"{r['step_voxels']:g}", r["renderer"], fmt(r["ms_median"], ".1f"),
              fmt(r["cost"], ".2f"), fmt(r["time_vs_vtk"], ".2f"), fmt(r["rmse"], ".2e"),
              fmt(r["max_abs"], ".3f")) for r in rows]
    widths = [max(len(h), *(len(l[i]) for l in lines)) if lines else len(h) for i, h in enumerate(head)]
    fmt_line = lambda cells: "| " + " | ".join(c.ljust(w) for c, w in zip(cells, widths)) + " |"   # noqa: E731
    return "\n".join([fmt_line(head), "|" + "|".join("-" * (w + 2) for w in widths) + "|"] + [fmt_line(l) for l in lines])


def format_convergence(c):
    lines = ["lit Marschner-Lobb against exact (RMSE), steps " + ", ".join(f"{k:g}" for k in c["steps_voxels"])
             + " voxel:"]
    for technique in ("raycast", "slice3d"):
        lines.append(f"  {technique:8s} " + " ".join(f"{e:.2e}" for e in c[technique])
                     + "   orders " + " ".join(f"{o:.2f}" for o in c[technique + "_orders"]))
    q = CONVERGENCE_STEPS.index(0.25)
    lines.append(f"  float64 marcher at 1/4 voxel {c['marcher_quarter']:.2e}: raycast "
                 f"{c['raycast'][q] / c['marcher_quarter']:.2f}x, slice3d {c['slice3d'][q] / c['marcher_quarter']:.2f}x")
    return "\n".join(lines)


def figure_png(rows, info) -> bytes:
    """Each renderer's frame time against its RMSE, log-log, one panel per data set: a
    line per configuration through its steps, a colour each (ray caster circles, 3D
    slicing squares, VTK triangles), the legend below the panels."""
    import matplotlib
    matplotlib.use("Agg", force=False)
    from matplotlib import colormaps
    from matplotlib.figure import Figure

    names = list(dict.fromkeys(r["dataset"] for r in rows))
    labels = list(dict.fromkeys(r["renderer"] for r in rows))
    colours = colormaps["tab20"](np.linspace(0, 1, 20))
    fig = Figure(figsize=(5.5 * len(names), 6.5), constrained_layout=True)
    axes = fig.subplots(1, len(names), squeeze=False)[0]
    for ax, name in zip(axes, names):
        for k, label in enumerate(labels):
            pts = sorted(((r["ms_median"], r["rmse"], r["step_voxels"]) for r in rows
                          if r["dataset"] == name and r["renderer"] == label), key=lambda p: -p[2])
            marker = "^" if label.startswith("VTK") else "s" if label.startswith("slice3d") else "o"
            ax.plot([p[0] for p in pts], [p[1] for p in pts], marker=marker, color=colours[k % 20], label=label)
        error_axes(ax, "median time per frame (ms)", "RMSE against exact (premultiplied RGBA)")
        ax.get_legend().remove()
        ax.set_title(f"{name}, {info.get('size')}x{info.get('size')}, steps " +
                     ", ".join(f"{s:g}" for s in info.get("steps_voxels", [])) + " voxel")
    handles, texts = axes[0].get_legend_handles_labels()
    fig.legend(handles, texts, loc="outside lower center", ncol=4, fontsize=8)
    return figure_bytes(fig)


def run_shading_bench(args) -> int:
    rows, info = run_shading(args)
    vtk = info.get("vtk", {}).get("renderer", "not run")
    print(f"{renderer_line(info)}; VTK: {vtk}; {info['size']}x{info['size']}, median of {info['repeats']} "
          f"frames; cost = / the same renderer plain; t/VTK = / VTK's row with the same lighting; "
          f"RMSE at {info['error_size']}x{info['error_size']}")
    print(format_shading_table(rows))
    print(format_convergence(info["convergence"]))
    if args.out:
        paths = write_results(rows, info, args.out, fields=CSV_FIELDS, figure=figure_png)
        print("wrote " + ", ".join(str(p) for p in paths))
    return 0
