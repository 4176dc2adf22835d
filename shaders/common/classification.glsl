// Transfer-function lookup (NumPy twin: transfer.LookupTable.lookup) and classified segments.
#ifndef DVR_CLASSIFICATION_GLSL
#define DVR_CLASSIFICATION_GLSL

#include "common/compositing.glsl"
#ifndef PRECISE
#define PRECISE   // common/precise.glsl, where a shader includes it first
#endif

uniform sampler2D t_tf;     // (n, 2) RGBA32F: row 0 colour and unit-distance opacity,
                            // row 1 transparency 1 - opacity (precise near opacity 1)
uniform float u_tf_lo;      // data value of entry 0
uniform float u_tf_scale;   // entries per data unit
uniform int u_tf_size;

// Linear interpolation between table entries done here, in full float precision,
// rather than by the texture unit's filter.
vec4 lerpTableRow(sampler2D table, float s, int row) {
    // (precise: the same value classified alike in every shader, bricks/resolve.frag too)
    PRECISE float u = clamp((s - u_tf_lo) * u_tf_scale, 0.0, float(u_tf_size - 1));
    int i0 = min(int(floor(u)), u_tf_size - 2);
    float f = u - float(i0);
    vec4 a = texelFetch(table, ivec2(i0, row), 0);
    vec4 b = texelFetch(table, ivec2(i0 + 1, row), 0);
    PRECISE vec4 value = a * (1.0 - f) + b * f;
    return value;
}

vec4 lookupTFRow(float s, int row) {
    return lerpTableRow(t_tf, s, row);
}

#ifndef STEP_TABLE
#define STEP_TABLE 0
#endif
#if STEP_TABLE
uniform sampler2D t_step_tf;   // (n, 1) RGBA32F: LookupTable.step_table for u_step, same entries
// A full step's segment at value s, premultiplied and opacity-corrected (NumPy twin:
// LookupTable.step_table, interpolated): what a sample of a full-length segment costs
// instead of a lookup, a log and an exp.
vec4 lookupStepTF(float s) {
    return lerpTableRow(t_step_tf, s, 0);
}
#endif

vec4 applyTF(float s) {
    return lookupTFRow(s, 0);
}

// 1 - alpha(s) with the relative precision a float32 alpha near 1 lacks.
float transparencyTF(float s) {
    return lookupTFRow(s, 1).r;
}

#ifndef OPTICAL_MODEL
#define OPTICAL_MODEL 0   // 0 emission-absorption, 1 absorption only, 2 emission only,
#endif                      // 3 Sabella (its segments as absorption only; the ray caster
                            // colours the ray at its end, common/sabella.glsl)
// The segment length_over_unit unit distances long of a sample whose straight colour and
// unit-distance opacity are rgba (its value s, for the precise transparency), as
// premultiplied RGBA under the scene's optical model (NumPy twin:
// reference.common.segment_of): emission-absorption (c alpha, alpha) with alpha corrected
// for the length; absorption only (0, alpha); emission only (c tau L, 0), nothing absorbed.
// transparency is 1 - alpha, precise near 1 (read only above alpha 0.5).
vec4 segmentWith(vec4 rgba, float transparency, float length_over_unit) {
    if (rgba.a <= 0.0) return vec4(0.0);
#if OPTICAL_MODEL == 2
    float log_transparency = rgba.a <= 0.5 ? log1pAccurate(-rgba.a) : log(transparency);
    return vec4(rgba.rgb * (-log_transparency * max(length_over_unit, 0.0)), 0.0);
#else
    float alpha = correctOpacity(rgba.a, transparency, length_over_unit);
  #if OPTICAL_MODEL == 1 || OPTICAL_MODEL == 3
    return vec4(0.0, 0.0, 0.0, alpha);
  #else
    return vec4(rgba.rgb * alpha, alpha);
  #endif
#endif
}

// The same for a sample of the 1D transfer function at value s.
vec4 segmentOf(vec4 rgba, float s, float length_over_unit) {
    if (rgba.a <= 0.0) return vec4(0.0);
    return segmentWith(rgba, rgba.a > 0.5 ? transparencyTF(s) : 1.0 - rgba.a, length_over_unit);
}

// Premultiplied colour and opacity of a segment length_over_unit unit distances long
// whose field value is s (NumPy twin: reference.common.classified_segment).
vec4 classifiedSegment(float s, float length_over_unit) {
    return segmentOf(applyTF(s), s, length_over_unit);
}

