// One splat on one pixel (NumPy twin: reference/splat.py): the kernel, an axis-aligned
// Gaussian of covariance diag(sigma^2), integrated exactly along this pixel's ray (no
// affine approximation: the ray's own direction, under perspective too), zero where the
// ray passes farther than the cutoff (in standard deviations) from the centre. The
// kernel's optical depth there becomes the splat's opacity; GL blends it over what is
// behind (splats arrive back to front). GEOMETRY: the ray ends at its first surface,
// drawn into the target first (the backmost layer); a kernel counts by its part in front.
#version 330 core

#ifndef ORTHO
#define ORTHO 0
#endif

#ifndef SHADING
#define SHADING 0
#endif

#ifndef GEOMETRY
#define GEOMETRY 0
#endif
#define PART_OF_RAY (N_CLIP_PLANES > 0 || CROP_BOX || GEOMETRY)

#include "common/camera_ray.glsl"
#include "common/compositing.glsl"
#include "common/clip.glsl"
#if SHADING
#include "common/shading.glsl"
flat in vec3 v_gradient;
#endif

flat in vec3 v_center;
flat in vec4 v_sample;
flat in float v_scale;         // this kernel's standard deviations are sigma * v_scale

uniform vec3 u_inv_var;        // 1 / sigma^2 per axis, at scale 1
uniform float u_cutoff2;       // cutoff^2
uniform float u_norm;          // 1 / (2 pi sqrt(det) (1 - exp(-cutoff^2 / 2))), at scale 1
#if GEOMETRY
uniform sampler2D t_surface;   // per pixel: the first surface's lit colour and its t (3e38: none)
#endif

out vec4 frag_color;

#if PART_OF_RAY
// erf(x) to 1.5e-7 (Abramowitz and Stegun 7.1.26; NumPy twin: reference.splat.erf_as)
float erfAS(float x) {
    float t = 1.0 / (1.0 + 0.3275911 * abs(x));
    float poly = t * (0.254829592 + t * (-0.284496736 + t * (1.421413741 + t * (-1.453152027 + t * 1.061405429))));
    return sign(x) * (1.0 - poly * exp(-x * x));
}
#endif

void main() {
    vec3 origin, dir;
    pixelRay(origin, dir);
    vec3 q = origin - v_center;
    vec3 inv_var = u_inv_var / (v_scale * v_scale);
    float a = dot(dir * dir, inv_var);
    float b = dot(dir * q, inv_var);
    if (b >= 0.0) discard;                    // the kernel's centre is not ahead of the ray's start
    // the ray's squared distance in standard deviations, from the offset at its closest
    // approach (c - b^2 / a would cancel catastrophically for a distant eye)
    vec3 off = q - (b / a) * dir;
    float m2 = dot(off * off, inv_var);
    if (m2 > u_cutoff2) discard;
    float depth = v_sample.a * u_norm / (v_scale * v_scale * v_scale) * inversesqrt(a) * exp(-0.5 * m2);
#if PART_OF_RAY
    // clipped, or ended at a surface: the kernel along the ray is a 1D Gaussian in t (mean
    // -b / a, standard deviation 1 / sqrt(a)); only its part in the ray's kept range counts
#if N_CLIP_PLANES > 0 || CROP_BOX
    vec2 kept = clipRange(origin, dir, vec2(0.0, 1.0 / 0.0));
#else
    vec2 kept = vec2(-1e30, 1e30);            // unclipped, the whole kernel counts
#endif
#if GEOMETRY
    kept.y = min(kept.y, texelFetch(t_surface, ivec2(gl_FragCoord.xy), 0).a);
#endif
    if (kept.y <= kept.x) discard;
    float centre_t = -b / a;
    float k = sqrt(0.5 * a);
    depth *= 0.5 * (erfAS((kept.y - centre_t) * k) - erfAS((kept.x - centre_t) * k));
#endif
    float alpha = -expm1Accurate(-depth);
#if SHADING
    frag_color = vec4(shadeBlinnPhong(v_sample.rgb, v_gradient, dir) * alpha, alpha);   // lit along this ray
#else
    frag_color = vec4(v_sample.rgb * alpha, alpha);
#endif
}
