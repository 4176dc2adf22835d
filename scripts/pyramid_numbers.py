"""The numbers of docs/notes/pyramid.md: an OME-Zarr pyramid made from the chest CT of
the shared data, rendered from the command line with ``--tolerance E`` at several E.

    nice python scripts/pyramid_numbers.py [--data ../shared/data] [--out DIR]
        [--tolerances 0.06 0.045 0.03 0.01] [--size 128] [--timing-size 512]

Steps, each timed:

1. the chest CT (256 x 256 x 133 uint8) written as a plain zarr store (chunks of 64),
   and its transfer function, the ``ct_8bit`` preset of the samples, as a JSON file
   (presets other than ``auto`` read every sample, which a store does not offer);
2. per E, the command a user types, run as its own process:
   ``dvr-gl render chest.zarr --spacing ... --tf tf.json --build-pyramid --tolerance E
   --size SIZExSIZE -o chest_E.png`` (the first run writes the pyramid, later ones reuse
   it); its wall time and its report (the level and the error bound it measured);
3. in this process, the same scene: the image ``tolerance=E`` returns at SIZE (on the
   very pixels the choice checked) against ``reference.exact`` of the level-0 samples
   in memory (float64, cached in the cache folder); the frame time of the chosen level
   and step at ``--timing-size`` (median of 5 after one untimed frame) against level 0
   at the default step (half a voxel), and against level 0 alone at the step the grid
   tolerance picks for the same E (``Renderer.tolerance_settings``, no level choice):
   its time and its error against exact, and the bytes of samples each draws from.

A JSON of every number goes to ``--out``.

``--per-brick [--brick-size N]``: only the per-brick choice (``per_brick=True``) against
the one-level choice per E (``per_brick_rows``); ``--seams [--brick-size N]``: only bricks
of two levels in a checkerboard against each level alone (``seam_rows``)."""

import argparse
import gzip
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

