"""Opaque geometry inside a scene: triangle meshes drawn with the volume.

A :class:`Surface` is an opaque, lit triangle mesh in world units. A ray that meets one
ends there: the data integrates up to the first surface the ray meets (the segment to
the surface counts, nothing behind it), and the surface's lit colour is seen through
what lies in front of it (image contract, "Opaque geometry").
"""

from __future__ import annotations

import hashlib

import numpy as np

from .checks import _vector3


class Surface:
    """An opaque triangle mesh: ``vertices`` (n, 3) world positions, ``faces`` (m, 3)
    vertex indices, one ``color`` (r, g, b in [0, 1]). Lit by the scene's lights with
    Blinn-Phong, two-sided, with each triangle's own (flat) normal, the scene's ``phong``
    coefficients. Arrays are stored read-only."""

    def __init__(self, vertices, faces, color=(0.85, 0.85, 0.85)):
        try:
            v = np.array(vertices, dtype=np.float64)
        except (TypeError, ValueError):
            raise TypeError(f"vertices must be an (n, 3) array of numbers, got {type(vertices).__name__}") from None
        if v.ndim != 2 or v.shape[1] != 3 or len(v) < 3:
            raise ValueError(f"vertices must be an (n, 3) array with n >= 3, got shape {v.shape}")
        if not np.all(np.isfinite(v)):
            raise ValueError("vertices must be finite, got NaN or infinity")
        try:
            f = np.array(faces)
        except (TypeError, ValueError):
            raise TypeError(f"faces must be an (m, 3) array of vertex indices, got {type(faces).__name__}") from None
        if f.ndim != 2 or f.shape[1] != 3 or len(f) < 1:
            raise ValueError(f"faces must be an (m, 3) array with m >= 1 (triangles), got shape {f.shape}")
        if not np.issubdtype(f.dtype, np.integer):
            raise TypeError(f"faces must hold integer vertex indices, got dtype {f.dtype}")
        if f.min() < 0 or f.max() >= len(v):
            raise ValueError(f"faces index vertices 0..{len(v) - 1}, got indices {int(f.min())}..{int(f.max())}")
        color = _vector3("color", color)
        if not np.all((color >= 0) & (color <= 1)):
            raise ValueError(f"color must be three numbers in [0, 1], got {tuple(float(c) for c in color)}")
        f = f.astype(np.int64)
        v.setflags(write=False)
        f.setflags(write=False)
        color.setflags(write=False)
        self.vertices = v
        self.faces = f
        self.color = color

    @property
    def n_faces(self):
        return len(self.faces)

    @property
    def bounds(self):
        """(lower, upper) corners of the vertices."""
        return self.vertices.min(axis=0), self.vertices.max(axis=0)

    def triangles(self):
        """(m, 3, 3) float64: each face's three corners."""
        return self.vertices[self.faces]

    def normals(self):
        """(m, 3) float64 unit normals of the faces (right-handed in their vertex order;
        zero for a degenerate triangle, which no ray hits)."""
        t = self.triangles()
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        length = np.linalg.norm(n, axis=1, keepdims=True)
        return np.where(length > 0, n / np.where(length > 0, length, 1.0), 0.0)

    def digest(self):
        h = hashlib.sha256()
        for a in (self.vertices, self.faces, self.color):
            h.update(np.ascontiguousarray(a).tobytes())
        return h.hexdigest()

    def __repr__(self):
        color = ", ".join(f"{float(c):g}" for c in self.color)
        return f"Surface({len(self.vertices)} vertices, {self.n_faces} faces, color=({color}))"


def check_geometry(geometry):
    """``None``, a Surface or a sequence of them -> a tuple of Surfaces."""
    if geometry is None:
        return ()
    if isinstance(geometry, Surface):
        return (geometry,)
    try:
        items = tuple(geometry)
    except TypeError:
        raise TypeError(f"geometry must be a dvr_gl.Surface or a sequence of them, got {geometry!r}") from None
    for i, item in enumerate(items):
        if not isinstance(item, Surface):
            raise TypeError(f"geometry[{i}] must be a dvr_gl.Surface, got {type(item).__name__}")
    return items
