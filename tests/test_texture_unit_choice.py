"""``tolerance=`` takes the texture unit's interpolation where its measured error is
within the request (``dvr_gl.rendering.filtering``). llvmpipe's unit is exact, so there
the choice is closed; a renderer told its unit quantises (its program cache's context
switch) opens it, and a unit whose images are off by more than the request is refused."""

import numpy as np
import pytest

import dvr_gl
from dvr_gl import Scene, reference
from dvr_gl.rendering import tolerance as tol

from test_raycast import TF, VOLUME, cameras

E = 3e-3


def scene():
    return Scene(VOLUME, TF, cameras(VOLUME)["perspective"], width=48, height=40)


def quantising_renderer():
    """A renderer that takes its texture unit as quantising: the ray caster interpolates
    fetches by default, and "texture_unit" reads the (here exact) unit."""
    r = dvr_gl.Renderer()
    r.programs._context_defines = {"TEXTURE_FILTER_EXACT": 0}
    return r


def test_an_exact_unit_leaves_nothing_to_choose(renderer):
    if not renderer.programs.context_defines.get("TEXTURE_FILTER_EXACT"):
        pytest.skip("this context's texture unit quantises its weights")
    renderer.render(scene(), tolerance=E)
    assert renderer.last_choice.interpolation == "exact"
    assert "interpolation" not in renderer.last_choice.sampling


def test_the_unit_is_taken_where_its_error_is_within_the_request():
    r = quantising_renderer()
    s = scene()
    image = r.render(s, tolerance=E)
    choice = r.last_choice
    assert choice.interpolation == "texture_unit" and choice.sampling["interpolation"] == "texture_unit"
    assert choice.checked_rmse <= tol.CHECK_TARGET * E
    exact = reference.exact(s)
    assert exact[..., 3].max() > 0.05
    assert float(np.sqrt(np.mean((image - exact) ** 2))) <= E
    # the caller's own say is kept
    r.render(s, tolerance=E, interpolation="exact")
    assert r.last_choice.interpolation == "exact"


def test_a_unit_off_by_more_than_the_request_is_refused(monkeypatch):
    r = quantising_renderer()
    real = tol.pilot_renderer

    def off_when_unit(renderer, technique, options, sampling=tol.PLAIN, **extra):
        render = real(renderer, technique, options, sampling, **extra)
        if options.get("interpolation") != "texture_unit":
            return render
        return lambda s, h: render(s, h) + np.float32(4 * E)     # every pixel 4 E off
    monkeypatch.setattr(tol, "pilot_renderer", off_when_unit)
    r.render(scene(), tolerance=E)
    assert r.last_choice.interpolation == "exact"


def test_a_bad_interpolation_is_named():
    with pytest.raises(ValueError, match="interpolation must be one of exact, texture_unit, got 'cubic'"):
        dvr_gl.Renderer().render(scene(), interpolation="cubic")
    with pytest.raises(ValueError, match="interpolation 'texture_unit' does not yet take bricks"):
        dvr_gl.Renderer().render(scene(), interpolation="texture_unit", brick_size=8)
