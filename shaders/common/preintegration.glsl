// Pre-integrated classification of a ray segment (NumPy twin:
// preintegration.PreintegrationTable.segment).
#ifndef DVR_PREINTEGRATION_GLSL
#define DVR_PREINTEGRATION_GLSL

#include "common/compositing.glsl"

uniform sampler2D t_preint;   // (size, 2 size) RGBA32F: x = back node, y = front node;
                              // rows 0 .. size - 1: (K_r, K_g, K_b, D), the colour per
                              // unit opacity at the table's nominal length and the mean
                              // extinction (1e30: opaque); rows size .. 2 size - 1: (K0, 0),
                              // the colour per unit opacity as the length goes to 0. With
                              // refinement (raycast), the shorter parts' table follows in
                              // rows 2 size .. 4 size - 1, laid out the same.
uniform float u_pi_lo;        // data value of node 0
uniform float u_pi_scale;     // nodes per data unit
uniform int u_pi_size;
uniform float u_pi_length;    // the nominal length of the table in rows 0 .. 2 size - 1
uniform vec2 u_pi_cut;        // 1 where the table stops at the TF's last opacity on that side
                              // (below node 0, above the last): values beyond are empty

#ifndef TEXTURE_FILTER_EXACT
#define TEXTURE_FILTER_EXACT 0   // 1: the texture unit interpolates the table (set by the
#endif                           // program cache where its weights are exact, as on llvmpipe)

// The table's bilinear interpolant at node coordinates (back, front) of the rows from
// first_row (the front index counts from there), in full float precision: by the texture
// unit where its filter weights are exact (one read instead of four texel fetches),
// else here.
vec4 tableAt(float ub, float uf, int first_row) {
#if TEXTURE_FILTER_EXACT
    return texture(t_preint, (vec2(ub, uf + float(first_row)) + 0.5) / vec2(textureSize(t_preint, 0)));
#else
    int b0 = min(int(floor(ub)), u_pi_size - 2);
    int f0 = min(int(floor(uf)), u_pi_size - 2);
    float wb = ub - float(b0);
    float wf = uf - float(f0);
    f0 += first_row;
    vec4 row0 = texelFetch(t_preint, ivec2(b0, f0), 0) * (1.0 - wb)
              + texelFetch(t_preint, ivec2(b0 + 1, f0), 0) * wb;
    vec4 row1 = texelFetch(t_preint, ivec2(b0, f0 + 1), 0) * (1.0 - wb)
              + texelFetch(t_preint, ivec2(b0 + 1, f0 + 1), 0) * wb;
    return row0 * (1.0 - wf) + row1 * wf;
#endif
}

// g(x) = 1/x - 1/(e^x - 1) - 1/2: the mean position in [0, 1] under the density e^(-x t),
// less 1/2 (series below 0.5, where the direct form cancels; -1/2 as x grows without
// bound, where exp overflows to infinity). Both forms are computed and one selected:
// llvmpipe runs both sides of a branch anyway, and exp(x) - 1 needs no care above 0.5.
float meanOffset(float x) {
    float x2 = x * x;
    float series = -x / 12.0 * (1.0 - x2 / 60.0 * (1.0 - x2 / 42.0));
    float direct = 1.0 / x - 1.0 / (exp(x) - 1.0) - 0.5;
    return x < 0.5 ? series : direct;
}

// Premultiplied (C, A) of a segment len world units long along which the scalar goes
// linearly from s_front (nearest the eye) to s_back, from the table in rows first_row ..
// first_row + 2 size - 1 made for segments `nominal` long. The table's values are
// interpolated bilinearly (tableAt). The opacity
// 1 - exp(-len D) is exact for every length. The colour per unit opacity is K at the
// nominal length; at other lengths it moves along the line from K0 through K (towards
// K0 as the segment shortens) by the weight that is exact for a constant extinction and
// a linear colour (preintegration.length_weight).
vec4 preintegratedSegmentIn(int first_row, float s_front, float s_back, float len, float nominal) {
    if (len <= 0.0) return vec4(0.0);
    float last = float(u_pi_size - 1);
    float uf_raw = (s_front - u_pi_lo) * u_pi_scale;
    float ub_raw = (s_back - u_pi_lo) * u_pi_scale;
    // beyond an end the table was not cut at, a value counts as the end's value
    if (u_pi_cut.x < 0.5) {
        uf_raw = max(uf_raw, 0.0);
        ub_raw = max(ub_raw, 0.0);
    }
    if (u_pi_cut.y < 0.5) {
        uf_raw = min(uf_raw, last);
        ub_raw = min(ub_raw, last);
    }
    float uf = clamp(uf_raw, 0.0, last);
    float ub = clamp(ub_raw, 0.0, last);
    // beyond a cut end the values are empty: a segment reaching there counts with the
    // length of its part within (the field linear along it)
    if (uf != uf_raw || ub != ub_raw) {
        float span = abs(ub_raw - uf_raw);
        len *= span > 0.0 ? clamp(abs(ub - uf) / span, 0.0, 1.0) : 0.0;
    }
    vec4 v = tableAt(ub, uf, first_row);
    vec3 k0 = tableAt(ub, uf, first_row + u_pi_size).rgb;
    float od = len * v.a;
    float g_nominal = meanOffset(nominal * v.a);
    float w = g_nominal != 0.0 ? meanOffset(od) / g_nominal : 1.0;
    vec3 k = k0 + (v.rgb - k0) * w;
    // exp(-88) is below float's smallest normal: the segment is opaque (this also
    // covers the sentinel D = 1e30 and a product that overflows to +inf)
    float a = od > 88.0 ? 1.0 : -expm1Accurate(-od);
    return vec4(k * a, a);
}

// The same from the table of the nominal length u_pi_length (rows 0 .. 2 size - 1).
vec4 preintegratedSegment(float s_front, float s_back, float len) {
    return preintegratedSegmentIn(0, s_front, s_back, len, u_pi_length);
}

#endif
