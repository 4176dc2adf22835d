"""The ``dvr-gl`` command line: ``info``, ``render``, ``movie``, ``isosurface``, ``demo``, ``bench`` and ``view``.

Exit codes: 0 success; 1 the work failed (no GL backend, a failed frame); 2 bad input
(a message on stderr names the option and the value; no traceback, no output file);
130 interrupted. Set ``DVR_GL_DEBUG=1`` to get tracebacks instead of one-line messages.

``render`` takes a volume file (see :func:`dvr_gl.formats.load_volume`), a tetrahedral (or
hexahedral, ...) mesh file (see :func:`dvr_gl.formats.load_mesh`; rendered by ``tetra``) or a
bundled data set, ``builtin:ct_head`` or ``builtin:synthetic``, e.g.::

    dvr-gl render builtin:ct_head --elevation 90 --size 512x512 --out head.png
    dvr-gl render scan.raw --shape 93,64,64 --dtype int16 --spacing 3.2,3.2,1.5 --out scan.png
    dvr-gl render bluntfin_tets.vtu --scalars Pressure --sort centroid --out fin.png

``info FILE`` describes a volume or mesh file instead of the GL backends; ``isosurface INPUT
--iso V -o out.ply`` writes a level set as a triangle mesh (:mod:`dvr_gl.frontends.isosurface`);
``movie INPUT -o out.mp4`` renders an orbit or a time series (:mod:`dvr_gl.frontends.movie`).
"""

from __future__ import annotations

import argparse
import importlib
import os
import platform
import sys
import time

from .. import formats as dvr_io
from .isosurface import add_isosurface_parser, cmd_isosurface
from .inputs import PRESETS  # presets and bundled data sets are shared with the viewer and dvr_gl.render
from .options import (MESH_TECHNIQUES, OPTION_OF_FIELD, UsageError, _check_input_options, _origin, _shape,
                      _spacing, add_orientation_option, add_render_options, check_dtype_option, check_png, check_technique, clip_args,
                      check_layer_options, geometry_args, input_is_mesh, load_input_args, load_layered_args,
                      technique_options)

PROG = "dvr-gl"

# ----------------------------------------------------------------------------- the parser

