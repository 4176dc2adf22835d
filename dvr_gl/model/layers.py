"""Several volumes in one scene: layers, label colours, channels.

A ``Layer`` is a grid (``Volume``) with its own classification, placed in the scene's
world by a rigid motion (``matrix``: a rotation and a translation, 4x4). Its own
spacing and origin give its samples' positions in its own frame, as for a lone volume;
the matrix carries that frame into the world. The scene's own volume and transfer
function are the first layer, placed by the identity, so the world is that volume's.

Layers are classified either by a ``TransferFunction`` (a scan: the field is trilinear,
as for any volume) or by ``LabelColors`` (a segmentation: the field is the label of the
nearest sample, piecewise constant, and each label has its own colour and opacity).

How layers combine (docs/contract.md, "Several volumes"):

- ``blend="mix"``: one medium. At every point the extinctions of the layers that
  contain it add, ``tau = sum tau_i``, and so do their emissions, ``c tau = sum c_i
  tau_i``; the ray integral of the contract then runs over the union of their domains.
- ``blend="add"``: each layer's own image (composited alone, in the scene's mode), the
  images summed: ``C = sum C_i``, ``A = 1 - prod (1 - A_i)``. Microscopy's additive
  channels.
"""

from __future__ import annotations

import hashlib
import math

import numpy as np

from .checks import _finite_number
from .transfer_function import TransferFunction
from .volume import Volume

__all__ = ["Layer", "LabelColors", "BLENDS", "MAX_LAYERS", "MAX_LABEL", "CHANNEL_COLORS", "channel_layers",
           "union_bounds", "Extent"]

BLENDS = ("mix", "add")
MAX_LAYERS = 4          # in one scene, its own volume included (texture units and registers per sample)
MAX_LABEL = 4095        # label tables are one texture row
# Microscopy's usual channel colours, in order (two channels: magenta and green).
CHANNEL_COLORS = ((1.0, 0.0, 1.0), (0.0, 1.0, 0.0), (0.0, 1.0, 1.0), (1.0, 1.0, 0.0))
_RIGID_TOL = 1e-6


class LabelColors:
    """Colours and opacities of a label volume: ``{label: (r, g, b, alpha)}`` for
    non-negative integer labels; labels not listed (0, the background, usually) are
    transparent. ``alpha`` is the opacity of a slab ``unit_distance`` thick, as in a
    ``TransferFunction``."""

    def __init__(self, colors, unit_distance=1.0):
        if not isinstance(colors, dict) or not colors:
            raise TypeError(f"colors must be a non-empty dict {{label: (r, g, b, alpha)}}, got {colors!r}")
        table = {}
        for label, rgba in colors.items():
            if isinstance(label, bool) or not isinstance(label, (int, np.integer)) or not 0 <= label <= MAX_LABEL:
                raise ValueError(f"labels must be integers from 0 to {MAX_LABEL}, got {label!r}")
            try:
                rgba = tuple(float(v) for v in rgba)
            except (TypeError, ValueError):
                raise TypeError(f"colors[{label}] must be (r, g, b, alpha), got {rgba!r}") from None
            if len(rgba) != 4 or not all(math.isfinite(v) and 0 <= v <= 1 for v in rgba):
                raise ValueError(f"colors[{label}] must be four numbers in [0, 1] (r, g, b, alpha), got {rgba!r}")
            table[int(label)] = rgba
        self.colors = dict(sorted(table.items()))
        self.unit_distance = _finite_number("unit_distance", unit_distance, positive=True)
        arr = np.zeros((max(self.colors) + 1, 4))
        for label, rgba in self.colors.items():
            arr[label] = rgba
        arr.setflags(write=False)
        self.table = arr          # row = label; labels beyond it are transparent

    def rgba(self, labels):
        """(..., 4) colour and opacity of integer labels (transparent where not listed)."""
        labels = np.asarray(labels)
        inside = (labels >= 0) & (labels < len(self.table))
        out = np.zeros(labels.shape + (4,))
        out[inside] = self.table[labels[inside].astype(np.int64)]
        return out

    def extinction(self, labels):
        """tau of integer labels; inf where alpha = 1."""
        a = self.rgba(labels)[..., 3]
        with np.errstate(divide="ignore"):
            return -np.log1p(-a) / self.unit_distance

    def key(self):
        return ("labels", self.table.tobytes(), self.unit_distance)

    def __repr__(self):
        return f"LabelColors({len(self.colors)} labels, unit_distance={self.unit_distance})"


