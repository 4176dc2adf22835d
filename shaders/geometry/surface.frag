// Each pixel's first surface (the depth test keeps the nearest fragment): its lit colour
// and how far along the pixel's ray it lies (NumPy twin:
// reference.exact_geometry.surface_hits). t is the ray caster's: from the eye
// (perspective, unit direction) or from the plane through it (orthographic), measured to
// the fragment's interpolated position, the triangle's point at the pixel centre.
#version 330 core

#ifndef ORTHO
#define ORTHO 0
#endif
#ifndef LIGHTS
#define LIGHTS 0
#endif

#include "common/camera_ray.glsl"
#include "common/shading.glsl"

in vec3 v_position;
flat in vec3 v_normal;
flat in vec3 v_color;
out vec4 f_surface;           // lit colour, t

void main() {
    vec3 origin, dir;
    pixelRay(origin, dir);
    float t = dot(v_position - origin, dir);
    if (!(t > 0.0)) discard;   // rays start at the eye (or its plane): nothing behind counts
    // two-sided Blinn-Phong with the face's normal (u_gradient_epsilon 0: always lit)
    f_surface = vec4(shadeBlinnPhong(v_color, v_normal, dir), t);
}