def build_parser(bench_module=None):
    """The argument parser; ``bench_module`` (dvr_gl.bench.cli, if loaded) adds its options."""
    from .._version import __version__

    parser = argparse.ArgumentParser(
        prog=PROG, description="Direct volume rendering with OpenGL, headless (EGL or OSMesa).")
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    i = sub.add_parser("info", help="list the GL backends (or describe a volume or mesh FILE)",
                       description="Try each headless GL backend and print what it offers; with FILE, "
                                   "describe that volume or mesh instead (no GL needed).")
    i.add_argument("file", nargs="?", metavar="FILE",
                   help="a volume file, mesh file or builtin:NAME to describe")
    i.add_argument("--scalars", metavar="NAME", help="mesh FILE: the point array whose range to print")
    i.add_argument("--key", metavar="KEY", help="zarr or HDF5 FILE: the array inside it (or FILE:/KEY)")
    info_raw = i.add_argument_group("raw files")
    info_raw.add_argument("--shape", type=_shape, metavar="NZ,NY,NX", help="sample counts of a raw file")
    info_raw.add_argument("--dtype", metavar="D", help="sample type of a raw file")
    info_raw.add_argument("--spacing", type=_spacing, metavar="SX,SY,SZ", help="sample spacing")
    info_raw.add_argument("--origin", type=_origin, metavar="OX,OY,OZ", help="world position of the first sample")
    info_raw.add_argument("--mask-nonfinite", action="store_true", help="allow NaN and inf samples")
    add_orientation_option(info_raw)

    r = sub.add_parser(
        "render", help="render a volume to a PNG",
        description="Render a volume to a PNG. INPUT is a volume file (.npy, .npz, .nrrd, .nhdr, "
                    ".mhd, .mha; any other name is raw samples and needs --shape, --dtype and "
                    "--spacing), a mesh file (.vtu, .vtk unstructured grid, .npz with points and "
                    "tets, or any other format meshio reads; rendered with --technique tetra) or a "
                    "bundled data set: builtin:ct_head, builtin:synthetic.")
    r.add_argument("--out", "-o", required=True, metavar="IMAGE.png", help="the PNG to write")
    r.add_argument("--transparent", action="store_true",
                   help="write un-premultiplied RGBA instead of RGB over the background")
    add_render_options(r)
    r.add_argument("--workers", type=int, metavar="N",
                   help="render sort-last on a local Dask cluster of N worker processes (dvr_gl.distributed)")
    r.add_argument("--scheduler", metavar="ADDRESS",
                   help="render sort-last on the Dask cluster of the scheduler at ADDRESS (tcp://host:8786)")
    r.add_argument("--build-pyramid", action="store_true",
                   help="write INPUT's OME-Zarr pyramid beside it once (NAME.pyramid.ome.zarr, reused when "
                        "there) and render from it; with --tolerance E the coarsest level within E is drawn")
    r.add_argument("--pyramid-levels", type=int, metavar="N",
                   help="--build-pyramid: N levels, level 0 included (default: halved until the largest side "
                        "is at most 32 samples)")

    from .movie import add_movie_parser    # the movie command lives in its own module
    add_movie_parser(sub)

    add_isosurface_parser(sub)

    d = sub.add_parser("demo", help="render the bundled demo scenes to PNGs",
                       description="Render the bundled demo scenes into a folder.")
    d.add_argument("--out-dir", metavar="DIR", help="folder for the images (default: the demo's own, dvr-gl-demo)")
    d.add_argument("--preintegrate", action="store_true",
                   help="render the composite scenes with pre-integrated classification")

    b = sub.add_parser("bench", help="time the techniques", description="Time the techniques.")
    if bench_module is not None:
        bench_module.add_arguments(b)
    else:
        b.add_argument("bench_args", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)

    v = sub.add_parser("view", help="open the interactive viewer (arguments go to the viewer)",
                       add_help=False, description="Open the interactive viewer.")
    v.add_argument("view_args", nargs=argparse.REMAINDER, help="arguments for the viewer")
    return parser


# ----------------------------------------------------------------------------- commands

def cmd_info(args, out=None):
    out = out or sys.stdout
    if getattr(args, "file", None) is not None:
        return cmd_info_file(args, out)
    import numpy
    from .._version import __version__
    try:
        import moderngl
        mgl = getattr(moderngl, "__version__", "?")
    except ImportError as e:
        mgl = f"not installed ({e})"
    print(f"dvr_gl {__version__}; python {platform.python_version()}, numpy {numpy.__version__}, "
          f"moderngl {mgl}", file=out)
    try:
        from ..gl import context
    except ImportError as e:
        print(f"GL context support is not available: {e}", file=out)
        return 1
    working = 0
    for name in context.BACKENDS:
        try:
            made = context.create_context(name)
        except Exception as e:  # every failure is a line of the report, not a crash
            print(f"{name}: failed: {_reason(e)}", file=out)
            continue
        ctx = made[0] if isinstance(made, tuple) else made  # (ctx, backend name)
        try:
            facts = context.describe(ctx)
        except Exception as e:
            print(f"{name}: context created, but describing it failed: {_reason(e)}", file=out)
            continue
        finally:
            release = getattr(ctx, "release", None)
            if callable(release):
                try:
                    release()
                except Exception:
                    pass
        working += 1
        print(f"{name}: ok", file=out)
        facts = dict(facts)
        width = max((len(str(k)) for k in facts), default=0)
        for key, value in facts.items():
            print(f"  {str(key) + ':':<{width + 1}} {value}", file=out)
    if not working:
        print("no GL backend works (each line above says why and how to fix it)", file=out)
    return 0 if working else 1


