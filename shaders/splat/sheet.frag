// Sheet-buffer splatting, the classification pass (see techniques/splat.py): this pixel's
// value on the sheet is the splatted sum over the weights; it is classified, lit when the
// scene asks, and its segment (the piece of the ray the sheet stands for, slabs.glsl) is
// blended front to back under what nearer sheets left (ONE_MINUS_DST_ALPHA, ONE).
// GEOMETRY: the ray's kept range ends at its first surface, as at a clip (the surface is
// blended under the sheets last, techniques.splat._draw_surface_under). A piece with an
// end at a cut or at the surface is not centred on its sheet: it takes the field at its
// middle from the volume's texture instead (END_PIECES), as 3D slicing samples it.
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
#ifndef GEOMETRY
#define GEOMETRY 0
#endif
#define END_PIECES (N_CLIP_PLANES > 0 || CROP_BOX || GEOMETRY)
// END_PIECES samples the volume (included whatever the switches: each file is inlined once)
#include "common/sampling.glsl"
#if SHADING
#include "common/shading.glsl"
uniform sampler2D t_sheet_gradient;   // (sum w gradient, 0)
#endif

uniform sampler2D t_sheet;    // (sum w value, sum w, sum w over non-finite samples, 0)
uniform vec3 u_extent;        // box size; the box is [0, u_extent]
uniform float u_inv_unit;     // 1 / transfer-function unit distance
#if GEOMETRY
uniform sampler2D t_surface;  // per pixel: the first surface's lit colour and its ray
                              // parameter t (3e38: none), techniques.geometry.surface_pass
#endif

flat in int v_slice;
out vec4 f_color;

void main() {
    vec3 origin, dir;
    pixelRay(origin, dir);
    // the sheets stand for the kept part of the ray only (clip planes, crop box)
    vec2 box = intersectBox(origin, dir, vec3(0.0), u_extent);
    vec2 range = clipRange(origin, dir, box);
#if GEOMETRY
    // and end at its first surface: sheets behind it are no sheets for this ray, the
    // piece that straddles it runs to it
    range.y = min(range.y, texelFetch(t_surface, ivec2(gl_FragCoord.xy), 0).a);
#endif
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
#if END_PIECES
    // the first piece behind a cut (no nearer sheet in the kept range, which starts past
    // the box's entry) or the last before a cut or the surface: up to half a step from
    // its sheet, so classified at its middle (reference.splat: the same rule in float64)
    bool cut_front = !sliceInside(k + 1, sliceT(k + 1, cos_theta), range) && range.x > box.x;
    bool cut_back = !sliceInside(k - 1, sliceT(k - 1, cos_theta), range) && range.y < box.y;
    if (cut_front || cut_back) {
        vec3 middle = origin + (0.5 * (slab.x + slab.y)) * dir;
#if MASK_NONFINITE
        if (!insideValidCell(middle)) discard;
#endif
        s = sampleVolume(middle);
    }
#endif
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
