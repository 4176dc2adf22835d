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

A JSON of every number goes to ``--out``."""

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
    args = ap.parse_args(argv)
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


if __name__ == "__main__":
    main()
