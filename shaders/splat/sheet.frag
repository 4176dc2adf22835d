// Sheet-buffer splatting, the classification pass (see techniques/splat.py): this pixel's
// value on the sheet is the splatted sum over the weights; it is classified, lit when the
// scene asks, and its segment (the piece of the ray the sheet stands for, slabs.glsl) is
// blended front to back under what nearer sheets left (ONE_MINUS_DST_ALPHA, ONE).
#version 330 core

#include "common/camera_ray.glsl"
#include "common/ray_box.glsl"
#include "common/clip.glsl"
#include "common/slabs.glsl"
#include "common/classification.glsl"

#ifndef SHADING
#define SHADING 0
#endif
#ifndef MASK_NONFINITE
#define MASK_NONFINITE 0
#endif
#if SHADING
#include "common/shading.glsl"
uniform sampler2D t_sheet_gradient;   // (sum w gradient, 0)
#endif

uniform sampler2D t_sheet;    // (sum w value, sum w, sum w over non-finite samples, 0)
uniform vec3 u_extent;        // box size; the box is [0, u_extent]
uniform float u_inv_unit;     // 1 / transfer-function unit distance

flat in int v_slice;
out vec4 f_color;

void main() {
    vec3 origin, dir;
    pixelRay(origin, dir);
    // the sheets stand for the kept part of the ray only (clip planes, crop box)
    vec2 range = clipRange(origin, dir, intersectBox(origin, dir, vec3(0.0), u_extent));
    float cos_theta = dot(dir, u_forward);
    int k = v_slice;
    float t = sliceT(k, cos_theta);
    if (!sliceInside(k, t, range)) discard;
    ivec2 pixel = ivec2(gl_FragCoord.xy);
    vec4 sheet = texelFetch(t_sheet, pixel, 0);
    // no sample drawn here (all transparent), or a non-finite corner: nothing
    if (sheet.y <= 0.0 || sheet.z > 0.0) discard;
    float s = sheet.x / sheet.y;
    vec2 slab = slabSegment(k, t, cos_theta, range);
    vec4 rgba = applyTF(s);
    float length_over_unit = (slab.y - slab.x) * u_inv_unit;
#if SHADING
    if (rgba.a > 0.0) {
        vec3 g = texelFetch(t_sheet_gradient, pixel, 0).xyz / sheet.y;
        float factor, opacity_scale;
        vec3 offset;
        termsFor(g, origin + t * dir, dir, factor, offset, opacity_scale);
        rgba.rgb = rgba.rgb * factor + offset;
        length_over_unit *= opacity_scale;
    }
#endif
    f_color = segmentOf(rgba, s, length_over_unit);
    if (f_color == vec4(0.0)) discard;    // blending nothing is a no-op; skip the write
}
