"""Several volumes in the front ends: what ``dvr_gl.render(layers=..., labels=...,
channels=...)``, ``dvr-gl render/view/movie --volume/--labels/--channels/--blend`` and
the viewer build from what a user names (see ``dvr_gl.model.layers`` and the section
"Several volumes" of docs/contract.md for what the scene means).

- **Extra scans** (``layers=[...]``, ``--volume FILE``): anything the main input takes
  (an array, a file, ``builtin:NAME``, a Volume), each classified by the automatic
  transfer function for its own data, as the main input is; or a ``dvr_gl.Layer`` as it
  is. Each sits in the world by its own spacing and origin (the identity placement: a
  file's origin is where it lies); a Layer keeps its matrix.
- **Channels** (``channels=True``, ``--channels``): the main input's first axis (a
  4-D array or a 4-D array file, read as ``dvr-gl movie`` reads a series) holds 2 to 4
  channels on one grid, each glowing in its colour (``model.layers.channel_layers``).
- **A label volume** (``labels=INPUT``, ``--labels FILE``): a segmentation of whole
  numbers, shown in :data:`LABEL_PALETTE` colours (label k in colour ``(k - 1) mod 10``,
  so a label keeps its colour whichever others are present; 0 is the background,
  transparent) with the opacity :data:`LABEL_OPACITY` per smallest sample spacing.

``blend`` defaults to ``"add"`` for channels (microscopy's additive channels) and
``"mix"`` (one medium) otherwise. Bad input is an ``InputError`` whose field
(``layers``, ``labels``, ``channels``, ``blend``) the command line turns into its option.

Reading an input and choosing its automatic transfer function are
``inputs.load_input`` and ``inputs.resolve_tf``; the functions that need them take them
as arguments (``load_input=``, ``resolve_tf=``), because ``inputs`` (the home of
``dvr_gl.render``) builds on this module.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from .. import formats as dvr_io
from ..formats import InputError
from ..model.layers import BLENDS, MAX_LABEL, MAX_LAYERS, Extent, LabelColors, Layer, channel_layers, union_bounds
from ..model.volume import Volume

# The ten "Tableau 10" category colours (matplotlib's tab10): distinct at a glance and
# readable on white and on black; labels past ten cycle through them again.
LABEL_PALETTE = tuple(tuple(int(h[i:i + 2], 16) / 255 for i in (0, 2, 4)) for h in (
    "1f77b4", "ff7f0e", "2ca02c", "d62728", "9467bd", "8c564b", "e377c2", "7f7f7f", "bcbd22", "17becf"))
# Opacity of one sample spacing of a labelled region: a structure 3 samples thick is
# half opaque and 10 samples 89 %, so that small structures (vessels, lesions) show over
# the scan, while the thin edges and small parts of larger ones stay translucent: layers
# are unlit, and translucency that grows with thickness is what shows their shape.
LABEL_OPACITY = 0.2


def wants_layers(layers=(), labels=None, channels=False):
    """Whether the input names more than one volume (extra layers, labels or channels)."""
    if channels or labels is not None:
        return True
    if layers is None:
        return False
    if isinstance(layers, (Layer, str, os.PathLike, np.ndarray, Volume)):
        return True
    return len(layers) > 0


def default_blend(channels, blend=None):
    """``blend`` checked, or its default: "add" for channels, "mix" otherwise."""
    if blend is None:
        return "add" if channels else "mix"
    if blend not in BLENDS:
        raise InputError("blend", f"must be one of {', '.join(BLENDS)}, got {blend!r}")
    return blend


def check_volume_count(count, what=""):
    """At most MAX_LAYERS volumes in one scene (``what`` says which were given)."""
    if count > MAX_LAYERS:
        raise InputError("layers", f"a scene holds at most {MAX_LAYERS} volumes in all, got {count}"
                                   + (f" ({what})" if what else ""))


def _name(source):
    if isinstance(source, (str, os.PathLike)):
        return os.fspath(source)
    return type(source).__name__


def _grid(source, field, spacing, load_input):
    """A Volume from ``source`` (what ``load_input`` takes); ``spacing`` applies to arrays
    (an extra array lies on the main input's grid unless it is given as a Volume)."""
    try:
        data, preset = load_input(source, spacing=spacing if isinstance(source, np.ndarray) else None)
    except InputError as e:
        raise InputError(field, f"{_name(source)}: {e.detail}") from None
    if not isinstance(data, Volume):
        raise InputError(field, f"{_name(source)} is a {type(data).__name__}; several volumes are grids")
    return data, preset


# files that hold samples and no geometry: an extra of the main input's shape lies on its grid
_BARE_SUFFIXES = (".npy",)


def on_main_grid(volume, source, main):
    """``volume`` placed on the main input's grid (its spacing, origin and orientation)
    when ``source`` carries no geometry of its own (an array or a .npy file) and has the
    main input's shape: a segmentation saved beside its scan, say."""
    bare = isinstance(source, np.ndarray) or (isinstance(source, (str, os.PathLike))
                                              and os.fspath(source).lower().endswith(_BARE_SUFFIXES))
    if main is None or not bare or volume.shape != main.shape:
        return volume
    return Volume(volume.data, spacing=main.spacing, origin=main.origin, mask_nonfinite=volume.mask_nonfinite,
                  orientation=main.orientation)


def scan_layer(source, spacing, load_input, resolve_tf, main=None):
    """A Layer for an extra scan: a Layer as it is, else the data of ``source`` classified
    by its automatic transfer function (``resolve_tf`` with no TF named), on the main
    volume's grid when it has no geometry of its own (:func:`on_main_grid`)."""
    if isinstance(source, Layer):
        return source
    volume, preset = _grid(source, "layers", spacing, load_input)
    volume = on_main_grid(volume, source, main)
    _, tf = resolve_tf(None, volume, preset)
    return Layer(volume, tf)


def label_colors(volume, opacity=LABEL_OPACITY, name="labels"):
    """The default ``LabelColors`` of a label volume: every label present but 0 in its
    LABEL_PALETTE colour with ``opacity`` per smallest spacing. Non-integer, negative or
    too large values, or nothing but the background, are an InputError (field labels)."""
    data = volume.data
    if volume.has_nonfinite:
        raise InputError("labels", f"{name} holds non-finite values; a label volume holds whole numbers")
    if data.dtype.kind == "f":
        fractional = data != np.round(data)
        if fractional.any():
            raise InputError("labels", f"{name} holds non-integer values such as {float(data[fractional].flat[0]):g}; "
                                       "a label volume holds whole numbers (a segmentation), not a scan")
    lo, hi = volume.data_range
    if lo < 0 or hi > MAX_LABEL:
        raise InputError("labels", f"{name} holds labels {lo:g}..{hi:g}; labels run from 0 to {MAX_LABEL}")
    present = np.flatnonzero(np.bincount(data.astype(np.int64, copy=False).ravel()))
    present = present[present > 0]
    if present.size == 0:
        raise InputError("labels", f"{name} holds only label 0 (the background): nothing to show")
    colors = {int(k): (*LABEL_PALETTE[(k - 1) % len(LABEL_PALETTE)], opacity) for k in present}
    return LabelColors(colors, unit_distance=float(min(volume.spacing)))


def label_layer(source, spacing, load_input, main=None):
    """A Layer for a label volume: a Layer as it is, else ``source``'s data in its default
    :func:`label_colors` (on the main volume's grid as :func:`on_main_grid` says)."""
    if isinstance(source, Layer):
        if not source.is_labels:
            raise InputError("labels", "a Layer given as labels must be classified by LabelColors")
        return source
    volume, _ = _grid(source, "labels", spacing, load_input)
    volume = on_main_grid(volume, source, main)
    return Layer(volume, label_colors(volume, name=_name(source)))


def read_channels(source, spacing=None, origin=None, mask_nonfinite=False):
    """(data, spacing, origin) of a channel input: a 4-D array (channels, nz, ny, nx), or
    a 4-D array file read as ``dvr-gl movie`` reads a series (its non-spatial axis is the
    channels). 2 to MAX_LAYERS channels, else an InputError (field channels)."""
    name = _name(source)
    if isinstance(source, np.ndarray):
        data, spacing, origin = source, spacing or (1.0, 1.0, 1.0), origin or (0.0, 0.0, 0.0)
    elif isinstance(source, (str, os.PathLike)) and dvr_io.is_series_file(source):
        series = dvr_io.load_series(source, spacing=spacing, origin=origin, mask_nonfinite=mask_nonfinite)
        data = np.stack([v.data for v in series])
        spacing, origin = tuple(series[0].spacing), tuple(series[0].origin)
    else:
        raise InputError("channels", f"reads the first axis of a 4-D array (channels, nz, ny, nx) or a 4-D .npy, "
                                     f".npz, .nrrd or .nii file as channels; {name} is not one")
    if data.ndim != 4 or not 2 <= data.shape[0] <= MAX_LAYERS:
        raise InputError("channels", f"reads 2 to {MAX_LAYERS} channels along the first axis; {name} has shape "
                                     f"{tuple(data.shape)}, so {data.shape[0] if data.ndim == 4 else 'no'} channels")
    return data, spacing, origin


@dataclass
class LayeredInput:
    """What the front ends render: the scene's own ``volume`` and ``tf`` (``tf_name``
    says where it came from), its extra ``layers`` and their ``blend``, and ``names``,
    a word on each volume in order (for messages)."""
    volume: object
    tf: object
    tf_name: str
    layers: tuple = ()
    blend: str = "mix"
    names: tuple = ()

    @property
    def framing(self):
        """What the first camera frames: the box around every volume, in the scene's
        own volume's anatomical frame."""
        if not self.layers:
            return self.volume
        extent = Extent(union_bounds((Layer(self.volume, self.tf),) + tuple(self.layers)))
        extent.orientation = getattr(self.volume, "orientation", None)
        return extent

    def describe(self):
        """A line on the volumes: each one's name, grid and classification, and the blend."""
        parts = []
        for name, layer in zip(self.names, (Layer(self.volume, self.tf),) + tuple(self.layers)):
            nz, ny, nx = layer.volume.shape
            kind = f"{len(layer.tf.colors)} labels" if layer.is_labels else "scan"
            parts.append(f"{name} ({nx}x{ny}x{nz}, {kind}{', placed' if layer.placed else ''})")
        return f"{len(parts)}, blend {self.blend}: " + "; ".join(parts)

    def scene_parts(self):
        """``layers`` and ``blend`` for a Scene (nothing when there is one volume)."""
        return {"layers": tuple(self.layers), "blend": self.blend} if self.layers else {}


def layered_input(main, tf_spec=None, layers=(), labels=None, channels=False, blend=None, spacing=None,
                  origin=None, mask_nonfinite=False, load_main=None, *, load_input, resolve_tf):
    """A :class:`LayeredInput` from the main input and the extras (see the module
    docstring). ``load_main()`` gives (data, preset) of the main input when it is not
    channels (default: ``load_input(main, spacing=spacing)``)."""
    extras = [layers] if isinstance(layers, (Layer, str, os.PathLike, np.ndarray, Volume)) else list(layers or ())
    given = ["the input" + (" as at least 2 channels" if channels else ""), f"{len(extras)} more"]
    check_volume_count((2 if channels else 1) + len(extras) + (labels is not None),
                       ", ".join(given) + (" and a label volume" if labels is not None else ""))
    blend = default_blend(channels, blend)
    if channels:
        if tf_spec is not None:
            raise InputError("tf", "each channel is coloured by its own ramp (dvr_gl.channel_layers); "
                                   "to choose their transfer functions, pass Layers")
        data, spacing_c, origin_c = read_channels(main, spacing, origin, mask_nonfinite)
        own = channel_layers(data, spacing=spacing_c, origin=origin_c)
        volume, tf, tf_name = own[0].volume, own[0].tf, "channel 1"
        more = own[1:]
        names = [f"channel {k + 1}" for k in range(len(own))]
    else:
        volume, preset = load_main() if load_main is not None else load_input(main, spacing=spacing)
        tf_name, tf = resolve_tf(tf_spec, volume, preset)
        more, names = [], [_name(main)]
    more += [scan_layer(x, spacing, load_input, resolve_tf, volume) for x in extras]
    names += [_name(x) for x in extras]
    if labels is not None:
        more.append(label_layer(labels, spacing, load_input, volume))
        names.append(_name(labels))
    check_volume_count(1 + len(more), ", ".join(names))
    return LayeredInput(volume, tf, tf_name, tuple(more), blend, tuple(names))


def describe_4d(path, out):
    """``dvr-gl info`` of a 4-D array file: its shape and the two ways to read it."""
    series = dvr_io.load_series(path)
    nz, ny, nx = series.shape
    n = len(series)
    print(f"4-D        {path}: {n} x {nx}x{ny}x{nz} (x, y, z) {series[0].data.dtype}", file=out)
    print("spacing    " + ",".join(f"{v:g}" for v in series[0].spacing), file=out)
    for k, v in enumerate(series.volumes[:MAX_LAYERS]):
        print(f"  [{k}]      values {v.data_range[0]:g}..{v.data_range[1]:g}", file=out)
    print(f"as time    {n} time steps: dvr-gl movie {path} -o out.mp4", file=out)
    if 2 <= n <= MAX_LAYERS:
        print(f"as channels {n} channels: dvr-gl render {path} --channels -o out.png (or view, movie)", file=out)
    else:
        print(f"as channels no: --channels reads 2 to {MAX_LAYERS} along that axis, this file has {n}", file=out)
    return 0
