// The compute stage's entry (common/pixel_stage.glsl): one invocation per pixel of the
// target runs the shader's PIXEL_MAIN and stores its f_color, every pixel written (those
// whose ray misses the volume with what PIXEL_MAIN left there: zero, or the sums so far).
// Include at the end of a shader that declares `vec4 f_color` when COMPUTE_PIXELS.
#if COMPUTE_PIXELS
#ifndef IMAGE_FORMAT
#define IMAGE_FORMAT rgba32f      // the target's format: its name (rgba32f, rgba16f, rgba8) is GLSL's
#endif
layout(local_size_x = 8, local_size_y = 8) in;
layout(IMAGE_FORMAT, binding = 0) uniform writeonly image2D u_target;
uniform ivec2 u_target_size;
uniform int u_rows_top_down;  // 1: store row 0 on top (an image read back next needs no flip)

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(px, u_target_size))) return;
    PIXEL_MAIN();
    imageStore(u_target, ivec2(px.x, u_rows_top_down != 0 ? u_target_size.y - 1 - px.y : px.y), f_color);
}
#endif
