// Pre-integrated classification of a ray segment (NumPy twin:
// preintegration.PreintegrationTable.segment).
#ifndef DVR_PREINTEGRATION_GLSL
#define DVR_PREINTEGRATION_GLSL

#include "common/compositing.glsl"

uniform sampler2D t_preint;   // (size, size) RGBA32F: x = back node, y = front node;
                              // (K_r, K_g, K_b, D): colour per unit opacity at the
                              // table's nominal length, mean extinction (1e30: opaque).
                              // With refinement (raycast), a second table of the same
                              // nodes for the shorter parts follows in rows size.. 2 size - 1
uniform float u_pi_lo;        // data value of node 0
uniform float u_pi_scale;     // nodes per data unit
uniform int u_pi_size;

// Premultiplied (C, A) of a segment len world units long along which the scalar goes
// linearly from s_front (nearest the eye) to s_back. (K, D) are interpolated
// bilinearly here, in full float precision (the texture unit's filter weights are the
// rasteriser's business), back index first, then front. The opacity 1 - exp(-len D) is
// exact for every length; the colour K * A is exact at the table's nominal length.
vec4 preintegratedSegmentIn(int first_row, float s_front, float s_back, float len) {
    if (len <= 0.0) return vec4(0.0);
    float last = float(u_pi_size - 1);
    float uf = clamp((s_front - u_pi_lo) * u_pi_scale, 0.0, last);
    float ub = clamp((s_back - u_pi_lo) * u_pi_scale, 0.0, last);
    int f0 = min(int(floor(uf)), u_pi_size - 2);
    int b0 = min(int(floor(ub)), u_pi_size - 2);
    float wf = uf - float(f0);
    float wb = ub - float(b0);
    f0 += first_row;
    vec4 row0 = texelFetch(t_preint, ivec2(b0, f0), 0) * (1.0 - wb)
              + texelFetch(t_preint, ivec2(b0 + 1, f0), 0) * wb;
    vec4 row1 = texelFetch(t_preint, ivec2(b0, f0 + 1), 0) * (1.0 - wb)
              + texelFetch(t_preint, ivec2(b0 + 1, f0 + 1), 0) * wb;
    vec4 v = row0 * (1.0 - wf) + row1 * wf;
    float od = len * v.a;
    // exp(-88) is below float's smallest normal: the segment is opaque (this also
    // covers the sentinel D = 1e30 and a product that overflows to +inf)
    float a = od > 88.0 ? 1.0 : -expm1Accurate(-od);
    return vec4(v.rgb * a, a);
}

// The same from the table of the nominal length (rows 0 .. size - 1).
vec4 preintegratedSegment(float s_front, float s_back, float len) {
    return preintegratedSegmentIn(0, s_front, s_back, len);
}

#endif
