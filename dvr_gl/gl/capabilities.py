"""What a context's GL does that shaders must know: probed once per context by running a
small program (``harness.evaluate``), and handed to the program cache as switches."""

from __future__ import annotations

import time

import numpy as np

from .context import current, idle_framebuffer
from .harness import evaluate


def context_defines(ctx) -> dict:
    """The shader switches that follow from ``ctx``: ``TEXTURE_FILTER_EXACT``
    (common/sampling.glsl, common/preintegration.glsl), 1 where the texture unit's linear
    filter is exact; else volumes, gradients, stacks and pre-integration tables are
    interpolated in the shader from texel fetches. ``LOCKSTEP_LANES`` (tetra/walk.frag),
    1 where code under a branch that no pixel takes costs as if taken (``lockstep_lanes``)."""
    return {"TEXTURE_FILTER_EXACT": int(linear_filter_is_exact(ctx)), "LOCKSTEP_LANES": int(lockstep_lanes(ctx))}


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


# the timing probes' full-screen triangle
_FULL_SCREEN = ("#version 330 core\nvoid main() { vec2 p = vec2(gl_VertexID == 1 ? 3.0 : -1.0, "
                "gl_VertexID == 2 ? 3.0 : -1.0); gl_Position = vec4(p, 0.0, 1.0); }")


def _best_seconds(ctx, run, repeats):
    """The least wall time to glFinish of ``repeats`` runs of ``run`` after one unmeasured
    run (the least disturbed by other work on the machine; llvmpipe's timer queries miss
    compute work)."""
    run()
    ctx.finish()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        ctx.finish()
        times.append(time.perf_counter() - start)
    return min(times)


# a loop whose rounds hold costly code under a branch: taken by every pixel or by none
_BRANCH_PROBE = """#version 330 core
uniform int u_rounds;
uniform float u_threshold;
out vec4 f_color;
void main() {
    vec4 a = vec4(gl_FragCoord.xy * 1e-3, 0.5, 0.25);
    for (int i = 0; i < u_rounds; ++i) {
        a = a * 0.999 + 1e-3;
        if (a.x < u_threshold)
            for (int k = 0; k < 4; ++k) a = sin(a * 1.1 + 0.3) + exp(-a * a) + log(abs(a) + 1.0);
    }
    f_color = a;
}
"""
_LOCKSTEP = {}     # the GL's vendor, renderer and version -> lockstep_lanes


def lockstep_lanes(ctx, side=64, min_seconds=2e-3) -> bool:
    """Whether code under a branch that no pixel takes costs ``ctx`` about as much as when
    every pixel takes it: true of llvmpipe, whose lanes (8 pixels a SIMD vector) follow
    execution masks through every branch and loop body with no jump over one that none
    takes; GPUs jump over it. Timed on a loop of costly rounds (lengthened until the
    taken pass takes ``min_seconds``): the untaken pass costing half the taken one or
    more says lockstep (llvmpipe: about 1; a GPU: a few hundredths). Asked once per GL
    implementation (vendor, renderer, version)."""
    with current(ctx):      # (moderngl keeps the first answer: ask with the context current)
        info = ctx.info
    key = (info.get("GL_VENDOR"), info.get("GL_RENDERER"), info.get("GL_VERSION"))
    if key in _LOCKSTEP:
        return _LOCKSTEP[key]
    with current(ctx):
        target = ctx.texture((side, side), 4, dtype="f4")
        fbo = ctx.framebuffer(color_attachments=[target])
        prog = ctx.program(
            vertex_shader=_FULL_SCREEN,
            fragment_shader=_BRANCH_PROBE)
        vao = ctx.vertex_array(prog, [])
        try:
            def seconds(threshold):
                prog["u_threshold"].value = threshold
                fbo.use()
                return _best_seconds(ctx, lambda: vao.render(vertices=3), 3)

            rounds = 16
            while True:
                prog["u_rounds"].value = rounds
                taken = seconds(1e30)
                if taken >= min_seconds or rounds >= 1 << 20:
                    break
                rounds *= 4
            untaken = seconds(-1e30)
        finally:
            idle_framebuffer(ctx).use()     # (never leave a released framebuffer bound: context.idle_framebuffer)
            for obj in (vao, prog, fbo, target):
                obj.release()
    _LOCKSTEP[key] = bool(untaken >= 0.5 * taken)
    return _LOCKSTEP[key]