CHEST = ("vtkjs_lidc2_ct", "LIDC2_256x256x133_uint8.raw.gz")
SHAPE = (133, 256, 256)
SPACING = (1.40625, 1.40625, 2.5)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=os.path.join(os.path.dirname(__file__), "..", "..", "shared", "data"))
    ap.add_argument("--out", default="pyramid_numbers")
    ap.add_argument("--tolerances", type=float, nargs="+", default=[0.06, 0.045, 0.03, 0.01])
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--timing-size", type=int, default=512)
    ap.add_argument("--per-brick", action="store_true",
                    help="only the per-brick choice against the one-level choice (per_brick_rows)")
    ap.add_argument("--brick-size", type=int, default=32)
    ap.add_argument("--seams", action="store_true",
                    help="only the seams check: bricks of two levels in a checkerboard against each alone")
    args = ap.parse_args(argv)
    if args.per_brick:
        return per_brick_rows(args)
    if args.seams:
        return seam_rows(args)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    import zarr
    import dvr_gl
    from dvr_gl.formats.stores import open_store, pyramid_path
    from dvr_gl.frontends.inputs import first_camera
    from dvr_gl.model.transfer import ct_8bit_preset, save_tf_json
    from dvr_gl.reference.exact import exact
    from dvr_gl.rendering.tolerance import median_seconds

    samples = np.frombuffer(gzip.open(os.path.join(args.data, *CHEST)).read(), np.uint8).reshape(SHAPE)
    store = out / "chest.zarr"
    if not store.exists():
        array = zarr.create_array(str(store), shape=SHAPE, chunks=(64, 64, 64), dtype=np.uint8)
        array[...] = samples
    full = dvr_gl.Volume(samples, spacing=SPACING)
    tf = ct_8bit_preset(full)
    save_tf_json(str(out / "tf.json"), tf)
    pyramid = pyramid_path(str(store))
    record = {"store": str(store), "shape": SHAPE, "spacing": SPACING, "size": args.size, "runs": []}

    spacing = ",".join(f"{v:g}" for v in SPACING)
    for tolerance in args.tolerances:
        command = ["dvr-gl", "render", str(store), "--spacing", spacing, "--tf", str(out / "tf.json"),
                   "--build-pyramid", "--tolerance", f"{tolerance:g}", "--size", f"{args.size}x{args.size}",
                   "-o", str(out / f"chest_{tolerance:g}.png")]
        t0 = time.perf_counter()
        done = subprocess.run(command, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        if done.returncode != 0:
            sys.exit(f"{' '.join(command)} failed:\n{done.stderr}")
        report = [line for line in done.stdout.splitlines() if line.split(" ")[0] in ("pyramid", "rendered", "levels",
                                                                                       "time")]
        print("$ " + " ".join(command).replace(str(out) + "/", ""))
        print("\n".join(report) + f"\n(wall {wall:.2f} s)\n", flush=True)
        record["runs"].append({"tolerance": tolerance, "command": command, "wall_seconds": wall, "report": report})

    volume = open_store(pyramid)
    renderer = dvr_gl.Renderer()
    camera = first_camera(volume)
    scene = dvr_gl.Scene(volume, tf, camera, width=args.size, height=args.size, shading=True)
    t0 = time.perf_counter()
    reference = exact(dvr_gl.Scene(full, tf, camera, width=args.size, height=args.size, shading=True))
    record["exact_seconds"] = time.perf_counter() - t0
    big = scene.replace(width=args.timing_size, height=args.timing_size)
    base = median_seconds(lambda: renderer.render(big, step=0.5 * volume.min_spacing))
    record["level0_half_voxel_seconds"] = base
    rows = []
    for tolerance in args.tolerances:
        t0 = time.perf_counter()
        image = renderer.render(scene, tolerance=tolerance)
        choice_seconds = time.perf_counter() - t0
        choice = renderer.last_choice
        error = float(np.sqrt(np.mean((np.asarray(image, np.float64) - reference) ** 2)))
        from dvr_gl.rendering.pyramid import level_volume
        level_scene = big.replace(volume=level_volume(volume, choice.level))
        frame = median_seconds(lambda: renderer.render(level_scene, step=choice.step, **choice.sampling))
        nz, ny, nx = choice.level_shape
        # level 0 alone, the step chosen by the grid tolerance for the same E
        scene0 = scene.replace(volume=level_volume(volume, 0))
        step0, sampling0 = renderer.tolerance_settings(scene0, tolerance)
        grid_error = float(np.sqrt(np.mean((np.asarray(renderer.render(scene0, step=step0, **sampling0),
                                                       np.float64) - reference) ** 2)))
        big0 = big.replace(volume=scene0.volume)
        grid_frame = median_seconds(lambda: renderer.render(big0, step=step0, **sampling0))
        row = {"tolerance": tolerance, "level": choice.level, "shape": f"{nx}x{ny}x{nz}",
               "step_voxels": choice.step_voxels, "bound": choice.checked_rmse, "exact_rmse": error,
               "choice_seconds": choice_seconds, "frame_seconds": frame,
               "level_bytes": int(nx * ny * nz), "level0_bytes": int(np.prod(SHAPE)),
               "grid_step_voxels": step0 / volume.min_spacing, "grid_exact_rmse": grid_error,
               "grid_frame_seconds": grid_frame, "trials": [list(t) for t in choice.trials]}
        rows.append(row)
        bound = "-" if choice.checked_rmse is None else f"{choice.checked_rmse:.4f}"
        print(f"E {tolerance:g}: level {choice.level} ({row['shape']}), step {choice.step_voxels:.3g} of its voxels, "
              f"bound {bound}, RMSE vs exact {error:.4f}, choice {choice_seconds:.2f} s, "
              f"frame at {args.timing_size}^2 {frame * 1e3:.0f} ms (level 0 at 0.5 voxel: {base * 1e3:.0f} ms); "
              f"level 0 alone at the grid's step {row['grid_step_voxels']:.3g} voxel: RMSE {grid_error:.4f}, "
              f"frame {grid_frame * 1e3:.0f} ms", flush=True)
    record["rows"] = rows
    record["pyramid"] = pyramid
    record["levels"] = [dict(key=lv.key, shape=lv.shape, spacing=lv.spacing, origin=lv.origin) for lv in volume.levels]
    (out / "pyramid_numbers.json").write_text(json.dumps(record, indent=1))
    print(f"exact image at {args.size}x{args.size}: {record['exact_seconds']:.1f} s (0 when cached)")
    print(re.sub(r"\s+", " ", f"wrote {out / 'pyramid_numbers.json'}"))


def per_brick_rows(args):
    """Per E: the one-level choice and the per-brick choice (``per_brick=True``) on the
    pyramid the command-line runs made, each against ``reference.exact`` of level 0 at
    SIZE, the bricks per level, the bytes of samples a frame reads, and the frame time of
    each at ``--timing-size`` (median of 3, the two interleaved, after one untimed frame)."""
    import dvr_gl
    from dvr_gl.formats.stores import open_store, pyramid_path
    from dvr_gl.frontends.inputs import first_camera
    from dvr_gl.model.transfer import load_tf_json
    from dvr_gl.reference.exact import exact
    from dvr_gl.formats.stores import build_pyramid
    from dvr_gl.model.transfer import ct_8bit_preset, save_tf_json
    from dvr_gl.rendering.pyramid import level_volume
    from dvr_gl.techniques.brick_levels import BrickLevels
    from dvr_gl.rendering.tolerance import median_seconds
    import zarr
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    samples = np.frombuffer(gzip.open(os.path.join(args.data, *CHEST)).read(), np.uint8).reshape(SHAPE)
    store = out / "chest.zarr"
    if not store.exists():           # as main() writes them
        array = zarr.create_array(str(store), shape=SHAPE, chunks=(64, 64, 64), dtype=np.uint8)
        array[...] = samples
    if not (out / "tf.json").exists():
        save_tf_json(str(out / "tf.json"), ct_8bit_preset(dvr_gl.Volume(samples, spacing=SPACING)))
    if not os.path.exists(pyramid_path(str(store))):
        build_pyramid(str(store), spacing=SPACING)
    volume = open_store(pyramid_path(str(store)))
    tf = load_tf_json(str(out / "tf.json"))
    camera = first_camera(volume)
    scene = dvr_gl.Scene(volume, tf, camera, width=args.size, height=args.size, shading=True)
    reference = exact(dvr_gl.Scene(dvr_gl.Volume(samples, spacing=SPACING), tf, camera, width=args.size,
                                   height=args.size, shading=True))
    big = scene.replace(width=args.timing_size, height=args.timing_size)
    renderer = dvr_gl.Renderer()
    rows = []

    def rmse(image):
        return float(np.sqrt(np.mean((np.asarray(image, np.float64) - reference) ** 2)))

    for tolerance in args.tolerances:
        single_image = renderer.render(scene, tolerance=tolerance)
        single = renderer.last_choice
        t0 = time.perf_counter()
        image = renderer.render(scene, tolerance=tolerance, per_brick=True, brick_size=args.brick_size)
        seconds = time.perf_counter() - t0
        chosen = renderer.last_choice
        level_scene = big.replace(volume=level_volume(volume, single.level))
        single_frame = median_seconds(lambda: renderer.render(level_scene, step=single.step, **single.sampling),
                                      repeats=1)
        nz, ny, nx = single.level_shape
        row = {"tolerance": tolerance, "single_level": single.level, "single_exact_rmse": rmse(single_image),
               "single_frame_seconds": single_frame, "single_bytes": int(nx * ny * nz),
               "mixed": chosen.mixed, "counts": list(chosen.counts), "bound": chosen.checked_rmse,
               "exact_rmse": rmse(image), "choice_seconds": seconds, "step_voxels": chosen.step_voxels,
               "trials": [[t, list(c), b] for t, c, b in chosen.trials]}
        if chosen.mixed:     # a fresh drawer of the same levels: what one frame reads from the store
            drawer = BrickLevels([level_volume(volume, k) for k in range(len(volume.levels))], dict(chosen.chosen))
            frame_scene = big.replace(volume=level_volume(volume, 0))
            options = dict(chosen.sampling, brick_size=args.brick_size, brick_levels=drawer)
            renderer.render(frame_scene, step=chosen.step, **options)
            row["mixed_store_bytes"] = int(drawer.cache.bytes_loaded)
            row["mixed_texture_bytes_per_level"] = list(drawer.bytes)
            # interleaved with the one-level frame: the machine's load moves both alike
            mixed_times, single_times = [], []
            for _ in range(3):
                t1 = time.perf_counter()
                renderer.render(frame_scene, step=chosen.step, **options)
                mixed_times.append(time.perf_counter() - t1)
                t1 = time.perf_counter()
                renderer.render(level_scene, step=single.step, **single.sampling)
                single_times.append(time.perf_counter() - t1)
            row["frame_seconds"] = float(np.median(mixed_times))
            row["single_frame_seconds"] = float(np.median(single_times))
        rows.append(row)
        print(json.dumps({k: v for k, v in row.items() if k != "trials"}), flush=True)
        print("   trials (threshold, bricks per level, bound):",
              "; ".join(f"{t:.3g} {tuple(c)} {b:.4f}" for t, c, b in chosen.trials), flush=True)
    (out / "pyramid_per_brick.json").write_text(json.dumps({"brick_size": args.brick_size, "size": args.size,
                                                            "timing_size": args.timing_size, "rows": rows}, indent=1))


def seam_rows(args):
    """The seams between levels: level 0's bricks (``--brick-size``) of two levels a and b
    in a checkerboard, against every brick at a and every brick at b (the same passes and
    step, 2 level-0 voxels), each against ``reference.exact`` at SIZE. A seam that lost or
    doubled samples would put the checkerboard's error above both; it lies between them."""
    import dvr_gl
    from dvr_gl.formats.stores import open_store, pyramid_path
    from dvr_gl.frontends.inputs import first_camera
    from dvr_gl.model.transfer import load_tf_json
    from dvr_gl.reference.exact import exact
    from dvr_gl.rendering.pyramid import level_volume
    from dvr_gl.techniques.bricks import partition
    from dvr_gl.techniques.brick_levels import BrickLevels
    out = Path(args.out)
    samples = np.frombuffer(gzip.open(os.path.join(args.data, *CHEST)).read(), np.uint8).reshape(SHAPE)
    volume = open_store(pyramid_path(str(out / "chest.zarr")))      # made by --per-brick or main()
    tf = load_tf_json(str(out / "tf.json"))
    camera = first_camera(volume)
    scene = dvr_gl.Scene(level_volume(volume, 0), tf, camera, width=args.size, height=args.size, shading=True)
    reference = exact(dvr_gl.Scene(dvr_gl.Volume(samples, spacing=SPACING), tf, camera, width=args.size,
                                   height=args.size, shading=True))
    levels = [level_volume(volume, k) for k in range(len(volume.levels))]
    renderer = dvr_gl.Renderer()
    step = 2 * volume.min_spacing
    bricks = partition(volume.shape, args.brick_size, 0)
    rows = []
    for a in range(len(levels) - 1):
        b = a + 1
        errors = {}
        for name, chosen in (("a", {}), ("b", {br.index: b for br in bricks}),
                             ("checker", {br.index: (b if sum(br.index) % 2 else a) for br in bricks})):
            drawer = BrickLevels(levels, chosen, default=a)
            image = renderer.render(scene, step=step, brick_size=args.brick_size, brick_levels=drawer)
            errors[name] = float(np.sqrt(np.mean((np.asarray(image, np.float64) - reference) ** 2)))
        rows.append({"levels": [a, b], **errors})
        print(f"levels {a}/{b}, bricks of {args.brick_size}: RMSE vs exact all {a} {errors['a']:.4f}, all {b} "
              f"{errors['b']:.4f}, checkerboard {errors['checker']:.4f}", flush=True)
    (out / f"pyramid_seams_{args.brick_size}.json").write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
