// Splatting: every classified sample a Gaussian kernel, drawn as a point sprite large
// enough for the kernel's truncation ellipsoid (bounded by a sphere of u_reach).
#version 330 core

#include "common/sprite.glsl"

#ifndef SHADING
#define SHADING 0
#endif

in vec3 a_position;            // relative to the data's lower corner
in vec4 a_sample;              // the sample's colour, and its extinction times its volume share
in float a_scale;              // the kernel's size relative to u_reach and the standard deviations

uniform mat4 u_view_proj;
uniform vec3 u_eye;            // relative to the data's lower corner
uniform vec3 u_forward;
uniform float u_reach;         // cutoff * the kernel's largest standard deviation
uniform float u_pixels_per_unit;

flat out vec3 v_center;
flat out vec4 v_sample;
flat out float v_scale;
#if SHADING
in vec3 a_gradient;            // the field's gradient at the sample
flat out vec3 v_gradient;
#endif

void main() {
    gl_Position = u_view_proj * vec4(a_position, 1.0);
    gl_PointSize = spriteSize(a_position, u_reach * a_scale, u_eye, u_forward, u_pixels_per_unit);
    v_center = a_position;
    v_sample = a_sample;
    v_scale = a_scale;
#if SHADING
    v_gradient = a_gradient;
#endif
}
