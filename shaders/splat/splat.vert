// Splatting: every classified sample a Gaussian kernel, drawn as a square sprite large
// enough for the kernel's truncation ellipsoid (bounded by a sphere of u_reach); splat.geom
// makes the square (GL's point sprites are capped in size: 255 pixels on llvmpipe, which
// cut coarse meshes' kernels at 512x512).
#version 330 core

#include "common/sprite.glsl"
#include "common/clip.glsl"

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

out vec3 g_center;
out vec4 g_sample;
out float g_scale;
out float g_size;              // the sprite's side in pixels
#if SHADING
in vec3 a_gradient;            // the field's gradient at the sample
out vec3 g_gradient;
#endif

void main() {
    gl_Position = u_view_proj * vec4(a_position, 1.0);
#if N_CLIP_PLANES > 0 || CROP_BOX
    // a kernel whose cutoff sphere misses the kept region: splat.geom drops it
    if (!insideClip(a_position, u_reach * a_scale)) gl_Position = vec4(0.0, 0.0, 2.0, 1.0);
#endif
    g_size = spriteSize(a_position, u_reach * a_scale, u_eye, u_forward, u_pixels_per_unit);
    g_center = a_position;
    g_sample = a_sample;
    g_scale = a_scale;
#if SHADING
    g_gradient = a_gradient;
#endif
}
