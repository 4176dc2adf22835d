"""NumPy references (same plan as the GL path, float64) and the exact image.

The twins (``render``, one module per technique) follow the plan a technique makes, and
so import its planning code; the exact image (``exact``) depends on the scene model
alone, so that no defect of a technique can hide in its own judge."""

from __future__ import annotations

# Imported here, not inside a function, so the package attribute `exact` is the function
# for good: importing the submodule first would otherwise leave the module in its place.
from .exact import exact

__all__ = ["exact", "quantize_unorm8", "render"]


def render(scene, technique="raycast", step=None, *, lut_exact=False, **options):
    """The NumPy reference image of ``technique`` for ``scene``: the same sample positions,
    order and tables as the shader, in float64. Options as for ``Renderer.render``.
    ``lut_exact=True`` classifies with the exact transfer function instead of its lookup
    table. Returns (H, W, 4) float64, premultiplied RGBA, row 0 on top."""
    import importlib

    from ..techniques import check_options, get_technique   # the plan; the exact image needs no technique
    check_options(technique, options)
    plan = get_technique(technique).make_plan(scene, step, **options)
    module = importlib.import_module(f"{__name__}.{technique}")
    image = module.render_plan(plan, lut_exact=lut_exact)
    if plan.target == "rgba8":
        image = quantize_unorm8(image)
    elif plan.target == "rgba16f":
        image = image.astype("float16").astype("float64")
    return image


def quantize_unorm8(image):
    """What an 8-bit normalised target stores: round(clamp(x) * 255) / 255."""
    import numpy as np
    return np.round(np.clip(image, 0, 1) * 255) / 255

