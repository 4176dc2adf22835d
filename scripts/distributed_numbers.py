"""The numbers of docs/notes/distributed.md: 1, 2 and 4 Dask worker processes rendering a
volume generated chunk by chunk by a dask function (never materialised), sort-last
(``dvr_gl.frontends.distributed``).

    nice python scripts/distributed_numbers.py [--shape 1024 1024 1024] [--workers 1 2 4]
        [--size 512] [--brick 128] [--frames 3] [--memory 2GiB] [--out DIR]

The volume: uniform noise 0..31 plus four Gaussian blobs, made chunk by chunk by a dask
function (the generator goes to the workers with the graph, and each worker makes the
chunks its bricks need); the TF is transparent below 48, so most bricks are empty and never
read. ``--shape`` (nz, ny, nx) points the script at any size, 2048 x 4096 x 4096 included. For each worker count a
LocalCluster of that many processes (one thread each; llvmpipe threads: the cores shared
out) renders one frame to warm up (compiling, reading the bricks into each worker's
cache) and then ``--frames`` frames, timed on the client (tasks, transfers and the
composite). Reported per count: the first and the median frame time, the largest
difference from the one-worker image (with early ray termination off, so that the
difference is the over composite's rounding alone; and with it on at 1e-3), the bytes
each frame moved (partial images back to the client, task arguments out, the volume's
graph scattered once; and dask's own count of the bytes the workers sent), the workers'
peak RSS, and the CPU seconds the workers used per frame (all of them, and the busiest:
on a machine shared with other work these say more than the wall time). A JSON of every number and a PNG go to ``--out``."""

import argparse
import json
import os
import resource
import statistics
import sys
import time
from pathlib import Path

import numpy as np

BLOBS = ((0.32, 0.37, 0.44, 0.06, 210.0), (0.78, 0.22, 0.25, 0.04, 190.0), (0.20, 0.80, 0.73, 0.05, 200.0),
         (0.62, 0.64, 0.56, 0.12, 150.0))        # x, y, z centre and width (fractions of the box), peak
THRESHOLD = 48                                   # the TF is transparent below (the noise stays below 32)


