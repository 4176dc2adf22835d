"""The exact image of the contract (docs/contract.md; ``shared/design/conventions.md``,
sections 3-7), in float64: what every error dvr_gl reports is measured against.

``exact(scene)`` computes it and keeps it in a cache folder, named by the scene's digest
and the integrators' ``VERSION``. The integrators: ``exact_one`` for a scene of one volume
or one mesh (its docstring gives the method and the measured accuracy), ``exact_layers``
for several volumes, which reuses ``exact_one``'s pieces and quadrature.
"""

from __future__ import annotations

import io
import os

import numpy as np

from ..model.scene import Scene
from .exact_layers import render_layers
from .exact_one import VERSION, render as render_one

__all__ = ["exact", "VERSION"]


def _cache_dir(cache_dir):
    if cache_dir is not None:
        return os.fspath(cache_dir)
    env = os.environ.get("DVR_GL_CACHE")
    if env:
        return env
    return os.path.join(os.path.expanduser("~"), ".cache", "dvr_gl", "exact")


def exact(scene, cache=True, cache_dir=None) -> np.ndarray:
    """The exact image of ``scene`` (``dvr_gl.Scene``): float64 ``(H, W, 4)``, premultiplied
    RGBA, row 0 on top, for modes composite, mip, minip, average and isosurface.

    With ``cache`` (default) the image is stored as ``.npy`` in ``cache_dir`` (default:
    ``$DVR_GL_CACHE``, else ``~/.cache/dvr_gl/exact``), named by ``scene.digest()`` and the
    integrator's ``VERSION``, and loaded from there next time. ``cache=False`` neither
    reads nor writes it."""
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a dvr_gl.Scene, got {type(scene).__name__}")
    if scene.is_mesh and scene.optical_model == "sabella":
        raise ValueError("optical_model='sabella' is defined here for grids (the peak of the trilinear field)")
    path = None
    if cache:
        directory = _cache_dir(cache_dir)
        path = os.path.join(directory, f"{scene.digest()}-{VERSION}.npy")
        try:
            img = np.load(path)
        except (OSError, ValueError):     # absent (or unreadable: computed again)
            img = None
        if img is not None and img.shape == (scene.height, scene.width, 4) and img.dtype == np.float64:
            return img
    with np.errstate(divide="ignore", invalid="ignore", over="ignore", under="ignore"):
        img = render_layers(scene) if scene.layers else render_one(scene)
    if path is not None:
        from ..util.files import atomic_write
        os.makedirs(directory, exist_ok=True)
        buffer = io.BytesIO()
        np.save(buffer, img)
        atomic_write(path, buffer.getvalue())  # readers never see a partial file
    return img