def cmd_info_file(args, out=None):
    """``info FILE``: what a volume or mesh file holds (no GL)."""
    out = out or sys.stdout
    if dvr_io.is_store(args.file) and not args.file.lower().endswith(".npy"):  # zarr, HDF5: not loaded
        print("\n".join(dvr_io.describe_store(args.file, getattr(args, "key", None))), file=out)
        return 0
    args.input = args.file
    check_dtype_option(args)
    mesh = input_is_mesh(args)
    if not mesh and dvr_io.is_series_file(args.input):      # time steps or channels
        from .layer_inputs import describe_4d
        return describe_4d(args.input, out)
    _check_input_options(args, mesh)
    data, preset = load_input_args(args)
    if mesh:
        arrays = dvr_io.point_arrays(args.input)
        chosen = getattr(data, "scalars_name", None) or args.scalars or "?"
        lo, hi = data.bounds
        listed = ", ".join(name + (f" ({k} components)" if k != 1 else "") + (" *" if name == chosen else "")
                           for name, k in arrays.items())
        print(f"mesh       {args.input}", file=out)
        print(f"points     {data.n_points}", file=out)
        print(f"tets       {data.n_tets} ({zero_volume_count(data)} of zero volume)", file=out)
        print("bounds     " + ", ".join(f"{axis} {a:g}..{b:g}" for axis, a, b in zip("xyz", lo, hi)), file=out)
        print(f"arrays     {listed} (* rendered)", file=out)
        print(f"range      {data.data_range[0]:g}..{data.data_range[1]:g} ({chosen})", file=out)
    else:
        nz, ny, nx = data.shape
        lo, hi = data.bounds
        print(f"volume     {args.input}", file=out)
        print(f"shape      {nx}x{ny}x{nz} (x, y, z)", file=out)
        print(f"dtype      {data.data.dtype}", file=out)
        print("spacing    " + ",".join(f"{v:g}" for v in data.spacing), file=out)
        print("bounds     " + ", ".join(f"{axis} {a:g}..{b:g}" for axis, a, b in zip("xyz", lo, hi)), file=out)
        print(f"range      {data.data_range[0]:g}..{data.data_range[1]:g}"
              + (" (non-finite samples masked)" if data.has_nonfinite else ""), file=out)
        if data.orientation is not None:
            given = getattr(args, "orientation", None)
            note = ""
            if getattr(data, "orientation_assumed", False):
                note = ("; assumed: the file names no anatomy, this is its format's convention "
                        "(MetaImage: ITK's LPS; NRRD 3D-right/left-handed: LPS/LPI); --orientation CODE says otherwise")
            elif given is not None:
                note = "; given by --orientation" if given == data.orientation else \
                    f"; --orientation {given} is a left-handed frame: loaded with x reversed, so no view is a mirror image"
            print(f"orientation {data.orientation} (x, y, z point {', '.join(_ANATOMY[c] for c in data.orientation)}"
                  f"{note})", file=out)
        else:
            print("orientation none in the file (the first view looks along -z with +y up; "
                  "--orientation CODE such as RAS says where the axes point)", file=out)
        if data.modality is not None:
            print(f"modality   {data.modality}", file=out)
    values = data.scalars if mesh else data.data
    print("histogram  " + text_histogram(values) + f"  ({data.data_range[0]:g} to {data.data_range[1]:g}, "
          "32 bins, height ~ log count)", file=out)
    from ..model.transfer import auto_preset_name
    name = preset if preset != "auto" else f"auto: {auto_preset_name(data)}"
    print(f"preset     {_describe_tf(name, PRESETS[preset](data))} (what render uses without --tf)", file=out)
    return 0


_ANATOMY = {"R": "right", "L": "left", "A": "anterior", "P": "posterior", "S": "superior", "I": "inferior"}


def text_histogram(values, bins=32):
    """A one-line histogram of the finite values: one block character per bin, its height
    the bin's count on a log scale (so sparse tails still show)."""
    import numpy as np
    v = np.asarray(values, np.float64).ravel()
    v = v[np.isfinite(v)]
    if v.size == 0:
        return "(no finite value)"
    counts, _ = np.histogram(v, bins=bins, range=(v.min(), v.max()) if v.max() > v.min() else None)
    levels = " \u2581\u2582\u2583\u2584\u2585\u2586\u2587\u2588"
    scaled = np.log1p(counts) / np.log1p(counts.max())
    return "".join(levels[int(round(s * (len(levels) - 1)))] if c else " " for s, c in zip(scaled, counts))