def make_generator(shape, chunk):
    """The samples of one chunk: uniform noise 0..31 (seeded by the chunk's index) plus
    Gaussian blobs, in uint8; a function of the chunk's place alone, so any process makes
    the same samples."""
    nz, ny, nx = shape
    scale = min(shape)

    def generate(block, block_info=None):
        (z0, z1), (y0, y1), (x0, x1) = block_info[None]["array-location"]
        out = np.random.default_rng((z0 // chunk, y0 // chunk, x0 // chunk)).integers(
            0, 32, (z1 - z0, y1 - y0, x1 - x0), dtype=np.uint8)
        z, y, x = np.ogrid[z0:z1, y0:y1, x0:x1]
        field = np.zeros(out.shape, np.float32)
        for cx, cy, cz, width, peak in BLOBS:
            sigma = width * scale
            d2 = (((x - cx * nx) ** 2).astype(np.float32) + ((y - cy * ny) ** 2).astype(np.float32)
                  + ((z - cz * nz) ** 2).astype(np.float32))
            field += peak * np.exp(-d2 / np.float32(2 * sigma * sigma))
        return np.minimum(out + field, 255).astype(np.uint8)

    return generate


def lazy_volume(shape, chunk):
    import dask.array as da
    from dvr_gl.model.lazy_volume import LazyVolume
    template = da.zeros(shape, np.uint8, chunks=chunk)
    array = da.map_blocks(make_generator(shape, chunk), template, dtype=np.uint8,
                          name=f"distributed-numbers-{shape}-{chunk}")
    return LazyVolume(array)


def transfer_function():
    import dvr_gl
    return dvr_gl.TransferFunction(
        color=[(float(THRESHOLD), 0.95, 0.55, 0.2), (140.0, 0.95, 0.85, 0.6), (255.0, 0.6, 0.8, 1.0)],
        opacity=[(0.0, 0.0), (float(THRESHOLD), 0.0), (120.0, 0.02), (255.0, 0.2)])


def worker_numbers(client):
    """Per worker: dask's total of bytes it sent to others (the client included), its peak
    RSS and the CPU seconds its process has used (all its threads, llvmpipe's included)."""
    def numbers(dask_worker):
        usage = resource.getrusage(resource.RUSAGE_SELF)
        return {"sent": int(getattr(dask_worker, "transfer_outgoing_bytes_total", 0)),
                "rss_peak": usage.ru_maxrss * 1024, "cpu": usage.ru_utime + usage.ru_stime}
    return client.run(numbers)


def run(count, scene, args, reference):
    from dvr_gl.frontends.distributed import ClusterRenderer
    start = time.perf_counter()
    with ClusterRenderer(workers=count) as renderer:
        startup = time.perf_counter() - start
        options = dict(brick_size=args.brick, memory=args.memory)
        t = time.perf_counter()
        renderer.render(scene, ert_transmittance=0.0, **options)       # warm: compile, read, upload
        first = time.perf_counter() - t
        first_record = renderer.last_frame
        before = worker_numbers(renderer.client)
        seconds, image = [], None
        for _ in range(args.frames):
            t = time.perf_counter()
            image = renderer.render(scene, ert_transmittance=0.0, **options)
            seconds.append(time.perf_counter() - t)
        after = worker_numbers(renderer.client)
        record = renderer.last_frame
        ert_image = renderer.render(scene, ert_transmittance=1e-3, **options)
        sent = sum(after[w]["sent"] - before[w]["sent"] for w in after) / args.frames
        cpu = sum(after[w]["cpu"] - before[w]["cpu"] for w in after) / args.frames
        slowest = max(after[w]["cpu"] - before[w]["cpu"] for w in after) / args.frames
        result = {"workers": count, "startup_s": startup, "first_s": first, "frame_s": statistics.median(seconds),
                  "frames_s": seconds, "worker_cpu_s": cpu, "busiest_worker_cpu_s": slowest, "shares": record.shares, "axis": "zyx"[record.axis],
                  "brick": record.brick_size, "windows": record.windows,
                  "partial_bytes": record.partial_bytes, "task_bytes": record.task_bytes,
                  "scattered_bytes_once": first_record.scattered_bytes, "dask_sent_bytes_per_frame": sent,
                  "worker_rss_peak": [after[w]["rss_peak"] for w in sorted(after)]}
    if reference is not None:
        result["max_diff_vs_1"] = float(np.abs(image - reference[0]).max())
        result["max_diff_vs_1_ert"] = float(np.abs(ert_image - reference[1]).max())
    return result, (image, ert_image)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--shape", type=int, nargs=3, default=(1024, 1024, 1024), metavar=("NZ", "NY", "NX"))
    parser.add_argument("--chunk", type=int, default=128)
    parser.add_argument("--brick", type=int, default=128)
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--workers", type=int, nargs="+", default=(1, 2, 4))
    parser.add_argument("--frames", type=int, default=3)
    parser.add_argument("--memory", default="2GiB", help="each worker's brick budget")
    parser.add_argument("--out", default="distributed_out")
    args = parser.parse_args(argv)

    import dvr_gl
    from dvr_gl.formats import save_png
    from dvr_gl.model.lazy_volume import brick_summary
    from dvr_gl.util.memory import format_bytes

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    shape = tuple(args.shape)
    volume = lazy_volume(shape, args.chunk)
    start = time.perf_counter()
    brick_summary(volume, args.brick, 2)          # once, on the client (kept in the cache folder)
    summary_s = time.perf_counter() - start
    camera = dvr_gl.default_camera(volume, azimuth=30, elevation=20, zoom=1.1)
    scene = dvr_gl.Scene(volume, transfer_function(), camera, width=args.size, height=args.size)
    print(f"volume {shape} uint8 ({format_bytes(volume.nbytes)}), chunks {args.chunk}^3, bricks {args.brick}^3, "
          f"{args.size}x{args.size}; summary {summary_s:.1f} s", file=sys.stderr)
    results, reference = [], None
    for count in args.workers:
        result, images = run(count, scene, args, reference)
        if reference is None:
            reference = images
            save_png(str(out / f"distributed_{args.size}.png"), images[0], background=(0.0, 0.0, 0.0))
        results.append(result)
        print(json.dumps({k: v for k, v in result.items() if k not in ("windows", "frames_s")}), file=sys.stderr)
    report = {"shape": shape, "bytes": volume.nbytes, "chunk": args.chunk, "brick": args.brick, "size": args.size,
              "memory": args.memory, "frames": args.frames, "cpu_count": os.cpu_count(), "summary_s": summary_s,
              "runs": results}
    (out / "distributed.json").write_text(json.dumps(report, indent=1))
    print("| workers | shares (axis) | first frame | frame (median) | workers' CPU a frame (all / busiest) | "
          "max diff vs 1 (ERT off / 1e-3) | partials back | tasks out | scattered once | dask: workers sent | "
          "worker peak RSS |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in results:
        diff = (f"{r['max_diff_vs_1']:.2g} / {r['max_diff_vs_1_ert']:.2g}" if "max_diff_vs_1" in r else "(reference)")
        print(f"| {r['workers']} | {r['shares']} ({r['axis']}) | {r['first_s']:.2f} s | {r['frame_s']:.2f} s | "
              f"{r['worker_cpu_s']:.2f} s / {r['busiest_worker_cpu_s']:.2f} s | {diff} | "
              f"{format_bytes(r['partial_bytes'])} | {format_bytes(r['task_bytes'])} | "
              f"{format_bytes(r['scattered_bytes_once'])} | {format_bytes(r['dask_sent_bytes_per_frame'])} | "
              f"{format_bytes(max(r['worker_rss_peak']))} |")


if __name__ == "__main__":
    main()
