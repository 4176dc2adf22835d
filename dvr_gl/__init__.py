"""dvr_gl: direct volume rendering with OpenGL, headless on llvmpipe or on a GPU,
checked against NumPy references and an exact float64 integrator."""

from .scene import Camera, Light, Scene, TetMesh, TransferFunction, TransferFunction2D, Volume, default_camera

__version__ = "0.1.0"

__all__ = ["Camera", "Light", "Renderer", "Scene", "TetMesh", "TransferFunction", "TransferFunction2D", "Volume", "default_camera",
           "metrics", "reference", "render", "__version__"]


def __getattr__(name):
    # GL and the references are imported on first use so that `import dvr_gl` stays cheap.
    if name == "Renderer":
        from .renderer import Renderer
        return Renderer
    if name == "render":
        from .inputs import render
        return render
    if name in ("reference", "metrics", "io", "transfer"):
        import importlib
        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module 'dvr_gl' has no attribute {name!r}")
