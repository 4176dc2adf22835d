"""File formats: loading volumes and meshes, saving images.

- :func:`load_volume` reads a structured scalar volume into a :class:`dvr_gl.Volume`:
  ``.npy``/``.npz``, NRRD, MetaImage, NIfTI, a DICOM series, a TIFF stack, VTK image data
  and raw samples. :mod:`dvr_gl.formats.volumes` describes each format, what the file
  supplies (spacing, origin, anatomical orientation, modality) and how samples are
  widened to the types a Volume holds.
- :func:`open_volume` opens a volume lazily (a :class:`dvr_gl.model.lazy_volume.LazyVolume`
  read block by block): zarr stores (v2, v3), OME-Zarr multiscale images, HDF5 datasets
  (``file.h5:/group/data``) and ``.npy`` memmaps without loading them, other formats
  loaded and wrapped; :func:`open_store` and :func:`is_store` are the store readers of
  :mod:`dvr_gl.formats.stores`.
- :func:`load_series` reads volumes over time into a
  :class:`dvr_gl.model.series.VolumeSeries`: a list of files or a glob pattern, or one
  4-D array (see :mod:`dvr_gl.formats.series` for where each format keeps time).
- :func:`load_mesh` reads an unstructured mesh into a :class:`dvr_gl.TetMesh` (``.npz``,
  ``.vtu``, legacy ``.vtk`` and what meshio reads); :func:`is_mesh_file` tells a mesh from
  a volume, :func:`point_arrays` lists a mesh file's point arrays. See
  :mod:`dvr_gl.formats.meshes`.
- :func:`load_surface` reads a triangle mesh file (what meshio reads; quadrilaterals
  split) into a :class:`dvr_gl.Surface` to draw inside a volume (``Scene.geometry``).
- :func:`save_surface` writes a :class:`dvr_gl.Surface` (an isosurface, say) to ``.ply``,
  ``.obj``, ``.stl``, ``.vtk`` or ``.vtu`` through meshio, atomically (see
  :mod:`dvr_gl.formats.surfaces`).
- :func:`save_png` writes a premultiplied float RGBA image (conventions section 7)
  atomically; :func:`to_png_array` is the 8-bit array it writes.
- :func:`parse_size`, :func:`parse_triplet` and :func:`parse_orientation` parse
  command-line values.

Every error is an :class:`InputError` (a ``ValueError``) whose ``field`` names what was
wrong (``path``, ``shape``, ``dtype``, ``spacing``, a header field, ...) and whose message
shows the offending value; a missing file raises :class:`MissingFileError`, which is also
a ``FileNotFoundError``.

One module per format family: :mod:`~dvr_gl.formats.numpy_files`,
:mod:`~dvr_gl.formats.nrrd`, :mod:`~dvr_gl.formats.metaimage`, :mod:`~dvr_gl.formats.nifti`,
:mod:`~dvr_gl.formats.dicom`, :mod:`~dvr_gl.formats.tiff`, :mod:`~dvr_gl.formats.vtk_image`
and :mod:`~dvr_gl.formats.raw` read volumes, :mod:`~dvr_gl.formats.volumes` chooses among
them by name; :mod:`~dvr_gl.formats.meshes` reads meshes, :mod:`~dvr_gl.formats.images`
writes PNGs. Beneath them: :mod:`~dvr_gl.formats.errors` (the errors, and the guards that
raise them), :mod:`~dvr_gl.formats.parsing` (values users give) and
:mod:`~dvr_gl.formats.anatomy` (orientation letters and modality codes).
"""

from __future__ import annotations

# what importers use, from the modules that define it (private names included: the
# command line checks a dtype early with _parse_dtype)
from ..util.files import atomic_write
from .anatomy import right_handed
from .errors import InputError, MissingFileError
from .images import save_png, to_png_array
from .meshes import AMBIGUOUS_MESH_EXTENSIONS, is_mesh_file, load_mesh, point_arrays
from .parsing import RAW_DTYPES, _parse_dtype, parse_orientation, parse_size, parse_triplet
from .raw import raw_name_layout
from .surfaces import SURFACE_FORMATS, load_surface, save_surface
from .volumes import SUPPORTED_VOLUMES, load_volume
from .stores import describe_store, is_store, open_store, open_volume
from .series import is_series_file, load_series, load_series_file, natural_key, series_paths

__all__ = ["InputError", "MissingFileError", "load_volume", "load_mesh", "is_mesh_file", "point_arrays",
           "save_png", "to_png_array", "load_surface", "save_surface", "parse_size", "parse_triplet", "parse_orientation", "RAW_DTYPES",
           "load_series", "is_series_file", "open_volume", "open_store", "is_store"]
