"""The options the front ends share: what ``dvr-gl render`` and ``dvr-gl view`` take
(:func:`add_render_options`), their argument types, and the checks and loading that turn
them into a scene (:func:`technique_options`, :func:`load_input_args`,
:func:`resolve_tf_option`, ...). Bad input is a :class:`UsageError` naming the option.
The command line (:mod:`dvr_gl.frontends.cli`) and the viewer (:mod:`dvr_gl.frontends.viewer`) both build on
this module, so neither reaches into the other; loading and presets themselves live in
:mod:`dvr_gl.frontends.inputs`, which :func:`dvr_gl.render` shares too."""

from __future__ import annotations

import argparse
import math
import os

from .. import formats as dvr_io
from .inputs import PRESETS
from ..model.layers import BLENDS
from ..model.scene import MODES

SORTS = ("mpvo", "centroid", "walk")  # dvr_gl.techniques.tetra's orders (imported lazily there)

# Which command-line option an InputError's field stands for.
OPTION_OF_FIELD = {"path": "INPUT", "shape": "--shape", "dtype": "--dtype", "spacing": "--spacing",
                    "origin": "--origin", "size": "--size", "background": "--background",
                    "scalars": "--scalars", "tf": "--tf", "orientation": "--orientation",
                    "layers": "--volume", "labels": "--labels", "channels": "--channels", "blend": "--blend"}


class UsageError(Exception):
    """Bad input found after parsing: ``option`` names it, the message says why."""

    def __init__(self, option, message):
        self.option = option
        super().__init__(f"{option}: {message}")


# ----------------------------------------------------------------------------- argument types

def _arg_type(func, name):
    def convert(text):
        try:
            return func(text)
        except dvr_io.InputError as e:
            raise argparse.ArgumentTypeError(e.detail) from None
    convert.__name__ = name
    return convert


def _finite(text, positive=False):
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be finite, got {text!r}")
    if positive and value <= 0:
        raise argparse.ArgumentTypeError(f"must be positive, got {text!r}")
    return value


def _number(text):
    return _finite(text)


def _six_numbers(text):
    parts = text.split(",")
    if len(parts) != 6:
        raise argparse.ArgumentTypeError(f"expected six comma-separated numbers, got {text!r}")
    return tuple(_finite(p) for p in parts)


def _clip_plane(text):
    """X,Y,Z,NX,NY,NZ -> (point, normal)."""
    v = _six_numbers(text)
    return v[:3], v[3:]


def _crop_box(text):
    """X0,Y0,Z0,X1,Y1,Z1 -> (lower, upper)."""
    v = _six_numbers(text)
    return v[:3], v[3:]


def clip_args(args, data):
    """The ``clip_planes`` and ``crop_box`` of a Scene from ``--clip`` and ``--crop``,
    checked against ``data``; a bad one is a UsageError naming its option."""
    from ..model.clipping import check_clip_planes, check_crop_box
    planes = getattr(args, "clip", None) or ()
    crop = getattr(args, "crop", None)
    try:
        check_clip_planes(planes)
    except (TypeError, ValueError) as e:
        raise UsageError("--clip", str(e)) from None
    try:
        check_crop_box(crop, data.bounds)
    except (TypeError, ValueError) as e:
        raise UsageError("--crop", str(e)) from None
    return {"clip_planes": tuple(planes), "crop_box": crop}


def _color_value(text):
    rgb = dvr_io.parse_triplet(text, "geometry_color")
    if not all(0 <= v <= 1 for v in rgb):
        raise dvr_io.InputError("geometry_color", f"components must lie in [0, 1], got {text!r}")
    return rgb


_geometry_color = _arg_type(_color_value, "colour")


