// Where a per-pixel ray shader runs (techniques.gpu.pixel_stage): as a fragment shader
// over a proxy, or, with COMPUTE_PIXELS, as a compute shader with one invocation per
// pixel of the target (ProgramCache.compute), on GPUs whose graphics pipeline reaches
// only some of their cores. FRAG_COORD is the pixel's centre in the target either way;
// PIXEL_MAIN names the shader's per-pixel function (common/pixel_store.glsl calls it).
#ifndef DVR_PIXEL_STAGE_GLSL
#define DVR_PIXEL_STAGE_GLSL
#ifndef COMPUTE_PIXELS
#define COMPUTE_PIXELS 0
#endif
#if COMPUTE_PIXELS
#define FRAG_COORD vec4(vec2(gl_GlobalInvocationID.xy) + 0.5, 0.5, 1.0)
#define PIXEL_MAIN shadePixel
#else
#define FRAG_COORD gl_FragCoord
#define PIXEL_MAIN main
#endif
#endif
