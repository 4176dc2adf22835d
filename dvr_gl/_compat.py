"""Old import paths (before the layered layout of 0.2) that keep working for one release.

``import dvr_gl.scene`` and the like still work, with a DeprecationWarning that names the
new path; the module object is the new one, so both paths see the same classes.
"""

import importlib
import importlib.abc
import importlib.util
import sys
import warnings

MOVED = {
    "dvr_gl.scene": "dvr_gl.model.scene",
    "dvr_gl.transfer": "dvr_gl.model.transfer",
    "dvr_gl.transfer2d": "dvr_gl.model.transfer2d",
    "dvr_gl.preintegration": "dvr_gl.model.preintegration",
    "dvr_gl.cell_split": "dvr_gl.model.cell_split",
    "dvr_gl.mesh": "dvr_gl.model.mesh",
    "dvr_gl.phantoms": "dvr_gl.data.phantoms",
    "dvr_gl.cache": "dvr_gl.util.cache",
    "dvr_gl.progress": "dvr_gl.util.progress",
    "dvr_gl.io": "dvr_gl.formats",
    "dvr_gl.shirley_tuchman": "dvr_gl.techniques.shirley_tuchman",
    "dvr_gl.particles": "dvr_gl.techniques.particle_sets",
    "dvr_gl.renderer": "dvr_gl.rendering.renderer",
    "dvr_gl.tolerance": "dvr_gl.rendering.tolerance",
    "dvr_gl.cli": "dvr_gl.frontends.cli",
    "dvr_gl.options": "dvr_gl.frontends.options",
    "dvr_gl.inputs": "dvr_gl.frontends.inputs",
    "dvr_gl.notebook": "dvr_gl.frontends.notebook",
    "dvr_gl.demo": "dvr_gl.frontends.demo",
    "dvr_gl.viewer": "dvr_gl.frontends.viewer",
    "dvr_gl.viewer_overlay": "dvr_gl.frontends.viewer.overlay",
    "dvr_gl.bench_all": "dvr_gl.bench.all",
    "dvr_gl.bench_mesh": "dvr_gl.bench.mesh",
    "dvr_gl.bench_particles": "dvr_gl.bench.particles",
    "dvr_gl.bench_shading": "dvr_gl.bench.shading",
    "dvr_gl.vtk_peer": "dvr_gl.bench.vtk_peer",
}


def moved_module(old):
    """The module now at the new path of ``old``, with a DeprecationWarning."""
    new = MOVED[old]
    warnings.warn(f"{old} is deprecated and will be removed in dvr_gl 0.3; import {new} instead",
                  DeprecationWarning, stacklevel=3)
    return importlib.import_module(new)


class _Alias(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    def find_spec(self, fullname, path=None, target=None):
        if fullname in MOVED:
            return importlib.util.spec_from_loader(fullname, self)
        return None

    def create_module(self, spec):
        module = moved_module(spec.name)
        self._own = {k: getattr(module, k) for k in ("__name__", "__spec__", "__loader__", "__package__")}
        return module

    def exec_module(self, module):
        # the new module ran when it was imported; the import system has just written the
        # old name's spec onto it: give it back its own
        for k, v in self._own.items():
            setattr(module, k, v)


def install():
    if not any(isinstance(f, _Alias) for f in sys.meta_path):
        sys.meta_path.append(_Alias())
