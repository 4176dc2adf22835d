"""``tolerance=`` and the texture unit's interpolation.

Where the context's texture unit quantises its linear filter's weights (GPUs: 8
fractional bits, ``gl.capabilities.linear_filter_is_exact``), the ray caster interpolates
eight texel fetches in the shader, so that its images keep their bounds; the texture
unit's own filter is 1.1x to 2.6x faster there (docs/notes/gpu.md). Its error is the
weights' rounding, up to 1/512 of the jump between neighbouring samples per axis: far
below most requests, a floor of about 1e-4 under the CT head's image. So after the
tolerance pilot has chosen its step and way of sampling (``tolerance.settings``), that
choice is rendered once more with ``interpolation="texture_unit"`` on the pilot's check
view and taken if its error bound there (``tolerance.error_bound``, against the same
reference) stays within the check's share of the request. Where the unit is exact
(llvmpipe) there is nothing to choose.
"""

from __future__ import annotations

import dataclasses

from . import tolerance as tol


def texture_unit_applies(renderer, scene, options):
    """Whether the choice between the shader's and the texture unit's interpolation is open:
    the context's unit is not exact, one texture (no bricks, no store), and the caller
    did not decide."""
    exact_unit = renderer.programs.context_defines.get("TEXTURE_FILTER_EXACT", 1)
    return not (exact_unit or "interpolation" in options or options.get("brick_size") is not None
                or scene.is_lazy or scene.layers)


def with_texture_unit(renderer, scene, tolerance, technique, options, choice):
    """``choice`` (a ``tolerance.Choice``) with the texture unit's interpolation where that
    keeps the check view's error bound within ``CHECK_TARGET * tolerance``; else ``choice``.
    The bound is kept with the check view's reference, so each view renders it once."""
    if not texture_unit_applies(renderer, scene, options):
        return choice
    sampling = choice.sampling
    check = tol.check_scene(scene)
    sampled = (check.width, check.height) != (scene.width, scene.height)
    reference = tol.reference_for(renderer, scene, tolerance, technique, options, choice.order, sampling)
    key = (choice.step_voxels, sampled, "texture_unit")
    bound = reference.bounds.get(key)
    if bound is None:
        render = tol.pilot_renderer(renderer, technique, dict(options, interpolation="texture_unit"), sampling)
        bound = tol.error_bound(render(reference.scene, choice.step), reference.image, reference.error, sampled)
        reference.bounds[key] = bound
    if bound > tol.CHECK_TARGET * tolerance:
        return choice
    return dataclasses.replace(choice, interpolation="texture_unit", checked_rmse=bound)
