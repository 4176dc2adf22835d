"""What the front ends share: turning what a user names (a file, a bundled data set, an
array) into scene data, and a transfer-function name into a transfer function; and
``dvr_gl.render``, the one-line way to a picture.

The command line (``dvr_gl.frontends.cli``), the viewer and :func:`render` use these, so that a
file, a preset or an error reads the same everywhere. Errors are
:class:`dvr_gl.formats.InputError` with the field that was wrong (``path``, ``shape``,
``dtype``, ``tf``, ...); the command line names its own option for each field.
"""

from __future__ import annotations

import os

import numpy as np

from .. import formats as dvr_io
from ..formats import InputError


def _transfer():
    from ..model import transfer
    return transfer


def _data():
    from .. import data
    return data


#: transfer-function presets: name -> function(data) -> TransferFunction.
PRESETS = {
    "auto": lambda data: _transfer().auto_preset(data),
    "ct": lambda data: _transfer().ct_preset(data, "ct"),
    "ct_bone": lambda data: _transfer().ct_preset(data, "ct_bone"),
    "ct_lung": lambda data: _transfer().ct_preset(data, "ct_lung"),
    "ct_8bit": lambda data: _transfer().ct_8bit_preset(data, "ct_8bit"),
    "ct_bone_8bit": lambda data: _transfer().ct_8bit_preset(data, "ct_bone_8bit"),
    "ct_lung_8bit": lambda data: _transfer().ct_8bit_preset(data, "ct_lung_8bit"),
    "mr": lambda data: _transfer().mr_preset(data),
    "warm": lambda data: _transfer().ramp_preset(data, _transfer().RAMPS["warm"]),
    "coolwarm": lambda data: _transfer().ramp_preset(data, _transfer().RAMPS["coolwarm"]),
    "grey": lambda data: _transfer().ramp_preset(data, _transfer().RAMPS["grey"]),
    **{name: (lambda data, name=name: _transfer().colormap_preset(data, name))
       for name in _transfer().COLORMAPS},
    "ct_head": lambda data: _data().ct_head_tf(),
    "synthetic": lambda data: _data().synthetic_tf(),
}

#: bundled data sets, named ``builtin:NAME``: name -> (loader, default preset).
BUILTINS = {
    "ct_head": (lambda: _data().ct_head(), "ct_head"),
    "synthetic": (lambda: _data().synthetic(), "synthetic"),
}


def suitable_presets(data):
    """The preset names that suit ``data``: auto first, the CT ones for Hounsfield units,
    their 8-bit forms for 8-bit data that may be CT (modality CT or not known), mr for an
    MRI (modality MR, or an anatomically oriented volume), then the generic ramps and
    colormaps."""
    transfer = _transfer()
    names = ["auto"]
    modality = getattr(data, "modality", None)
    if transfer.looks_like_hu(data):
        names += ["ct", "ct_bone", "ct_lung"]
    elif transfer.is_8bit(data) and modality in (None, "CT"):
        names += list(transfer.CT_8BIT_WINDOWS)
    if modality == "MR" or transfer.is_oriented_scan(data):
        names.append("mr")
    names += ["warm", "coolwarm", "grey"]
    import importlib.util
    if importlib.util.find_spec("matplotlib") is not None:   # the colormap presets need it
        names += ["viridis", "magma"]
    return names


def is_mesh_input(source, shape=None, dtype=None):
    """Whether the named ``source`` is a mesh (rendered by cell projection) rather than a
    grid volume: a mesh file (``dvr_gl.formats.is_mesh_file``), unless raw geometry (``shape``,
    ``dtype``) makes it a volume whatever its extension."""
    if not isinstance(source, (str, os.PathLike)):
        return False
    path = os.fspath(source)
    if not path or path.startswith("builtin:") or shape is not None or dtype is not None:
        return False
    return dvr_io.is_mesh_file(path)


