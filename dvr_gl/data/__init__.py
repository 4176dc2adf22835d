"""Bundled scenes: a real CT head and a synthetic volume with a known analytic form.

- :func:`ct_head` -- the VTK "headsq" CT head at quarter resolution, 64 x 64 x 93 int16,
  spacing (3.2, 3.2, 1.5), values 0..3926 (VTK Data, BSD-3-Clause style; origin and the
  verbatim notice in ``LICENSE-headsq.txt`` beside this file).
- :func:`synthetic` -- :func:`synthetic_field` sampled on an n^3 grid: a tilted Gaussian
  torus (peak 1.0), a Gaussian blob in its hole (peak 0.6) and a smaller one outside it
  (peak 0.35). The world box is always ``[0, 63]^3``, whatever ``n``: a finer grid samples
  the same continuous field, so resolution studies compare like with like.
- :func:`delaunay_ball` -- the same field on scattered points in the ball inscribed in
  that box, tetrahedralised by Delaunay: an unstructured mesh (4,000 points, about 24,000
  tetrahedra by default) for the projected-tetrahedra technique.

Each comes with a default transfer function in data units whose unit distance is one
voxel: the smallest spacing of the head (1.5), and 1.0 for the synthetic box (one voxel
at the default ``n = 64``).

Volumes and meshes are cached: calling :func:`ct_head` twice returns the same immutable object, so
renderers that cache GPU resources by identity upload it once.
"""

from __future__ import annotations

import functools
import importlib.resources
import math

import numpy as np

from ..model.transfer_function import TransferFunction
from ..model.volume import Volume

__all__ = ["ct_head", "ct_head_tf", "synthetic", "synthetic_field", "synthetic_tf",
           "SYNTHETIC_EXTENT"]

_HEADSQ_FILE = "headsq_quarter.npz"

#: World size of the synthetic volume's box on every axis; the box is [0, SYNTHETIC_EXTENT]^3.
SYNTHETIC_EXTENT = 63.0

# The synthetic field's parts, in world units (box [0, 63]^3, centre 31.5).
_CENTRE = np.array([31.5, 31.5, 31.5])
_TORUS_RADIUS = 20.0            # major radius
_TORUS_SIGMA = 3.0              # Gaussian width of the tube
_TORUS_TILT = math.radians(35)  # its axis: +z turned towards +y about +x
_TORUS_AXIS = np.array([0.0, math.sin(_TORUS_TILT), math.cos(_TORUS_TILT)])
_BLOBS = (  # (centre offset from the box centre, sigma, peak)
    (np.array([0.0, 0.0, 0.0]), 6.0, 0.6),
    (np.array([-15.0, 13.0, 13.0]), 4.0, 0.35),
)


@functools.lru_cache(maxsize=1)
def ct_head() -> Volume:
    """The VTK "headsq" CT head, quarter resolution: data (93, 64, 64) int16 (z, y, x),
    spacing (3.2, 3.2, 1.5), origin (0, 0, 0), values 0..3926.

    The face looks towards -y and the top of the head is at z = 0: an eye on -y with -z
    up sees the face upright (as ``dvr-gl demo`` and the gallery show it; the file names
    no orientation, ``"RPI"`` says it to ``dvr_gl.render``).
    """
    with importlib.resources.files(__name__).joinpath(_HEADSQ_FILE).open("rb") as f:
        with np.load(f, allow_pickle=False) as npz:
            data = npz["data"].astype(np.int16)  # native byte order
            spacing = tuple(float(v) for v in npz["spacing"])
            origin = tuple(float(v) for v in npz["origin"])
    return Volume(data, spacing=spacing, origin=origin)


def ct_head_tf() -> TransferFunction:
    """A translucent skull behind a faint skin: air and soft tissue clear, the skin's
    boundary (500-950) a thin brown veil, bone (above 1150) from tan to ivory.

    Data units (CT values of this data set: air ~0-200, soft tissue ~900-1100, bone
    ~1200-2600); unit distance 1.5, the head's smallest spacing (one voxel along z).
    Unshaded, so bone stays translucent: opaque bone would render as a flat silhouette.
    """
    return TransferFunction(
        color=[(500.0, 0.55, 0.25, 0.15),
               (1000.0, 0.88, 0.60, 0.48),
               (1150.0, 0.70, 0.45, 0.30),
               (1500.0, 0.95, 0.85, 0.70),
               (2500.0, 1.00, 1.00, 0.96)],
        opacity=[(400.0, 0.0),
                 (700.0, 0.05),
                 (950.0, 0.0),
                 (1150.0, 0.0),
                 (1500.0, 0.04),
                 (2500.0, 0.25)],
        unit_distance=1.5)


