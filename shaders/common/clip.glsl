// Clip planes and a crop box: the part of a ray the scene keeps (NumPy twin:
// model.clipping.clip_interval). Box coordinates, as the rays.
#ifndef DVR_CLIP_GLSL
#define DVR_CLIP_GLSL

#include "common/ray_box.glsl"

#ifndef N_CLIP_PLANES
#define N_CLIP_PLANES 0   // planes, each keeping dot(n, p) >= d
#endif
#ifndef CROP_BOX
#define CROP_BOX 0        // an axis-aligned box keeping what lies inside it
#endif

#if N_CLIP_PLANES > 0
uniform vec4 u_clip_planes[N_CLIP_PLANES];   // (unit normal, offset d)
#endif
#if CROP_BOX
uniform vec3 u_crop_lo;
uniform vec3 u_crop_hi;
#endif

// The part of range = (t_enter, t_exit) that the planes and the crop box keep; the ray
// misses the kept region where the result's y <= x. The kept region is convex, so it is
// one interval of the ray.
vec2 clipRange(vec3 origin, vec3 dir, vec2 range) {
#if CROP_BOX
    vec2 crop = intersectBox(origin, dir, u_crop_lo, u_crop_hi);
    range = vec2(max(range.x, crop.x), min(range.y, crop.y));
#endif
#if N_CLIP_PLANES > 0
    for (int i = 0; i < N_CLIP_PLANES; ++i) {
        float along = dot(u_clip_planes[i].xyz, dir);
        float height = dot(u_clip_planes[i].xyz, origin) - u_clip_planes[i].w;   // >= 0: origin kept
        if (along > 0.0) {
            range.x = max(range.x, -height / along);
        } else if (along < 0.0) {
            range.y = min(range.y, -height / along);
        } else if (height < 0.0) {
            range.y = -1.0 / 0.0;                     // parallel to the plane, on the cut side
        }
    }
#endif
    return range;
}

// Is the point p within margin of the kept region: at most margin outside every plane's
// kept side (dot(n, p) >= d - margin) and inside the crop box grown by margin, boundaries
// included (NumPy twin: model.clipping.inside_clip)? With margin 0, whether p is kept. A
// sphere of radius margin about a point that fails it meets no kept point: the point
// techniques skip such particles and kernels before they are rasterised.
bool insideClip(vec3 p, float margin) {
    bool inside = true;
#if CROP_BOX
    inside = all(greaterThanEqual(p, u_crop_lo - margin)) && all(lessThanEqual(p, u_crop_hi + margin));
#endif
#if N_CLIP_PLANES > 0
    for (int i = 0; i < N_CLIP_PLANES; ++i) {
        inside = inside && dot(u_clip_planes[i].xyz, p) >= u_clip_planes[i].w - margin;
    }
#endif
    return inside;
}

#endif
