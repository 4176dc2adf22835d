// Gradients and Blinn-Phong headlight shading (NumPy twin: reference.shading).
#ifndef DVR_SHADING_GLSL
#define DVR_SHADING_GLSL
#include "common/sampling.glsl"

uniform vec4 u_phong;              // ka, kd, ks, shininess
uniform float u_gradient_epsilon;  // |g| at or below this leaves a sample unshaded

// Central differences one spacing apart per axis, in world units. Points outside the
// domain are clamped to it by clamp-to-edge sampling; the divisor stays 2 * spacing.
vec3 gradient(vec3 p_world) {
    vec3 g;
    for (int i = 0; i < 3; ++i) {
        vec3 h = vec3(0.0);
        h[i] = u_spacing[i];
        g[i] = (sampleVolume(p_world + h) - sampleVolume(p_world - h)) / (2.0 * u_spacing[i]);
    }
    return g;
}

// Two-sided headlight: L = V = H = the direction back along the ray.
vec3 shadeBlinnPhong(vec3 color, vec3 grad, vec3 ray_dir) {
    float len = length(grad);
    if (len <= u_gradient_epsilon) return color;
    vec3 n = -grad / len;
    float ndotl = abs(dot(n, -ray_dir));
    return color * (u_phong.x + u_phong.y * ndotl) + u_phong.z * pow(ndotl, u_phong.w);
}

#endif
