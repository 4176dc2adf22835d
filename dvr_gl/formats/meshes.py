"""Loading meshes.

:func:`load_mesh` reads an unstructured mesh into a :class:`dvr_gl.TetMesh`
(conventions section 2):

- ``.npz`` with arrays ``points`` (N, 3) and ``tets`` (M, 4) -- the layout of the shared
  mesh data sets -- and one (N,) array per point scalar (others, such as an (N, 3)
  vector, may be there too).
- ``.vtu``, legacy ``.vtk`` (``DATASET UNSTRUCTURED_GRID``) and every other format meshio
  reads (``.msh``, ``.xdmf``, ``.inp``, ``.mesh``, ``.vol``, ...). Tetrahedra are kept;
  hexahedra, wedges and pyramids are split into tetrahedra conformingly
  (:mod:`dvr_gl.model.cell_split`); vertices, lines and surface cells are ignored when the
  file has 3-D cells; any other 3-D cell (quadratic, polyhedral) is an error naming it.

The field is a point array chosen by name (``scalars``; default: the first array with
one component and more than three distinct values, so that blanking flags such as
IBlank are passed over; the first one-component array if all are flags). Cell arrays
(one value per cell) are not a field here; a file without a point array is an error that
names them. Points no cell uses are kept. :func:`is_mesh_file` says whether a path is a
mesh rather than a volume; :func:`point_arrays` lists a mesh file's point arrays.
"""

from __future__ import annotations

import contextlib
import io
import os
import zlib

import numpy as np

from ..model.mesh import TetMesh
from .errors import InputError, _existing_file, _named_errors
from .numpy_files import _npz_keys
from .vtk_image import _vtk_dataset


#: meshio's extensions that are also common names for raw volumes: a mesh only when the
#: command line gives no raw geometry (see dvr_gl.frontends.cli).
AMBIGUOUS_MESH_EXTENSIONS = (".dat", ".vol")

_SPLIT_CELLS = ("tetra", "pyramid", "wedge", "hexahedron")
_LOW_DIMENSIONAL_PREFIXES = ("vertex", "line", "triangle", "quad", "polygon")


def _mesh_path(path):
    return _existing_file(path, "mesh")


def _meshio_extensions():
    try:
        import meshio
    except ImportError:
        return ()
    return tuple(sorted(getattr(meshio, "extension_to_filetypes", {}), key=len, reverse=True))


def is_mesh_file(path) -> bool:
    """Whether ``path`` names an unstructured mesh (for :func:`load_mesh`) rather than a
    volume (for :func:`load_volume`): ``.vtu``; ``.vtk`` whose DATASET is
    UNSTRUCTURED_GRID; ``.npz`` holding ``points`` and ``tets``; any other extension
    meshio reads (``.dat`` and ``.vol`` included, see ``AMBIGUOUS_MESH_EXTENSIONS``)."""
    path = os.fspath(path)
    lower = path.lower()
    if lower.endswith(".vtu"):
        return True
    if lower.endswith(".vtk"):
        return _vtk_dataset(path) == "UNSTRUCTURED_GRID"
    if lower.endswith(".npz"):
        return os.path.isfile(path) and {"points", "tets"} <= set(_npz_keys(path))
    if lower.endswith((".npy", ".nrrd", ".nhdr", ".mhd", ".mha", ".raw", ".raw.gz")):
        return False
    return any(lower.endswith(ext) for ext in _meshio_extensions())


class _MeshFile:
    """What a mesh file holds: points, tetrahedra, the point arrays by name, and the names
    of its cell arrays (not rendered: named in errors, so that a file of cell data says why
    it has no field)."""

    def __init__(self, points, tets, arrays, cell_arrays=()):
        self.points, self.tets, self.arrays = points, tets, arrays
        self.cell_arrays = tuple(cell_arrays)


_last_read = {}


@_named_errors
def _read_mesh_file(path):
    """The file's content, read once per (path, size, mtime): ``dvr-gl info`` asks for the
    mesh and its array names without reading a large file twice."""
    st = os.stat(path)
    key = (os.path.abspath(path), st.st_size, st.st_mtime_ns)
    if key not in _last_read:
        content = _read_npz_mesh(path) if path.lower().endswith(".npz") else _read_meshio(path)
        _last_read.clear()
        _last_read[key] = content
    return _last_read[key]


def _read_npz_mesh(path):
    try:
        with np.load(path, allow_pickle=False) as npz:
            missing = [k for k in ("points", "tets") if k not in npz.files]
            if missing:
                raise InputError("path", f"{path!r} is not a mesh: it lacks {missing} "
                                         f"(it has {sorted(npz.files)})")
            points, tets = npz["points"], npz["tets"]
            arrays = {k: npz[k] for k in npz.files if k not in ("points", "tets")}
    except InputError:
        raise
    except (ValueError, OSError, zlib.error) as e:
        raise InputError("path", f"cannot read {path!r} as .npz: {e}") from None
    if tets.dtype.kind not in "iu":
        raise InputError("tets", f"{path!r}: tets must be integer indices, got dtype {tets.dtype}")
    if tets.ndim != 2 or tets.shape[1] != 4:
        raise InputError("tets", f"{path!r}: tets must have shape (M, 4), got {tets.shape}")
    return _MeshFile(points, tets.astype(np.int64), arrays)


