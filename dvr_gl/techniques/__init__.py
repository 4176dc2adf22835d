"""The techniques, by name. Each module offers ``make_plan(scene, step, **options)`` (the
plan the GL path and the NumPy reference share), ``draw(renderer, plan)`` (renders into
the renderer's target, ``gpu.target_fbo``, and returns that framebuffer), ``MODES`` (the scene modes it
renders), ``TAKES_STEP`` (whether ``step`` is an option) and ``DATA`` ("volume" for grids,
"mesh" for TetMesh scenes, or a tuple of both); the reference of the same name lives in ``dvr_gl.reference``."""

from __future__ import annotations

import importlib

_MODULES = {"raycast": "dvr_gl.techniques.raycast", "slice2d": "dvr_gl.techniques.slice2d",
            "slice3d": "dvr_gl.techniques.slice3d", "tetra": "dvr_gl.techniques.tetra",
            "particles": "dvr_gl.techniques.particles", "splat": "dvr_gl.techniques.splat"}


def names():
    return tuple(_MODULES)


def for_scene(scene):
    """The names of the techniques that can render ``scene`` (its data and its mode)."""
    return for_data(scene.volume, scene.mode)


def for_data(data, mode="composite"):
    """The names of the techniques that render ``data`` (a Volume or a TetMesh) in ``mode``."""
    kind = "mesh" if getattr(data, "n_tets", None) is not None else "volume"
    return tuple(n for n in _MODULES
                 if mode in get_technique(n).MODES and kind in _kinds(get_technique(n).DATA))


def _kinds(data):
    return (data,) if isinstance(data, str) else tuple(data)


def get_technique(name):
    """The technique module called ``name``."""
    if name not in _MODULES:
        raise ValueError(f"technique must be one of {', '.join(_MODULES)}, got {name!r}")
    return importlib.import_module(_MODULES[name])


def options(name):
    """The keyword options ``name``'s ``make_plan`` takes (``step`` and the renderer's
    ``tables`` aside)."""
    import inspect
    module = get_technique(name)
    params = inspect.signature(module.make_plan).parameters
    keywords = tuple(p for p, v in params.items() if v.kind == v.KEYWORD_ONLY and p != "tables")
    return (("step",) if module.TAKES_STEP else ()) + keywords


def check_options(name, given):
    """An option ``name`` does not take is a TypeError that names the ones it does."""
    unknown = [k for k in given if k not in options(name) or k == "step"]   # step is its own argument
    if unknown:
        raise TypeError(f"{name} has no option {unknown[0]!r}; its options are {', '.join(options(name))}")
