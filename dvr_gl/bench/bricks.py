"""Bricked against single-texture rendering: the largest difference and the frame time
(``python -m dvr_gl.bench.bricks [--technique raycast|slice3d] [--size 512] [--repeats 5]
[--data DIR]``; docs/guide/bricks.md).

For the bench's CT head and chest CT (``common.datasets``: their transfer functions and
oblique views; the chest where the data folder has it), at the default step: the single
texture and each brick size rendered in turn ``repeats`` times after a warm-up frame
each, the medians, the largest difference of any channel against the single texture,
and the bricks drawn (empty ones are never made) with their texels per sample."""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np


def scenes(data_dir, size):
    """(name, Scene) pairs: the bench's CT head and chest CT (``common.datasets``, their
    oblique views), the chest where the data folder has it."""
    from ..model.scene import Scene
    from .common import CHEST_FILE, datasets
    names = ["head"] + (["chest"] if os.path.exists(os.path.join(data_dir, CHEST_FILE)) else [])
    return [(f"{name} {'x'.join(map(str, volume.shape[::-1]))} {volume.data.dtype}",
             Scene(volume, tf, camera, width=size, height=size))
            for name, volume, tf, camera in datasets(names, os.path.join(data_dir, CHEST_FILE))]


def timed(renderer, scene, repeats, configs):
    """Per option set in ``configs``: (image, median seconds of ``repeats`` frames), the
    sets taken in turn each round (so that other load on the machine falls on all alike),
    after one warm-up frame each."""
    images = [renderer.render(scene, **options) for options in configs]
    times = [[] for _ in configs]
    for _ in range(repeats):
        for options, out in zip(configs, times):
            start = time.perf_counter()
            renderer.render(scene, **options)
            out.append(time.perf_counter() - start)
    return [(image, statistics.median(t)) for image, t in zip(images, times)]


def main(argv=None):
    from ..rendering.renderer import Renderer
    parser = argparse.ArgumentParser(prog="python -m dvr_gl.bench.bricks", description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--bricks", type=int, nargs="+", default=[32, 64])
    parser.add_argument("--technique", choices=("raycast", "slice3d"), default="raycast",
                        help="the ray caster (default) or 3-D texture slicing")
    from .common import DEFAULT_DATA_DIR
    parser.add_argument("--data", default=os.environ.get("DVR_GL_DATA", DEFAULT_DATA_DIR),
                        help="the shared data folder (default: $DVR_GL_DATA, else the bench's)")
    parser.add_argument("--float-texels", action="store_true",
                        help="bricks of integer data as float32 textures (the texture unit's filter) "
                             "instead of their own integers (interpolated from fetches)")
    args = parser.parse_args(argv)
    if args.float_texels:
        from ..techniques import bricks
        bricks.INTEGER_TEXELS = {}
    renderer = Renderer()
    print(f"{args.technique}, {args.size}x{args.size}, median of {args.repeats}, "
          f"LP_NUM_THREADS={os.environ.get('LP_NUM_THREADS', '-')}")
    for name, scene in scenes(args.data, args.size):
        configs = [{"technique": args.technique}] + [{"technique": args.technique, "brick_size": n} for n in args.bricks]
        (single, t_single), *bricked = timed(renderer, scene, args.repeats, configs)
        print(f"{name}: single texture {t_single * 1e3:.0f} ms")
        for n, (image, t) in zip(args.bricks, bricked):
            drawn, total, texels = brick_counts(scene, n, args.technique)
            print(f"  bricks of {n}: {t * 1e3:.0f} ms ({t / t_single:.2f}x), largest difference "
                  f"{float(np.abs(image - single).max()):.2g}, {drawn} of {total} bricks drawn, "
                  f"{texels / scene.volume.data.size:.2f} texels a sample")


def brick_counts(scene, brick_size, technique="raycast"):
    """(bricks drawn, bricks, texels in the drawn bricks' textures) at the default options."""
    from ..model.transfer import LookupTable
    from ..techniques import bricks, slice3d, slice3d_bricks
    if technique == "slice3d":      # its halo and emptiness (over each texture's samples)
        halo = slice3d_bricks.slice_halo(scene, slice3d.default_step(scene.volume), False)
        parts = bricks.partition(scene.volume.shape, brick_size, halo)
        ranges = slice3d_bricks.texture_ranges(scene.volume, parts)
    else:
        parts = bricks.partition(scene.volume.shape, brick_size, bricks.halo_for(scene))
        ranges = bricks.value_ranges(scene.volume, parts)
    occupied = bricks.brick_occupancy(ranges, LookupTable(scene.tf))
    texels = sum(int(np.prod([b - a for a, b in p.samples])) for p, o in zip(parts, occupied) if o)
    return int(occupied.sum()), len(parts), texels


if __name__ == "__main__":
    main()