def synthetic_field(x, y, z):
    """The synthetic scalar field at world points (arrays broadcast), float64.

    A Gaussian tube (sigma 3) around a circle of radius 20 centred in the box, its axis
    tilted 35 degrees from +z towards +y, peak 1.0; a Gaussian blob (sigma 6, peak 0.6) at
    the box centre; one (sigma 4, peak 0.35) at centre + (-15, 13, 13), above the torus
    plane. The parts barely overlap (the field's maximum is about 1.002) and the field is
    below 1e-3 on the faces of the box [0, 63]^3.
    """
    p = np.stack(np.broadcast_arrays(np.asarray(x, np.float64), np.asarray(y, np.float64),
                                     np.asarray(z, np.float64)), axis=-1) - _CENTRE
    h = p @ _TORUS_AXIS                                   # height above the torus plane
    r = np.sqrt(np.maximum((p * p).sum(axis=-1) - h * h, 0.0))  # distance from the axis
    f = np.exp(-((r - _TORUS_RADIUS) ** 2 + h * h) / (2 * _TORUS_SIGMA ** 2))
    for offset, sigma, peak in _BLOBS:
        q = p - offset
        f = f + peak * np.exp(-(q * q).sum(axis=-1) / (2 * sigma ** 2))
    return f


def synthetic(n: int = 64) -> Volume:
    """:func:`synthetic_field` sampled on an n x n x n grid spanning [0, 63]^3
    (spacing 63 / (n - 1)), float32."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)):
        raise TypeError(f"n must be an integer, got {n!r}")
    if not 2 <= n <= 1024:
        raise ValueError(f"n must be between 2 and 1024 samples per axis, got {n!r}")
    return _synthetic(int(n))


@functools.lru_cache(maxsize=4)
def _synthetic(n):
    h = SYNTHETIC_EXTENT / (n - 1)
    axis = np.arange(n) * h
    z, y, x = np.meshgrid(axis, axis, axis, indexing="ij")  # (nz, ny, nx), x fastest
    data = synthetic_field(x, y, z).astype(np.float32)
    return Volume(data, spacing=(h, h, h), origin=(0.0, 0.0, 0.0))


def synthetic_tf() -> TransferFunction:
    """Bands of opacity at the three peaks: the small blob (0.35) cyan, the centre blob
    (0.6) amber, the torus core (1.0) red, with faint shells between; values below 0.1
    clear. Unit distance 1.0 (one voxel at n = 64)."""
    return TransferFunction(
        color=[(0.10, 0.15, 0.25, 0.90),
               (0.35, 0.15, 0.80, 0.95),
               (0.60, 0.98, 0.75, 0.15),
               (1.00, 0.90, 0.15, 0.10)],
        opacity=[(0.10, 0.0), (0.25, 0.02), (0.34, 0.30), (0.42, 0.02),
                 (0.55, 0.05), (0.60, 0.30), (0.68, 0.05), (0.90, 0.20), (1.00, 0.80)],
        unit_distance=1.0)


def delaunay_ball(n_points: int = 4000, seed: int = 0):
    """The synthetic field on scattered points: ``n_points`` points in the ball inscribed
    in the synthetic box (radius 31.5 about its centre; a fifth of them on the sphere),
    drawn from ``numpy.random.default_rng(seed)``, tetrahedralised by Delaunay
    (``TetMesh.from_points``), scalars :func:`synthetic_field`. Render it with
    :func:`synthetic_tf`."""
    if isinstance(n_points, bool) or not isinstance(n_points, (int, np.integer)) or n_points < 8:
        raise ValueError(f"n_points must be an integer >= 8, got {n_points!r}")
    return _delaunay_ball(int(n_points), int(seed))


@functools.lru_cache(maxsize=2)
def _delaunay_ball(n, seed):
    from ..model.mesh import TetMesh
    rng = np.random.default_rng(seed)
    direction = rng.normal(size=(n, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    radius = SYNTHETIC_EXTENT / 2 * np.where(np.arange(n) < n // 5, 1.0, rng.random(n) ** (1 / 3))
    points = _CENTRE + direction * radius[:, None]
    return TetMesh.from_points(points, synthetic_field(*points.T))