def zero_volume_count(mesh):
    """How many tetrahedra are flat (|6 V| at most 1e-12 times the cube of the longest
    edge, the test ``dvr_gl.model.mesh`` applies): they are kept but draw nothing."""
    p = mesh.points[mesh.tets]
    edges = p[:, [1, 2, 3, 2, 3, 3]] - p[:, [0, 0, 0, 1, 1, 2]]
    longest = (edges ** 2).sum(-1).max(axis=1) ** 0.5
    return int((abs(6 * mesh.signed_volumes()) <= 1e-12 * longest ** 3).sum())


def _reason(exc):
    """``Type: message``, continuation lines indented under the backend's line."""
    text = str(exc).strip().replace("\n", "\n  ")
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _describe_tf(name, tf):
    if hasattr(tf, "table"):    # a TransferFunction2D
        (lo, hi), (g0, g1) = tf.value_range, tf.gradient_range
        return (f"{name} (2D: values {lo:g}..{hi:g}, gradient magnitudes {g0:g}..{g1:g}, "
                f"unit distance {tf.unit_distance:g})")
    lo, hi = float(tf.knots[0]), float(tf.knots[-1])
    return f"{name} ({lo:g}..{hi:g}, unit distance {tf.unit_distance:g})"


def cmd_render(args, out=None):
    out = out or sys.stdout
    from .inputs import FIRST_AZIMUTH, FIRST_ELEVATION, first_camera, shading_for
    from ..model.scene import Scene
    from ..model.transfer_function import TransferFunction2D
    from ..techniques.common import SHADING_TECHNIQUES

    check_png(args.out)
    check_technique(args.technique)
    render_kwargs = technique_options(args)
    mode = args.mode or ("isosurface" if args.iso is not None else "composite")
    if mode == "isosurface" and args.iso is None:
        raise UsageError("--iso", "an iso-value is required with --mode isosurface")
    if args.iso is not None and mode != "isosurface":
        raise UsageError("--iso", f"is only used with --mode isosurface, not --mode {mode}")
    if args.shading and mode not in ("composite", "isosurface"):
        raise UsageError("--shading", f"lights composite samples (isosurfaces always are), not --mode {mode}")
    if args.optical_model not in (None, "emission_absorption"):
        if args.optical_model == "sabella" and args.technique != "raycast":
            raise UsageError("--optical-model", f"sabella applies to --technique raycast, not {args.technique}")
        cell_model = args.technique == "tetra" and args.optical_model in ("absorption", "emission")
        if args.technique not in SHADING_TECHNIQUES and not cell_model:
            raise UsageError("--optical-model", f"{args.optical_model} applies to --technique "
                                                f"{', '.join(SHADING_TECHNIQUES)} (tetra: absorption, emission), "
                                                f"not {args.technique}")
        if args.preintegrate:
            raise UsageError("--optical-model", f"{args.optical_model} is sampled at segment midpoints; "
                                                "leave out --preintegrate")
    layered = check_layer_options(args, mode)
    if args.shading is None:   # lit by default where lighting is defined (several volumes: not yet)
        args.shading = shading_for(args.technique, mode, args.optical_model or "emission_absorption") and not layered
    if args.light and not (args.shading or mode == "isosurface"):
        raise UsageError("--light", "is only used with --shading (or --mode isosurface)")
    if args.light and len(args.light) > 4:
        raise UsageError("--light", f"at most 4 lights, got {len(args.light)}")
    check_dtype_option(args)

    t0 = time.perf_counter()
    if getattr(args, "pyramid_levels", None) is not None and not args.build_pyramid:
        raise UsageError("--pyramid-levels", "is the number of levels --build-pyramid writes; give --build-pyramid")
    if getattr(args, "build_pyramid", False):
        args.input = _pyramid_input(args, out)
    data = load_layered_args(args)      # the input's volume and TF, and any more volumes
    volume, tf_name, tf = data.volume, data.tf_name, data.tf
    if args.gradients is not None and not (args.shading or mode == "isosurface" or args.illustration
                                           or isinstance(tf, TransferFunction2D)):
        raise UsageError("--gradients", "is only used with --shading, --illustration, a 2D --tf or --mode isosurface")
    camera = first_camera(data.framing, azimuth=args.azimuth, elevation=args.elevation, zoom=args.zoom,
                          fov=args.fov, ortho=args.ortho)
    width, height = args.size
    if mode == "isosurface":
        lo, hi = volume.data_range
        if not lo <= args.iso <= hi:
            print(f"{PROG} render: warning: --iso {args.iso:g} is outside the data's range {lo:g}..{hi:g}: "
                  "the surface is empty", file=sys.stderr)
    optical = {"optical_model": args.optical_model} if args.optical_model else {}
    if args.illustration:
        if mode != "composite":
            raise UsageError("--illustration", f"applies to --mode composite, not --mode {mode}")
        if args.technique not in SHADING_TECHNIQUES + ("tetra",):
            raise UsageError("--illustration", f"applies to --technique {', '.join(SHADING_TECHNIQUES)} "
                                               f"and tetra, not {args.technique}")
        if args.preintegrate and {"boundary", "silhouette"} & set(args.illustration):
            raise UsageError("--illustration", "boundary and silhouette scale the extinction per sample; "
                                               "leave out --preintegrate")
        optical["illustration"] = args.illustration
    try:
        scene = Scene(volume, tf, camera, width=width, height=height, mode=mode, iso_value=args.iso,
                      shading=args.shading, **({"lights": tuple(args.light)} if args.light else {}), **optical,
                      **clip_args(args, data.framing), **geometry_args(args, args.technique), **data.scene_parts())
    except ValueError as e:
        if not optical:
            raise
        raise UsageError("--optical-model" if args.optical_model else "--illustration", str(e)) from None
    if getattr(args, "transparent", False):
        if args.background is not None:
            raise UsageError("--transparent", "writes RGBA; it takes no --background")
    elif args.background is None:       # the picture as it is seen: over white, a glow over black
        args.background = (0.0, 0.0, 0.0) if args.optical_model == "emission" else (1.0, 1.0, 1.0)
    t_load = time.perf_counter() - t0

    from ..rendering.renderer import Renderer
    renderer_kwargs = {"backend": args.backend}
    t1 = time.perf_counter()
    if args.workers is not None or args.scheduler is not None:    # sort-last on a Dask cluster
        from .distributed import render_for_cli
        image, t2, t3, backend = render_for_cli(scene, render_kwargs, args.workers, args.scheduler, args.backend)
        choice = None
    else:
        with Renderer(**renderer_kwargs) as renderer:
            t2 = time.perf_counter()
            image = renderer.render(scene, **render_kwargs)
            t3 = time.perf_counter()
            backend = _backend_name(renderer, args.backend)
            choice = renderer.last_choice if "tolerance" in render_kwargs else None
    dvr_io.save_png(args.out, image, background=args.background)

    lo, hi = volume.data_range
    azimuth = FIRST_AZIMUTH if args.azimuth is None else args.azimuth
    elevation = FIRST_ELEVATION if args.elevation is None else args.elevation
    frame = "from the front, head up" if getattr(volume, "orientation", None) else "from +z, +y up"
    view = f"{frame}, azimuth {azimuth:g}, elevation {elevation:g}, zoom {args.zoom:g}"
    view += ", orthographic" if args.ortho else f", fov {args.fov:g}"
    if args.technique in MESH_TECHNIQUES:
        step = f"sort {render_kwargs.get('sort', 'mpvo')}"
    else:
        step = f"step {args.step:g}" if args.step is not None else "default step"
    if choice is not None and scene.is_mesh:
        step = (f"{choice.label} for tolerance {choice.tolerance:g} (pilot RMSE {choice.pilot_rmse:.2g} at "
                f"{choice.pilot_size[0]}x{choice.pilot_size[1]}, pilot {choice.pilot_seconds:.2f} s)")
    elif choice is not None and hasattr(choice, "level"):      # a pyramid's level (rendering.pyramid)
        step = choice.describe()
    elif choice is not None:
        step = (f"step {choice.step:g} ({choice.step_voxels:.3g} voxel) for tolerance {choice.tolerance:g}, "
                f"predicted RMSE {choice.predicted_rmse:.2g}")
        step += ", preintegrate" * choice.preintegrate + f", refine {choice.refine}" * (choice.refine > 1)
    extras = [f"{k} {v}" if not isinstance(v, bool) else k for k, v in render_kwargs.items()
              if k not in ("technique", "step", "sort", "tolerance")]
    step += "".join(", " + e for e in extras)
    if scene.is_mesh:
        name = getattr(volume, "scalars_name", None) or args.scalars or "?"
        print(f"mesh       {args.input}: {volume.n_points} points, {volume.n_tets} tets, "
              f"scalars {name} {lo:g}..{hi:g}", file=out)
    else:
        nz, ny, nx = volume.shape
        sx, sy, sz = (float(v) for v in volume.spacing)
        dtype = volume.dtype if hasattr(volume, "read") else volume.data.dtype   # (a store: a LazyVolume)
        print(f"volume     {args.input}: {nx}x{ny}x{nz} (x, y, z) {dtype}, spacing {sx:g},{sy:g},{sz:g}, "
              f"values {lo:g}..{hi:g}", file=out)
    if tf_name == "auto":
        from ..model.transfer import auto_preset_name
        tf_name = f"auto: {auto_preset_name(volume)}"
    print(f"transfer   {_describe_tf(tf_name, tf)}", file=out)
    if data.layers:
        print(f"volumes    {data.describe()}", file=out)
    print(f"rendered   {args.technique}, mode {mode}" + (f" {args.iso:g}" if mode == "isosurface" else "")
          + (", lit" if scene.shading else "")
          + f", {step}, {width}x{height}, {view}, backend {backend}", file=out)
    if choice is not None and hasattr(choice, "level"):
        tried = ", ".join(f"{level}@{k:g} {bound:.3g}" for level, k, bound in choice.trials) or "none"
        print(f"levels     measured (level@step in its voxels, error bound): {tried}; level 0's reference "
              f"error {choice.reference_error:.2g}", file=out)
    print(f"time       load {t_load:.3f} s, GL context {t2 - t1:.3f} s, first frame {t3 - t2:.3f} s "
          "(includes shader compile and upload)", file=out)
    print(f"wrote      {args.out}" + (" (RGB over background)" if args.background else " (RGBA)"), file=out)
    return 0


