// The pixel's ray against the particle's sphere (NumPy twin: reference/particles.py):
// kept where it passes within the radius, at the distance where it enters the sphere
// (0 for an eye inside it), which the depth test compares. The colour (the transfer
// function's at the particle, lit with the particle's gradient when SHADING) is opaque.
#version 330 core

#ifndef ORTHO
#define ORTHO 0
#endif

#ifndef SHADING
#define SHADING 0
#endif

#ifndef GEOMETRY
#define GEOMETRY 0        // opaque surfaces end the rays: particles behind them do not count
#endif

#include "common/camera_ray.glsl"
#include "common/clip.glsl"
#if SHADING
#include "common/shading.glsl"
flat in vec3 v_gradient;
#endif

flat in vec3 v_center;
flat in vec3 v_color;

uniform float u_radius;
uniform float u_inv_far;       // 1 / a distance beyond every particle: depth in [0, 1]
#if GEOMETRY
uniform sampler2D t_surface;   // per pixel: the first surface's lit colour and its t (3e38: none)
#endif

out vec4 frag_color;

void main() {
    vec3 origin, dir;
    pixelRay(origin, dir);
    vec3 v = v_center - origin;
    float t = dot(v, dir);
    vec3 off = v - t * dir;
    float miss = u_radius * u_radius - dot(off, off);
    if (miss < 0.0) discard;
    float half_chord = sqrt(miss);
    if (t + half_chord <= 0.0) discard;       // the sphere is behind the ray's start
#if N_CLIP_PLANES > 0 || CROP_BOX
    // clipped: the particle counts on this ray where its centre's projection on the ray
    // lies in the ray's kept part (techniques/particles.py)
    vec2 kept = clipRange(origin, dir, vec2(0.0, 1.0 / 0.0));
    if (t < kept.x || t > kept.y) discard;
#endif
#if GEOMETRY
    // the ray ends at its first surface: a particle counts where its centre's projection
    // lies in front of it, the clip rule with t_hit as the kept interval's end
    if (t > texelFetch(t_surface, ivec2(gl_FragCoord.xy), 0).a) discard;
#endif
    gl_FragDepth = clamp(max(t - half_chord, 0.0) * u_inv_far, 0.0, 1.0);
#if SHADING
    frag_color = vec4(shadeBlinnPhong(v_color, v_gradient, dir), 1.0);   // lit along this pixel's ray
#else
    frag_color = vec4(v_color, 1.0);
#endif
}