def _rigid(matrix):
    if matrix is None:
        m = np.eye(4)
    else:
        try:
            m = np.array(matrix, dtype=np.float64)
        except (TypeError, ValueError):
            raise TypeError(f"matrix must be a 4x4 array of numbers, got {matrix!r}") from None
        if m.shape == (3, 3):
            m = np.block([[m, np.zeros((3, 1))], [np.zeros((1, 3)), np.ones((1, 1))]])
        if m.shape != (4, 4) or not np.all(np.isfinite(m)):
            raise ValueError(f"matrix must be a finite 4x4 (or 3x3 rotation) array, got shape {np.shape(matrix)}")
        rotation = m[:3, :3]
        if (np.abs(m[3] - (0, 0, 0, 1)).max() > 0
                or np.abs(rotation @ rotation.T - np.eye(3)).max() > _RIGID_TOL
                or np.linalg.det(rotation) <= 0):
            raise ValueError("matrix must be a rigid motion (an orthonormal rotation with determinant +1 and a "
                             f"translation, last row 0 0 0 1): scale a layer by its volume's spacing; got {m.tolist()}")
    m.setflags(write=False)
    return m


class Layer:
    """A volume in a scene of several: ``volume`` (a ``Volume``), its classification
    ``tf`` (a ``TransferFunction``, or ``LabelColors`` for a label volume) and ``matrix``,
    the rigid motion from the volume's own frame to the world (None: identity; a 3x3
    rotation, or a 4x4 with a translation)."""

    def __init__(self, volume, tf, matrix=None):
        if not isinstance(volume, Volume):
            raise TypeError(f"volume must be a dvr_gl.Volume (layers are grids), got {type(volume).__name__}")
        if not isinstance(tf, (TransferFunction, LabelColors)):
            raise TypeError(f"tf must be a dvr_gl.TransferFunction or LabelColors, got {type(tf).__name__}")
        if isinstance(tf, LabelColors):
            if volume.has_nonfinite:
                raise ValueError("a label volume must hold integer labels everywhere, got non-finite samples")
            data = volume.data
            if data.dtype.kind == "f" and not np.array_equal(data, np.round(data)):
                bad = data[data != np.round(data)].flat[0].item()
                raise ValueError(f"a label volume must hold integer labels, got {bad!r}")
            if volume.data_range[0] < 0:
                raise ValueError(f"labels must be non-negative, got {volume.data_range[0]!r}")
        self.volume = volume
        self.tf = tf
        self.matrix = _rigid(matrix)

    @property
    def is_labels(self):
        """True for a label volume (nearest sample, label colours)."""
        return isinstance(self.tf, LabelColors)

    @property
    def placed(self):
        """True when the matrix is not the identity."""
        return not np.array_equal(self.matrix, np.eye(4))

    @property
    def rotation(self):
        return self.matrix[:3, :3]

    @property
    def translation(self):
        return self.matrix[:3, 3]

    def to_world(self, points):
        """World positions of points given in the volume's own frame."""
        return np.asarray(points, np.float64) @ self.rotation.T + self.translation

    def to_local(self, points):
        """The volume's own frame of world points."""
        return (np.asarray(points, np.float64) - self.translation) @ self.rotation

    def direction_to_local(self, directions):
        return np.asarray(directions, np.float64) @ self.rotation

    def corners(self):
        """(8, 3) world corners of the volume's box."""
        lo, hi = self.volume.bounds
        c = np.array([[x, y, z] for z in (lo[2], hi[2]) for y in (lo[1], hi[1]) for x in (lo[0], hi[0])])
        return self.to_world(c)

    def world_bounds(self):
        """(lower, upper) of the axis-aligned world box around the placed volume."""
        c = self.corners()
        return c.min(axis=0), c.max(axis=0)

    def digest(self):
        h = hashlib.sha256()
        h.update(self.volume.digest().encode())
        h.update(repr(self.tf.key()).encode())
        h.update(self.matrix.tobytes())
        return h.hexdigest()

    def __repr__(self):
        kind = "labels" if self.is_labels else "scan"
        return f"Layer({self.volume!r}, {kind}{', placed' if self.placed else ''})"