def _pyramid_input(args, out):
    """--build-pyramid: the pyramid beside INPUT (written now unless there already)."""
    from ..formats.stores import build_pyramid, pyramid_path, split_key
    source, key = split_key(args.input, getattr(args, "key", None))
    path = pyramid_path(source)
    if getattr(args, "key", None) is not None:      # the key named the array in INPUT, not in its pyramid
        args.key = None
    if os.path.exists(path):
        print(f"pyramid    {path} (there already: reused)", file=out)
        return path
    load = {name: getattr(args, name) for name in ("shape", "dtype") if getattr(args, name, None) is not None}
    t0 = time.perf_counter()
    try:
        build_pyramid(source, out=path, key=key, levels=args.pyramid_levels, spacing=getattr(args, "spacing", None),
                      origin=getattr(args, "origin", None), **load)
    except dvr_io.InputError as e:
        if e.field != "levels":
            raise
        raise UsageError("--pyramid-levels", e.detail) from None
    print(f"pyramid    wrote {path} in {time.perf_counter() - t0:.2f} s", file=out)
    return path


def _backend_name(renderer, requested):
    for attr in ("backend_name", "backend"):
        value = getattr(renderer, attr, None)
        if isinstance(value, str):
            return value
    return requested


def cmd_demo(args):
    try:
        demo = importlib.import_module("dvr_gl.frontends.demo")
    except ModuleNotFoundError as e:
        if e.name != "dvr_gl.frontends.demo":
            raise
        print(f"{PROG} demo: the demo is not available yet", file=sys.stderr)
        return 2
    kwargs = {} if args.out_dir is None else {"out_dir": args.out_dir}
    if args.preintegrate:
        kwargs["preintegrate"] = True
    return int(demo.run_demo(**kwargs) or 0)


