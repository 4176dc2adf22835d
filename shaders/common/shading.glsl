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
    return texture(t_gradient, worldToTex(p_world)).xyz;
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

// A straight colour lit at a sample point (declared in common/classification.glsl).
vec3 litColor(vec3 color, vec3 p_world, vec3 ray_dir) {
    return shadeBlinnPhong(color, gradient(p_world), ray_dir);
}

// A premultiplied segment (c * alpha, alpha) lit: the lit colour, associated with alpha.
vec4 shadeSegment(vec4 segment, vec3 grad, vec3 ray_dir) {
    vec2 k = phongTerms(grad, ray_dir);
    return vec4(segment.rgb * k.x + k.y * segment.a, segment.a);
}

#endif
