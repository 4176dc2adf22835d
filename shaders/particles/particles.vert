// Particle-based volume rendering: each particle an opaque sphere of radius u_radius,
// drawn as a point sprite just large enough for its outline; the fragment shader keeps
// the pixels whose ray meets the sphere.
#version 330 core

#ifndef ORTHO
#define ORTHO 0
#endif

in vec3 a_position;            // relative to the data's lower corner
in vec3 a_color;               // the transfer function's colour at the particle

uniform mat4 u_view_proj;
uniform vec3 u_eye;            // relative to the data's lower corner
uniform vec3 u_forward;
uniform float u_radius;
uniform float u_pixels_per_unit;   // pixels per world unit at unit depth (ortho: at any depth)

flat out vec3 v_center;
flat out vec3 v_color;

void main() {
    gl_Position = u_view_proj * vec4(a_position, 1.0);
#if ORTHO
    float reach = u_radius;
#else
    // The outline reaches tan(theta + a) - tan(theta) = sin a / (cos(theta + a) cos theta)
    // from the centre's image at unit depth (theta off the axis, a the sphere's angular
    // radius): its far side, the widest. Near 90 degrees the sprite is capped (and GL's
    // own point size limit applies).
    vec3 to = a_position - u_eye;
    float dist = length(to);
    float cos_t = dot(to, u_forward) / dist;
    float sin_t = sqrt(max(1.0 - cos_t * cos_t, 0.0));
    float sin_a = min(u_radius / dist, 1.0);
    float cos_a = sqrt(1.0 - sin_a * sin_a);
    float reach = sin_a / max((cos_t * cos_a - sin_t * sin_a) * cos_t, 1e-3);
#endif
    // pixel centres inside the outline lie within reach * ppu of the centre's image, so
    // inside the sprite's square; the margin covers float rounding only
    gl_PointSize = 2.0 * reach * u_pixels_per_unit * 1.001 + 0.01;
    v_center = a_position;
    v_color = a_color;
}
