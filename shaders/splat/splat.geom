// Splatting: a kernel's sprite as a square of two triangles, g_size pixels a side about
// its centre's image: what a point sprite of that size covers, without GL's cap on point
// sizes. A kernel whose centre lies outside the clip volume is dropped, as GL drops such
// a point (the NumPy twin, reference/sprites.py, follows the same rule).
#version 330 core

#ifndef SHADING
#define SHADING 0
#endif

layout(points) in;
layout(triangle_strip, max_vertices = 4) out;

in vec3 g_center[];
in vec4 g_sample[];
in float g_scale[];
in float g_size[];
flat out vec3 v_center;
flat out vec4 v_sample;
flat out float v_scale;
#if SHADING
in vec3 g_gradient[];
flat out vec3 v_gradient;
#endif

uniform vec2 u_target_size;    // pixels of the target drawn into

void main() {
    vec4 c = gl_in[0].gl_Position;
    if (!(c.w > 0.0) || any(greaterThan(abs(c.xyz), vec3(c.w)))) return;
    vec2 half_side = vec2(g_size[0]) / u_target_size * c.w;    // clip units: 2 / size per pixel
    for (int i = 0; i < 4; ++i) {
        vec2 corner = vec2(float(i & 1), float(i >> 1)) * 2.0 - 1.0;
        gl_Position = vec4(c.xy + corner * half_side, c.z, c.w);
        v_center = g_center[0];
        v_sample = g_sample[0];
        v_scale = g_scale[0];
#if SHADING
        v_gradient = g_gradient[0];
#endif
        EmitVertex();
    }
    EndPrimitive();
}