def geometry_args(args, technique):
    """The ``geometry`` of a Scene from ``--geometry`` files (``formats.load_surface``,
    coloured by ``--geometry-color``); a file that cannot be read, or a technique that
    does not draw geometry, is a UsageError naming the option."""
    from ..techniques.common import GEOMETRY_TECHNIQUES
    paths = getattr(args, "geometry", None) or ()
    color = getattr(args, "geometry_color", None)
    if color is not None and not paths:
        raise UsageError("--geometry-color", "colours the surfaces of --geometry; give one")
    if not paths:
        return {}
    if technique not in GEOMETRY_TECHNIQUES:
        raise UsageError("--geometry", f"is drawn by --technique {', '.join(GEOMETRY_TECHNIQUES)}, "
                                       f"not {technique}")
    surfaces = []
    for path in paths:
        try:
            surfaces.append(dvr_io.load_surface(path, **({} if color is None else {"color": color})))
        except dvr_io.InputError as e:
            raise UsageError("--geometry", e.detail) from None
    return {"geometry": tuple(surfaces)}


def whole_number(minimum):
    """An argument type: a whole number of at least ``minimum``."""
    def convert(text):
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be a whole number, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be {minimum} or more, got {value}")
        return value
    convert.__name__ = "whole number"
    return convert


_count = whole_number(0)


def _positive(text):
    return _finite(text, positive=True)


_size = _arg_type(dvr_io.parse_size, "size")
_shape = _arg_type(lambda t: dvr_io.parse_triplet(t, "shape", kind=int, positive=True), "shape")
_spacing = _arg_type(lambda t: dvr_io.parse_triplet(t, "spacing", positive=True), "spacing")
_origin = _arg_type(lambda t: dvr_io.parse_triplet(t, "origin"), "origin")
_orientation = _arg_type(dvr_io.parse_orientation, "orientation")


def _background_value(text):
    rgb = dvr_io.parse_triplet(text, "background")
    if not all(0 <= v <= 1 for v in rgb):
        raise dvr_io.InputError("background", f"components must lie in [0, 1] (1,1,1 is white), got {text!r}")
    return rgb


_background = _arg_type(_background_value, "background")


def _illustration(text):
    from ..model.scene import ILLUSTRATION_TERMS
    names = [t.strip() for t in text.split(",") if t.strip()]
    unknown = [n for n in names if n not in ILLUSTRATION_TERMS]
    if not names or unknown:
        raise argparse.ArgumentTypeError(f"terms are {', '.join(ILLUSTRATION_TERMS)}, got {text!r}")
    return tuple(names)


def _light(text):
    from .inputs import parse_light
    return _arg_type(parse_light, "light")(text)


# ----------------------------------------------------------------------------- the render options

def add_raw_options(parser, mask_help="treat NaN and inf samples as outside the volume instead of rejecting "
                                         "them"):
    """The options that describe a raw file or override a file's geometry: --shape,
    --dtype, --spacing, --origin, --orientation, --mask-nonfinite."""
    raw = parser.add_argument_group("raw and overriding geometry")
    raw.add_argument("--shape", type=_shape, metavar="NZ,NY,NX", help="sample counts of a raw file, z slowest")
    raw.add_argument("--dtype", metavar="D", help="sample type of a raw file: uint8, int16, <f4, >u2, ...")
    raw.add_argument("--spacing", type=_spacing, metavar="SX,SY,SZ",
                     help="sample spacing (required for raw files; replaces the file's otherwise)")
    raw.add_argument("--origin", type=_origin, metavar="OX,OY,OZ", help="world position of the first sample")
    add_orientation_option(raw)
    raw.add_argument("--mask-nonfinite", action="store_true", help=mask_help)
    return raw


def check_dtype_option(args):
    """A --dtype that names no sample type is a UsageError, before anything is read."""
    if getattr(args, "dtype", None) is not None:
        try:
            dvr_io._parse_dtype(args.dtype)
        except dvr_io.InputError as e:
            raise UsageError("--dtype", e.detail) from None


