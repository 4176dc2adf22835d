"""What the command line decides before any window opens: :class:`Settings`, made from
``dvr-gl view``'s arguments by :func:`settings_from_args` (which checks the options and
loads the input, so that a bad file fails here).

The viewer takes every option of ``dvr-gl render`` (:func:`build_parser`) and a few of its
own. The data is a :class:`dvr_gl.Volume` or a :class:`dvr_gl.TetMesh` (:func:`is_mesh`).
"""

from __future__ import annotations

import argparse
import os
from dataclasses import dataclass, field

from ...model.mesh import TetMesh

PROG = "dvr-gl view"


def is_mesh(volume):
    """Whether the data is a tetrahedral mesh (else a grid)."""
    return isinstance(volume, TetMesh)


def describe_data(volume):
    """A few words on the data for the title and the console: the grid's shape (x, y, z),
    or a mesh's point and cell counts."""
    if is_mesh(volume):
        return f"{volume.n_points} points, {volume.n_tets} tets"
    nz, ny, nx = volume.shape
    return f"{nx}x{ny}x{nz}"


@dataclass
class Settings:
    """What the command line decided. ``volume``: a :class:`dvr_gl.Volume` or a
    :class:`dvr_gl.TetMesh` (shown with a technique that renders meshes: tetra)."""
    volume: object
    tf: object
    tf_name: str = "auto"
    input_name: str = ""
    technique: str = "raycast"
    mode: str = "composite"
    iso: float | None = None
    step: float | None = None
    size: tuple = (512, 512)
    azimuth: float | None = None         # None: the first view's (inputs.first_camera)
    elevation: float | None = None
    zoom: float = 1.0
    fov: float = 30.0
    ortho: bool = False
    background: tuple | None = None     # screenshots: RGB over this, else RGBA (as render)
    screenshot: str | None = None
    tf_out: str = "dvr-gl-tf.json"
    editor: bool = True
    vsync: bool = True
    visible: bool = True
    options: dict = field(default_factory=dict)   # technique options (preintegrate, interpolate, ...)
    shading: bool | None = None          # lit composite (key l switches it); None: lit where defined
    optical_model: str = "emission_absorption"   # composite's optical model (key x cycles it)
    illustration: tuple = ()             # Ebert-Rheingans terms by name (key i cycles them)
    lights: tuple | None = None          # dvr_gl.Light objects; None: the headlight
    tolerance: float | None = None       # raycast: full frames at the step for this RMSE
    clip_planes: tuple = ()              # ((point, normal), ...), world units
    crop_box: tuple | None = None        # (lower, upper) world corners
    geometry: tuple = ()                 # opaque dvr_gl.Surface meshes (--geometry)
    layers: tuple = ()                   # more volumes (dvr_gl.Layer): --volume, --labels, --channels
    blend: str = "mix"                   # how the volumes combine (--blend)
    layer_names: tuple = ()              # a name for each volume, INPUT's first


def build_parser():
    """``dvr-gl render``'s options (:func:`dvr_gl.frontends.options.add_render_options`) plus the viewer's."""
    from ..options import add_render_options, whole_number

    description = ("Open a volume in an interactive window. Takes every option of dvr-gl render "
                   "(--size is the window size). Press h in the window for the keys.")
    epilog = "Off-screen (scripts, CI): xvfb-run -a dvr-gl view INPUT --screenshot out.png --frames 5"
    parser = argparse.ArgumentParser(prog=PROG, description=description, epilog=epilog)
    add_render_options(parser)
    parser.add_argument("--out", "-o", help=argparse.SUPPRESS)
    for action in parser._actions:
        if action.dest == "out":  # render's --out: here another name for --screenshot
            action.required = False
            action.help = argparse.SUPPRESS
        elif action.dest == "size":
            action.help = "window size in pixels (default: 512x512)"
        elif action.dest == "backend":
            action.help = "accepted for dvr-gl render's sake; the viewer renders in its window's context"
    parser.add_argument("--screenshot", metavar="IMAGE.png",
                        help="where s (and --frames) write the screenshot: the render without overlays, "
                             "as dvr-gl render writes it (default: dvr-gl-view-NNN.png)")
    parser.add_argument("--frames", type=whole_number(1), metavar="N",
                        help="render N frames at full quality, save the screenshot (if --screenshot) and exit")
    parser.add_argument("--tf-out", default="dvr-gl-tf.json", metavar="FILE.json",
                        help="where ctrl+s saves the edited transfer function and ctrl+o loads it from "
                             "(default: dvr-gl-tf.json)")
    parser.add_argument("--hide-editor", action="store_true", help="start with the transfer-function editor hidden")
    return parser


def settings_from_args(args) -> Settings:
    """Check the options and load the input (no window yet): a bad file fails here."""
    from ..options import UsageError, check_png, check_technique, check_layer_options, load_layered_args, \
        technique_options, clip_args, geometry_args, check_dtype_option

    screenshot, option = (args.screenshot, "--screenshot") if args.screenshot else (args.out, "--out")
    if screenshot:
        check_png(screenshot, option)
    check_technique(args.technique)
    options = dict(technique_options(args))    # checks that each option fits the technique
    options.pop("technique", None)
    options.pop("step", None)
    tolerance = options.pop("tolerance", None)
    # unlike render, isosurface mode needs no --iso: the viewer picks one (keys , and . move it)
    mode = args.mode or ("isosurface" if args.iso is not None else "composite")
    if args.iso is not None and mode != "isosurface":
        raise UsageError("--iso", f"is only used with --mode isosurface, not --mode {mode}")
    check_dtype_option(args)
    if not args.tf_out.lower().endswith(".json"):
        raise UsageError("--tf-out", f"must name a .json file, got {args.tf_out!r}")
    check_layer_options(args, mode)
    data = load_layered_args(args)              # INPUT's volume and TF, and any more volumes
    volume, tf_name, tf = data.volume, data.tf_name, data.tf
    return Settings(volume=volume, tf=tf, tf_name=tf_name, input_name=os.path.basename(args.input) or args.input,
                    technique=args.technique, mode=mode, iso=args.iso, step=args.step, size=tuple(args.size),
                    azimuth=args.azimuth, elevation=args.elevation, zoom=args.zoom, fov=args.fov,
                    ortho=args.ortho, background=args.background, screenshot=screenshot,
                    tf_out=args.tf_out, editor=not args.hide_editor, vsync=args.frames is None,
                    options=options, shading=getattr(args, "shading", None),
                    lights=tuple(args.light) if getattr(args, "light", None) else None,
                    optical_model=getattr(args, "optical_model", None) or "emission_absorption",
                    illustration=tuple(getattr(args, "illustration", None) or ()), tolerance=tolerance,
                    layers=data.layers, blend=data.blend, layer_names=data.names,
                    **clip_args(args, data.framing), **geometry_args(args, args.technique))