#ifndef SAMPLE_TERMS
#define SAMPLE_TERMS 0   // lighting or illustration terms: shaders/common/shading.glsl
#endif
#if SAMPLE_TERMS   // defined in shaders/common/shading.glsl
vec3 sampleTerms(vec3 color, vec3 p_world, vec3 ray_dir, out float opacity_scale);
vec4 termsSegment(vec4 segment, vec3 p_world, vec3 ray_dir);
vec3 gradient(vec3 p_world);
void termsFor(vec3 g, vec3 p_world, vec3 ray_dir, out float factor, out vec3 offset, out float opacity_scale);
#endif

#ifndef TF_2D
#define TF_2D 0          // a 2D transfer function over (value, |gradient|); needs SAMPLE_TERMS
#endif
#if TF_2D
uniform sampler2D t_tf2d;    // (n_value, 2 n_gradient) RGBA32F: rows [0, n_gradient) the table,
                             // rows [n_gradient, 2 n_gradient) 1 - alpha in red
uniform vec2 u_tf2d_lo;      // value and gradient magnitude of entry (0, 0)
uniform vec2 u_tf2d_scale;   // entries per unit of each
uniform ivec2 u_tf2d_size;   // (n_value, n_gradient)

// The table's bilinear interpolant at value s and gradient magnitude g, and its
// transparency (NumPy twin: TransferFunction2D.lookup), in full float precision.
vec4 lookupTF2D(float s, float g, out float transparency) {
    vec2 u = clamp((vec2(s, g) - u_tf2d_lo) * u_tf2d_scale, vec2(0.0), vec2(u_tf2d_size - 1));
    ivec2 i = min(ivec2(floor(u)), u_tf2d_size - 2);
    vec2 f = u - vec2(i);
    vec4 lower = texelFetch(t_tf2d, i, 0) * (1.0 - f.x) + texelFetch(t_tf2d, i + ivec2(1, 0), 0) * f.x;
    vec4 upper = texelFetch(t_tf2d, i + ivec2(0, 1), 0) * (1.0 - f.x) + texelFetch(t_tf2d, i + ivec2(1, 1), 0) * f.x;
    vec4 rgba = lower * (1.0 - f.y) + upper * f.y;
    transparency = 1.0 - rgba.a;
    if (rgba.a > 0.5) {
        ivec2 t = i + ivec2(0, u_tf2d_size.y);
        float t_lower = texelFetch(t_tf2d, t, 0).r * (1.0 - f.x) + texelFetch(t_tf2d, t + ivec2(1, 0), 0).r * f.x;
        float t_upper = texelFetch(t_tf2d, t + ivec2(0, 1), 0).r * (1.0 - f.x) + texelFetch(t_tf2d, t + ivec2(1, 1), 0).r * f.x;
        transparency = t_lower * (1.0 - f.y) + t_upper * f.y;
    }
    return rgba;
}
#endif

// The segment of a sample at p on a ray along ray_dir whose classification rgba (at value
// s) is known: its colour lit (and its extinction scaled) there, when the scene asks,
// before it is associated.
// With a 2D transfer function rgba is its envelope (the largest opacity at s): zero there
// means nothing at any gradient, so only the others read the gradient and the 2D table.
vec4 sampleSegmentOf(vec4 rgba, float s, float length_over_unit, vec3 p_world, vec3 ray_dir) {
    if (rgba.a <= 0.0) return vec4(0.0);
#if TF_2D
    vec3 g = gradient(p_world);
    float transparency;
    rgba = lookupTF2D(s, length(g), transparency);
    float factor, opacity_scale;
    vec3 offset;
    termsFor(g, p_world, ray_dir, factor, offset, opacity_scale);
    rgba.rgb = rgba.rgb * factor + offset;
    return segmentWith(rgba, transparency, length_over_unit * opacity_scale);
#elif SAMPLE_TERMS
    float opacity_scale;
    rgba.rgb = sampleTerms(rgba.rgb, p_world, ray_dir, opacity_scale);
    length_over_unit *= opacity_scale;
#endif
    return segmentOf(rgba, s, length_over_unit);
}

// The same, classifying the value s.
vec4 sampleSegment(float s, float length_over_unit, vec3 p_world, vec3 ray_dir) {
    return sampleSegmentOf(applyTF(s), s, length_over_unit, p_world, ray_dir);
}

// A premultiplied (pre-integrated) segment with the colour terms of a sample at p; as it
// is when the scene has none.
vec4 litSegment(vec4 segment, vec3 p_world, vec3 ray_dir) {
#if SAMPLE_TERMS
    if (segment.a > 0.0) return termsSegment(segment, p_world, ray_dir);
#endif
    return segment;
}

#endif