def check_layers(layers, volume, tf, *, mode, blend, shading, optical_model, tf_2d, illustration):
    """The scene's extra layers as a tuple, checked against the rest of the scene."""
    if isinstance(layers, Layer):
        layers = (layers,)
    try:
        layers = tuple(layers)
    except TypeError:
        raise TypeError(f"layers must be a sequence of dvr_gl.Layer, got {layers!r}") from None
    if blend not in BLENDS:
        raise ValueError(f"blend must be one of {', '.join(BLENDS)}, got {blend!r}")
    if not layers:
        return layers
    for i, layer in enumerate(layers):
        if not isinstance(layer, Layer):
            raise TypeError(f"layers[{i}] must be a dvr_gl.Layer, got {type(layer).__name__}")
    if not isinstance(volume, Volume):
        raise ValueError("layers are grids drawn with the scene's own grid; this scene holds a "
                         f"{type(volume).__name__}")
    if 1 + len(layers) > MAX_LAYERS:
        raise ValueError(f"a scene holds at most {MAX_LAYERS} volumes (its own and {MAX_LAYERS - 1} layers), "
                         f"got {1 + len(layers)}")
    if tf_2d is not None:
        raise ValueError("a scene with layers classifies each by a 1D TransferFunction (or LabelColors); "
                         "got a TransferFunction2D")
    if optical_model != "emission_absorption" or illustration:
        raise ValueError("a scene with layers renders the emission-absorption model without illustration terms, "
                         f"got optical_model={optical_model!r}, illustration={sorted(illustration)!r}")
    if shading:
        raise ValueError("lighting several volumes is not rendered yet: a scene with layers takes shading=False")
    modes = ("composite",) if blend == "mix" else ("composite", "mip", "minip", "average")
    if mode not in modes:
        raise ValueError(f"blend={blend!r} renders mode {' or '.join(repr(m) for m in modes)} "
                         f"(a mixture is one medium, so only its composite is defined), got mode {mode!r}")
    if mode != "composite" and any(layer.is_labels for layer in layers):
        raise ValueError(f"label layers are composited; mode {mode!r} has no meaning for labels")
    return layers


class Extent:
    """Anything with ``bounds``, for functions that only need a box (default_camera)."""

    def __init__(self, bounds):
        self.bounds = bounds


def union_bounds(layers):
    """(lower, upper) of the world box around every layer."""
    boxes = [layer.world_bounds() for layer in layers]
    return np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)


def channel_layers(data, spacing=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0), colors=None, windows=None,
                   max_opacity=0.3, unit_distance=None):
    """One layer per channel of ``data`` (shape (channels, nz, ny, nx), 2 to 4 channels),
    on one grid: channel k glows in ``colors[k]`` (default ``CHANNEL_COLORS``) with an
    opacity ramp from 0 at its window's low end to ``max_opacity`` at its high end
    (``windows[k] = (low, high)``; default: its 1st and 99.9th percentiles), as a
    microscope viewer shows channels. ``unit_distance`` defaults to the smallest spacing."""
    data = np.asarray(data)
    if data.ndim != 4 or not 2 <= data.shape[0] <= MAX_LAYERS:
        raise ValueError(f"data must have shape (channels, nz, ny, nx) with 2 to {MAX_LAYERS} channels, "
                         f"got shape {data.shape}")
    n = data.shape[0]
    colors = CHANNEL_COLORS[:n] if colors is None else tuple(colors)
    if len(colors) != n:
        raise ValueError(f"colors must give one RGB colour per channel ({n}), got {len(colors)}")
    if windows is not None and len(windows) != n:
        raise ValueError(f"windows must give one (low, high) per channel ({n}), got {len(windows)}")
    max_opacity = _finite_number("max_opacity", max_opacity, positive=True)
    if max_opacity >= 1:
        raise ValueError(f"max_opacity must be below 1, got {max_opacity!r}")
    layers = []
    for k in range(n):
        volume = Volume(data[k], spacing=spacing, origin=origin)
        if windows is None:
            lo, hi = (float(v) for v in np.percentile(data[k], (1.0, 99.9)))
        else:
            lo, hi = (float(v) for v in windows[k])
        if not hi > lo:
            hi = lo + max(abs(lo), 1.0) * 1e-6
        rgb = tuple(float(v) for v in colors[k])
        if len(rgb) != 3 or not all(0 <= v <= 1 for v in rgb):
            raise ValueError(f"colors[{k}] must be an RGB triple in [0, 1], got {colors[k]!r}")
        tf = TransferFunction([(lo, *rgb), (hi, *rgb)], [(lo, 0.0), (hi, max_opacity)],
                              unit_distance=float(min(volume.spacing)) if unit_distance is None else unit_distance)
        layers.append(Layer(volume, tf))
    return layers
