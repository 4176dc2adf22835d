// Gradients and Blinn-Phong headlight shading (NumPy twin: reference.shading).
#ifndef DVR_SHADING_GLSL
#define DVR_SHADING_GLSL
#include "common/sampling.glsl"

#ifndef GRADIENT_TEXTURE
#define GRADIENT_TEXTURE 0
#endif
// The field at a world point; 2D slicing reads it from its stack instead of t_volume.
#ifndef FIELD_AT
#define FIELD_AT sampleVolume
#endif

uniform vec4 u_phong;              // ka, kd, ks, shininess
uniform float u_gradient_epsilon;  // |g| at or below this leaves a sample unshaded

#if GRADIENT_TEXTURE
uniform sampler3D t_gradient;      // central differences at the samples, world units

// Trilinear interpolation of the samples' central differences is the contract's
// gradient itself, boundary clamping included (see reference.shading.sample_gradients):
// one fetch instead of six, the same value up to float32 storage.
vec3 gradient(vec3 p_world) {
    return filteredAt(t_gradient, p_world).xyz;
}
#else
// Central differences one spacing apart per axis, in world units. Points outside the
// domain are clamped to it by clamp-to-edge sampling; the divisor stays 2 * spacing.
vec3 gradient(vec3 p_world) {
    vec3 g;
    for (int i = 0; i < 3; ++i) {
        vec3 h = vec3(0.0);
        h[i] = u_spacing[i];
        g[i] = (FIELD_AT(p_world + h) - FIELD_AT(p_world - h)) / (2.0 * u_spacing[i]);
    }
    return g;
}
#endif

#ifndef LIGHTS
#define LIGHTS 0
#endif

#if !LIGHTS
// The headlight's (diffuse factor, specular term) for a sample with gradient grad, seen
// along ray_dir: two-sided, L = V = H = -ray_dir. (1, 0) where the gradient vanishes, so
// that sample keeps its colour.
vec2 phongTerms(vec3 grad, vec3 ray_dir) {
    float len = length(grad);
    if (len <= u_gradient_epsilon) return vec2(1.0, 0.0);
    float ndotl = abs(dot(grad / len, ray_dir));
    return vec2(u_phong.x + u_phong.y * ndotl, u_phong.z * pow(ndotl, u_phong.w));
}
#else
#define MAX_LIGHTS 4
uniform int u_light_count;
uniform vec4 u_lights[MAX_LIGHTS];  // xyz: unit world direction towards the light (0: the
                                    // headlight, L = V); w: intensity

// The same for the scene's lights, with the contract's two-sided formula per light:
// kd I |N.L| and ks I |N.H|^n, H the unit half vector of L and V (none where L = -V).
vec2 phongTerms(vec3 grad, vec3 ray_dir) {
    float len = length(grad);
    if (len <= u_gradient_epsilon) return vec2(1.0, 0.0);
    vec3 v = -ray_dir;
    vec3 n = grad / len;  // its sign does not matter under abs
    vec2 terms = vec2(u_phong.x, 0.0);
    for (int i = 0; i < u_light_count; ++i) {
        vec3 l = u_lights[i].xyz;
        if (l == vec3(0.0)) l = v;
        vec3 h = l + v;
        float hl = length(h);
        float specular = hl > 0.0 ? u_phong.z * pow(abs(dot(n, h)) / hl, u_phong.w) : 0.0;
        terms += u_lights[i].w * vec2(u_phong.y * abs(dot(n, l)), specular);
    }
    return terms;
}
#endif

// A straight colour lit.
vec3 shadeBlinnPhong(vec3 color, vec3 grad, vec3 ray_dir) {
    vec2 k = phongTerms(grad, ray_dir);
    return color * k.x + k.y;
}

// The terms a composite sample's position changes (NumPy twin:
// reference.shading.SampleTerms): the lights (SHADING), and the illustration terms of
// Ebert and Rheingans (2000): tone (an added warm-to-cool colour), depth cue (a factor
// on the colour), boundary and silhouette enhancement (factors on the extinction).
#ifndef SHADING
#define SHADING 0
#endif
#ifndef TONE
#define TONE 0
#endif
#ifndef DEPTH_CUE
#define DEPTH_CUE 0
#endif
#ifndef BOUNDARY
#define BOUNDARY 0
#endif
#ifndef SILHOUETTE
#define SILHOUETTE 0
#endif
#define NEEDS_GRADIENT (SHADING || TONE || BOUNDARY || SILHOUETTE)