def cmd_bench(args, bench_module):
    if bench_module is None:
        print(f"{PROG} bench: the benchmark is not available yet", file=sys.stderr)
        return 2
    return int(bench_module.run_bench(args) or 0)


def cmd_view(args):
    try:
        viewer = importlib.import_module("dvr_gl.frontends.viewer")
    except ModuleNotFoundError as e:
        if e.name == "dvr_gl.frontends.viewer":
            print(f"{PROG} view: the interactive viewer is not available yet", file=sys.stderr)
            return 2
        if e.name == "glfw" or (e.name or "").startswith("glfw."):
            print(f"{PROG} view: the interactive viewer needs glfw (pip install glfw): {e}", file=sys.stderr)
            return 2
        raise
    return int(viewer.main(list(args.view_args)) or 0)


def _load_bench(argv):
    """dvr_gl.bench.cli when the command is ``bench`` (its options join the parser), else None."""
    command = next((a for a in argv if not a.startswith("-")), None)
    if command != "bench":
        return None
    try:
        return importlib.import_module("dvr_gl.bench.cli")
    except ModuleNotFoundError as e:
        if e.name != "dvr_gl.bench.cli":
            raise
        return None


# ----------------------------------------------------------------------------- main

def main(argv=None) -> int:
    """Run the command line; returns the exit status (0, 1, 2 or 130)."""
    try:
        return _main(argv)
    except BrokenPipeError:
        # The reader of stdout went away (``dvr-gl info | head -1``): not an error. Files
        # are written before anything is printed about them, and atomically, so nothing
        # is half-written; stdout goes to /dev/null so that the interpreter's final flush
        # stays quiet.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
        return 0


