"""What a context's GL does that shaders must know: probed once per context by running a
small program (``harness.evaluate``), and handed to the program cache as switches."""

from __future__ import annotations

import numpy as np

from .context import current
from .harness import evaluate


def context_defines(ctx) -> dict:
    """The shader switches that follow from ``ctx``: ``TEXTURE_FILTER_EXACT``
    (common/sampling.glsl, common/preintegration.glsl), 1 where the texture unit's linear
    filter is exact; else volumes, gradients, stacks and pre-integration tables are
    interpolated in the shader from texel fetches."""
    return {"TEXTURE_FILTER_EXACT": int(linear_filter_is_exact(ctx))}


def linear_filter_is_exact(ctx, tolerance=1e-5):
    """Whether ``ctx``'s texture unit filters float textures with float weights: a two-texel
    RGBA32F texture (0 and 1) read through ``texture()`` at 101 fractions between its
    centres, against the fractions themselves. llvmpipe's are exact to float rounding;
    GPUs commonly quantise the weights to 8 or 9 bits (errors up to ~2e-3), where tables
    that need full precision are interpolated in the shader."""
    frac = np.linspace(0.0, 1.0, 101)
    inputs = np.zeros((frac.size, 4), np.float32)
    inputs[:, 0] = frac
    with current(ctx):
        tex = ctx.texture((2, 1), 4, np.array([[0, 0, 0, 0], [1, 1, 1, 1]], np.float32).tobytes(), dtype="f4")
        tex.filter = (ctx.LINEAR, ctx.LINEAR)
        tex.repeat_x = tex.repeat_y = False
    try:
        out = evaluate(ctx, [], "out0 = texture(t_probe, vec2((in0.x + 0.5) / 2.0, 0.5));", [inputs],
                       textures={"t_probe": tex}, preamble="uniform sampler2D t_probe;")
    finally:
        with current(ctx):
            tex.release()
    return bool(np.all(np.abs(out[:, 0] - frac) <= tolerance))


def max_3d_texture_size(ctx) -> int:
    """GL_MAX_3D_TEXTURE_SIZE: the most texels a side of one 3-D texture (OpenGL 3.3
    promises 256; llvmpipe reports 2048)."""
    with current(ctx):
        size = ctx.info.get("GL_MAX_3D_TEXTURE_SIZE")
    return int(size) if size else 256
