"""The numbers of docs/notes/big_volume.md: a volume generated chunk by chunk by a dask
function (never materialised) rendered by the ray caster through its bricks.

    nice python scripts/big_volume_numbers.py [--shape 2048 4096 4096] [--size 512]
        [--error-size 64] [--brick 128] [--memory 4GiB] [--all-bricks] [--out DIR]

The shape is (nz, ny, nx); the default is 32 GiB of uint8 samples. A small shape
(``--shape 128 256 256``) runs in seconds. Phases, each timed, with the peak RSS after it:

1. the brick summary (per-brick min/max, one pass over the samples; kept in the cache
   folder, so a second run reads it from there: run with a fresh ``DVR_GL_CACHE`` for the
   first-time figure);
2. the frame at ``--size`` (skipping the bricks the TF leaves empty), written as a PNG;
3. the error at ``--error-size``: the ray caster at the default step and at half of it,
   each with and without early ray termination (four frames on one renderer), and the
   exact image of the same samples (``reference.exact_lazy``, reading only the chunks
   its rays cross); the step's error estimated from the two steps (order 2);
4. with ``--all-bricks``: the same frame with every brick read (``skip_empty=False``),
   against phase 2's reads and time.

The samples: noise (0..31, uniform, from a per-chunk seed) everywhere, plus a few
Gaussian blobs and a spherical shell; the TF is transparent below 48, so noise alone is
invisible and most bricks are empty. A JSON of every number goes to ``--out``."""

import argparse
import gc
import hashlib
import inspect
import json
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

FULL = (2048, 4096, 4096)
SPACING = (1.0, 1.0, 2.0)          # x, y, z: the box 4096 x 4096 x 4096 world units at full size
THRESHOLD = 48                     # the TF's opacity is 0 below (noise stays below 32)


def features(shape):
    """(kind, centre (x, y, z) in world units, size, peak) scaled to the box of ``shape``."""
    nz, ny, nx = shape
    box = np.array([(nx - 1) * SPACING[0], (ny - 1) * SPACING[1], (nz - 1) * SPACING[2]])
    scale = float(box.min())
    return [("blob", box * (0.32, 0.37, 0.44), 0.061 * scale, 210.0),
            ("blob", box * (0.78, 0.22, 0.25), 0.037 * scale, 190.0),
            ("blob", box * (0.20, 0.80, 0.73), 0.044 * scale, 200.0),
            ("shell", box * (0.66, 0.63, 0.54), (0.17 * scale, 0.010 * scale), 180.0)]


def reach(feature):
    """World distance from the centre beyond which a feature adds less than 1."""
    kind, _, size, peak = feature
    sigma = size if kind == "blob" else size[1]
    spread = sigma * np.sqrt(2 * np.log(peak))
    return spread if kind == "blob" else size[0] + spread


def visible_share(shape):
    """An upper bound of the share of the box where the TF's opacity can be above 0:
    there the features' sum reaches THRESHOLD - 31, so one of the four reaches a quarter
    of that; the union of those balls and shells over the box's volume."""
    nz, ny, nx = shape
    box = np.array([(nx - 1) * SPACING[0], (ny - 1) * SPACING[1], (nz - 1) * SPACING[2]])
    floor = (THRESHOLD - 31) / 4.0
    total = 0.0
    for kind, _, size, peak in features(shape):
        sigma = size if kind == "blob" else size[1]
        w = sigma * np.sqrt(2 * np.log(peak / floor))
        if kind == "blob":
            total += 4 / 3 * np.pi * w ** 3
        else:
            total += 4 / 3 * np.pi * ((size[0] + w) ** 3 - max(size[0] - w, 0.0) ** 3)
    return total / float(np.prod(box))


