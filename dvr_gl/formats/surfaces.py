"""Surfaces in and out: opaque triangle meshes (:class:`dvr_gl.Surface`).

- :func:`load_surface` reads any surface file meshio reads (``.obj``, ``.stl``, ``.ply``,
  ``.off``, ``.vtk``, ``.vtu``, ``.gltf``, ...) to draw inside a volume
  (``Scene.geometry``): triangles are kept, quadrilaterals split into two triangles
  along their first diagonal (corners 0-1-2 and 0-2-3), every other cell (points,
  lines, polygons, volume cells) is ignored. A file with neither triangles nor
  quadrilaterals is an error naming it. Points are in the file's units, taken as world
  units (the volume's); points no face uses are kept.
- :func:`save_surface` writes a Surface (an isosurface, say) to ``.ply``, ``.obj``,
  ``.stl``, ``.vtk`` or ``.vtu`` (``SURFACE_FORMATS``; :func:`surface_format` names the
  format of a path) through meshio, atomically: a temporary file beside the target,
  renamed over it once whole.
"""

from __future__ import annotations

import os

import numpy as np

from ..model.geometry import Surface
from ..util.files import atomic_path
from .errors import InputError, _existing_file, _named_errors, _optional

__all__ = ["load_surface", "save_surface", "surface_format", "SURFACE_FORMATS"]

# extension -> meshio's name of the format
_WRITERS = {".ply": "ply", ".obj": "obj", ".stl": "stl", ".vtk": "vtk", ".vtu": "vtu"}
SURFACE_FORMATS = tuple(_WRITERS)


def surface_format(path):
    """meshio's name of the format ``path``'s extension names (one of
    ``SURFACE_FORMATS``); an InputError naming the path otherwise."""
    try:
        name = os.fspath(path)
    except TypeError:
        raise InputError("path", f"expected a file name, got {path!r}") from None
    extension = os.path.splitext(name)[1].lower()
    if extension not in _WRITERS:
        raise InputError("path", f"{name!r}: a surface file ends in {', '.join(SURFACE_FORMATS)}, "
                                 f"got {extension or 'no extension'!r}")
    return _WRITERS[extension]


def save_surface(path, surface):
    """Write ``surface`` (a :class:`dvr_gl.Surface`) to ``path`` in the format its
    extension names (:func:`surface_format`): ``.ply`` and ``.vtk`` binary, ``.stl``
    binary (float32 corners, three per triangle), ``.obj`` text, ``.vtu`` VTK XML. The
    vertices and triangles are written, not the colour. Atomically: meshio writes a
    temporary file with the same extension in the same folder, flushed to disk and then
    renamed over ``path``; on any failure it is removed and ``path`` is left as it was.
    Returns ``path``."""
    if not isinstance(surface, Surface):
        raise TypeError(f"surface must be a dvr_gl.Surface, got {type(surface).__name__}")
    file_format = surface_format(path)
    meshio = _optional("meshio", "writing a surface file")
    path = os.fspath(path)
    directory = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(directory):
        raise InputError("path", f"{path!r}: the folder {directory!r} does not exist")
    if os.path.isdir(path):
        raise InputError("path", f"{path!r} is a folder")
    stem, extension = os.path.splitext(os.path.basename(path))
    faces = np.asarray(surface.faces)
    if len(surface.vertices) < 2 ** 31:        # what PLY and STL readers expect (meshio warns otherwise)
        faces = faces.astype(np.int32)
    mesh = meshio.Mesh(np.asarray(surface.vertices, np.float64), [("triangle", faces)])
    options = {"binary": True} if file_format in ("ply", "stl", "vtk") else {}
    with atomic_path(path, extension) as tmp:
        meshio.write(tmp, mesh, file_format=file_format, **options)
    return path


@_named_errors
def _read(path):
    meshio = _optional("meshio", "reading a surface file")
    try:
        return meshio.read(path)
    except meshio.ReadError as e:
        raise InputError("path", f"{path!r} is not a surface file meshio reads: {e}") from None


def load_surface(path, color=(0.85, 0.85, 0.85)) -> Surface:
    """The triangles (and split quadrilaterals) of the surface file ``path`` as a
    :class:`dvr_gl.Surface` of one ``color`` (r, g, b in [0, 1])."""
    path = _existing_file(path, "surface")
    mesh = _read(path)
    faces, found = [], []
    for block in mesh.cells:
        found.append(block.type)
        data = np.asarray(block.data, np.int64)
        if block.type == "triangle":
            faces.append(data.reshape(-1, 3))
        elif block.type == "quad":
            quads = data.reshape(-1, 4)
            faces.append(np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]))
    if sum(len(f) for f in faces) == 0:
        kinds = ", ".join(sorted(set(found))) or "no cells"
        raise InputError("path", f"{path!r} holds no triangles or quadrilaterals (found: {kinds})")
    points = np.asarray(mesh.points, np.float64)
    if points.ndim != 2 or points.shape[1] not in (2, 3):
        raise InputError("path", f"{path!r}: points must be 2-D or 3-D, got shape {points.shape}")
    if points.shape[1] == 2:                      # a planar file: z = 0
        points = np.concatenate([points, np.zeros((len(points), 1))], axis=1)
    try:
        return Surface(points, np.concatenate(faces), color=color)
    except (TypeError, ValueError) as e:
        raise InputError("path", f"{path!r}: {e}") from None
