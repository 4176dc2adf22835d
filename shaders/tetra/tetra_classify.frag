// Projected tetrahedra, mip / minip / average: classify the reduced value of each pixel
// (tetra.frag wrote it) with the transfer function, as the contract's section 5 says.
// Pixels no cell covered stay (0, 0).
#version 330 core

#ifndef MODE_MINIP
#define MODE_MINIP 0
#endif
#ifndef MODE_AVERAGE
#define MODE_AVERAGE 0
#endif
#ifndef GEOMETRY
#define GEOMETRY 0      // the pixel's first surface composited behind the classified value
#endif

#include "common/linear_segment.glsl"

uniform sampler2D t_reduced;   // (value or integral, length, 0, covered)
uniform bool u_rows_top_down;  // the image read back next: its row 0 (the top) stored first
#if GEOMETRY
uniform sampler2D t_surface;   // the first surface's lit colour and t (3e38: none)
#endif
out vec4 frag_color;

vec4 classified(vec4 r);

void main() {
    ivec2 pixel = ivec2(gl_FragCoord.xy);
    if (u_rows_top_down) pixel.y = textureSize(t_reduced, 0).y - 1 - pixel.y;
    vec4 r = texelFetch(t_reduced, pixel, 0);
    frag_color = classified(r);
#if GEOMETRY
    // the surface under the over operator: C + (1 - A) colour, A = 1 (contract)
    vec4 surface = texelFetch(t_surface, pixel, 0);
    if (surface.a < 1e38) frag_color = vec4(frag_color.rgb + (1.0 - frag_color.a) * surface.rgb, 1.0);
#endif
}

// the reduced value r classified with the transfer function (0 where no cell was met)
vec4 classified(vec4 r) {
    if (r.a <= 0.0) return vec4(0.0);
#if MODE_AVERAGE
    if (r.g <= 0.0) return vec4(0.0);
    float s = r.r / r.g;
#elif MODE_MINIP
    float s = -r.r;
#else
    float s = r.r;
#endif
    int j = knotsBelow(s, false) - 1;
    vec3 c;
    float a, w;
    knotLine(j, s, c, a, w);
    return vec4(c * a, a);
}
