"""dvr_gl: direct volume rendering with OpenGL, headless on llvmpipe or on a GPU,
checked against NumPy references and an exact float64 integrator."""

from .model import Camera, LabelColors, Layer, Light, Scene, Surface, TetMesh, TransferFunction, TransferFunction2D, Volume, default_camera

from ._version import __version__

from . import _compat

_compat.install()

__all__ = ["Camera", "LabelColors", "Layer", "Light", "Renderer", "Scene", "Surface", "TetMesh", "TransferFunction", "TransferFunction2D", "Volume", "default_camera",
           "metrics", "reference", "render", "__version__"]


def __getattr__(name):
    # GL and the references are imported on first use so that `import dvr_gl` stays cheap.
    if name == "Renderer":
        from .rendering.renderer import Renderer
        return Renderer
    if name == "render":
        from .frontends.inputs import render
        return render
    if name == "distributed":          # sort-last rendering on a Dask cluster (needs dask.distributed)
        import importlib
        return importlib.import_module(".frontends.distributed", __name__)
    if name in ("reference", "metrics"):
        import importlib
        return importlib.import_module(f".{name}", __name__)
    if f"{__name__}.{name}" in _compat.MOVED:      # dvr_gl.io and the like, for one release
        return _compat.moved_module(f"{__name__}.{name}")
    raise AttributeError(f"module 'dvr_gl' has no attribute {name!r}")