def load_input(source, *, scalars=None, shape=None, dtype=None, spacing=None, origin=None, mask_nonfinite=False,
               orientation=None):
    """(data, default preset name) for ``source``: a file (a volume, or a mesh as
    ``dvr_gl.formats.is_mesh_file`` tells), ``"builtin:NAME"`` (a bundled data set), a 3-D
    array (nz, ny, nx), or a ``Volume`` / ``TetMesh`` (returned as it is). ``spacing``
    and ``origin`` apply to arrays and bundled data too; ``shape`` and ``dtype`` are for
    raw files. ``orientation`` (three letters such as ``"RAS"``: where the x, y and z
    axes point anatomically) replaces or supplies a volume's; a mesh takes none."""
    from ..model.mesh import TetMesh
    from ..model.volume import Volume
    if orientation is not None:
        orientation = dvr_io.parse_orientation(orientation)
        if isinstance(source, TetMesh) or is_mesh_input(source, shape, dtype):
            raise InputError("orientation", "is for grid volumes (anatomical scans), not meshes")
    if isinstance(source, Volume):
        if orientation is None or orientation == source.orientation:
            return source, "auto"
        data, orientation = dvr_io.right_handed(source.data, orientation)     # no mirror image
        return Volume(data, spacing=source.spacing, origin=source.origin, mask_nonfinite=source.mask_nonfinite,
                      orientation=orientation, modality=source.modality), "auto"
    if isinstance(source, TetMesh) or _is_lazy(source):
        return source, "auto"
    if isinstance(source, np.ndarray):
        data, orientation = dvr_io.right_handed(source, orientation)
        return Volume(data, spacing=spacing or (1.0, 1.0, 1.0), origin=origin or (0.0, 0.0, 0.0),
                      mask_nonfinite=mask_nonfinite, orientation=orientation), "auto"
    try:
        path = os.fspath(source)
    except TypeError:
        raise InputError("path", f"expected a file name, 'builtin:NAME', an array or a Volume, "
                                 f"got {type(source).__name__}") from None
    if path.startswith("builtin:"):
        name = path[len("builtin:"):].replace("-", "_")
        if name not in BUILTINS:
            raise InputError("path", f"no bundled data set {name!r}; there are "
                                     f"{', '.join('builtin:' + n for n in BUILTINS)}")
        for field, value in (("shape", shape), ("dtype", dtype)):
            if value is not None:
                raise InputError(field, f"is for raw files, not the bundled {path}")
        loader, preset = BUILTINS[name]
        volume = loader()
        if spacing is not None or origin is not None or orientation is not None:
            data, orientation = dvr_io.right_handed(volume.data, orientation or volume.orientation)
            volume = Volume(data, spacing=spacing or volume.spacing, origin=origin or volume.origin,
                            orientation=orientation, modality=volume.modality)
        return volume, preset
    if is_mesh_input(path, shape, dtype):
        return dvr_io.load_mesh(path, scalars=scalars), "auto"
    from ..formats.stores import split_key, store_kind
    store_path, _ = split_key(path)
    if os.path.exists(store_path) and store_kind(store_path) in ("zarr", "hdf5"):   # read brick by brick
        return dvr_io.open_volume(path, spacing=spacing, origin=origin), "auto"
    return dvr_io.load_volume(path, shape=shape, dtype=dtype, spacing=spacing, origin=origin,
                              mask_nonfinite=mask_nonfinite, orientation=orientation), "auto"


def _is_tf2d_file(path):
    """Whether a JSON file holds a 2D transfer function (widgets or a table)."""
    import json
    try:
        with open(path) as f:
            spec = json.load(f)
    except (OSError, ValueError):
        return False           # the 1D reader reports what is wrong with it
    return isinstance(spec, dict) and ("widgets" in spec or "table" in spec)


def _is_lazy(data):
    from ..model.lazy_volume import LazyVolume
    return isinstance(data, LazyVolume)


def range_tf(data, spec=None):
    """A LazyVolume's transfer function (``tf`` None or "auto"): the warm ramp from the
    middle of the range its brick summary gives to its top (the presets' percentiles
    would read every sample). Other presets are an InputError naming ``tf``."""
    if spec not in (None, "auto"):
        raise InputError("tf", f"presets other than 'auto' read every sample's value; a store read brick by "
                               f"brick takes 'auto' (a ramp over its summary's range), a JSON file or a "
                               f"TransferFunction, got {spec!r}")
    from ..model.transfer_function import TransferFunction
    lo, hi = data.data_range
    lo, hi = (lo + hi) / 2, (hi if hi > lo else lo + 1.0)
    colors = _transfer().RAMPS["warm"]
    xs = np.linspace(lo, hi, len(colors))
    return TransferFunction(color=[(float(x), *c) for x, c in zip(xs, colors)], opacity=[(lo, 0.0), (hi, 0.5)],
                            unit_distance=data.min_spacing)