def make_generator(shape, chunk):
    feats = [(f, reach(f)) for f in features(shape)]
    sx, sy, sz = SPACING

    def generate(block, block_info=None):
        (z0, z1), (y0, y1), (x0, x1) = block_info[None]["array-location"]
        seed = (z0 // chunk, y0 // chunk, x0 // chunk)
        size = (z1 - z0, y1 - y0, x1 - x0)
        out = (np.frombuffer(np.random.default_rng(seed).bytes(int(np.prod(size))), np.uint8) >> 3).reshape(size)
        lo = np.array([x0 * sx, y0 * sy, z0 * sz])
        hi = np.array([(x1 - 1) * sx, (y1 - 1) * sy, (z1 - 1) * sz])
        field = None
        for (kind, centre, size, peak), r in feats:
            if np.linalg.norm(np.clip(centre, lo, hi) - centre) > r:     # the chunk is beyond its reach
                continue
            z, y, x = np.ogrid[z0:z1, y0:y1, x0:x1]
            d2 = (((x * sx - centre[0]) ** 2).astype(np.float32) + ((y * sy - centre[1]) ** 2).astype(np.float32)
                  + ((z * sz - centre[2]) ** 2).astype(np.float32))
            if kind == "blob":
                term = peak * np.exp(-d2 / np.float32(2 * size ** 2))
            else:
                radius, sigma = size
                term = peak * np.exp(-((np.sqrt(d2) - np.float32(radius)) ** 2) / np.float32(2 * sigma ** 2))
            field = term if field is None else field + term
        if field is not None:
            out = np.minimum(out + field, 255).astype(np.uint8)
        return out

    return generate


def lazy_volume(shape, chunk):
    import dask.array as da
    from dvr_gl.model.lazy_volume import LazyVolume
    template = da.zeros(shape, np.uint8, chunks=chunk)
    # named by the generator's code, the shape and the chunks: the summary kept in the
    # cache folder is found again by the next run, and a change to the samples makes a new one
    code = "".join(inspect.getsource(f) for f in (features, reach, make_generator)) + repr((THRESHOLD, SPACING))
    source = hashlib.sha256(code.encode()).hexdigest()[:16]
    name = f"big-volume-{source}-{'x'.join(map(str, shape))}-{chunk}"
    array = da.map_blocks(make_generator(shape, chunk), template, dtype=np.uint8, name=name)
    return LazyVolume(array, spacing=SPACING)


def transfer_function(shape):
    """Transparent below THRESHOLD; opacity per 1/128 of the box's smallest side, so that
    the picture is alike at every shape."""
    import dvr_gl
    nz, ny, nx = shape
    side = min((nx - 1) * SPACING[0], (ny - 1) * SPACING[1], (nz - 1) * SPACING[2])
    return dvr_gl.TransferFunction(
        color=[(float(THRESHOLD), 0.95, 0.45, 0.15), (140.0, 0.95, 0.85, 0.55), (255.0, 0.55, 0.8, 1.0)],
        opacity=[(0.0, 0.0), (float(THRESHOLD), 0.0), (120.0, 0.04), (255.0, 0.3)], unit_distance=side / 128)


def peak_rss():
    """Peak resident set of this process so far, bytes."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def counting(volume):
    """Count the store reads (calls, bytes, seconds: making the samples) of ``volume``."""
    counts = {"reads": 0, "bytes": 0, "seconds": 0.0}
    read = volume.read

    def counted(*block):
        start = time.perf_counter()
        data = read(*block)
        counts["seconds"] += time.perf_counter() - start
        counts["reads"] += 1
        counts["bytes"] += int(data.nbytes)
        return data
    volume.read = counted
    return counts


def frame(volume, scene, memory, brick, renderer=None, **options):
    """(image, seconds, numbers) of one frame on ``renderer``, else on a fresh one (a
    cold brick cache)."""
    import dvr_gl
    from dvr_gl.techniques import bricks
    from dvr_gl.util.memory import parse_bytes
    counts = counting(volume)
    own = renderer is None
    renderer = dvr_gl.Renderer() if own else renderer
    try:
        start = time.perf_counter()
        image = np.asarray(renderer.render(scene, "raycast", memory=memory, brick_size=brick, **options))
        seconds = time.perf_counter() - start
        textures = bricks.lazy_textures(renderer, volume, parse_bytes(memory), bricks.filter_is_exact(renderer))
        numbers = {"seconds": seconds, "bricks_read": textures.bricks_read, "store_reads": counts["reads"],
                   "store_bytes": counts["bytes"], "store_seconds": counts["seconds"], "cache_misses": textures.cache.misses,
                   "cache_hits": textures.cache.hits, "by_chunks": textures.by_chunks}
    finally:
        if own:
            renderer.release()
            gc.collect()            # its brick cache goes now, not in the next frame's peak
        del volume.read
    return image, seconds, numbers


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--shape", type=int, nargs=3, default=FULL, metavar=("NZ", "NY", "NX"))
    parser.add_argument("--chunk", type=int, default=128)
    parser.add_argument("--brick", type=int, default=128)
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--error-size", type=int, default=64)
    parser.add_argument("--memory", default="4GiB")
    parser.add_argument("--all-bricks", action="store_true")
    parser.add_argument("--skip-error", action="store_true")
    parser.add_argument("--out", default="big_volume_out")
    args = parser.parse_args(argv)

    import dask
    import dvr_gl
    from dvr_gl import metrics
    from dvr_gl.formats import save_png
    from dvr_gl.model.lazy_volume import brick_summary, summary_path
    from dvr_gl.reference.exact_lazy import exact_lazy
    from dvr_gl.techniques import bricks
    from dvr_gl.util.memory import format_bytes

    dask.config.set(scheduler="synchronous")     # one chunk at a time, in this thread
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    shape = tuple(args.shape)
    volume = lazy_volume(shape, args.chunk)
    result = {"shape": shape, "bytes": volume.nbytes, "chunk": args.chunk, "brick": args.brick,
              "memory": args.memory, "spacing": SPACING, "cpu_count": os.cpu_count()}
    print(f"volume {shape} uint8: {format_bytes(volume.nbytes)}, chunks {args.chunk}^3, bricks {args.brick}^3",
          file=sys.stderr)
    result["rss_start"] = peak_rss()

    # 1. the summary (made once, then read from the cache folder)
    cached = os.path.exists(summary_path(volume, args.brick, 2))
    start = time.perf_counter()
    summary = brick_summary(volume, args.brick, 2)
    result["summary"] = {"seconds": time.perf_counter() - start, "from_cache": cached,
                         "grid": summary.grid, "rss_peak": peak_rss()}
    tf = transfer_function(shape)
    camera = dvr_gl.default_camera(volume, azimuth=30, elevation=20, zoom=1.1)
    scene = dvr_gl.Scene(volume, tf, camera, width=args.size, height=args.size)
    plan_lut = __import__("dvr_gl.techniques.raycast", fromlist=["make_plan"]).make_plan(
        scene, brick_size=args.brick, memory=args.memory).lut
    occupied = bricks.brick_occupancy((summary.lo.ravel(), summary.hi.ravel()), plan_lut)
    result["bricks"] = {"total": int(occupied.size), "occupied": int(occupied.sum()),
                        "visible_share_bound": visible_share(shape)}
    print(f"summary {result['summary']['seconds']:.1f} s ({'cache' if cached else 'made'}); "
          f"{occupied.sum()} of {occupied.size} bricks occupied", file=sys.stderr)
    dump(out, result)

    # 2. the frame
    image, seconds, numbers = frame(volume, scene, args.memory, args.brick)
    numbers["rss_peak"] = peak_rss()
    result["frame"] = numbers
    save_png(str(out / f"big_volume_{args.size}.png"), image, background=(0.0, 0.0, 0.0))
    print(f"frame {args.size}x{args.size}: {seconds:.1f} s, {numbers}", file=sys.stderr)
    dump(out, result)

    # 3. the error at the error size against the exact image of the same samples
    if not args.skip_error:
        small = scene.replace(width=args.error_size, height=args.error_size)
        step = 0.5 * volume.min_spacing
        renderer = dvr_gl.Renderer()          # one brick cache for the four frames
        images, seconds = {}, {}
        for name, options in (("default", dict(step=step)), ("half_step", dict(step=step / 2)),
                              ("no_ert", dict(step=step, ert_transmittance=0.0)),
                              ("no_ert_half_step", dict(step=step / 2, ert_transmittance=0.0))):
            images[name], seconds[name], _ = frame(volume, small, args.memory, args.brick, renderer, **options)
        renderer.release()
        stats = {}
        start = time.perf_counter()
        reference = exact_lazy(small, stats=stats)
        t_exact = time.perf_counter() - start
        np.save(out / f"big_volume_exact_{args.error_size}.npy", reference)
        step_error = metrics.rmse(images["no_ert"], images["no_ert_half_step"]) * 4.0 / 3.0
        result["error"] = {"size": args.error_size, "step": step, "ert_transmittance": 1e-3,
                           **{f"rmse_{k}": metrics.rmse(v, reference) for k, v in images.items()},
                           **{f"max_abs_{k}": metrics.max_abs_error(v, reference) for k, v in images.items()},
                           "step_error_estimate": step_error, "bound": step_error + 1e-3,
                           "frame_seconds": seconds, "exact_seconds": t_exact, **stats, "rss_peak": peak_rss()}
        save_png(str(out / f"big_volume_exact_{args.error_size}.png"), reference, background=(0.0, 0.0, 0.0))
        print(f"error {result['error']}", file=sys.stderr)
        dump(out, result)

    # 4. every brick read, against the frame that skips the empty ones
    if args.all_bricks:
        _, seconds, numbers = frame(volume, scene, args.memory, args.brick, skip_empty=False)
        numbers["rss_peak"] = peak_rss()
        result["all_bricks"] = numbers
        print(f"all bricks {args.size}x{args.size}: {seconds:.1f} s, {numbers}", file=sys.stderr)

    result["rss_peak"] = peak_rss()
    print(dump(out, result))


def dump(out, result):
    """Write the numbers so far (a long run leaves them phase by phase)."""
    text = json.dumps(result, indent=1, default=lambda v: v.tolist() if hasattr(v, "tolist") else str(v))
    (out / "big_volume.json").write_text(text)
    return text


if __name__ == "__main__":
    main()
