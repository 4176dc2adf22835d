// 3D texture slicing: one fragment per (pixel, slice). The slice's point on the pixel's
// ray and its neighbours' points define the segment this fragment contributes, blended
// far to near with ONE, ONE_MINUS_SRC_ALPHA (see techniques/slice3d.py).
#version 330 core

#ifndef PREINTEGRATE
#define PREINTEGRATE 0
#endif
#ifndef MASK_NONFINITE
#define MASK_NONFINITE 0
#endif
#ifndef GAP
#define GAP 0
#endif
#ifndef SAMPLE_TERMS
#define SAMPLE_TERMS 0
#endif
#ifndef GEOMETRY
#define GEOMETRY 0        // opaque surfaces end the rays (their colour is drawn first)
#endif

#include "common/camera_ray.glsl"
#include "common/ray_box.glsl"
#include "common/bricks.glsl"
#include "common/clip.glsl"
#include "common/slabs.glsl"
#include "common/sampling.glsl"
#include "common/classification.glsl"
#if PREINTEGRATE
#include "common/preintegration.glsl"
#endif
#if SAMPLE_TERMS
#include "common/shading.glsl"
#endif

uniform vec3 u_extent;        // box size; the box is [0, u_extent]
uniform float u_inv_unit;     // 1 / transfer-function unit distance

flat in int v_slice;
out vec4 f_color;

#if BRICKED
uniform int u_slice_base;     // the first slice of this brick's draw (instanced proxies;
                              // 0 where the vertices carry their global index)
#define SLICE_INDEX (v_slice + u_slice_base)
#else
#define SLICE_INDEX v_slice
#endif

#if GEOMETRY
uniform sampler2D t_surface;  // per pixel: the first surface's lit colour and its ray
                              // parameter t (3e38: none), techniques.geometry.surface_pass
#endif

// The ray's kept interval, ended at its first surface (an empty range where the surface
// is in front of it): slices beyond are no slices for this ray, slabs run to it.
vec2 rayRange(vec3 origin, vec3 dir) {
    vec2 range = clipRange(origin, dir, intersectBox(origin, dir, vec3(0.0), u_extent));
#if GEOMETRY
    range.y = min(range.y, texelFetch(t_surface, ivec2(gl_FragCoord.xy), 0).a);
#endif
    return range;
}

#if !PREINTEGRATE
vec4 segmentColor(vec3 origin, vec3 dir, float a, float b) {
    vec3 p = origin + (0.5 * (a + b)) * dir;
#if MASK_NONFINITE
    if (!insideValidCell(p)) return vec4(0.0);
#endif
    return sampleSegment(sampleVolume(p), (b - a) * u_inv_unit, p, dir);
}
#else
vec4 segmentColor(vec3 origin, vec3 dir, float a, float b) {
    vec3 pa = origin + a * dir;
    vec3 pb = origin + b * dir;
#if MASK_NONFINITE
    if (!insideValidCell(0.5 * (pa + pb))) return vec4(0.0);
#endif
    vec4 segment = preintegratedSegment(sampleVolume(pa), sampleVolume(pb), b - a);
    segment = litSegment(segment, 0.5 * (pa + pb), dir);
    return segment;
}
#endif

#if !GAP
void main() {
    vec3 origin, dir;
    pixelRay(origin, dir);
    vec2 range = rayRange(origin, dir);
    float cos_theta = dot(dir, u_forward);
    int k = SLICE_INDEX;
    float t = sliceT(k, cos_theta);
    if (!sliceInside(k, t, range)) discard;
#if !PREINTEGRATE
    // the slab halfway to each neighbour, or to the box where there is none
    vec2 slab = slabSegment(k, t, cos_theta, range);
    // bricks: the brick whose cells hold the slab's sample draws it (no other does)
    if (!OWNED(origin + (0.5 * (slab.x + slab.y)) * dir)) discard;
    f_color = segmentColor(origin, dir, slab.x, slab.y);
#else
    float t_near = sliceT(k + 1, cos_theta);
    float t_far = sliceT(k - 1, cos_theta);
    bool near_inside = sliceInside(k + 1, t_near, range);
    bool far_inside = sliceInside(k - 1, t_far, range);
    // the segment from this slice to the next one behind it (or the exit), and in front
    // of the first slice a ray meets, the piece from the entry
    vec4 back = segmentColor(origin, dir, t, far_inside ? t_far : range.y);
    if (!near_inside) {
        back = over(segmentColor(origin, dir, range.x, t), back);
    }
    f_color = back;
#endif
    if (f_color == vec4(0.0)) discard;  // emission-only segments have alpha 0  // blending nothing is a no-op; skip the write
}
#else
#include "common/slice_gap.glsl"

// The gap pass: one fragment per pixel of the box; only rays that meet no slice inside
// the box are kept, and their whole chord is integrated.
void main() {
    vec3 origin, dir;
    pixelRay(origin, dir);
    vec2 range = rayRange(origin, dir);
    if (!(range.y > range.x)) discard;
    float cos_theta = dot(dir, u_forward);
#if SHELLS
    float per_t = 1.0;        // the slices' depth (radius) grows as t
#else
    float per_t = cos_theta;  // the slices' depth grows as t * cos
#endif
    // slices 2 steps apart along the ray always leave one inside; a shorter chord has
    // at most the slices around the one at its far end to look at (the same test as the
    // slice fragments, so a pixel gets a slice or the gap, never both nor neither)
    if ((range.y - range.x) * per_t > 2.0 * u_step) discard;
    int k = int(ceil((u_far_depth - range.y * per_t) / u_step));
    for (int i = k - 1; i <= k + 2; ++i) {
        if (sliceInside(i, sliceT(i, cos_theta), range)) discard;
    }
    // bricks: the chord is the brick's that owns its midpoint (its halo holds the rest)
    if (!OWNED(origin + (0.5 * (range.x + range.y)) * dir)) discard;
    f_color = chordColor(origin, dir, range.x, range.y, u_step);
    if (f_color == vec4(0.0)) discard;  // emission-only segments have alpha 0
}
#endif