def resolve_tf(spec, data, default="auto"):
    """(name, transfer function) for ``spec``: None (the ``default`` preset), a preset
    name, a JSON file (``dvr_gl.model.transfer.load_tf_json``; with "widgets" or "table", a 2D
    one, ``dvr_gl.model.transfer2d.load_tf2d_json``, whose ranges default to the data's values
    and gradient magnitudes) or a TransferFunction (1D or 2D)."""
    from ..model.transfer_function import TransferFunction, TransferFunction2D
    from ..model.transfer import load_tf_json
    if isinstance(spec, (TransferFunction, TransferFunction2D)):
        return "given", spec
    if _is_lazy(data) and (spec is None or str(spec) in PRESETS or str(spec).startswith("cmap:")):
        return "range", range_tf(data, spec)
    if spec is None:
        return default, PRESETS[default](data)
    key = str(spec).replace("-", "_")
    try:
        if key in PRESETS:  # a file that happens to have a preset's name: pass it as ./NAME
            return key, PRESETS[key](data)
        if key.startswith("cmap:"):
            return key, _transfer().colormap_preset(data, str(spec)[5:])
        kind, colon, window = key.partition(":")
        if colon and kind in _transfer().CT_8BIT_WINDOWS:     # ct_8bit:LO,HI, the window in HU
            window = str(spec).partition(":")[2]               # as given: "-" is a minus sign here
            return f"{kind}:{window}", _transfer().ct_8bit_preset(data, kind, _transfer().parse_hu_window(window))
    except ValueError as e:
        raise InputError("tf", str(e)) from None
    if os.path.isfile(spec):
        try:
            if _is_tf2d_file(spec):
                from ..model.field import gradient_max
                from ..model.transfer2d import load_tf2d_json
                return spec, load_tf2d_json(spec, data.data_range, (0.0, gradient_max(data)))
            return spec, load_tf_json(spec)
        except (ValueError, TypeError) as e:
            raise InputError("tf", str(e)) from None
        except OSError as e:
            raise InputError("tf", f"cannot read {spec!r}: {e}") from None
    if str(spec).lower().endswith(".json"):
        raise InputError("tf", f"no such file {spec!r}")
    raise InputError("tf", f"{spec!r} is neither a preset ({', '.join(PRESETS)}, cmap:NAME for any matplotlib "
                           f"colormap, ct_8bit:LO,HI for 8-bit CT windowed from LO to HI HU) nor a file")


#: the first view's turn (degrees), as pyvista's default view is oblique: azimuth about
#: the up direction, then elevation towards it
FIRST_AZIMUTH, FIRST_ELEVATION = 30.0, 20.0


def first_camera(data, azimuth=None, elevation=None, zoom=1.0, fov=30.0, ortho=False):
    """The camera a front end starts with: ``default_camera`` in the data's own frame
    (for a volume with an anatomical orientation, the eye in front of the face with the
    head up; otherwise looking along -z with +y up), turned by ``azimuth`` and
    ``elevation``, which default to an oblique FIRST_AZIMUTH, FIRST_ELEVATION."""
    from ..model.camera import anatomical_frame, default_camera
    frame = anatomical_frame(data)
    azimuth = FIRST_AZIMUTH if azimuth is None else azimuth
    elevation = FIRST_ELEVATION if elevation is None else elevation
    extra = {} if frame is None else {"front": frame[0], "up": frame[1]}
    return default_camera(data, azimuth=azimuth, elevation=elevation, zoom=zoom, fov=fov, ortho=ortho, **extra)


# where front ends light by default; tetra lights when asked (a cell's gradient is constant,
# so lighting shows the cells' facets)
LIGHTING_TECHNIQUES = ("raycast", "slice3d", "slice2d")


def shading_for(technique, mode="composite", optical_model="emission_absorption", wanted=True):
    """Whether a front end lights the scene: what the user wants (by default yes), where
    it is defined: the techniques that light samples, composite mode, an optical model
    that emits (isosurfaces are always lit)."""
    return bool(wanted) and technique in LIGHTING_TECHNIQUES and mode == "composite" \
        and optical_model in ("emission_absorption", "emission")


def parse_light(text):
    """A light from text: ``headlight``, ``world:X,Y,Z`` or ``view:X,Y,Z`` (the direction
    towards the light), each optionally followed by ``:INTENSITY``."""
    from ..model.camera import Light
    parts = str(text).strip().split(":")
    space = parts[0].strip().lower()
    try:
        if space == "headlight" and len(parts) <= 2:
            return Light(intensity=float(parts[1]) if len(parts) == 2 else 1.0)
        if space in Light.SPACES and len(parts) in (2, 3):
            direction = dvr_io.parse_triplet(parts[1], "light")
            return Light(direction, space=space, intensity=float(parts[2]) if len(parts) == 3 else 1.0)
    except ValueError as e:
        raise InputError("light", f"{e} in {text!r}") from None
    raise InputError("light", f"expected headlight[:I], world:X,Y,Z[:I] or view:X,Y,Z[:I], got {text!r}")


_RENDERERS = {}


def _surfaces(geometry):
    """``geometry`` for a Scene: Surfaces as they are, file names read as surfaces."""
    items = (geometry,) if isinstance(geometry, (str, os.PathLike)) or hasattr(geometry, "faces") else geometry
    if items is None:
        return ()
    try:
        items = tuple(items)
    except TypeError:
        return geometry                       # the Scene names what is wrong
    return tuple(dvr_io.load_surface(g) if isinstance(g, (str, os.PathLike)) else g for g in items)


