"""The techniques, by name. Each module offers ``make_plan(scene, step, **options)`` (the
plan the GL path and the NumPy reference share), ``draw(renderer, plan)`` (renders into
``renderer.target(...)`` and returns that framebuffer) and its option names; the reference of the same name lives in ``dvr_gl.reference``."""

from __future__ import annotations

import importlib

_MODULES = {"raycast": "dvr_gl.techniques.raycast"}


def names():
    return tuple(_MODULES)


def get_technique(name):
    """The technique module called ``name``."""
    if name not in _MODULES:
        raise ValueError(f"technique must be one of {', '.join(_MODULES)}, got {name!r}")
    return importlib.import_module(_MODULES[name])
