// Bricked ray casting (techniques/bricks.py): one pass per brick, front to back, each
// taking the segments whose midpoint lies in the cells the brick owns and continuing the
// ray's sums from the image of the bricks before it.
#ifndef DVR_BRICKS_GLSL
#define DVR_BRICKS_GLSL
#include "common/pixel_stage.glsl"

#ifndef BRICKED
#define BRICKED 0
#endif

#if BRICKED
uniform sampler2D t_accum;    // the passes so far: premultiplied RGBA per pixel
uniform vec3 u_own_lo;        // the owned box, world units from the volume's lower corner:
uniform vec3 u_own_hi;        // lo <= p < hi per axis (+-3e38 on the volume's outer faces)
uniform vec3 u_pass_lo;       // the owned box grown by half a cell: every owned sample of
uniform vec3 u_pass_hi;       // a ray lies where the ray crosses it

// Every pass computes a sample's position alike, bit for bit, and the boxes' shared
// faces are the same numbers: each sample is owned by exactly one brick.
bool ownedSample(vec3 p) {
    return all(greaterThanEqual(p, u_own_lo)) && all(lessThan(p, u_own_hi));
}

vec4 accumulatedSoFar() {
    return texelFetch(t_accum, ivec2(FRAG_COORD.xy), 0);
}

// Segment indices [k_lo, k_hi] (either convention: k's midpoint at t0 + (jitter + k + 0.5)
// step, or k spanning [t0 + (jitter + k) step, ...]) that can hold an owned midpoint, one
// segment of slack each side; k_hi < k_lo where the ray misses the brick.
ivec2 brickSegments(vec3 origin, vec3 dir, float t0, float jitter, float step) {
    vec2 t = intersectBox(origin, dir, u_pass_lo, u_pass_hi);
    if (t.y < t.x) return ivec2(0, -1);
    float lo = clamp(floor((t.x - t0) / step - jitter) - 1.0, -2.0, 1e9);
    float hi = clamp(ceil((t.y - t0) / step - jitter) + 1.0, -2.0, 1e9);
    return ivec2(int(lo), int(hi));
}
#define OWNED(p) ownedSample(p)
#else
#define OWNED(p) true
#endif

#endif