def add_render_options(r):
    """The options shared by ``render`` and ``view``: the input, its geometry, the transfer
    function, the technique and its options, the mode, the camera and the image size."""
    r.add_argument("input", metavar="INPUT", help="volume file, mesh file (.vtu, .vtk, .npz with points "
                                                  "and tets, ...) or builtin:NAME")
    r.add_argument("--tf", metavar="PRESET|FILE.json",
                   help=f"transfer function: a preset ({', '.join(PRESETS)}), ct_8bit:LO,HI (likewise "
                        "ct_bone_8bit, ct_lung_8bit) for CT windowed to 8 bits from LO to HI Hounsfield units, "
                        "cmap:NAME for any matplotlib colormap, or a JSON file "
                        "{\"color\": [[s, r, g, b], ...], \"opacity\": [[s, a], ...], \"unit_distance\": u}, "
                        "or a 2D one over (value, gradient magnitude) {\"widgets\": [...]} or {\"table\": ...}; "
                        "default: auto (the data set's own for builtin inputs)")
    r.add_argument("--technique", default=None,
                   help="rendering technique: raycast, slice2d or slice3d for volumes, tetra for meshes, "
                        "particles or splat for both (default: raycast, or tetra for a mesh)")
    r.add_argument("--scalars", metavar="NAME",
                   help="mesh inputs: the point array to render (default: the first scalar array)")
    r.add_argument("--sort", choices=("auto",) + SORTS,
                   help="tetra: cell order, exact per pixel (mpvo) or by centroid distance, or none: each ray "
                        "walked cell to cell on the GPU (walk) (default: auto, the walk for meshes of fewer "
                        "than 2^24 tets)")
    r.add_argument("--repetitions", type=_count, metavar="R",
                   help="particles: independent particle sets averaged (default: 1)")
    r.add_argument("--seed", type=_count, metavar="N", help="particles: random seed (default: 0)")
    r.add_argument("--radius", type=_positive, metavar="W",
                   help="particles: particle radius in world units (default: half a pixel at the data); "
                        "splat --kernel gaussian: kernel standard deviation in sample spacings (default: 0.4)")
    r.add_argument("--kernel", choices=("tent", "gaussian"),
                   help="splat: trilinear tents into post-classified sheets (default for grids) or "
                        "pre-classified Gaussian footprints (meshes' only kernel)")
    r.add_argument("--density", type=_count, metavar="K",
                   help="splat: sheets per smallest spacing (tent) or samples per spacing along each axis "
                        "(gaussian) (default: 1)")
    r.add_argument("--cutoff", type=_positive, metavar="C",
                   help="splat --kernel gaussian: kernel truncation in standard deviations (default: 3)")
    r.add_argument("--sampler", choices=("rejection", "uniform", "metropolis"),
                   help="particles: placement in each cell (default: rejection, unbiased)")
    r.add_argument("--step", type=_positive, metavar="S",
                   help="sampling step (slice distance for slice3d) in world units (default: half "
                        "the smallest spacing; slice2d takes none, see --interpolate; tetra none)")
    r.add_argument("--tolerance", type=_positive, metavar="E",
                   help="raycast: choose the step for an RMSE of at most E against the exact image "
                        "(measured on a small pilot of the same view); not with --step. A mesh: render "
                        "it the fastest way measured within E (tetra's sorts or a resampled grid)")
    r.add_argument("--preintegrate", action="store_true",
                   help="pre-integrated classification of whole segments (composite mode)")
    r.add_argument("--refine", type=whole_number(1), metavar="K",
                   help="raycast with --preintegrate: cut segments that may cross a bend of the TF's "
                        "opacity into K parts and at cell faces (adaptive sampling; default: 1, none)")
    r.add_argument("--brick-size", type=whole_number(1), metavar="N",
                   help="raycast, slice3d: draw the volume in bricks of N cells a side, one texture each "
                        "(particles, splat: made brick by brick; the same image to float rounding; default: "
                        "bricks only where a side exceeds one 3-D texture)")
    r.add_argument("--memory", type=_memory_size, metavar="SIZE",
                   help="raycast of a store (zarr, HDF5): bytes of bricks held at once, e.g. 2GB or 512MiB "
                        "(default: a quarter of the memory available)")
    r.add_argument("--interpolate", type=_count, metavar="K",
                   help="slice2d: K intermediate slices per cell (default: 0)")
    r.add_argument("--proxy", choices=("cpu", "vertex"),
                   help="slice3d: slice polygons made on the CPU or in the vertex shader (default: cpu)")
    r.add_argument("--shells", action="store_true",
                   help="slice3d: slice along spherical shells around the eye instead of planes")
    r.add_argument("--optical-model", choices=("emission_absorption", "absorption", "emission", "sabella"),
                   help="composite mode: emission and absorption (default), absorption only (C = 0, "
                        "A = 1 - T), emission only (C = integral of c tau, A = 0; written over black "
                        "unless --background), or sabella (raycast: brightness 1 - T, hue from the "
                        "ray's peak value, saturation fading with its depth)")
    r.add_argument("--illustration", type=_illustration, metavar="TERM[,TERM...]",
                   help="composite mode: Ebert-Rheingans terms with their default parameters: boundary, "
                        "silhouette (extinction scaled by gradient magnitude / by view angle), tone "
                        "(warm-to-cool colour), depth_cue (darker with depth)")
    r.add_argument("--shading", action=argparse.BooleanOptionalAction, default=None,
                   help="light the samples (Blinn-Phong, the headlight unless --light): on by default "
                        "where it is defined (raycast, slice3d, slice2d in composite mode with an "
                        "emitting optical model), on request for tetra (each cell's own gradient); "
                        "--no-shading turns it off")
    r.add_argument("--light", type=_light, action="append", metavar="SPACE:X,Y,Z[:I]",
                   help="with --shading: a directional light towards X,Y,Z in world or view space "
                        "(world:1,1,0, view:-1,1,1:0.5) or headlight[:I]; repeat for up to 4 "
                        "(default: the headlight)")
    r.add_argument("--gradients", choices=("on_the_fly", "texture"),
                   help="with --shading: gradients from six field lookups or one gradient-texture "
                        "lookup (default: on_the_fly)")
    r.add_argument("--target", choices=("rgba32f", "rgba16f", "rgba8"),
                   help="render target format (default: rgba32f)")
    r.add_argument("--mode", choices=MODES,
                   help="rendering mode (default: composite, or isosurface when --iso is given)")
    r.add_argument("--iso", type=_number, metavar="V", help="iso-value for --mode isosurface (data units)")
    r.add_argument("--clip", type=_clip_plane, action="append", metavar="X,Y,Z,NX,NY,NZ",
                   help="a clip plane through the world point X,Y,Z keeping the side its normal NX,NY,NZ "
                        "points to; repeat for up to 6")
    r.add_argument("--crop", type=_crop_box, metavar="X0,Y0,Z0,X1,Y1,Z1",
                   help="keep only what lies inside this axis-aligned box (world corners)")
    r.add_argument("--geometry", action="append", metavar="FILE",
                   help="raycast: an opaque triangle mesh (.obj, .stl, .ply, .vtk, ... in world units) drawn "
                        "inside the data, lit; rays end at it. Clips leave it whole. Repeat for more")
    r.add_argument("--geometry-color", type=_geometry_color, metavar="R,G,B",
                   help="the colour of the --geometry surfaces (components in [0, 1]; default: 0.85,0.85,0.85)")
    add_layer_options(r)
    r.add_argument("--size", type=_size, default=(512, 512), metavar="WxH",
                   help="image size in pixels (default: 512x512)")
    r.add_argument("--azimuth", type=_number, default=None, metavar="DEG",
                   help="turn the camera about the up direction (default: 30). 0 looks along -z with +y "
                        "up, or, for a scan with an anatomical orientation (from its file or --orientation), "
                        "at the face with the head up")
    r.add_argument("--elevation", type=_number, default=None, metavar="DEG",
                   help="then raise it towards the up direction (default: 20)")
    r.add_argument("--zoom", type=_positive, default=1.0, metavar="F", help="> 1 moves closer (default: 1)")
    r.add_argument("--fov", type=_positive, default=30.0, metavar="DEG",
                   help="vertical field of view (default: 30)")
    r.add_argument("--ortho", action="store_true", help="orthographic instead of perspective projection")
    r.add_argument("--background", type=_background, metavar="R,G,B",
                   help="composite over this colour (components in [0, 1]); render: default white "
                        "(black for --optical-model emission), RGB unless --transparent; view: the "
                        "window's first background, screenshots RGBA unless given")
    add_raw_options(r)
    r.add_argument("--backend", choices=("auto", "egl", "osmesa"), default="auto",
                   help="headless GL backend (default: auto, EGL then OSMesa)")