def _main(argv):
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["view"]:
        # the viewer parses its own arguments (argparse's REMAINDER would reject options
        # before INPUT, --help included)
        return cmd_view(argparse.Namespace(command="view", view_args=argv[1:]))
    debug = bool(os.environ.get("DVR_GL_DEBUG"))
    bench_module = _load_bench(argv)
    parser = build_parser(bench_module)
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # argparse: --help, --version, or a usage error (already printed)
        return e.code if isinstance(e.code, int) else (0 if e.code is None else 2)
    command = args.command
    try:
        if command == "info":
            if args.file is not None:
                return _guarded("info", cmd_info_file, args, debug)
            return cmd_info(args)
        if command == "isosurface":
            return _guarded("isosurface", cmd_isosurface, args, debug)
        if command == "movie":
            from .movie import cmd_movie
            return _guarded("movie", cmd_movie, args, debug)
        if command == "demo":
            return cmd_demo(args)
        if command == "bench":
            return cmd_bench(args, bench_module)
        if command == "view":
            return cmd_view(args)
        return _run_render(args, debug)
    except KeyboardInterrupt:
        print(f"{PROG} {command}: interrupted", file=sys.stderr)
        return 130


def _run_render(args, debug):
    """``render`` with its errors turned into one-line messages and exit codes."""
    return _guarded("render", cmd_render, args, debug)


def _guarded(command, func, args, debug):
    """``func(args)`` with its errors turned into one-line messages and exit codes."""
    try:
        return func(args)
    except UsageError as e:
        if debug:
            raise
        return _fail(command, str(e), 2)
    except dvr_io.InputError as e:
        if debug:
            raise
        option = OPTION_OF_FIELD.get(e.field)
        return _fail(command, f"{option}: {e.detail}" if option else f"INPUT: {e}", 2)
    except (ValueError, TypeError, NotImplementedError) as e:
        # The scene and the renderer validate their input and name the parameter.
        if debug:
            raise
        return _fail(command, str(e).replace("pass mask_nonfinite=True", "pass --mask-nonfinite"), 2)
    except BrokenPipeError:
        raise  # the reader went away: main() ends quietly
    except (RuntimeError, OSError) as e:  # no GL context, a failed frame, a full disk
        if debug:
            raise
        return _fail(command, f"{type(e).__name__}: {e}", 1)


def _fail(command, message, code):
    print(f"{PROG} {command}: error: {message}", file=sys.stderr)
    return code


if __name__ == "__main__":
    sys.exit(main())
