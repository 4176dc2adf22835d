// 2D texture slicing: one fragment per (pixel, slice of the stack). The slice's point on
// the pixel's ray and its neighbours' points define the slab this fragment stands for,
// blended far to near with ONE, ONE_MINUS_SRC_ALPHA (see techniques/slice2d.py).
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
#include "common/clip.glsl"
#include "common/sampling.glsl"
#include "common/classification.glsl"
#if PREINTEGRATE
#include "common/preintegration.glsl"
#endif

uniform sampler2DArray t_stack;  // one float32 layer per sample plane along the axis
uniform vec3 u_extent;           // box size; the box is [0, u_extent]
uniform ivec3 u_axes;            // stack axis w, then the other two (u lower, v higher)
uniform float u_slice_distance;  // between slices along the axis
uniform int u_slice_count;
uniform int u_per_cell;          // slices per cell: interpolate + 1
uniform float u_min_depth;       // nearer points are not drawn (GL clips them)
uniform float u_inv_unit;        // 1 / transfer-function unit distance

flat in int v_slice;
out vec4 f_color;

#if GEOMETRY
uniform sampler2D t_surface;  // per pixel: the first surface's lit colour and its ray
                              // parameter t (3e38: none), techniques.geometry.surface_pass

// The ray parameter of this pixel's first surface: the ray ends there.
float surfaceT() {
    return texelFetch(t_surface, ivec2(gl_FragCoord.xy), 0).a;
}
#endif

// The ray's kept interval, ended at its first surface (an empty range where the surface
// is in front of it).
vec2 rayRange(vec3 origin, vec3 dir) {
    vec2 range = clipRange(origin, dir, intersectBox(origin, dir, vec3(0.0), u_extent));
#if GEOMETRY
    range.y = min(range.y, surfaceT());
#endif
    return range;
}

// Ray distance of slice j's plane. Neighbours call this with j +- 1 and get exactly what
// that slice's own fragments compute, so slabs tile the ray without gaps.
float sliceT(int j, vec3 origin, vec3 dir) {
    return (float(j) * u_slice_distance - origin[u_axes.x]) / dir[u_axes.x];
}

#if N_CLIP_PLANES > 0 || CROP_BOX
uniform ivec2 u_kept_slices;     // the first and last slice the clip keeps along the axis

// Do the clip planes and the crop box keep slice j's point p? Along the stack axis the
// plan decided it (u_kept_slices: the crop box's faces across the axis, the planes
// parallel to the slices), so that a face on a slice plane keeps or cuts the slice for
// every pixel alike, as the box's own faces do; here the rest, closed as clipRange keeps.
bool clipKeeps(int j, vec3 p) {
    if (j < u_kept_slices.x || j > u_kept_slices.y) return false;
#if CROP_BOX
    float pu = p[u_axes.y], pv = p[u_axes.z];
    if (pu < u_crop_lo[u_axes.y] || pu > u_crop_hi[u_axes.y] || pv < u_crop_lo[u_axes.z] || pv > u_crop_hi[u_axes.z])
        return false;
#endif
#if N_CLIP_PLANES > 0
    for (int i = 0; i < N_CLIP_PLANES; ++i) {
        vec3 n = u_clip_planes[i].xyz;
        if (n[u_axes.y] == 0.0 && n[u_axes.z] == 0.0) continue;   // parallel to the slices: in u_kept_slices
        if (dot(n, p) - u_clip_planes[i].w < 0.0) return false;
    }
#endif
    return true;
}
#endif

// Does slice j exist, with its point on this ray inside its rectangle and drawn? With
// clip planes or a crop box, the point (on the slice's own plane) must also be kept.
bool sliceInside(int j, float t, vec3 origin, vec3 dir, float cos_theta) {
    if (j < 0 || j >= u_slice_count || t * cos_theta < u_min_depth) return false;
#if GEOMETRY
    if (t > surfaceT()) return false;   // behind the pixel's surface
#endif
    vec3 p = origin + t * dir;
    float pu = p[u_axes.y], pv = p[u_axes.z];
#if N_CLIP_PLANES > 0 || CROP_BOX
    p[u_axes.x] = float(j) * u_slice_distance;
    if (!clipKeeps(j, p)) return false;
#endif
    return pu >= 0.0 && pu <= u_extent[u_axes.y] && pv >= 0.0 && pv <= u_extent[u_axes.z];
}

// Layer `layer` of the stack, bilinear at texel coordinates st (centres at integers): by
// the texture unit where its weights are exact, else from fetches (common/sampling.glsl).
float stackAt(vec2 st, int layer) {
#if TEXTURE_FILTER_EXACT
    return texture(t_stack, vec3((st + 0.5) / vec2(u_dims[u_axes.y], u_dims[u_axes.z]), float(layer))).r;
#else
    return fetchBilinear(t_stack, st, layer).r;
#endif
}

// The field at slice j's point: bilinear in the layer, linear between two layers for an
// intermediate slice.
float sampleSlice(int j, float t, vec3 origin, vec3 dir) {
    vec3 p = origin + t * dir;
    vec2 st = vec2(p[u_axes.y] / u_spacing[u_axes.y], p[u_axes.z] / u_spacing[u_axes.z]);
    int layer = j / u_per_cell;
    int rest = j - layer * u_per_cell;
    float s = stackAt(st, layer);
    if (rest > 0) {
        float f = float(rest) / float(u_per_cell);
        s = s * (1.0 - f) + stackAt(st, layer + 1) * f;
    }
    return s;
}