def render(source, *, tf=None, technique=None, size=(512, 512), azimuth=None, elevation=None, zoom=1.0, fov=30.0,
           ortho=False, mode="composite", iso=None, shading=None, lights=None, scalars=None, spacing=None,
           orientation=None, clip_planes=(), crop_box=None, geometry=(), layers=(), labels=None, channels=False,
           blend=None, backend="auto", **options):
    """Render ``source`` (anything :func:`load_input` takes) in one call; returns the
    (height, width, 4) float32 premultiplied RGBA image, row 0 on top, as a
    :class:`dvr_gl.frontends.images.RenderedImage` (an ndarray that Jupyter shows as a picture).

    >>> image = dvr_gl.render("ct.nrrd", azimuth=30, elevation=20)          # doctest: +SKIP
    >>> image = dvr_gl.render(np.random.rand(32, 32, 32), tf="auto")          # doctest: +SKIP

    ``tf``: a preset name, a JSON file or a TransferFunction (default: the data's
    preset). ``technique``: as ``Renderer.render`` (default: raycast for grids, tetra
    for meshes); its own options (``step``, ``sort``, ``repetitions``, ...) pass through
    ``options``. The camera is :func:`first_camera` (an oblique view, in front of the
    face for an anatomically oriented volume; ``orientation="LPS"`` and the like says
    where a scan's axes point when its file does not). Composite samples are lit where the
    technique lights them (:func:`shading_for`) unless ``shading=False``; ``lights``: a
    ``dvr_gl.Light`` or a list of them (the headlight by default). One renderer per
    backend is kept for the process, so later calls do not compile or upload again.
    ``clip_planes`` and ``crop_box`` cut the data as in :class:`dvr_gl.Scene`; ``geometry``:
    opaque :class:`dvr_gl.Surface` meshes (or surface files, read by
    :func:`dvr_gl.formats.load_surface`) drawn with the data (technique raycast). A zarr
    store or HDF5 file (or a LazyVolume) is read brick by brick by raycast, within
    ``memory=`` bytes of bricks (a size such as "2GB"; ``techniques.lazy_bricks``).

    Several volumes (:mod:`dvr_gl.frontends.layer_inputs`; rendered by raycast, unlit):
    ``layers``: extra scans, each anything ``source`` may be (classified by its own
    automatic transfer function) or a :class:`dvr_gl.Layer`; ``labels``: a label volume
    shown in category colours (0 transparent); ``channels=True`` reads ``source``'s first
    axis as 2 to 4 channels; ``blend``: "mix" (default) or "add" (default for channels)."""
    from ..rendering.renderer import Renderer
    from ..model.scene import Scene
    from .layer_inputs import layered_input, wants_layers
    layered = None
    if wants_layers(layers, labels, channels):
        layered = layered_input(source, tf, layers, labels, channels, blend, spacing, load_main=lambda: load_input(
            source, scalars=scalars, spacing=spacing, orientation=orientation), load_input=load_input,
                                resolve_tf=resolve_tf)
        data, tf = layered.volume, layered.tf
    else:
        if blend is not None:
            raise InputError("blend", f"combines several volumes (layers, labels or channels); got blend={blend!r} "
                                      "with one")
        data, preset = load_input(source, scalars=scalars, spacing=spacing, orientation=orientation)
        _, tf = resolve_tf(tf, data, preset)
    try:
        width, height = (int(size), int(size)) if np.isscalar(size) else (int(size[0]), int(size[1]))
    except (TypeError, ValueError, IndexError):
        raise InputError("size", f"expected an int or (width, height), got {size!r}") from None
    if technique is None:
        technique = "tetra" if getattr(data, "n_tets", None) is not None else "raycast"
    if iso is not None and not data.data_range[0] <= iso <= data.data_range[1]:
        import warnings
        warnings.warn(f"iso {iso:g} is outside the data's range {data.data_range[0]:g}..{data.data_range[1]:g}: "
                      "the surface is empty", stacklevel=2)
    if shading is None:
        shading = shading_for(technique, mode) and layered is None    # several volumes are not lit yet
    scene = Scene(data, tf, first_camera(data if layered is None else layered.framing, azimuth=azimuth,
                                         elevation=elevation, zoom=zoom, fov=fov, ortho=ortho),
                  width=width, height=height, mode=mode, iso_value=iso, shading=shading,
                  **({} if lights is None else {"lights": lights}), clip_planes=clip_planes, crop_box=crop_box,
                  geometry=_surfaces(geometry), **({} if layered is None else layered.scene_parts()))
    renderer = _RENDERERS.get(backend)
    if renderer is None:
        renderer = _RENDERERS[backend] = Renderer(backend=backend)
    from .images import RenderedImage        # shows itself in Jupyter; a plain array otherwise
    return RenderedImage(renderer.render(scene, technique=technique, **options))