def add_layer_options(parser):
    """--volume, --labels, --channels and --blend: several volumes in one scene
    (:mod:`dvr_gl.frontends.layer_inputs`)."""
    g = parser.add_argument_group("several volumes (technique raycast, unlit)")
    g.add_argument("--volume", action="append", metavar="FILE",
                   help="another scan drawn with INPUT, on its own grid (its spacing and origin place it) with "
                        "its own automatic transfer function; repeat for more (4 volumes in all)")
    g.add_argument("--labels", metavar="FILE",
                   help="a label volume (a segmentation of whole numbers) shown in category colours, "
                        "label 0 transparent")
    g.add_argument("--channels", action="store_true",
                   help="INPUT is a 4-D array file whose first axis holds 2 to 4 channels (a microscope's), "
                        "each in its own colour")
    g.add_argument("--blend", choices=BLENDS,
                   help="how the volumes combine: mix, one medium (default; composite only), or add, each "
                        "volume's image summed (default with --channels; also for --mode mip, minip, average)")


def check_layer_options(args, mode):
    """The several-volume options against the rest, before anything is read; True when
    the scene has several volumes. Each conflict is a UsageError naming an option."""
    from ..model.layers import MAX_LAYERS
    from ..techniques.common import LAYER_TECHNIQUES
    extras, labels, channels = getattr(args, "volume", None) or (), getattr(args, "labels", None), \
        getattr(args, "channels", False)
    if not (extras or labels is not None or channels):
        if getattr(args, "blend", None) is not None:
            raise UsageError("--blend", "combines several volumes: give --volume, --labels or --channels")
        return False
    option = "--channels" if channels else "--volume" if extras else "--labels"
    if input_is_mesh(args):
        raise UsageError(option, f"combines grid volumes; {args.input} is a mesh")
    if args.technique not in LAYER_TECHNIQUES:
        raise UsageError("--technique", f"{args.technique} renders one volume; several ({option}) are rendered by "
                                        f"--technique {' or '.join(LAYER_TECHNIQUES)}")
    if getattr(args, "shading", None):
        raise UsageError("--shading", f"lighting several volumes is not rendered yet; leave it out with {option}")
    if channels and args.tf is not None:
        raise UsageError("--tf", "--channels colours each channel with its own ramp; leave out --tf")
    if channels and (args.shape is not None or args.dtype is not None):
        raise UsageError("--channels", "reads a 4-D array file (.npy, .npz, .nrrd, .nii), not raw samples")
    count = (2 if channels else 1) + len(extras) + (labels is not None)
    if count > MAX_LAYERS:
        raise UsageError("--volume" if extras else "--channels", f"a scene holds at most {MAX_LAYERS} volumes in all, "
                         f"got {count}: INPUT{' (2 or more channels)' if channels else ''}, {len(extras)} --volume"
                         + (" and --labels" if labels is not None else ""))
    blend = args.blend or ("add" if channels else "mix")
    modes = ("composite",) if blend == "mix" else ("composite", "mip", "minip", "average")
    if mode not in modes:
        raise UsageError("--mode", f"--blend {blend} renders --mode {' or '.join(modes)}, not {mode}"
                         + (" (a mix is one medium: use --blend add)" if blend == "mix" else ""))
    if labels is not None and mode != "composite":
        raise UsageError("--labels", f"label volumes are composited; --mode {mode} has no meaning for labels")
    return True


