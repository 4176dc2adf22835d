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

#include "common/linear_segment.glsl"

uniform sampler2D t_reduced;   // (value or integral, length, 0, covered)
out vec4 frag_color;

void main() {
    vec4 r = texelFetch(t_reduced, ivec2(gl_FragCoord.xy), 0);
    if (r.a <= 0.0) { frag_color = vec4(0.0); return; }
#if MODE_AVERAGE
    if (r.g <= 0.0) { frag_color = vec4(0.0); return; }
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
    frag_color = vec4(c * a, a);
}
