// Adds one repetition's image, divided by their count, into the output (blended ONE, ONE);
// GEOMETRY: the first surface's lit colour is composited behind it (opacity 1).
#version 330 core

#ifndef GEOMETRY
#define GEOMETRY 0
#endif

uniform sampler2D t_image;
uniform float u_weight;        // 1 / repetitions
#if GEOMETRY
uniform sampler2D t_surface;   // per pixel: the first surface's lit colour and its t (3e38: none)
#endif

out vec4 frag_color;

void main() {
    vec4 c = texelFetch(t_image, ivec2(gl_FragCoord.xy), 0);
#if GEOMETRY
    vec4 surface = texelFetch(t_surface, ivec2(gl_FragCoord.xy), 0);
    if (surface.a < 1e38) c = vec4(c.rgb + (1.0 - c.a) * surface.rgb, 1.0);
#endif
    frag_color = u_weight * c;
}