def load_layered_args(args):
    """The scene's data from the parsed options: a :class:`layer_inputs.LayeredInput`
    (one volume, or INPUT with --volume, --labels, --channels and --blend)."""
    from .inputs import load_input, resolve_tf
    from .layer_inputs import LayeredInput, layered_input, wants_layers
    extras, labels, channels = getattr(args, "volume", None) or (), getattr(args, "labels", None), \
        getattr(args, "channels", False)
    if not wants_layers(extras, labels, channels):
        volume, preset = load_input_args(args)
        name, tf = resolve_tf_option(args.tf, volume, preset)
        return LayeredInput(volume, tf, name, names=(args.input,))
    return layered_input(args.input, args.tf, extras, labels, channels, getattr(args, "blend", None), args.spacing,
                         args.origin, args.mask_nonfinite, load_main=lambda: load_input_args(args),
                         load_input=load_input, resolve_tf=resolve_tf)


def add_orientation_option(group):
    """``--orientation CODE``, shared by render, view and info."""
    group.add_argument("--orientation", type=_orientation, metavar="CODE",
                       help="where the x, y and z axes point anatomically, three letters such as RAS (x "
                            "towards the patient's right, y anterior, z superior) or LPI; replaces the "
                            "file's, or supplies one where the file has none, so that the first view "
                            "faces the subject with the head up")


