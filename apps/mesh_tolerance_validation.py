"""Requested against achieved error of ``Renderer.render(mesh_scene, "tetra", tolerance=E)``
on the bench's four meshes and two made here, at 128x128 against the exact image, beside
every fixed way of ``dvr_gl.rendering.mesh_tolerance.WAYS``: the choice's frame time
against that of the fastest fixed way that meets E (frames timed with the view turning
0.5 degree a frame, median of 5). Prints one JSON row per (mesh, E) and a Markdown table.

    LP_NUM_THREADS=2 python apps/mesh_tolerance_validation.py [--meshes ball,sphere,...] [--size 128]

Meshes: ``ball``, ``bluntfin``, ``combustor``, ``loxpost`` (``dvr_gl.bench.common.MESHES``);
``sphere``, the Delaunay mesh of 20,000 random points in the unit ball (a fifth on the
sphere) with the field sin(3x) cos(2y) + z^2; ``grid_tets``, the bundled synthetic volume
at every second sample (32^3) split into tetrahedra (``cell_split.grid_to_tets``).
"""

import argparse
import json
import statistics
import time

import numpy as np

import dvr_gl
from dvr_gl import Scene, TetMesh, Volume
from dvr_gl import data as bundled
from dvr_gl.bench.common import load_mesh_dataset, mesh_tf
from dvr_gl.model import cell_split
from dvr_gl.model.camera import default_camera
from dvr_gl.reference.exact import exact
from dvr_gl.rendering import mesh_tolerance as mt

TOLERANCES = (1e-2, 3e-3, 1e-3)
REPEATS = 5


def load(name):
    if name == "sphere":
        rng = np.random.default_rng(7)
        n = 20000
        d = rng.normal(size=(n, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        p = d * np.where(np.arange(n) < n // 5, 1.0, rng.random(n) ** (1 / 3))[:, None]
        mesh = TetMesh.from_points(p, np.sin(3 * p[:, 0]) * np.cos(2 * p[:, 1]) + p[:, 2] ** 2)
        return mesh, mesh_tf(mesh)
    if name == "grid_tets":
        v = bundled.synthetic()
        small = Volume(np.ascontiguousarray(v.data[::2, ::2, ::2]), spacing=2 * v.spacing, origin=v.origin)
        return cell_split.grid_to_tets(small), bundled.synthetic_tf()
    return load_mesh_dataset(name)


def camera(mesh, turn=0.0):
    return default_camera(mesh, azimuth=30.0 + turn, elevation=20.0)


def frame_ms(renderer, scene, arguments):
    """Median ms of REPEATS frames, the view turning 0.5 degree a frame, after one untimed."""
    times = []
    for i in range(-1, REPEATS):
        s, technique, step, options = arguments(scene.replace(camera=camera(scene.volume, 0.5 * (i + 1))))
        t0 = time.perf_counter()
        renderer.render(s, technique, step=step, **options)
        if i >= 0:
            times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times)


def measure(name, size):
    mesh, tf = load(name)
    scene = Scene(mesh, tf, camera(mesh), size, size)
    truth = exact(scene)
    fixed = {}
    with dvr_gl.Renderer() as r:
        for way in [w for w in mt.available_ways() if mt.fits(w, mesh)]:
            s, technique, step, options = mt.way_arguments(scene, way, r.tables)
            image = r.render(s, technique, step=step, **options)
            fixed[way.label] = {"rmse": float(np.sqrt(np.mean((image - truth) ** 2))),
                                "ms": frame_ms(r, scene, lambda v, way=way: mt.way_arguments(v, way, r.tables))}
    rows = []
    with dvr_gl.Renderer() as r:                 # a fresh renderer: the pilot starts from nothing
        for tolerance in TOLERANCES:
            t0 = time.perf_counter()
            image = r.render(scene, "tetra", tolerance=tolerance)
            first = time.perf_counter() - t0
            c = r.last_choice
            meets = {k: v for k, v in fixed.items() if v["rmse"] <= tolerance}
            best = min(meets, key=lambda k: meets[k]["ms"]) if meets else None
            rows.append(dict(mesh=name, tets=mesh.n_tets, E=tolerance, choice=c.label, pilot_rmse=c.pilot_rmse,
                             achieved=float(np.sqrt(np.mean((image - truth) ** 2))), first_s=first,
                             choice_ms=fixed[c.label]["ms"], fastest=best,
                             fastest_ms=meets[best]["ms"] if best else None, fixed=fixed))
            print(json.dumps({k: v for k, v in rows[-1].items() if k != "fixed"}), flush=True)
    return rows


def table(rows):
    lines = ["| mesh | tets | E | chosen | pilot RMSE | achieved | first frame s | chosen ms | fastest fixed within E | its ms | ratio |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['mesh']} | {r['tets']:,} | {r['E']:g} | {r['choice']} | {r['pilot_rmse']:.2g} | "
                     f"{r['achieved']:.2g} | {r['first_s']:.1f} | {r['choice_ms']:.0f} | {r['fastest']} | "
                     f"{r['fastest_ms']:.0f} | {r['choice_ms'] / r['fastest_ms']:.2f} |")
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--meshes", default="ball,bluntfin,combustor,loxpost,sphere,grid_tets")
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--json", help="write the rows (with every fixed way's error and time) here")
    args = parser.parse_args()
    rows = [row for name in args.meshes.split(",") for row in measure(name.strip(), args.size)]
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)
    print(table(rows))


if __name__ == "__main__":
    main()