#if TONE
uniform vec3 u_tone_warm;
uniform vec3 u_tone_cool;
uniform vec3 u_tone_light;   // towards the first light (world); 0: the headlight
#endif
#if DEPTH_CUE
#include "common/camera_ray.glsl"
uniform vec3 u_depth_cue;    // nearest and farthest depth of the box, strength
#ifndef DEPTH_CUE_ALONG_SEGMENT
#define DEPTH_CUE_ALONG_SEGMENT 0
#endif

// The depth cue's colour factor at a point: 1 at the box's nearest depth, 1 - strength at
// its farthest.
float depthCue(vec3 p_world) {
    float u = clamp((dot(p_world - u_eye, u_forward) - u_depth_cue.x) / (u_depth_cue.y - u_depth_cue.x), 0.0, 1.0);
    return 1.0 - u_depth_cue.z * u;
}
#endif
#if BOUNDARY
uniform vec3 u_boundary;     // k_gc, k_gs, k_ge
uniform float u_gradient_max;
#endif
#if SILHOUETTE
uniform vec3 u_silhouette;   // k_sc, k_ss, k_se
#endif

// The terms at a sample with gradient g: its colour becomes color * factor + offset, its
// extinction is multiplied by opacity_scale. (A mesh's cell passes its own gradient.)
void termsFor(vec3 g, vec3 p_world, vec3 ray_dir, out float factor, out vec3 offset, out float opacity_scale) {
    factor = 1.0;
    offset = vec3(0.0);
    opacity_scale = 1.0;
#if NEEDS_GRADIENT
    float len = length(g);
    bool oriented = len > u_gradient_epsilon;
    vec3 n = oriented ? g / len : vec3(0.0);
#endif
#if SHADING
    vec2 k = phongTerms(g, ray_dir);
    factor = k.x;
    offset = vec3(k.y);
#endif
#if TONE
    if (oriented) {
        vec3 l = u_tone_light == vec3(0.0) ? -ray_dir : u_tone_light;
        float t = abs(dot(n, l));
        offset += t * u_tone_warm + (1.0 - t) * u_tone_cool;
    }
#endif
#if BOUNDARY
    opacity_scale *= u_boundary.x + u_boundary.y * pow(u_gradient_max > 0.0 ? len / u_gradient_max : 0.0,
                                                        u_boundary.z);
#endif
#if SILHOUETTE
    if (oriented) {
        opacity_scale *= u_silhouette.x + u_silhouette.y * pow(max(1.0 - abs(dot(n, ray_dir)), 0.0),
                                                                u_silhouette.z);
    }
#endif
#if DEPTH_CUE && !DEPTH_CUE_ALONG_SEGMENT    // (projected tetrahedra integrate it along the segment)
    float cue = depthCue(p_world);
    factor *= cue;
    offset *= cue;
#endif
}

// The terms at a sample of the volume: its gradient read there (only when a term needs it).
void termsAt(vec3 p_world, vec3 ray_dir, out float factor, out vec3 offset, out float opacity_scale) {
#if NEEDS_GRADIENT
    termsFor(gradient(p_world), p_world, ray_dir, factor, offset, opacity_scale);
#else
    termsFor(vec3(0.0), p_world, ray_dir, factor, offset, opacity_scale);
#endif
}

// A sample's straight colour with its terms (declared in common/classification.glsl).
vec3 sampleTerms(vec3 color, vec3 p_world, vec3 ray_dir, out float opacity_scale) {
    float factor;
    vec3 offset;
    termsAt(p_world, ray_dir, factor, offset, opacity_scale);
    return color * factor + offset;
}

// A premultiplied (pre-integrated) segment (c * alpha, alpha) with the colour terms of a
// sample at p: (c * factor + offset) associated with alpha.
vec4 termsSegment(vec4 segment, vec3 p_world, vec3 ray_dir) {
    float factor, unused;
    vec3 offset;
    termsAt(p_world, ray_dir, factor, offset, unused);
    return vec4(segment.rgb * factor + offset * segment.a, segment.a);
}

#endif
