"""Movies: an orbit around a volume or mesh, the time steps of a series, or both, written
to an ``.mp4`` (H.264) or a ``.gif``. :func:`render_movie` in Python; ``dvr-gl movie`` on
the command line (:func:`add_movie_parser`, :func:`cmd_movie`)::

    dvr-gl movie builtin:ct_head -o head.mp4 --frames 240 --size 256x256
    dvr-gl movie "steps/t_*.nrrd" -o steps.gif --fps 8
    dvr-gl movie flow.nii.gz -o flow.mp4 --frames 120 --orbit 90

**Frames.** A still volume or mesh turns: frame ``i`` of ``N`` looks from azimuth
``azimuth + orbit * i / N`` (default: a whole turn, 360 degrees, in ``N = 120`` frames;
the turn ends one step short of where it began, so the movie loops without a repeated
frame). A series (:class:`dvr_gl.model.series.VolumeSeries`) gives one frame per time step
unless ``frames`` is given; then frame ``i`` shows step ``floor(i * steps / N)`` (each step
held equally long, steps skipped where ``N`` is smaller). A series does not turn unless
``orbit`` is given; with it, it turns and plays at once.

**One transfer function for every frame**, resolved once: over a series, presets read the
samples of every step (:meth:`VolumeSeries.pooled`), so the colours mean the same values
in every frame. **One renderer** draws every frame (programs compiled once, a step's
volume uploaded once).

**Files.** ``.mp4`` is H.264 (libx264) in yuv420p, whose colour planes have half the
picture's width and height: the width and height must be even (an odd one is an error
naming ``size``; nothing is padded). ``.gif`` keeps 256 colours per frame and a delay in
whole hundredths of a second (24 fps plays at 25). Frames are RGB over ``background``
(white, or black for the emission-only optical model). The movie is written to a
temporary file in the target's folder and renamed when complete; after a failure nothing
is left. Writing needs imageio and imageio-ffmpeg (which brings its own ffmpeg):
``pip install "dvr-gl[movie]"``.
"""

from __future__ import annotations

import os
import statistics
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from .. import formats as dvr_io
from ..formats import InputError
from ..model.series import VolumeSeries
from ..util.files import atomic_path
from ..formats.series import is_pattern
from .options import (UsageError, _number, _positive, add_render_options, check_dtype_option, check_layer_options,
                      check_technique, clip_args, geometry_args, technique_options, whole_number)

#: frames of an orbit when not given: five seconds at 24 fps
ORBIT_FRAMES = 120
#: the movie formats, by extension
FORMATS = {".mp4": "H.264", ".gif": "GIF"}
MAX_FPS = 240.0
#: GIF delays are whole hundredths of a second, and viewers slow down those under 0.02 s
GIF_MAX_FPS = 50.0
#: which command-line option an InputError's field stands for, here
MOVIE_OPTIONS = {"out": "--out", "size": "--size", "fps": "--fps", "frames": "--frames", "orbit": "--orbit"}


class MovieDependencyError(ImportError):
    """imageio or imageio-ffmpeg is not installed: the message names the extra to install."""


# ----------------------------------------------------------------------------- checks

def movie_format(path):
    """The extension of a movie file name (``.mp4`` or ``.gif``), in an existing folder."""
    try:
        path = os.fspath(path)
    except TypeError:
        raise InputError("out", f"expected a file name, got {path!r}") from None
    ext = os.path.splitext(path)[1].lower()
    if ext not in FORMATS:
        raise InputError("out", f"must name a {' or '.join(FORMATS)} file, got {path!r}")
    directory = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(directory):
        raise InputError("out", f"the folder {directory!r} does not exist")
    if os.path.isdir(path):
        raise InputError("out", f"{path!r} is a folder")
    return ext


