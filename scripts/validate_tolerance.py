"""Does ``tolerance=E`` keep its promise on scenes it was not tuned on?

Builds a seeded set of scenes that share nothing with the scenes the step model was
developed on (the tests' and the guide's: fixed cameras, the auto preset, 48- and
128-pixel images): the shared data's volumes, the bundled ones, and generated fields
(Marschner-Lobb at 48 and 64 samples a side, smooth noise), each seen from a random
oblique camera (azimuth anywhere, elevation 12 to 65 degrees up or down, zoom 0.8 to
1.5), at a random size from 64 to 512 pixels (the larger sizes go to the smaller
volumes, to keep the exact images affordable), lit or unlit, with one of three TF
families: the data's preset, a narrow opacity spike (2 % of the value range wide) at a
random value, and a broad ramp. Each scene is rendered with ``tolerance=E`` for
E = 1e-2, 3e-3 and 1e-3 in a fresh renderer per scene, and its RMSE measured against
``reference.exact`` at the requested size (cached on disk by scene digest). Writes a
Markdown table: kept / total and the achieved / requested ratios.

    python scripts/validate_tolerance.py [--scenes 42] [--seed 31] [--out FILE.md]
                                         [--first K] [--max-size 512]
"""

from __future__ import annotations

import argparse
import gzip
import os
import sys
import time

import numpy as np

import dvr_gl
from dvr_gl import data as bundled, metrics, reference
from dvr_gl.data.phantoms import marschner_lobb
from dvr_gl.formats import atomic_write, load_volume
from dvr_gl.model.transfer import auto_preset
from dvr_gl.rendering import tolerance as tol

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = os.environ.get("DVR_GL_DATA", os.path.join(HERE, os.pardir, os.pardir, "shared", "data"))
TOLERANCES = (1e-2, 3e-3, 1e-3)
# image sides: the exact integrator's time grows with the pixels and with the crossings of
# features a ray makes (a lit 384x288 Marschner-Lobb image took 400 s on 2 cores), so the
# large sizes go to unlit scenes of the measured volumes up to 80^3 samples
SIZES_UNLIT_SMALL_VOLUME = (64, 96, 128, 192, 256, 384, 512)
SIZES_OTHERS = (64, 96, 128, 160)
GENERATED = ("marschner_lobb", "smooth noise")


def raw_gz(path, shape, dtype, spacing):
    with gzip.open(path, "rb") as f:
        values = np.frombuffer(f.read(), dtype).reshape(shape)
    return dvr_gl.Volume(values.astype(np.float32), spacing=spacing)


def smooth_noise(n, cutoff, seed):
    """Gaussian-filtered white noise on n^3 samples (a Gaussian of ``cutoff`` cycles per
    side in the frequency domain), scaled to [0, 1]: detail everywhere, like turbulence."""
    rng = np.random.default_rng(seed)
    k = np.fft.fftfreq(n) * n
    kx, ky, kz = np.meshgrid(k, k, k, indexing="ij")
    spectrum = np.fft.fftn(rng.standard_normal((n, n, n))) * np.exp(-(kx ** 2 + ky ** 2 + kz ** 2) / (2 * cutoff ** 2))
    field = np.real(np.fft.ifftn(spectrum))
    field = (field - field.min()) / (field.max() - field.min())
    return dvr_gl.Volume(field.astype(np.float32), spacing=(1.0, 1.0, 1.0))


