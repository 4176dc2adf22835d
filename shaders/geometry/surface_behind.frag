// Opaque geometry under back-to-front blending (techniques.geometry.draw_surface_behind):
// each pixel's first surface, lit colour with opacity 1, written into the target before
// the slices or cells are blended over it, which gives C + (1 - A) * lit with A = 1.
#version 330 core

uniform sampler2D t_surface;  // per pixel: lit colour and ray parameter t (3e38: none)
out vec4 f_color;

void main() {
    vec4 surface = texelFetch(t_surface, ivec2(gl_FragCoord.xy), 0);
    if (!(surface.a < 1e38)) discard;
    f_color = vec4(surface.rgb, 1.0);
}