def check_fps(fps, fmt=".mp4"):
    """Frames per second: a finite number above 0, at most MAX_FPS (GIF_MAX_FPS for a GIF)."""
    try:
        value = float(fps)
    except (TypeError, ValueError):
        raise InputError("fps", f"expected a number, got {fps!r}") from None
    most = GIF_MAX_FPS if fmt == ".gif" else MAX_FPS
    if not np.isfinite(value) or value <= 0 or value > most:
        why = " (GIF delays are whole hundredths of a second)" if fmt == ".gif" else ""
        raise InputError("fps", f"must be above 0 and at most {most:g} for {fmt}{why}, got {fps!r}")
    return value


def check_movie_size(size, fmt=".mp4"):
    """(width, height) from an int, a pair or ``"WxH"``; even for an .mp4."""
    try:
        if isinstance(size, str):
            width, height = dvr_io.parse_size(size)
        elif np.isscalar(size):
            width = height = int(size)
        else:
            width, height = (int(v) for v in size)
    except (TypeError, ValueError) as e:
        if isinstance(e, InputError):
            raise
        raise InputError("size", f"expected an int, (width, height) or 'WxH', got {size!r}") from None
    if width < 1 or height < 1:
        raise InputError("size", f"must be positive, got {width}x{height}")
    if fmt == ".mp4" and (width % 2 or height % 2):
        even = f"{width + width % 2}x{height + height % 2}"
        raise InputError("size", f"H.264 (.mp4, yuv420p) needs an even width and height, got {width}x{height}; "
                                 f"use {even}, or write a .gif")
    return width, height


