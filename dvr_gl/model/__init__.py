"""The data model: plain, validated data that knows nothing of GL or of files.

- ``volume``: :class:`Volume`, a structured grid; ``mesh``: :class:`TetMesh` and what is
  derived once per mesh (connectivity, face planes, each cell's linear field);
- ``transfer_function``: :class:`TransferFunction` and :class:`TransferFunction2D`;
  ``transfer``: their lookup and knot tables, opacity correction and presets;
  ``transfer2d``: 2-D transfer functions built from widgets; ``preintegration``: the
  pre-integrated segment table;
- ``camera``: :class:`Camera`, :class:`Light`, default views; ``scene``: :class:`Scene`;
- ``field``: the field between samples (interpolation, gradients), read alike by the
  techniques, their NumPy twins and the exact integrator;
- ``clipping``: clip planes and crop boxes; ``geometry``: opaque :class:`Surface` meshes;
- ``layers``: :class:`Layer` and :class:`LabelColors`, several volumes (scans, channels,
  label volumes) in one scene;
- ``series``: ``VolumeSeries``, volumes over time on one grid;
- ``cell_split``: hexahedra, wedges and pyramids into tetrahedra; ``mesh_grid``: a mesh's field
  resampled onto a regular grid; ``checks``: argument checks.
"""

from .camera import Camera, Light, anatomical_frame, default_camera
from .geometry import Surface
from .layers import LabelColors, Layer
from .mesh import TetMesh
from .scene import Scene
from .transfer_function import TransferFunction, TransferFunction2D
from .volume import Volume

__all__ = ["Camera", "LabelColors", "Layer", "Light", "Scene", "Surface", "TetMesh", "TransferFunction", "TransferFunction2D", "Volume",
           "anatomical_frame", "default_camera"]
