// Particle-based volume rendering: each particle an opaque sphere of radius u_radius,
// drawn as a point sprite just large enough for its outline; the fragment shader keeps
// the pixels whose ray meets the sphere.
#version 330 core

#include "common/sprite.glsl"
#include "common/clip.glsl"

#ifndef SHADING
#define SHADING 0
#endif

in vec3 a_position;            // relative to the data's lower corner
in vec3 a_color;               // the transfer function's colour at the particle

uniform mat4 u_view_proj;
uniform vec3 u_eye;            // relative to the data's lower corner
uniform vec3 u_forward;
uniform float u_radius;
uniform float u_pixels_per_unit;   // pixels per world unit at unit depth (ortho: at any depth)
uniform float u_size_step;         // GL_POINT_SIZE_GRANULARITY: sizes may be rounded to it

flat out vec3 v_center;
flat out vec3 v_color;
#if SHADING
in vec3 a_gradient;            // the field's gradient at the particle
flat out vec3 v_gradient;
#endif

void main() {
    // GL discards a point whose centre lies outside the clip volume (what the reference
    // does); some GPUs draw the part of a wide point's sprite that falls in the view
    // instead. The rule is made explicit: such a point is moved beyond the far plane.
    vec4 clip = u_view_proj * vec4(a_position, 1.0);
    bool inside = all(lessThanEqual(abs(clip.xyz), vec3(clip.w)));
#if N_CLIP_PLANES > 0 || CROP_BOX
    inside = inside && insideClip(a_position, u_radius);   // a sphere that misses the kept region
#endif
    gl_Position = inside ? clip : vec4(0.0, 0.0, 2.0, 1.0);
    gl_PointSize = spriteSize(a_position, u_radius, u_eye, u_forward, u_pixels_per_unit) + u_size_step;
    v_center = a_position;
    v_color = a_color;
#if SHADING
    v_gradient = a_gradient;
#endif
}
