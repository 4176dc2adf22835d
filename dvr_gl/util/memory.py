"""Memory budgets: sizes in bytes as people write them ("2GB", "512MiB"), a cache of
bricks bounded in bytes, and the folder where summaries made once per store are kept."""

from __future__ import annotations

import os
import re
from collections import OrderedDict

# Decimal units are powers of 1000, binary ones (KiB ...) and the bare letters K/M/G/T
# powers of 1024 (as ``--memory 2G`` means in most tools).
_UNITS = {"": 1, "B": 1,
          "KB": 1000, "MB": 1000 ** 2, "GB": 1000 ** 3, "TB": 1000 ** 4,
          "KIB": 1024, "MIB": 1024 ** 2, "GIB": 1024 ** 3, "TIB": 1024 ** 4,
          "K": 1024, "M": 1024 ** 2, "G": 1024 ** 3, "T": 1024 ** 4}
_SIZE = re.compile(r"^\s*([0-9]+(?:\.[0-9]*)?|\.[0-9]+)\s*([A-Za-z]*)\s*$")


def parse_bytes(value, field="memory"):
    """A size in bytes from an int or a string such as ``"2GB"`` (2 * 10**9),
    ``"512MiB"`` (512 * 2**20), ``"1.5G"`` (binary) or ``"4096"``. A ValueError names
    ``field`` and the value when it is not a positive size."""
    if isinstance(value, bool):
        raise ValueError(f"{field} must be a size such as 2GB or 512MiB, got {value!r}")
    if isinstance(value, int):
        nbytes = value
    else:
        match = _SIZE.match(value) if isinstance(value, str) else None
        unit = match.group(2).upper() if match else None
        if unit not in _UNITS:
            raise ValueError(f"{field} must be a size such as 2GB, 512MiB or 4096 (bytes); units "
                             f"B, kB, MB, GB, TB (powers of 1000), KiB, MiB, GiB, TiB or K, M, G, T "
                             f"(powers of 1024), got {value!r}")
        nbytes = int(float(match.group(1)) * _UNITS[unit])
    if nbytes <= 0:
        raise ValueError(f"{field} must be a positive size, got {value!r}")
    return nbytes


def format_bytes(nbytes):
    """``nbytes`` in binary units, three significant figures: ``'32.0 GiB'``."""
    size = float(nbytes)
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if size < 1024 or unit == "TiB":
            return f"{int(size)} B" if unit == "B" else f"{size:.3g} {unit}"
        size /= 1024
    return f"{nbytes} B"  # not reached


def cache_folder(kind):
    """Where summaries of ``kind`` (``"summaries"``) are kept: ``$DVR_GL_CACHE/kind`` if
    DVR_GL_CACHE is set (as for exact images), else ``~/.cache/dvr_gl/kind``."""
    root = os.environ.get("DVR_GL_CACHE") or os.path.join(os.path.expanduser("~"), ".cache", "dvr_gl")
    return os.path.join(root, kind)


class BudgetError(ValueError):
    """A memory budget too small for what must fit in it at once (one brick)."""

    def __init__(self, budget, needed, what="one brick"):
        self.budget = int(budget)
        self.needed = int(needed)
        super().__init__(f"memory budget {format_bytes(budget)} ({int(budget)} bytes) is smaller than {what} "
                         f"({format_bytes(needed)}, {int(needed)} bytes); give at least that much memory")


class BrickCache:
    """Bricks (arrays) kept under a budget of ``memory_bytes`` (an int or a size string),
    least recently used dropped first. ``get(volume, brick_index, loader)`` returns the
    cached brick or ``loader()``'s, which must have ``nbytes``. Keys are the volume's
    ``digest()`` where it has one (two openings of one store share bricks), else the
    volume object itself. A brick larger than the whole budget is a :class:`BudgetError`.

    ``hits``, ``misses``, ``bytes_loaded`` and ``nbytes`` (held now) count what it did."""

    def __init__(self, memory_bytes):
        self.budget = parse_bytes(memory_bytes)
        self.items = OrderedDict()
        self.nbytes = 0
        self.hits = self.misses = self.bytes_loaded = 0
        self._volumes = {}

    def require(self, nbytes, what="one brick"):
        """A BudgetError if ``nbytes`` cannot fit in the budget (checked before reading)."""
        if nbytes > self.budget:
            raise BudgetError(self.budget, nbytes, what)

    def _volume_key(self, volume):
        digest = getattr(volume, "digest", None)
        value = digest() if callable(digest) else None
        if value is not None:
            return value
        self._volumes.setdefault(id(volume), volume)   # held, so that its id is not reused
        return ("object", id(volume))

    def get(self, volume, brick_index, loader):
        key = (self._volume_key(volume), tuple(int(i) for i in brick_index) if not isinstance(brick_index, str)
               else brick_index)
        if key in self.items:
            self.items.move_to_end(key)
            self.hits += 1
            return self.items[key]
        value = loader()
        size = int(value.nbytes)
        self.require(size)
        self.misses += 1
        self.bytes_loaded += size
        while self.items and self.nbytes + size > self.budget:
            _, old = self.items.popitem(last=False)
            self.nbytes -= int(old.nbytes)
        self.items[key] = value
        self.nbytes += size
        return value

    def __contains__(self, volume_and_index):
        volume, brick_index = volume_and_index
        return (self._volume_key(volume), tuple(int(i) for i in brick_index)) in self.items

    def __len__(self):
        return len(self.items)

    def clear(self):
        self.items.clear()
        self.nbytes = 0
        self._volumes.clear()

    def __repr__(self):
        return (f"BrickCache({format_bytes(self.budget)}, holding {len(self.items)} bricks, "
                f"{format_bytes(self.nbytes)}; {self.hits} hits, {self.misses} misses)")


def available_memory():
    """Bytes of memory available to this process (Linux's MemAvailable), or None."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None
