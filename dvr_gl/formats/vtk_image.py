"""VTK image data -- ``.vti``, legacy ``.vtk`` structured points, ``.slc`` -- through VTK's
own readers, and the DATASET keyword of a legacy ``.vtk`` file (which says whether it
is an image or a mesh)."""

from __future__ import annotations

from .errors import InputError, _named_errors


def _vtk_dataset(path):
    """The DATASET keyword of a legacy .vtk file (its header is ASCII even when the data
    is binary), or None."""
    try:
        with open(path, "rb") as f:
            for _ in range(12):
                line = f.readline(1024)
                if not line:
                    break
                words = line.decode("latin-1").split()
                if len(words) >= 2 and words[0].upper() == "DATASET":
                    return words[1].upper()
    except OSError:
        return None
    return None


@_named_errors
def _load_vtk_image(path):
    """(data (nz, ny, nx), spacing, origin) of VTK image data -- XML ``.vti``, legacy
    ``.vtk`` structured points, ``.slc`` -- through VTK's own readers."""
    lower = path.lower()
    if lower.endswith(".vtk") and _vtk_dataset(path) not in ("STRUCTURED_POINTS", None):
        raise InputError("path", f"{path!r} is a legacy VTK {_vtk_dataset(path)}; load_volume reads "
                                 "STRUCTURED_POINTS (load_mesh reads UNSTRUCTURED_GRID)")
    try:
        from vtkmodules.util.numpy_support import vtk_to_numpy
        from vtkmodules.vtkIOImage import vtkSLCReader
        from vtkmodules.vtkIOLegacy import vtkStructuredPointsReader
        from vtkmodules.vtkIOXML import vtkXMLImageDataReader
    except ImportError:
        raise InputError("path", f"{path!r} is VTK image data, which needs VTK: pip install \"dvr-gl[io]\" "
                                 "(or pip install vtk)") from None
    reader = (vtkXMLImageDataReader() if lower.endswith(".vti") else vtkSLCReader() if lower.endswith(".slc")
              else vtkStructuredPointsReader())
    reader.SetFileName(path)
    reader.Update()
    image = reader.GetOutput()
    points = image.GetPointData() if image is not None else None
    scalars = points.GetScalars() if points is not None else None
    if scalars is None and points is not None and points.GetNumberOfArrays():
        scalars = points.GetArray(0)
    if scalars is None or image.GetNumberOfPoints() == 0:
        raise InputError("path", f"{path!r}: VTK read no image with point scalars from it")
    if scalars.GetNumberOfComponents() != 1:
        raise InputError("path", f"{path!r}: the scalars {scalars.GetName()!r} have "
                                 f"{scalars.GetNumberOfComponents()} components; a volume has one")
    nx, ny, nz = image.GetDimensions()
    data = vtk_to_numpy(scalars).reshape(nz, ny, nx).copy()
    return data, tuple(float(v) for v in image.GetSpacing()), tuple(float(v) for v in image.GetOrigin())