def _cell_dimension(cell_type):
    """3 for solid cells, less for vertices, lines and surface cells; None if unknown."""
    try:
        from meshio._mesh import topological_dimension
        if cell_type in topological_dimension:
            return topological_dimension[cell_type]
    except ImportError:
        pass
    if cell_type.startswith(_LOW_DIMENSIONAL_PREFIXES):
        return 2
    return None


def _read_meshio(path):
    try:
        import meshio
    except ImportError as e:
        raise InputError("path", f"reading {path!r} needs meshio (pip install meshio): {e}") from None
    m = _meshio_read(meshio, path)
    blocks, ignored = [], []
    for block in m.cells:
        dimension = _cell_dimension(block.type)
        if block.type in _SPLIT_CELLS:
            blocks.append((block.type, np.asarray(block.data)))
        elif dimension is not None and dimension < 3:
            ignored.append(block.type)
        else:
            raise InputError("cells", f"{path!r} has {len(block.data)} cells of type {block.type!r}, which "
                                      f"cannot be rendered; supported 3-D cells: {', '.join(_SPLIT_CELLS)}")
    if not blocks:
        kinds = ", ".join(sorted(set(ignored))) or "none"
        raise InputError("cells", f"{path!r} has no 3-D cells (cell types: {kinds}); a volume mesh needs "
                                  f"{', '.join(_SPLIT_CELLS)}")
    from ..model.cell_split import split_cells
    try:
        tets = split_cells(blocks)
    except (TypeError, ValueError) as e:
        raise InputError("cells", f"{path!r}: {e}") from None
    arrays = {name: np.asarray(a) for name, a in m.point_data.items()}
    return _MeshFile(np.asarray(m.points), tets, arrays, m.cell_data.keys())


def _meshio_read(meshio, path):
    """``meshio.read`` for each format the extension allows, with meshio's own printing
    kept off the terminal: on a malformed file it prints and calls ``sys.exit``."""
    lower = path.lower()
    formats = next((types for ext, types in sorted(getattr(meshio, "extension_to_filetypes", {}).items(),
                                                    key=lambda item: -len(item[0]))
                    if lower.endswith(ext)), [None])
    problems = []
    for file_format in formats:
        chatter = io.StringIO()
        try:
            with contextlib.redirect_stdout(chatter), contextlib.redirect_stderr(chatter):
                return meshio.read(path, file_format=file_format)
        except (Exception, SystemExit) as e:  # meshio's readers raise many types for a bad file
            said = " ".join(chatter.getvalue().split())
            problems.append(str(e).strip() if isinstance(e, Exception) and str(e).strip()
                            else said or type(e).__name__)
    kinds = " or ".join(f for f in formats if f) or "a mesh"
    raise InputError("path", f"cannot read {path!r} as {kinds}: {'; '.join(problems)}")


def _components(array):
    return 1 if array.ndim == 1 else int(np.prod(array.shape[1:]))


def point_arrays(path) -> dict:
    """A mesh file's point arrays: name -> number of components, in file order."""
    path = _mesh_path(path)
    return {name: _components(a) for name, a in _read_mesh_file(path).arrays.items()}


def _is_flag(values):
    """A point array of at most three distinct values (a blanking or ghost flag)."""
    return len(np.unique(np.asarray(values).ravel()[:100000])) <= 3


def load_mesh(path, scalars=None) -> TetMesh:
    """Read a mesh file (see the module docstring for formats) with the point array
    ``scalars`` (default: the first one-component point array that is not a flag of at
    most three values, such as IBlank) as the field."""
    path = _mesh_path(path)
    content = _read_mesh_file(path)
    arrays = content.arrays
    listing = ", ".join(f"{n} ({_components(a)} components)" if _components(a) != 1 else n
                        for n, a in arrays.items()) or "none"
    # a field per cell (as finite-volume solvers write): named as the reason there is none
    cell_note = (f". Its cell arrays are not rendered (the field is linear in each cell, from values at "
                 f"the points): {', '.join(content.cell_arrays)}" if content.cell_arrays else "")
    if scalars is None:
        candidates = [n for n, a in arrays.items() if _components(a) == 1]
        # a field, not a flag: blanking arrays (IBlank: -1, 0, 1) come first in some files
        name = next((n for n in candidates if not _is_flag(arrays[n])), candidates[0] if candidates else None)
        if name is None:
            raise InputError("scalars", f"{path!r} has no scalar point array to render "
                                        f"(point arrays: {listing})" + cell_note)
    else:
        name = str(scalars)
        if name not in arrays:
            raise InputError("scalars", f"{path!r} has no point array {name!r}; available: {listing}" + cell_note)
    values = arrays[name]
    if _components(values) != 1:
        raise InputError("scalars", f"point array {name!r} in {path!r} has {_components(values)} components; "
                                    "a scalar field has 1")
    if values.dtype.kind not in "biuf":
        raise InputError("scalars", f"point array {name!r} in {path!r} holds {values.dtype}, not numbers")
    points = np.asarray(content.points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise InputError("points", f"{path!r}: points must be (N, 3), got shape {points.shape}")
    try:
        mesh = TetMesh(points, content.tets, values.reshape(len(values)).astype(np.float64))
    except (TypeError, ValueError) as e:
        raise InputError("mesh", f"{path!r}: {e}") from None
    mesh.scalars_name = name     # which array the field is (dvr-gl info marks it)
    return mesh
