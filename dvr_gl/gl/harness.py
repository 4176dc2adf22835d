"""Evaluate one GLSL expression over a batch of inputs (transform feedback), so each
function in ``shaders/common`` can be compared with its NumPy twin on its own."""

from __future__ import annotations

import numpy as np

from .context import current, idle_framebuffer
from .programs import apply_defines, resolve_text

_TEMPLATE = """#version 330 core
{includes}
{preamble}
in vec4 in0;
in vec4 in1;
in vec4 in2;
out vec4 out0;
void main() {{
    {body}
}}
"""


def evaluate(ctx, includes, body, inputs, textures=None, uniforms=None, defines=None, preamble=""):
    """Run ``body`` (GLSL statements assigning ``out0``, reading ``in0..in2``) once per
    row of the inputs (each an (N, 4) array, at most three) and return out0 as (N, 4)
    float32. ``textures`` maps sampler names to moderngl textures; ``preamble`` is GLSL
    placed after the includes (declarations the body needs)."""
    arrays = [np.ascontiguousarray(a, dtype=np.float32) for a in inputs]
    n = arrays[0].shape[0]
    while len(arrays) < 3:
        arrays.append(np.zeros((n, 4), np.float32))
    src = _TEMPLATE.format(includes="\n".join(f'#include "{i}"' for i in includes), preamble=preamble, body=body)
    src = apply_defines(resolve_text(src), defines or {})
    with current(ctx):
        prog = ctx.program(vertex_shader=src, varyings=["out0"])
        buffers = [ctx.buffer(a.tobytes()) for a in arrays]
        layout = [(buf, "4f", f"in{i}") for i, buf in enumerate(buffers) if f"in{i}" in prog]
        vao = ctx.vertex_array(prog, layout)
        for unit, (name, tex) in enumerate((textures or {}).items()):
            tex.use(location=unit)
            if name in prog:
                prog[name].value = unit
        for name, value in (uniforms or {}).items():
            if name in prog:
                prog[name].value = value
        out = ctx.buffer(reserve=n * 16)
        idle_framebuffer(ctx).use()
        vao.transform(out, mode=ctx.POINTS, vertices=n)
        result = np.frombuffer(out.read(), np.float32).reshape(n, 4).copy()
        for obj in [vao, out, prog] + buffers:
            obj.release()
    return result