def volumes():
    """name -> a function returning the Volume; files missing from the data folder are
    left out (and said so)."""
    def shared(rel, **kw):
        return lambda: load_volume(os.path.join(DATA, rel), **kw)
    found = {
        "ct_head (bundled)": bundled.ct_head,
        "synthetic (bundled, 48)": lambda: bundled.synthetic(48),
        "marschner_lobb 48": lambda: marschner_lobb(48),
        "marschner_lobb 64": lambda: marschner_lobb(64),
        "smooth noise 40 (4 cycles)": lambda: smooth_noise(40, 4.0, 1),
        "smooth noise 64 (8 cycles)": lambda: smooth_noise(64, 8.0, 2),
    }
    files = {
        "chest CT (lidc2)": ("vtkjs_lidc2_ct/LIDC2_256x256x133_uint8.raw.gz",
                             lambda p: raw_gz(p, (133, 256, 256), np.uint8, (1.40625, 1.40625, 2.5))),
        "neghip": ("vtk_neghip/neghip_66x66x66_uint8.raw", None),
        "ironprot": ("vtk_ironprot/ironProt.vtk", None),
        "hydrogen": ("vtk_hydrogen/hydrogen_64x64x64_float32.raw", None),
        "head MR": ("vtk_headmr/HeadMRVolume.mhd", None),
        "carotid": ("vtk_carotid/carotid.vtk", None),
        "colin27 ch2": ("debian_mricron_colin27/ch2.nii.gz", None),
        "mni152": ("nilearn_mni152_2009a/mni_icbm152_t1_tal_nlin_sym_09a_converted.nii.gz", None),
        "embryo": ("vtk_embryo/embryo_256x256x256_uint8.raw.gz",
                   lambda p: raw_gz(p, (256, 256, 256), np.uint8, (1.0, 1.0, 1.0))),
    }
    raw_shapes = {"neghip_66x66x66_uint8.raw": ((66, 66, 66), "uint8"),
                  "hydrogen_64x64x64_float32.raw": ((64, 64, 64), "float32")}
    for name, (rel, loader) in files.items():
        path = os.path.join(DATA, rel)
        if not os.path.exists(path):
            print(f"left out: {name} ({rel} not in the data folder)", file=sys.stderr)
            continue
        if loader is not None:
            found[name] = (lambda p=path, f=loader: f(p))
        elif os.path.basename(rel) in raw_shapes:
            shape, dtype = raw_shapes[os.path.basename(rel)]
            found[name] = shared(rel, shape=shape, dtype=dtype, spacing=(1, 1, 1))
        else:
            found[name] = shared(rel)
    return found


def spike_tf(volume, rng):
    """An opacity spike 2 % of the value range wide at a random value between the 55th
    and 99th percentiles of the samples."""
    lo, hi = volume.data_range
    values = np.asarray(volume.data, np.float64).ravel()[::7]
    centre = float(np.percentile(values, rng.uniform(55, 99)))
    width = 0.02 * (hi - lo)
    centre = min(max(centre, lo + width), hi - width)
    return dvr_gl.TransferFunction(
        color=[(lo, 0.2, 0.4, 0.9), (centre, 1.0, 0.9, 0.7), (hi, 0.9, 0.3, 0.2)],
        opacity=[(lo, 0.0), (centre - width / 2, 0.0), (centre, rng.uniform(0.5, 0.95)), (centre + width / 2, 0.0),
                 (hi, 0.0)], unit_distance=volume.min_spacing)


def ramp_tf(volume, rng):
    """A broad ramp: opacity rising linearly from a low percentile to the top of the
    range, colour from blue to white to orange."""
    lo, hi = volume.data_range
    values = np.asarray(volume.data, np.float64).ravel()[::7]
    start = float(np.percentile(values, rng.uniform(20, 60)))
    start = min(max(start, lo + 0.05 * (hi - lo)), lo + 0.8 * (hi - lo))
    return dvr_gl.TransferFunction(
        color=[(lo, 0.1, 0.2, 0.8), (0.5 * (lo + hi), 0.95, 0.95, 0.95), (hi, 1.0, 0.5, 0.1)],
        opacity=[(lo, 0.0), (start, 0.0), (hi, rng.uniform(0.2, 0.6))], unit_distance=volume.min_spacing)