def frame_plan(steps=1, frames=None, orbit=None):
    """[(time step, turn in degrees)] for each frame (see the module docstring): a still
    volume (``steps == 1``) turns ``orbit`` (default 360) over ``frames`` (default
    ORBIT_FRAMES); a series shows its steps, one frame each unless ``frames`` is given,
    and turns only if ``orbit`` is given."""
    if orbit is None:
        orbit = 360.0 if steps == 1 else 0.0
    try:
        orbit = float(orbit)
    except (TypeError, ValueError):
        raise InputError("orbit", f"expected a number of degrees, got {orbit!r}") from None
    if not np.isfinite(orbit):
        raise InputError("orbit", f"must be finite, got {orbit!r}")
    if frames is None:
        frames = ORBIT_FRAMES if steps == 1 else steps
    if isinstance(frames, bool) or not isinstance(frames, (int, np.integer)) or frames < 1:
        raise InputError("frames", f"must be a whole number, 1 or more, got {frames!r}")
    return [(i * steps // frames, orbit * i / frames) for i in range(int(frames))]


# ----------------------------------------------------------------------------- input

def load_movie_input(source, *, scalars=None, shape=None, dtype=None, spacing=None, origin=None,
                     mask_nonfinite=False, orientation=None):
    """(data, default preset name): a :class:`VolumeSeries` for a series (one, a 4-D
    array, a list of files, a glob pattern or a 4-D array file; see
    :func:`dvr_gl.formats.load_series`), else what :func:`dvr_gl.frontends.inputs.load_input`
    gives (a Volume or a TetMesh)."""
    from .inputs import load_input
    geometry = dict(spacing=spacing, origin=origin, mask_nonfinite=mask_nonfinite, orientation=orientation)
    if isinstance(source, VolumeSeries):
        return source, "auto"
    if isinstance(source, np.ndarray) and source.ndim == 4:
        code = None if orientation is None else dvr_io.parse_orientation(orientation)
        steps = [dvr_io.right_handed(step, code) for step in source]
        from ..model.volume import Volume
        return VolumeSeries([Volume(s, spacing=spacing or (1.0, 1.0, 1.0), origin=origin or (0.0, 0.0, 0.0),
                                    mask_nonfinite=mask_nonfinite, orientation=c) for s, c in steps]), "auto"
    if isinstance(source, (list, tuple)) or (isinstance(source, (str, os.PathLike)) and (
            is_pattern(os.fspath(source)) or dvr_io.is_series_file(source))):
        return dvr_io.load_series(source, shape=shape, dtype=dtype, **geometry), "auto"
    return load_input(source, scalars=scalars, shape=shape, dtype=dtype, **geometry)


def resolve_movie_tf(spec, data, default="auto"):
    """(name, transfer function), as :func:`dvr_gl.frontends.inputs.resolve_tf`, once for
    the whole movie: over a series, presets read every step's samples and a 2D
    transfer function's ranges span every step's values and gradient magnitudes."""
    from .inputs import _is_tf2d_file, resolve_tf
    if not isinstance(data, VolumeSeries):
        return resolve_tf(spec, data, default)
    if isinstance(spec, (str, os.PathLike)) and os.path.isfile(spec) and _is_tf2d_file(spec):
        from ..model.field import gradient_max
        from ..model.transfer2d import load_tf2d_json
        try:
            return os.fspath(spec), load_tf2d_json(spec, data.data_range, (0.0, max(gradient_max(v) for v in data)))
        except (ValueError, TypeError) as e:
            raise InputError("tf", str(e)) from None
    return resolve_tf(spec, data.pooled(), default)


class MovieVolumes:
    """Several volumes in a movie: the input's (a Volume or a VolumeSeries) and its
    transfer function, then the extra layers, each a Volume or a VolumeSeries with its
    classification and matrix. Every series shares one time count (``steps``); a still
    volume shows in every frame."""

    def __init__(self, main, tf, extras, blend, names):
        self.main, self.tf, self.extras, self.blend, self.names = main, tf, tuple(extras), blend, tuple(names)
        counts = [(name, len(d)) for name, d in zip(self.names, (main,) + tuple(e[0] for e in self.extras))
                  if isinstance(d, VolumeSeries)]
        for name, n in counts[1:]:
            if n != counts[0][1]:
                raise InputError("layers", f"volumes with different time counts: {counts[0][0]} has {counts[0][1]} "
                                           f"steps, {name} has {n}; every series in a movie has as many")
        self.steps = counts[0][1] if counts else 1

    def layers_at(self, step):
        """The extra layers at time ``step``."""
        from ..model.layers import Layer
        return tuple(Layer(d[step] if isinstance(d, VolumeSeries) else d, tf, matrix) for d, tf, matrix in self.extras)

    def framing(self, first):
        """The box around every volume at step 0, in the input's anatomical frame."""
        from ..model.layers import Extent, Layer, union_bounds
        extent = Extent(union_bounds((Layer(first, self.tf),) + self.layers_at(0)))
        extent.orientation = getattr(first, "orientation", None)
        return extent


def movie_volumes(source, tf=None, layers=(), labels=None, channels=False, blend=None, **geometry):
    """:class:`MovieVolumes` for ``source`` and its extras (see
    :mod:`dvr_gl.frontends.layer_inputs`): extra scans may be series (a 4-D array or file,
    a glob pattern), each classified once over all its steps; ``channels`` reads the
    input's first axis as channels (not time); a label volume is still."""
    from ..model.layers import Layer
    from ..model.volume import Volume
    from .inputs import load_input, resolve_tf
    from .layer_inputs import _name, check_volume_count, default_blend, label_layer, layered_input
    extras = [layers] if isinstance(layers, (Layer, str, os.PathLike, np.ndarray, Volume)) else list(layers or ())
    blend = default_blend(channels, blend)
    if channels:
        own = layered_input(source, tf, (), None, True, blend, geometry.get("spacing"), geometry.get("origin"),
                            geometry.get("mask_nonfinite", False), load_input=load_input, resolve_tf=resolve_tf)
        main, tf, names = own.volume, own.tf, list(own.names)
        found = [(layer.volume, layer.tf, layer.matrix) for layer in own.layers]
    else:
        main, preset = load_movie_input(source, **geometry)
        _, tf = resolve_movie_tf(tf, main, preset)
        names, found = [_name(source)], []
    check_volume_count(1 + len(found) + len(extras) + (labels is not None), ", ".join(names) + f" and "
                       f"{len(extras) + (labels is not None)} more")
    for item in extras:
        if isinstance(item, Layer):
            found.append((item.volume, item.tf, item.matrix))
            continue
        try:
            data, preset = load_movie_input(item, spacing=geometry.get("spacing") if isinstance(item, np.ndarray)
                                            else None)
        except InputError as e:
            raise InputError("layers", f"{_name(item)}: {e.detail}") from None
        if getattr(data, "n_tets", None) is not None:
            raise InputError("layers", f"{_name(item)} is a mesh; several volumes are grids")
        found.append((data, resolve_movie_tf(None, data, preset)[1], None))
    names += [_name(x) for x in extras]
    if labels is not None:
        layer = label_layer(labels, geometry.get("spacing"), load_input, main)
        found.append((layer.volume, layer.tf, layer.matrix))
        names.append(_name(labels))
    return MovieVolumes(main, tf, found, blend, names)


# ----------------------------------------------------------------------------- rendering

@dataclass
class MovieResult:
    """What :func:`render_movie` wrote and how long it took (seconds per frame: rendering
    with the read-back, and converting and encoding)."""
    path: str
    frames: int
    width: int
    height: int
    fps: float
    technique: str
    render_s: list = field(default_factory=list)
    write_s: list = field(default_factory=list)
    total_s: float = 0.0

    @property
    def first_frame_s(self):
        """The first frame (it compiles programs and uploads the data)."""
        return self.render_s[0] + self.write_s[0]

    @property
    def per_frame_s(self):
        """The median frame after the first (the first where there is only one)."""
        times = [r + w for r, w in zip(self.render_s, self.write_s)]
        return statistics.median(times[1:] or times)

    def summary(self):
        rest = slice(1, None) if self.frames > 1 else slice(None)
        return (f"{self.per_frame_s:.3f} s per frame (median; render {statistics.median(self.render_s[rest]):.3f} s, "
                f"encode {statistics.median(self.write_s[rest]):.3f} s), first frame {self.first_frame_s:.3f} s "
                f"(compiles and uploads); {self.total_s:.1f} s in all")


def render_movie(source, path, *, frames=None, orbit=None, fps=24, size=(512, 512), tf=None, technique=None,
                 azimuth=None, elevation=None, zoom=1.0, fov=30.0, ortho=False, mode="composite", iso=None,
                 shading=None, lights=None, optical_model=None, illustration=None, clip_planes=(), crop_box=None,
                 geometry=(), background=None, scalars=None, spacing=None, origin=None, orientation=None, shape=None,
                 dtype=None, mask_nonfinite=False, layers=(), labels=None, channels=False, blend=None, backend="auto",
                 renderer=None, progress=True, **options) -> MovieResult:
    """Render a movie of ``source`` to ``path`` (``.mp4`` or ``.gif``); returns a
    :class:`MovieResult`. The module docstring says which frames are drawn.

    >>> render_movie("builtin:ct_head", "head.mp4", frames=240, size=256)          # doctest: +SKIP
    >>> render_movie("steps/t_*.npy", "steps.gif", fps=8, tf="warm")               # doctest: +SKIP

    ``source``: what :func:`dvr_gl.render` takes (a file, ``builtin:NAME``, an array, a
    Volume or TetMesh), or a series: a :class:`VolumeSeries`, a 4-D array (nt, nz, ny,
    nx), a list of files, a glob pattern, or a 4-D array file. ``frames``, ``orbit``
    (degrees) and ``fps`` as in the module docstring; ``size``: an int, (width, height)
    or ``"WxH"``. The scene and technique options are :func:`dvr_gl.render`'s
    (``tf``, ``technique``, the camera, ``mode``, ``iso``, ``shading``, ``lights``,
    ``clip_planes``, ``crop_box``, ``geometry``, technique options in ``options``), and
    ``optical_model`` and ``illustration`` as in :class:`dvr_gl.Scene`; the camera's
    ``azimuth`` is where the orbit starts. ``renderer``: a ``dvr_gl.Renderer`` to draw
    with (default: one made for this movie and released after it). ``progress``: a bar on
    stderr. ``layers``, ``labels``, ``channels`` and ``blend``: several volumes, as in
    :func:`dvr_gl.render` (:func:`movie_volumes`; extra series share the input's time
    count)."""
    from ..model.scene import Scene
    from ..util.progress import Progress
    from .inputs import FIRST_AZIMUTH, _surfaces, first_camera, shading_for

    fmt = movie_format(path)
    fps = check_fps(fps, fmt)
    width, height = check_movie_size(size, fmt)
    imageio = _imageio(fmt)
    from .layer_inputs import wants_layers
    stack = source if isinstance(source, MovieVolumes) else None
    if stack is not None:
        data, tf = stack.main, stack.tf
    elif wants_layers(layers, labels, channels):
        stack = movie_volumes(source, tf, layers, labels, channels, blend, scalars=scalars, shape=shape, dtype=dtype,
                              spacing=spacing, origin=origin, mask_nonfinite=mask_nonfinite, orientation=orientation)
        data, tf = stack.main, stack.tf
    elif blend is not None:
        raise InputError("blend", f"combines several volumes (layers, labels or channels); got blend={blend!r} "
                                  "with one")
    else:
        data, preset = load_movie_input(source, scalars=scalars, shape=shape, dtype=dtype, spacing=spacing,
                                        origin=origin, mask_nonfinite=mask_nonfinite, orientation=orientation)
        _, tf = resolve_movie_tf(tf, data, preset)
    series = data if isinstance(data, VolumeSeries) else None
    first = data[0] if series is not None else data
    plan = frame_plan(stack.steps if stack is not None else len(series) if series is not None else 1, frames, orbit)
    framing = first if stack is None else stack.framing(first)
    if technique is None:
        technique = "tetra" if getattr(first, "n_tets", None) is not None else "raycast"
    optical_model = optical_model or "emission_absorption"
    if shading is None:
        shading = shading_for(technique, mode, optical_model) and stack is None    # several volumes: unlit
    if background is None:
        background = (0.0, 0.0, 0.0) if optical_model == "emission" else (1.0, 1.0, 1.0)
    view = dict(elevation=elevation, zoom=zoom, fov=fov, ortho=ortho)
    start = FIRST_AZIMUTH if azimuth is None else float(azimuth)
    layered = {} if stack is None else {"layers": stack.layers_at(0), "blend": stack.blend}
    base = Scene(first, tf, first_camera(framing, azimuth=start, **view), width=width, height=height, mode=mode,
                 iso_value=iso, shading=shading, **({} if lights is None else {"lights": lights}),
                 optical_model=optical_model, illustration=illustration, clip_planes=clip_planes, crop_box=crop_box,
                 geometry=_surfaces(geometry), **layered)

    own = renderer is None
    if own:
        from ..rendering.renderer import Renderer
        renderer = Renderer(backend=backend)
    result = MovieResult(os.fspath(path), len(plan), width, height, fps, technique)
    bar = Progress(len(plan)) if progress else None
    began = time.perf_counter()
    try:
        with atomic_path(os.fspath(path), fmt) as tmp:
            writer = _open_writer(imageio, tmp, fmt, fps)
            try:
                for i, (step, turn) in enumerate(plan):
                    if bar is not None:
                        label = "" if series is None else f", {series.label(step)}"
                        bar.begin(f"frame {i + 1}/{len(plan)}{label}")
                    scene = base.replace(volume=first if series is None else series[step],
                                         camera=first_camera(framing, azimuth=start + turn, **view),
                                         **({} if stack is None else {"layers": stack.layers_at(step)}))
                    t0 = time.perf_counter()
                    image = renderer.render(scene, technique=technique, **options)
                    t1 = time.perf_counter()
                    writer.append_data(dvr_io.to_png_array(image, background=background))
                    result.render_s.append(t1 - t0)
                    result.write_s.append(time.perf_counter() - t1)
                    if bar is not None:
                        bar.advance()
            except BaseException:
                try:
                    writer.close()
                except Exception:       # the error that stopped the movie is the one to report
                    pass
                raise
            writer.close()
    finally:
        if bar is not None:
            bar.close()
        if own:
            renderer.release()
    result.total_s = time.perf_counter() - began
    return result


def _imageio(fmt):
    """imageio.v2, with imageio-ffmpeg for an .mp4; a MovieDependencyError naming the
    extra when one is missing."""
    try:
        import imageio.v2 as imageio
        if fmt == ".mp4":
            import imageio_ffmpeg  # noqa: F401  (the ffmpeg binary comes inside its wheel)
    except ImportError as e:
        raise MovieDependencyError(f"writing {fmt} movies needs imageio and imageio-ffmpeg ({e.name or e} is "
                                   "missing): pip install \"dvr-gl[movie]\"") from None
    return imageio


def _open_writer(imageio, tmp, fmt, fps):
    if fmt == ".mp4":
        # macro_block_size=1: imageio would otherwise scale to a multiple of 16; crf 18
        # is close to visually lossless for H.264
        return imageio.get_writer(tmp, format="FFMPEG", mode="I", fps=fps, codec="libx264",
                                  pixelformat="yuv420p", macro_block_size=1, quality=None,
                                  output_params=["-crf", "18"], ffmpeg_log_level="error")
    return imageio.get_writer(tmp, format="GIF", mode="I", duration=1000.0 / fps, loop=0)


# ----------------------------------------------------------------------------- the command

def add_movie_parser(sub):
    """``dvr-gl movie``: its options, on the ``sub`` parsers of the command line."""
    m = sub.add_parser(
        "movie", help="render an orbit or a time series to a movie (.mp4, .gif)",
        description="Render a movie: a volume or mesh turning about its up direction (--orbit, --frames), "
                    "the time steps of a series (INPUT a glob pattern such as 'steps/t_*.nrrd', quoted, or a "
                    "4-D .npy, .npz, .nrrd or .nii file), or both. One transfer function fits every step. "
                    "An .mp4 is H.264 and needs an even --size; a .gif keeps 256 colours per frame.")
    m.add_argument("--out", "-o", required=True, metavar="MOVIE.mp4|MOVIE.gif", help="the movie to write")
    m.add_argument("--frames", type=whole_number(1), metavar="N",
                   help=f"frames in all (default: {ORBIT_FRAMES} for an orbit, one per step for a series, "
                        "whose steps are spread over N frames when given)")
    m.add_argument("--orbit", type=_number, metavar="DEG",
                   help="degrees the camera turns over the movie (default: 360 for a volume or mesh, "
                        "0 for a series)")
    m.add_argument("--fps", type=_positive, default=24.0, metavar="F",
                   help=f"frames per second (default: 24; at most {GIF_MAX_FPS:g} for a .gif)")
    add_render_options(m)
    for action in m._actions:
        if action.dest == "input":
            action.help = ("volume or mesh file, builtin:NAME, a quoted glob pattern of volume files (one per "
                           "time step, sorted naturally) or a 4-D array file (.npy/.npz time first, .nrrd "
                           "its time axis, .nii time last)")
        if action.dest == "background":
            action.help = "composite over this colour (components in [0, 1]; default white, black for " \
                          "--optical-model emission)"
    return m


def cmd_movie(args, out=None):
    """Run ``dvr-gl movie``; the checks that need no data come before any is read."""
    out = out or sys.stdout
    try:
        fmt = movie_format(args.out)
        check_fps(args.fps, fmt)
        check_movie_size(args.size, fmt)
        _imageio(fmt)
    except InputError as e:
        raise UsageError(MOVIE_OPTIONS[e.field], e.detail) from None
    except MovieDependencyError as e:
        print(f"dvr-gl movie: error: {e}", file=sys.stderr)
        return 2
    check_technique(args.technique)
    options = technique_options(args)
    technique = options.pop("technique")
    mode = args.mode or ("isosurface" if args.iso is not None else "composite")
    if mode == "isosurface" and args.iso is None:
        raise UsageError("--iso", "an iso-value is required with --mode isosurface")
    if args.iso is not None and mode != "isosurface":
        raise UsageError("--iso", f"is only used with --mode isosurface, not --mode {mode}")
    if args.light and len(args.light) > 4:
        raise UsageError("--light", f"at most 4 lights, got {len(args.light)}")
    check_dtype_option(args)

    geometry = dict(scalars=args.scalars, shape=args.shape, dtype=args.dtype, spacing=args.spacing, origin=args.origin,
                    mask_nonfinite=args.mask_nonfinite, orientation=args.orientation)
    stack = None
    if check_layer_options(args, mode):          # several volumes: INPUT's, --volume, --labels, --channels
        stack = movie_volumes(args.input, args.tf, args.volume or (), args.labels, args.channels, args.blend,
                              **geometry)
        data, tf, tf_name = stack.main, None, "one ramp per channel" if args.channels else (args.tf or "auto")
        framing = stack.framing(data[0] if isinstance(data, VolumeSeries) else data)
    else:
        data, preset = load_movie_input(args.input, **geometry)
        try:
            tf_name, tf = resolve_movie_tf(args.tf, data, preset)
        except InputError as e:
            raise UsageError("--tf", e.detail) from None
        framing = data
    scene_parts = dict(clip_args(args, framing), **geometry_args(args, technique))   # clips, crop, surfaces
    series = data if isinstance(data, VolumeSeries) else None
    try:
        result = render_movie(data if stack is None else stack, args.out, frames=args.frames, orbit=args.orbit,
                              fps=args.fps, size=args.size,
                              tf=tf, technique=technique, azimuth=args.azimuth, elevation=args.elevation,
                              zoom=args.zoom, fov=args.fov, ortho=args.ortho, mode=mode, iso=args.iso,
                              shading=args.shading, lights=tuple(args.light) if args.light else None,
                              optical_model=args.optical_model, illustration=args.illustration,
                              background=args.background, backend=args.backend, **scene_parts, **options)
    except InputError as e:
        if e.field in MOVIE_OPTIONS:
            raise UsageError(MOVIE_OPTIONS[e.field], e.detail) from None
        raise
    lo, hi = data.data_range
    if series is not None:
        nz, ny, nx = series.shape
        what = f"series of {len(series)} steps, {nx}x{ny}x{nz} (x, y, z) each"
    elif getattr(data, "n_tets", None) is not None:
        what = f"mesh, {data.n_points} points, {data.n_tets} tets"
    else:
        nz, ny, nx = data.shape
        what = f"volume, {nx}x{ny}x{nz} (x, y, z)"
    print(f"input      {args.input}: {what}, values {lo:g}..{hi:g}", file=out)
    print(f"transfer   {tf_name}, resolved once for every frame", file=out)
    if stack is not None:
        print(f"volumes    {len(stack.names)}, blend {stack.blend}: {'; '.join(stack.names)}"
              + (f", {stack.steps} time steps" if stack.steps > 1 else ""), file=out)
    still = series is None and (stack is None or stack.steps == 1)
    turn = args.orbit if args.orbit is not None else (360.0 if still else 0.0)
    print(f"movie      {result.frames} frames, {result.width}x{result.height}, {result.fps:g} fps "
          f"({result.frames / result.fps:.1f} s), orbit {turn:g} degrees, {technique}", file=out)
    print(f"time       {result.summary()}", file=out)
    print(f"wrote      {args.out} ({FORMATS[fmt]})", file=out)
    return 0