# which technique takes which option
TECHNIQUE_OPTIONS = {"interpolate": ("slice2d",), "proxy": ("slice3d",), "shells": ("slice3d",),
                     "preintegrate": ("raycast", "slice2d", "slice3d"), "refine": ("raycast",), "sort": ("tetra",),
                     "repetitions": ("particles",), "seed": ("particles",), "radius": ("particles", "splat"),
                     "sampler": ("particles",), "density": ("splat",), "cutoff": ("splat",), "kernel": ("splat",),
                     "gradients": ("raycast", "slice2d", "slice3d"), "tolerance": ("raycast", "tetra"),
                     "brick_size": ("raycast", "slice3d", "particles", "splat"), "memory": ("raycast",)}

#: the techniques that render meshes (cell projection); the others render grid volumes
MESH_TECHNIQUES = ("tetra",)
GRID_TECHNIQUES = ("raycast", "slice2d", "slice3d")

# volume-only options (raw geometry and masking): given with a mesh INPUT, a usage error
_VOLUME_OPTIONS = (("spacing", "--spacing"), ("origin", "--origin"), ("mask_nonfinite", "--mask-nonfinite"),
                   ("orientation", "--orientation"))


def input_is_mesh(args):
    """Whether INPUT is a mesh (rendered by cell projection) rather than a grid volume.
    Raw geometry (--shape, --dtype) makes it a volume, whatever its extension."""
    from .inputs import is_mesh_input
    return is_mesh_input(getattr(args, "input", None) or "", getattr(args, "shape", None),
                         getattr(args, "dtype", None))


def _memory_size(text):
    """--memory: a size such as 2GB, kept as given (dvr_gl.util.memory.parse_bytes)."""
    from ..util.memory import parse_bytes
    try:
        parse_bytes(text, "--memory")
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None
    return text