def make_scenes(count, seed, max_size):
    """[(label, scene)], ``count`` of them, cycling the volumes and TF families."""
    rng = np.random.default_rng(seed)
    loaders = volumes()
    loaded = {}
    out = []
    families = ("preset", "spike", "ramp")
    names = list(loaders)
    for i in range(count):
        name = names[i % len(names)]
        if name not in loaded:
            loaded[name] = loaders[name]()
        volume = loaded[name]
        family = families[(i // len(names) + i) % 3]
        tf = {"preset": lambda: auto_preset(volume), "spike": lambda: spike_tf(volume, rng),
              "ramp": lambda: ramp_tf(volume, rng)}[family]()
        azimuth, elevation = rng.uniform(0, 360), rng.uniform(12, 65) * rng.choice([-1, 1])
        zoom = rng.uniform(0.8, 1.5)
        camera = dvr_gl.default_camera(volume, azimuth=azimuth, elevation=elevation, zoom=zoom)
        lit = bool(i % 2)
        small = np.prod(volume.data.shape) <= 80 ** 3 and not name.startswith(GENERATED)
        sizes = SIZES_UNLIT_SMALL_VOLUME if small and not lit else SIZES_OTHERS
        sizes = [s for s in sizes if s <= max_size] or [min(sizes)]
        side = int(rng.choice(sizes))
        height = int(side * rng.choice([1.0, 0.75]))
        scene = dvr_gl.Scene(volume, tf, camera, side, max(height, 64), shading=lit)
        out.append((f"{name}, {family}, {'lit' if lit else 'unlit'}, {scene.width}x{scene.height}, "
                    f"az {azimuth:.0f} el {elevation:.0f} zoom {zoom:.2f}", scene))
    return out


def first_frames(tolerance=1e-3, size=512, repeats=3):
    """The first frame of ``tolerance=E`` against a plain frame (the default step) of the
    same 512x512 image, on the CT head and the chest CT, in a fresh renderer: the plain
    frame cold (shaders compiled) and warm (median of ``repeats``), then the tolerance
    request's first frame (the error model measured), then a new view's (the model kept),
    then that view again (nothing measured). Returns Markdown lines."""
    from dvr_gl.bench.common import chest_ct, chest_tf
    cases = [("CT head (bundled)", bundled.ct_head, lambda v: bundled.ct_head_tf())]
    if os.path.exists(os.path.join(DATA, "vtkjs_lidc2_ct")):
        cases.append(("chest CT", lambda: chest_ct(os.path.join(DATA, "vtkjs_lidc2_ct",
                                                                "LIDC2_256x256x133_uint8.raw.gz")), chest_tf))
    lines = ["| scene | E | plain cold s | plain warm s | tolerance first s (x plain warm) | new view s (x) | "
             "same view again s | steps (voxel) |", "|---|---|---|---|---|---|---|---|"]
    for name, load, make_tf in cases:
        volume = load()
        tf = make_tf(volume)
        views = [dvr_gl.default_camera(volume, azimuth=az, elevation=el) for az, el in ((37, 24), (131, -33))]
        scenes = [dvr_gl.Scene(volume, tf, cam, size, size) for cam in views]
        with dvr_gl.Renderer() as r:
            t0 = time.perf_counter()
            r.render(scenes[0])
            cold = time.perf_counter() - t0
            warm = tol.median_seconds(lambda: r.render(scenes[0]))
            times, steps = [], []
            for scene in (scenes[0], scenes[1], scenes[1]):
                t0 = time.perf_counter()
                r.render(scene, tolerance=tolerance)
                times.append(time.perf_counter() - t0)
                steps.append(f"{r.last_choice.step_voxels:.3g}")
        lines.append(f"| {name} | {tolerance:g} | {cold:.2f} | {warm:.3f} | {times[0]:.2f} ({times[0] / warm:.1f}) | "
                     f"{times[1]:.2f} ({times[1] / warm:.1f}) | {times[2]:.3f} | {', '.join(steps)} |")
        print(lines[-1], flush=True)
    return lines


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenes", type=int, default=42)
    p.add_argument("--seed", type=int, default=31)
    p.add_argument("--first", type=int, default=None, help="run only the first K scenes (a subset)")
    p.add_argument("--max-size", type=int, default=512)
    p.add_argument("--out", default=None, help="Markdown file for the table (default: print only)")
    p.add_argument("--safety", type=float, default=None,
                   help="the pilot's aim as a fraction of E (tolerance.SAFETY), to see what the check holds alone")
    p.add_argument("--first-frames", action="store_true",
                   help="measure only the first frames of tolerance= at 512x512 (CT head, chest CT)")
    args = p.parse_args(argv)
    if args.first_frames:
        lines = []
        for E in TOLERANCES:
            lines += first_frames(E)[0 if not lines else 2:]
        text = "\n".join(lines) + "\n"
        print(text)
        if args.out:
            atomic_write(args.out, text.encode())
        return
    if args.safety is not None:
        tol.SAFETY = args.safety
    scenes = make_scenes(args.scenes, args.seed, args.max_size)
    if args.first is not None:
        scenes = scenes[:args.first]
    rows = []
    started = time.perf_counter()
    for n, (label, scene) in enumerate(scenes, 1):
        t0 = time.perf_counter()
        exact = reference.exact(scene)
        exact_seconds = time.perf_counter() - t0
        with dvr_gl.Renderer() as r:
            for E in TOLERANCES:
                t1 = time.perf_counter()
                image = r.render(scene, tolerance=E)
                seconds = time.perf_counter() - t1
                c = r.last_choice
                got = metrics.rmse(image, exact)
                way = "plain" if not c.preintegrate else ("pre-int." if c.refine == 1 else f"refine {c.refine}")
                bound = getattr(c, "checked_rmse", None)
                rows.append((n, label, E, c.step_voxels, way, got, seconds, bound))
        kept = sum(row[5] <= row[2] for row in rows)
        print(f"[{n}/{len(scenes)}] {label}: exact {exact_seconds:.1f} s; ratios "
              + ", ".join(f"{row[5] / row[2]:.2f}" for row in rows[-3:])
              + f"; kept so far {kept}/{len(rows)}; {time.perf_counter() - started:.0f} s in all", flush=True)
    text = report(rows, args, time.perf_counter() - started)
    print(text)
    if args.out:
        atomic_write(args.out, text.encode())


def report(rows, args, seconds):
    ratios = np.array([row[5] / row[2] for row in rows])
    kept = int(np.sum(ratios <= 1.0))
    lines = [f"`python scripts/validate_tolerance.py --scenes {args.scenes} --seed {args.seed}"
             + (f" --first {args.first}" if args.first else "") + (f" --max-size {args.max_size}"
                                                                 if args.max_size != 512 else "")
             + (f" --safety {args.safety:g}" if args.safety is not None else "") + "`"
             f" ({len(rows) // len(TOLERANCES)} scenes, {seconds / 60:.0f} min; SAFETY {tol.SAFETY:g})", "",
             "| # | scene | requested | step (voxel) | sampling | achieved | achieved / requested | "
             "check's bound / requested | first frame s |",
             "|---|---|---|---|---|---|---|---|---|"]
    for n, label, E, step, way, got, secs, bound in rows:
        mark = "" if got <= E else " **over**"
        checked = "-" if bound is None else f"{bound / E:.2f}"
        lines.append(f"| {n} | {label} | {E:g} | {step:.3g} | {way} | {got:.2e} | {got / E:.2f}{mark} | {checked} | "
                     f"{secs:.2f} |")
    lines += ["", f"Kept {kept} of {len(rows)}; achieved / requested: median {np.median(ratios):.2f}, "
                  f"max {ratios.max():.2f}, min {ratios.min():.2f}."]
    for E in TOLERANCES:
        r = np.array([row[5] / row[2] for row in rows if row[2] == E])
        lines.append(f"- E = {E:g}: kept {int(np.sum(r <= 1))} of {len(r)}, ratio median {np.median(r):.2f}, "
                     f"max {r.max():.2f}")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
