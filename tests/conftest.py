"""Shared fixtures: one headless GL renderer per backend for the session.

A missing backend skips GL tests on a user's machine, but fails them when CI is set."""

import os

import numpy as np
import pytest

import dvr_gl
from dvr_gl.gl.context import BackendUnavailable, current

_renderers = {}


def _get_renderer(backend):
    if backend not in _renderers:
        try:
            _renderers[backend] = dvr_gl.Renderer(backend=backend)
        except BackendUnavailable as e:
            _renderers[backend] = e
    r = _renderers[backend]
    if isinstance(r, Exception):
        if os.environ.get("CI"):
            pytest.fail(f"GL backend {backend!r} unavailable under CI: {r}")
        pytest.skip(f"GL backend {backend!r} unavailable: {r}")
    return r


@pytest.fixture(scope="session")
def renderer():
    """The default (auto: EGL, else OSMesa) renderer."""
    return _get_renderer("auto")


@pytest.fixture(scope="session")
def osmesa_renderer():
    return _get_renderer("osmesa")


@pytest.fixture(scope="session")
def egl_renderer():
    return _get_renderer("egl")


@pytest.fixture(scope="session")
def fetch_renderer():
    """A renderer whose shaders interpolate volumes from texel fetches (as where the
    texture unit's filter is not exact)."""
    r = dvr_gl.Renderer()
    r.programs.context_defines["TEXTURE_FILTER_EXACT"] = 0
    yield r
    r.release()


@pytest.fixture
def ctx(renderer):
    """The renderer's context, checked for GL errors before and after the test."""
    c = renderer.ctx
    with current(c):
        assert c.error == "GL_NO_ERROR"
    yield c
    with current(c):
        assert c.error == "GL_NO_ERROR"


@pytest.fixture(autouse=True)
def _deterministic():
    np.random.seed(0)


def pytest_sessionfinish(session, exitstatus):
    for r in _renderers.values():
        if not isinstance(r, Exception):
            r.release()
    _renderers.clear()


def rounds_to_nearest(renderer):
    """Whether the renderer's writes and blends to 8-bit targets round to nearest. GL
    only says a conversion gives one of the two nearest representable values (and should
    round to nearest); llvmpipe does round to nearest (measured, what the tight bounds
    assume; its half floats truncate, which those bounds already allow). A GPU measured
    here did not always: elsewhere a bound takes the spec's one unit per rounding."""
    with current(renderer.ctx):
        return "llvmpipe" in (renderer.ctx.info.get("GL_RENDERER") or "")