def technique_options(args):
    """The keyword arguments for ``Renderer.render`` from parsed render options; an option
    the chosen technique does not take is a usage error naming it, and so is a technique
    for the other kind of input (a grid technique on a mesh, tetra on a volume). Without
    --technique, ``args.technique`` is set to tetra for a mesh INPUT, raycast otherwise."""
    mesh = input_is_mesh(args)
    if args.technique is None:
        args.technique = MESH_TECHNIQUES[0] if mesh else "raycast"
    _check_input_kind(args, mesh)
    kwargs = {"technique": args.technique}
    if getattr(args, "tolerance", None) is not None and args.step is not None:
        raise UsageError("--tolerance", "chooses the step: leave out --step")
    if getattr(args, "tolerance", None) is not None and getattr(args, "sort", None) is not None:
        raise UsageError("--tolerance", "picks the mesh's way of rendering (tetra's sort or a grid): leave out --sort")
    if (getattr(args, "refine", None) or 1) > 1 and not getattr(args, "preintegrate", False):
        raise UsageError("--refine", f"cuts pre-integrated segments: add --preintegrate (got --refine {args.refine})")
    for name in ("step", "tolerance", "preintegrate", "refine", "interpolate", "proxy", "shells", "sort", "repetitions",
                 "seed", "radius", "sampler", "kernel", "density", "cutoff", "gradients", "target", "brick_size",
                 "memory"):
        value = getattr(args, name, None)
        if value is None or value is False:
            continue
        takers = TECHNIQUE_OPTIONS.get(name)
        if takers is not None and args.technique not in takers:
            raise UsageError(f"--{name}", f"applies to --technique {' or '.join(takers)} only, "
                                          f"not {args.technique}")
        if name == "step" and args.technique == "slice2d":
            raise UsageError("--step", "slice2d's slice distance is fixed by the data "
                                       "(spacing / (interpolate + 1)); use --interpolate K")
        if name == "step" and args.technique in MESH_TECHNIQUES:
            raise UsageError("--step", f"{args.technique} integrates each cell exactly and takes no step")
        if name == "step" and args.technique == "particles":
            raise UsageError("--step", "particles takes no step (the particles' density follows the TF)")
        if name == "step" and args.technique == "splat":
            raise UsageError("--step", "splat takes no step; --density sets the samples per spacing")
        kwargs[name] = value
    return kwargs


def _check_input_kind(args, mesh):
    """Technique and input options against the kind of INPUT (mesh or grid volume)."""
    technique = args.technique
    if mesh and technique in GRID_TECHNIQUES:
        raise UsageError("--technique", f"{technique} renders grid volumes, but {args.input} is a mesh; "
                                        f"use --technique {' or '.join(MESH_TECHNIQUES)}")
    if not mesh and technique in MESH_TECHNIQUES:
        raise UsageError("--technique", f"{technique} renders tetrahedral meshes, but {args.input} is a "
                                        f"grid volume; use --technique {', '.join(GRID_TECHNIQUES[:-1])} or {GRID_TECHNIQUES[-1]}")
    _check_input_options(args, mesh)


def _check_input_options(args, mesh):
    """--scalars only for meshes, the raw-volume options only for grids."""
    if not mesh and getattr(args, "scalars", None) is not None:
        raise UsageError("--scalars", f"chooses a mesh's point array; {args.input} is a grid volume")
    if mesh:
        for attr, option in _VOLUME_OPTIONS:
            value = getattr(args, attr, None)
            if value is not None and value is not False:
                raise UsageError(option, f"is for grid volumes, not the mesh {args.input}")


# ----------------------------------------------------------------------------- loading

def load_input_args(args):
    """The volume (or mesh) and the default preset name (dvr_gl.frontends.inputs.load_input)."""
    from .inputs import load_input
    return load_input(args.input, scalars=getattr(args, "scalars", None), shape=args.shape, dtype=args.dtype,
                      spacing=args.spacing, origin=args.origin, mask_nonfinite=args.mask_nonfinite,
                      orientation=getattr(args, "orientation", None))


def resolve_tf_option(spec, volume, default):
    from .inputs import resolve_tf
    try:
        return resolve_tf(spec, volume, default)
    except dvr_io.InputError as e:
        raise UsageError("--tf", e.detail) from None


def check_png(path, option="--out"):
    """``path`` names a PNG file in an existing folder (nothing is written yet)."""
    if not path.lower().endswith(".png"):
        raise UsageError(option, f"must name a .png file, got {path!r}")
    directory = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(directory):
        raise UsageError(option, f"the folder {directory!r} does not exist")
    if os.path.isdir(path):
        raise UsageError(option, f"{path!r} is a folder")


def check_technique(name):
    if name is None:  # the default for the input's kind: technique_options picks it
        return
    try:
        from ..techniques import names
    except ImportError:  # no registry: the renderer will judge
        return
    if name not in names():
        raise UsageError("--technique", f"must be one of {', '.join(names())}, got {name!r}")
