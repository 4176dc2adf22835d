// The cell walk, composite: the accumulated premultiplied colour into the image's
// target, with the pixel's first surface behind it (over operator: C + (1 - A) lit, A = 1).
#version 330 core

#ifndef GEOMETRY
#define GEOMETRY 0
#endif

uniform sampler2D t_acc;
#if GEOMETRY
uniform sampler2D t_surface;   // the first surface's lit colour and t (3e38: none)
#endif
out vec4 frag_color;

void main() {
    vec4 acc = texelFetch(t_acc, ivec2(gl_FragCoord.xy), 0);
#if GEOMETRY
    vec4 surface = texelFetch(t_surface, ivec2(gl_FragCoord.xy), 0);
    if (surface.a < 1e38) acc = vec4(acc.rgb + (1.0 - acc.a) * surface.rgb, 1.0);
#endif
    frag_color = acc;
}
