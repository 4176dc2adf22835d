"""Ray casting a LazyVolume: a store read brick by brick, under a memory budget.

A scene whose volume is a :class:`dvr_gl.model.lazy_volume.LazyVolume` is always drawn
in bricks (``techniques.bricks``): of ``brick_size`` cells a side when given, else of the
brick size of the volume's last :func:`~dvr_gl.model.lazy_volume.brick_summary` (else
``DEFAULT_BRICK``). Which bricks are empty comes from that summary's per-brick min and
max (made once per store and kept in the cache folder), never from the samples: a
brick whose range has zero opacity under the TF (``bricks.brick_occupancy``) is never
read. The summary's ranges cover each brick's samples and ``halo >= 1`` more on every
side, as wide as the in-memory ``bricks.value_ranges`` or wider, so no brick that shows
something is skipped.

The bricks that are drawn are read through a :class:`dvr_gl.util.memory.BrickCache`
bounded by ``memory`` (bytes, or a size such as ``"2GB"``; default a quarter of the
memory available when first asked, ``DEFAULT_MEMORY_FRACTION``): where the store is
chunked (and a chunk is small beside the budget) the cache holds its chunks and a brick
is put together from them, so neighbouring bricks, whose halos meet the same chunks,
read each chunk once; one brick's texture is held on the GPU at a time, released
before the next is uploaded. A budget smaller than one brick is a
``BudgetError`` before anything is read. Samples are taken as finite (a LazyVolume
cannot say otherwise without reading it all): a brick read with non-finite samples is a
ValueError naming the brick.

The plan's part is here; the summary's occupancy and the textures read through the
cache are in ``techniques.bricks`` (``lazy_occupied``, ``LazyBrickTextures``). Other
techniques given a LazyVolume raise :class:`LazyVolumeTechniqueError`.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from ..model.lazy_volume import DEFAULT_BRICK
from ..util.memory import BrickCache, available_memory, parse_bytes

DEFAULT_MEMORY_FRACTION = 0.25      # of the memory available, when no budget is given
FALLBACK_MEMORY = 2 ** 30           # where the memory available cannot be read


class LazyVolumeTechniqueError(ValueError):
    """A technique other than the ray caster was given a LazyVolume."""

    def __init__(self, technique):
        self.technique = technique
        super().__init__(f"{technique} renders volumes held in memory; only the ray caster (technique "
                         f"'raycast') renders a LazyVolume (a store read brick by brick) yet: for {technique}, "
                         f"load it whole (dvr_gl.formats.open_volume(path, lazy=False))")


@dataclass(frozen=True)
class LazyBricking:
    """What a ray-casting plan of a LazyVolume keeps: the memory budget in bytes and
    whether empty bricks are skipped (composite mode with skip_empty)."""
    memory: int
    skip_empty: bool


@functools.lru_cache(maxsize=1)
def default_memory():
    """DEFAULT_MEMORY_FRACTION of the memory available when first asked (FALLBACK_MEMORY
    if unknown); kept, so that renders share one brick cache."""
    have = available_memory()
    return FALLBACK_MEMORY if have is None else max(int(have * DEFAULT_MEMORY_FRACTION), 1)


def summary_brick_size(volume):
    """Cells per brick side of the volume's last summary (a cube), else DEFAULT_BRICK."""
    summary = getattr(volume, "_summary", None)
    if summary is not None and len(set(summary.brick)) == 1:
        return int(summary.brick[0])
    return DEFAULT_BRICK


def largest_brick_bytes(shape, brick_size, halo, itemsize):
    """Bytes of the largest block a brick of ``brick_size`` cells with ``halo`` reads."""
    side = [min(n, brick_size + 1 + 2 * halo) for n in shape]
    return int(np.prod(side, dtype=np.int64)) * int(itemsize)


def plan_lazy(scene, brick_size, memory, skip_empty, halo):
    """(brick size, LazyBricking) of a ray-casting plan of a LazyVolume (``brick_size``
    already checked; None: the summary's). A budget below the largest brick is a
    BudgetError now, before any read."""
    volume = scene.volume
    if brick_size is None:
        brick_size = summary_brick_size(volume)
    budget = default_memory() if memory is None else parse_bytes(memory, "memory")
    cache = BrickCache(budget)
    cache.require(largest_brick_bytes(volume.shape, brick_size, halo, volume.dtype.itemsize),
                  f"one brick of {brick_size} cells a side with its halo of {halo}")
    composite = scene.mode == "composite" and scene.optical_model != "sabella"
    return brick_size, LazyBricking(budget, bool(skip_empty) and composite)