# the bare loop both stages run: a column of trilinear reads per pixel
_PROBE_LOOP = """
uniform sampler3D t_probe;
uniform int u_samples;
vec4 probeColumn(vec2 pixel) {
    float acc = 0.0;
    for (int i = 0; i < u_samples; ++i)
        acc += texture(t_probe, vec3(pixel / 256.0, (float(i) + 0.5) / float(u_samples))).r;
    return vec4(acc, 0.0, 0.0, 1.0);
}
"""
COMPUTE_MARGIN = 3.0    # the compute stage is taken only where it is this much faster


def pixel_stage_times(ctx, side=256, min_seconds=2e-3):
    """Seconds of the same per-pixel loop of trilinear reads run as a fragment shader
    over a full-screen triangle and as a compute shader, one invocation a pixel
    (``{"fragment": s, "compute": s}``; no "compute" below GL 4.3). The loop is lengthened
    until the fragment pass takes ``min_seconds``, so that a fast GPU's times are not
    its launch overhead. GPUs built for compute may run fragment shaders on a few of
    their cores only (NVIDIA's H100 and H200: two of their texture processing clusters),
    where the compute stage reaches the whole chip."""
    if ctx.version_code < 430:
        return {"fragment": 1.0}
    with current(ctx):
        data = np.random.default_rng(0).random((64, 64, 64)).astype(np.float32)
        tex = ctx.texture3d((64, 64, 64), 1, data.tobytes(), dtype="f4")
        tex.filter = (ctx.LINEAR, ctx.LINEAR)
        target = ctx.texture((side, side), 4, dtype="f4")
        fbo = ctx.framebuffer(color_attachments=[target])
        frag = ctx.program(
            vertex_shader=_FULL_SCREEN,
            fragment_shader="#version 330 core\n" + _PROBE_LOOP
                            + "out vec4 f_color;\nvoid main() { f_color = probeColumn(gl_FragCoord.xy); }")
        comp = ctx.compute_shader(
            "#version 430 core\nlayout(local_size_x = 8, local_size_y = 8) in;\n"
            "layout(rgba32f, binding = 0) uniform writeonly image2D u_target;\n" + _PROBE_LOOP
            + "void main() { imageStore(u_target, ivec2(gl_GlobalInvocationID.xy), "
              "probeColumn(vec2(gl_GlobalInvocationID.xy) + 0.5)); }")
        vao = ctx.vertex_array(frag, [])
        try:
            tex.use(0)
            for prog in (frag, comp):
                prog["t_probe"].value = 0

            def fragment_pass():
                fbo.use()
                vao.render(vertices=3)

            def compute_pass():
                target.bind_to_image(0, read=False, write=True)
                comp.run(side // 8, side // 8, 1)
                ctx.memory_barrier()

            def seconds(run):
                return _best_seconds(ctx, run, 5)

            samples = 16
            while True:
                for prog in (frag, comp):
                    prog["u_samples"].value = samples
                fragment = seconds(fragment_pass)
                if fragment >= min_seconds or samples >= 4096:
                    break
                samples *= 4
            return {"fragment": fragment, "compute": seconds(compute_pass)}
        finally:
            idle_framebuffer(ctx).use()     # (never leave a released framebuffer bound: context.idle_framebuffer)
            for obj in (vao, frag, comp, fbo, target, tex):
                obj.release()


def prefers_compute_stage(ctx) -> bool:
    """Whether per-pixel ray shaders run faster as compute shaders on ``ctx``
    (``pixel_stage_times``: by COMPUTE_MARGIN or more; llvmpipe runs both alike)."""
    times = pixel_stage_times(ctx)
    return "compute" in times and times["fragment"] >= COMPUTE_MARGIN * times["compute"]
