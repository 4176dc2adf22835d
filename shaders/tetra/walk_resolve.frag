// The cell walk, composite: the accumulated premultiplied colour into the image's
// target, with the pixel's first surface behind it (over operator: C + (1 - A) lit, A = 1).
#version 330 core

#ifndef GEOMETRY
#define GEOMETRY 0
#endif

uniform sampler2D t_acc;
uniform bool u_rows_top_down;  // the image read back next: its row 0 (the top) stored first
#if GEOMETRY
uniform sampler2D t_surface;   // the first surface's lit colour and t (3e38: none)
#endif
out vec4 frag_color;

void main() {
    ivec2 pixel = ivec2(gl_FragCoord.xy);
    if (u_rows_top_down) pixel.y = textureSize(t_acc, 0).y - 1 - pixel.y;
    vec4 acc = texelFetch(t_acc, pixel, 0);
#if GEOMETRY
    vec4 surface = texelFetch(t_surface, pixel, 0);
    if (surface.a < 1e38) acc = vec4(acc.rgb + (1.0 - acc.a) * surface.rgb, 1.0);
#endif
    frag_color = acc;
}
