"""Small caches keyed by the identity of scene objects (which are immutable)."""

from __future__ import annotations

from collections import OrderedDict


_BY_VALUE = (str, int, float)  # plain values (a kind, a step) compare by value


class IdentityKey:
    """Hashable by the identity of the objects it holds (plain strings and numbers by
    value); holding them keeps ``id``s from being reused while the entry lives."""

    __slots__ = ("objects",)

    def __init__(self, *objects):
        self.objects = objects

    def __hash__(self):
        return hash(tuple((type(o).__name__, o) if isinstance(o, _BY_VALUE) else id(o) for o in self.objects))

    def __eq__(self, other):
        return (isinstance(other, IdentityKey) and len(other.objects) == len(self.objects)
                and all(a is b or (isinstance(a, _BY_VALUE) and type(a) is type(b) and a == b)
                        for a, b in zip(self.objects, other.objects)))


class LRU:
    """At most ``capacity`` values; ``release`` is called on values that are dropped, if
    they have it (GL objects)."""

    def __init__(self, capacity):
        self.capacity = capacity
        self.items = OrderedDict()

    def get(self, key, make):
        if key in self.items:
            self.items.move_to_end(key)
            return self.items[key]
        value = make()
        self.items[key] = value
        while len(self.items) > self.capacity:
            _, old = self.items.popitem(last=False)
            _release(old)
        return value

    def put(self, key, value):
        """Keep ``value`` under ``key``, replacing what was there (not released: the
        caller's new value may be built on it)."""
        self.items[key] = value
        self.items.move_to_end(key)
        while len(self.items) > self.capacity:
            _, old = self.items.popitem(last=False)
            _release(old)

    def release(self):
        for value in self.items.values():
            _release(value)
        self.items.clear()


def _release(value):
    release = getattr(value, "release", None)
    if release is not None:
        release()


class TableCache:
    """CPU tables derived from scene objects (a TF's lookup table, a volume's brick value
    ranges, their occupancy): built on first use, reused while the objects live in the
    cache. Each kind (the part of ``kind`` before any ":") keeps its own ``capacity`` most
    recent entries, so that scenes used in turn (a bench's configurations, a viewer's
    toggles) never push each other's tables out."""

    def __init__(self, capacity=4):
        self.capacity = capacity
        self._lrus = {}

    def get(self, kind, *objects, make):
        """``make(*objects)``, built once while these objects stay in the cache."""
        group = kind.split(":", 1)[0]
        lru = self._lrus.get(group)
        if lru is None:
            lru = self._lrus[group] = LRU(self.capacity)
        return lru.get(IdentityKey(kind, *objects), lambda: make(*objects))
