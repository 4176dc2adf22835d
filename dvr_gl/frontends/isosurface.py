"""``dvr-gl isosurface``: the level set of a volume or a mesh, written as a triangle mesh.

    dvr-gl isosurface builtin:ct_head --iso 1300 -o bone.ply
    dvr-gl isosurface bluntfin_tets.vtu --scalars Density --iso 1.2 -o shock.stl

INPUT is anything ``dvr-gl render`` takes (a volume file, a mesh file, ``builtin:NAME``,
with the same input options). A volume goes through marching cubes, a mesh through
marching tetrahedra (:mod:`dvr_gl.model.isosurface`); the file's format follows its
extension, ``.ply``, ``.obj``, ``.stl``, ``.vtk`` or ``.vtu``
(:func:`dvr_gl.formats.save_surface`). The command prints the triangle count and the
time each step took.
"""

from __future__ import annotations

import os
import sys
import time

from .. import formats as dvr_io
from ..formats.surfaces import surface_format
from .options import (UsageError, _check_input_options, _number, add_raw_options, check_dtype_option, input_is_mesh,
                      load_input_args)


def add_isosurface_parser(sub):
    """The ``isosurface`` command's parser, added to the command line's subparsers."""
    s = sub.add_parser(
        "isosurface", help="extract an isosurface as a triangle mesh (.ply, .obj, .stl, .vtk, .vtu)",
        description="Extract the surface where INPUT's value equals --iso and write it as a triangle "
                    "mesh: marching cubes for a volume, marching tetrahedra for a mesh. INPUT is what "
                    "render takes: a volume file, a mesh file or builtin:ct_head, builtin:synthetic. "
                    "Inside is value >= V; triangle normals point towards lower values.")
    s.add_argument("input", metavar="INPUT", help="volume file, mesh file or builtin:NAME")
    s.add_argument("--iso", type=_number, required=True, metavar="V", help="the level (data units)")
    s.add_argument("--out", "-o", required=True, metavar="SURFACE",
                   help=f"the file to write; its extension names the format: {', '.join(dvr_io.SURFACE_FORMATS)}")
    s.add_argument("--scalars", metavar="NAME",
                   help="mesh inputs: the point array to contour (default: the first scalar array)")
    add_raw_options(s, mask_help="treat NaN and inf samples as outside the volume (their cells give no triangles)")
    return s


def check_surface_path(path, option="--out"):
    """``path`` names a surface file (a known extension) in an existing folder."""
    try:
        surface_format(path)
    except dvr_io.InputError as e:
        raise UsageError(option, e.detail) from None
    directory = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(directory):
        raise UsageError(option, f"the folder {directory!r} does not exist")
    if os.path.isdir(path):
        raise UsageError(option, f"{path!r} is a folder")


def cmd_isosurface(args, out=None):
    """Run ``dvr-gl isosurface``; returns the exit status."""
    out = out or sys.stdout
    check_surface_path(args.out)
    check_dtype_option(args)
    mesh = input_is_mesh(args)
    _check_input_options(args, mesh)

    t0 = time.perf_counter()
    data, _ = load_input_args(args)
    t1 = time.perf_counter()
    lo, hi = data.data_range
    if not lo <= args.iso <= hi:
        raise UsageError("--iso", f"{args.iso:g} is outside the data's range {lo:g}..{hi:g}: there is no surface")
    from ..model.isosurface import isosurface
    try:
        surface = isosurface(data, args.iso)
    except ImportError as e:           # scikit-image, for marching cubes
        print(f"dvr-gl isosurface: error: {e}", file=sys.stderr)
        return 1
    except ValueError as e:            # no surface at this level
        raise UsageError("--iso", str(e)) from None
    t2 = time.perf_counter()
    dvr_io.save_surface(args.out, surface)
    t3 = time.perf_counter()

    if mesh:
        name = getattr(data, "scalars_name", None) or args.scalars or "?"
        print(f"mesh       {args.input}: {data.n_points} points, {data.n_tets} tets, scalars {name} {lo:g}..{hi:g}",
              file=out)
    else:
        nz, ny, nx = data.shape
        sx, sy, sz = (float(v) for v in data.spacing)
        print(f"volume     {args.input}: {nx}x{ny}x{nz} (x, y, z) {data.data.dtype}, spacing {sx:g},{sy:g},{sz:g}, "
              f"values {lo:g}..{hi:g}", file=out)
    method = "marching tetrahedra" if mesh else "marching cubes"
    print(f"surface    {surface.n_faces} triangles, {len(surface.vertices)} vertices at level {args.iso:g} "
          f"({method})", file=out)
    print(f"time       load {t1 - t0:.3f} s, extract {t2 - t1:.3f} s, write {t3 - t2:.3f} s", file=out)
    print(f"wrote      {args.out}", file=out)
    return 0
