#version 330 core
// Shows the float render target in the window, composited over the background:
// C + (1 - A) * B for premultiplied (C, A) (conventions section 4).
//
// The target is either the window's size (then each pixel copies its own texel exactly:
// the bilinear weights below are exactly 0) or smaller while the user drags (progressive
// refinement: then it is magnified bilinearly). Interpolation is done here with
// texelFetch, so no filter or sampler state is changed on the renderer's texture.

uniform sampler2D t_image;
uniform vec2 u_ratio;       // target size / window framebuffer size
uniform vec3 u_background;

out vec4 f_color;

vec4 fetchClamped(ivec2 p) {
    ivec2 last = textureSize(t_image, 0) - 1;
    return texelFetch(t_image, clamp(p, ivec2(0), last), 0);
}

void main() {
    vec2 pos = gl_FragCoord.xy * u_ratio - 0.5;   // in texel-centre units of the target
    vec2 cell = floor(pos);
    vec2 w = pos - cell;
    ivec2 i = ivec2(cell);
    vec4 c = mix(mix(fetchClamped(i), fetchClamped(i + ivec2(1, 0)), w.x),
                 mix(fetchClamped(i + ivec2(0, 1)), fetchClamped(i + ivec2(1, 1)), w.x), w.y);
    c = clamp(c, 0.0, 1.0);
    f_color = vec4(c.rgb + (1.0 - c.a) * u_background, 1.0);
}