// The field at any point of the box, from the two layers around it (the partial slabs
// at the box entry and exit are sampled at their midpoints this way).
float sampleBetween(vec3 p) {
    vec2 st = vec2(p[u_axes.y] / u_spacing[u_axes.y], p[u_axes.z] / u_spacing[u_axes.z]);
    float x = clamp(p[u_axes.x] / u_spacing[u_axes.x], 0.0, u_dims[u_axes.x] - 1.0);
    float layer = min(floor(x), u_dims[u_axes.x] - 2.0);
    float f = x - layer;
    return stackAt(st, int(layer)) * (1.0 - f) + stackAt(st, int(layer) + 1) * f;
}

#if SAMPLE_TERMS
// Gradients from the stack: sampleBetween is the trilinear field itself.
#define FIELD_AT sampleBetween
#include "common/shading.glsl"
#endif

#if MASK_NONFINITE
bool validAt(int j, float t, vec3 origin, vec3 dir) {
    vec3 p = origin + t * dir;
    p[u_axes.x] = float(j) * u_slice_distance;
    return insideValidCell(p);
}
#endif

#if !GAP
void main() {
    vec3 origin, dir;
    pixelRay(origin, dir);
    if (dir[u_axes.x] == 0.0) discard;  // parallel to the slices
    vec2 range = rayRange(origin, dir);
    float cos_theta = dot(dir, u_forward);
    int j = v_slice;
    float t = sliceT(j, origin, dir);
    if (!sliceInside(j, t, origin, dir, cos_theta)) discard;
#if MASK_NONFINITE
    if (!validAt(j, t, origin, dir)) discard;
#endif
    int ahead = dir[u_axes.x] > 0.0 ? 1 : -1;  // index step away from the eye
    float t_near = sliceT(j - ahead, origin, dir);
    float t_far = sliceT(j + ahead, origin, dir);
    bool near_inside = sliceInside(j - ahead, t_near, origin, dir, cos_theta);
    bool far_inside = sliceInside(j + ahead, t_far, origin, dir, cos_theta);
    float s = sampleSlice(j, t, origin, dir);
#if !PREINTEGRATE
    float a = near_inside ? 0.5 * (t_near + t) : range.x;
    float b = far_inside ? 0.5 * (t + t_far) : range.y;
    vec3 p = origin + t * dir;  // where s was sampled
    p[u_axes.x] = float(j) * u_slice_distance;
    if (!(near_inside && far_inside)) {
        p = origin + (0.5 * (a + b)) * dir;
        s = sampleBetween(p);
    }
    f_color = sampleSegment(s, (b - a) * u_inv_unit, p, dir);  // zero for b <= a
#else
    // from this slice to the next one behind it (or to the box exit), and in front of
    // the first slice a ray meets, the piece from the box entry
    float s_back = far_inside ? sampleSlice(j + ahead, t_far, origin, dir)
                              : sampleBetween(origin + range.y * dir);
    float t_back = far_inside ? t_far : range.y;
    vec4 back = litSegment(preintegratedSegment(s, s_back, max(t_back - t, 0.0)), origin + (0.5 * (t + t_back)) * dir, dir);
    if (!near_inside) {
        vec4 front = preintegratedSegment(sampleBetween(origin + range.x * dir), s, max(t - range.x, 0.0));
        back = over(litSegment(front, origin + (0.5 * (range.x + t)) * dir, dir), back);
    }
    f_color = back;
#endif
    if (f_color == vec4(0.0)) discard;  // emission-only segments have alpha 0
}
#else
// The segment [a, b] of a gap ray, from the two layers around each point.
vec4 segmentColor(vec3 origin, vec3 dir, float a, float b) {
#if !PREINTEGRATE
    vec3 p = origin + (0.5 * (a + b)) * dir;
#if MASK_NONFINITE
    if (!insideValidCell(p)) return vec4(0.0);
#endif
    return sampleSegment(sampleBetween(p), (b - a) * u_inv_unit, p, dir);
#else
#if MASK_NONFINITE
    if (!insideValidCell(origin + (0.5 * (a + b)) * dir)) return vec4(0.0);
#endif
    return litSegment(preintegratedSegment(sampleBetween(origin + a * dir), sampleBetween(origin + b * dir), b - a),
               origin + (0.5 * (a + b)) * dir, dir);
#endif
}

#include "common/slice_gap.glsl"

// The gap pass: one fragment per pixel of the box; only rays that meet no slice inside
// the box (or run parallel to the slices) are kept, and their whole chord is integrated.
void main() {
    vec3 origin, dir;
    pixelRay(origin, dir);
    vec2 range = rayRange(origin, dir);
    if (!(range.y > range.x)) discard;
    float cos_theta = dot(dir, u_forward);
    // the slice planes the chord spans along the stack axis; more than two between its
    // ends always leave one inside, fewer are tested as the slice fragments test them
    float wa = (origin[u_axes.x] + range.x * dir[u_axes.x]) / u_slice_distance;
    float wb = (origin[u_axes.x] + range.y * dir[u_axes.x]) / u_slice_distance;
    int j_lo = int(floor(min(wa, wb)));
    int j_hi = int(ceil(max(wa, wb)));
    if (j_hi - j_lo > 3) discard;
    if (dir[u_axes.x] != 0.0) {
        for (int j = j_lo; j <= j_hi; ++j) {
            if (sliceInside(j, sliceT(j, origin, dir), origin, dir, cos_theta)) discard;
        }
    }
    f_color = chordColor(origin, dir, range.x, range.y, u_slice_distance);
    if (f_color == vec4(0.0)) discard;  // emission-only segments have alpha 0
}
#endif
