// Particle-based volume rendering: each particle an opaque sphere of radius u_radius,
// drawn as a point sprite large enough to hold its projection; the fragment shader
// keeps the pixels whose ray meets the sphere.
#version 330 core

#ifndef ORTHO
#define ORTHO 0
#endif

in vec4 a_particle;            // position relative to the data's lower corner, scalar

uniform mat4 u_view_proj;
uniform vec3 u_eye;            // relative to the data's lower corner
uniform vec3 u_forward;
uniform float u_radius;
uniform float u_pixels_per_unit;   // pixels per world unit at unit depth (ortho: at any depth)

flat out vec3 v_center;
flat out float v_scalar;

void main() {
    vec3 p = a_particle.xyz;
    gl_Position = u_view_proj * vec4(p, 1.0);
#if ORTHO
    float depth = 1.0;
#else
    // the sphere's nearest depth; 1.5 covers the stretch of its outline off the axis
    float depth = max(dot(p - u_eye, u_forward) - u_radius, 1e-6);
#endif
    gl_PointSize = 3.0 * u_radius * u_pixels_per_unit / depth + 2.0;
    v_center = p;
    v_scalar = a_particle.w;
}
