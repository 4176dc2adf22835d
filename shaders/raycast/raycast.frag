// Single-pass ray casting: one ray per pixel centre, ray-box entry and exit, midpoint
// samples on segments `u_step` long with the last (shorter) segment at its true length.
#version 330 core
// precise (common/precise.glsl) on the ray's positions, the texel coordinates and the
// sums: the bricked passes (BRICKED) must evaluate them exactly as the single pass does
#include "common/precise.glsl"

// Feature switches, off by default; the renderer defines exactly those a scene uses.
#ifndef MODE_COMPOSITE
#define MODE_COMPOSITE 0
#endif
#ifndef MODE_MIP
#define MODE_MIP 0
#endif
#ifndef MODE_MINIP
#define MODE_MINIP 0
#endif
#ifndef MODE_AVERAGE
#define MODE_AVERAGE 0
#endif
#ifndef MODE_ISOSURFACE
#define MODE_ISOSURFACE 0
#endif
#ifndef JITTER
#define JITTER 0
#endif
#ifndef SKIP_EMPTY
#define SKIP_EMPTY 0
#endif
#ifndef EARLY_RAY_TERMINATION
#define EARLY_RAY_TERMINATION 0
#endif
#ifndef MASK_NONFINITE
#define MASK_NONFINITE 0
#endif
#ifndef PREINTEGRATE
#define PREINTEGRATE 0
#endif
#ifndef SAMPLE_TERMS
#define SAMPLE_TERMS 0
#endif
#ifndef STEP_TABLE
#define STEP_TABLE 0      // composite, emission-absorption, no pre-integration: see below
#endif
#ifndef REFINE
#define REFINE 0          // pre-integration: split segments that may meet TF detail
#endif
#ifndef GEOMETRY
#define GEOMETRY 0        // opaque surfaces end the rays and show behind them
#endif

#include "common/camera_ray.glsl"
#include "common/ray_box.glsl"
#include "common/bricks.glsl"
#include "common/clip.glsl"
#include "common/sampling.glsl"
#include "common/classification.glsl"
#include "common/compositing.glsl"
#if PREINTEGRATE
#include "common/preintegration.glsl"
#endif
#if MODE_ISOSURFACE || SAMPLE_TERMS
#include "common/shading.glsl"
#endif
#if MODE_ISOSURFACE
#include "common/isosurface.glsl"
#endif
#ifndef OPTICAL_MODEL
#define OPTICAL_MODEL 0
#endif
#define SABELLA (MODE_COMPOSITE && OPTICAL_MODEL == 3)
#if SABELLA
#include "common/sabella.glsl"
uniform vec2 u_depth_range;   // nearest and farthest depth of the box
#endif

uniform vec3 u_extent;        // box size; the box is [0, u_extent]
uniform float u_step;         // segment length, world units
uniform float u_inv_unit;     // 1 / transfer-function unit distance
uniform int u_max_segments;   // upper bound on segments per ray (a safety net)
#if JITTER
uniform sampler2D t_jitter;   // offsets in [0, 1) of a step, tiled over the image
#endif
#if SKIP_EMPTY
uniform sampler3D t_occupancy; // per brick: 1 if any value in it has non-zero opacity
                               // (pre-integrated: any value within a table cell of its range)
uniform float u_brick;         // brick size in samples
#endif
#if REFINE
uniform sampler3D t_reach;     // R32F per block of u_reach_block cells (1 unless the volume
                               // is large): a bound on the field's gradient over it and
                               // the blocks half a step around it (raycast.gradient_bounds)
uniform float u_reach_block;
#ifndef DETAIL_COUNT
#define DETAIL_COUNT 1
#endif
uniform vec2 u_detail[DETAIL_COUNT];  // value intervals holding the TF's detail knots
uniform int u_refine;         // even parts per refined segment
uniform float u_pi_fine_length; // the nominal length of their table
uniform int u_refine_cuts;    // a bound on a refined segment's cuts (its parts and faces)
// Can a value in [lo, hi] lie on a knot where the TF's opacity bends?
bool touchesDetail(float lo, float hi) {
    bool touches = false;
    for (int k = 0; k < DETAIL_COUNT; ++k) {
        touches = touches || (hi >= u_detail[k].x && lo <= u_detail[k].y);
    }
    return touches;
}
#include "common/reach_walk.glsl"
#endif
#if EARLY_RAY_TERMINATION
uniform float u_ert_transmittance;
#endif
#if GEOMETRY
uniform sampler2D t_surface;  // per pixel: the first surface's lit colour and its ray
                              // parameter t (3e38: none), techniques.geometry.surface_pass
#endif
#if MODE_ISOSURFACE
uniform float u_iso;
#endif

#if COMPUTE_PIXELS
vec4 f_color;                 // stored by common/pixel_store.glsl's main()
#else
out vec4 f_color;
#endif

#ifndef OCCUPIED_RANGE
#define OCCUPIED_RANGE 0   // segments start and stop where the ray meets occupied bricks
#endif
#if OCCUPIED_RANGE
uniform sampler2D t_occupied_range;   // per pixel: (least entry, -greatest exit) into the
                                      // occupied bricks' grown boxes (raycast.occupied_range)
#endif
#ifndef CROSSING_WALK
#define CROSSING_WALK 0    // pre-integration: cells walked, cut where the field crosses TF knots
#endif
#if CROSSING_WALK
#include "common/crossing_walk.glsl"
#endif

#if SKIP_EMPTY
// Whether the brick holding p is empty, and if so where the ray leaves it.
bool emptyBrickExit(vec3 p, vec3 origin, vec3 dir, out float t_exit) {
    ivec3 brick = clamp(ivec3(floor(p / u_spacing / u_brick)), ivec3(0), textureSize(t_occupancy, 0) - 1);
    t_exit = 0.0;
    if (texelFetch(t_occupancy, brick, 0).r >= 0.5) return false;
    vec3 lo = vec3(brick) * u_brick * u_spacing;
    vec3 hi = lo + u_brick * u_spacing;
    vec3 t_far = max((lo - origin) / dir, (hi - origin) / dir);
    t_exit = min(min(t_far.x, t_far.y), t_far.z);
    return true;
}
#endif

#if SKIP_EMPTY && PREINTEGRATE
// A pre-integrated segment k (midpoint p) came out fully transparent: if its brick is
// empty, every later segment with both ends in the brick is exactly zero (its ends'
// values, and the table nodes around them, have zero opacity); return the last of them
// (k if none). The one after it needs its front sample: the caller walks the last one
// again only to read its end.
int lastSegmentInEmptyBrick(vec3 p, vec3 origin, vec3 dir, float t0, float jitter, int k) {
    float t_exit;
    if (!emptyBrickExit(p, origin, dir, t_exit)) return k;
    return max(k, int(floor((t_exit - t0) / u_step - jitter)) - 1);
}
#elif SKIP_EMPTY
// A sample at p (segment k) came out fully transparent: if its brick is empty, every
// midpoint inside it has zero opacity, so return the segment before the one whose
// midpoint first passes the brick's exit (rounding can only make the ray look once more,
// never skip a sample); else k.
int skipEmptyBrick(vec3 p, vec3 origin, vec3 dir, float t0, float jitter, int k) {
    float t_exit;
    if (!emptyBrickExit(p, origin, dir, t_exit)) return k;
    int k_next = int(ceil((t_exit - t0) / u_step - jitter - 0.5)) - 1;
    return max(k, k_next - 1);
}
#endif

#ifndef SEGMENT_GROUP
#define SEGMENT_GROUP 4    // full segments per loop round (step table): 4 or 1
#endif
#if STEP_TABLE
// Full segment k's midpoint: from k, never accumulated, so a skip cannot move a sample.
vec3 segmentMidpoint(vec3 origin, vec3 dir, float t0, float jitter, int k) {
    PRECISE float t = t0 + (jitter + float(k) + 0.5) * u_step;
    PRECISE vec3 p = origin + t * dir;
    return p;
}

// A full segment's corrected, premultiplied piece from the step table (0 in a masked cell).
vec4 fullSegment(vec3 p) {
    if (!OWNED(p)) return vec4(0.0);   // (bricks: another brick's sample)
  #if MASK_NONFINITE
    if (!insideValidCell(p)) return vec4(0.0);
  #endif
    return lookupStepTF(sampleVolume(p));
}

// A full segment composited unless the ray has ended, then whether it has: opaque, or
// (with early termination) its transmittance under the threshold. A zero piece leaves
// the sums exactly as they are.
void compositeUntilEnd(inout vec3 color, inout float alpha_acc, vec4 piece, inout bool ended) {
    compositePremultiplied(color, alpha_acc, ended ? vec4(0.0) : piece);
  #if EARLY_RAY_TERMINATION
    ended = ended || 1.0 - alpha_acc < u_ert_transmittance;
  #endif
    ended = ended || alpha_acc >= 1.0;
}

// A partial segment [a, b] of the ray (the first, jittered one or the last, shorter one),
// its opacity corrected for its own length, composited front to back.
void compositePartial(vec3 origin, vec3 dir, float a, float b, inout vec3 color, inout float alpha_acc) {
    float len = b - a;
    if (len <= 0.0) return;
    PRECISE vec3 p = origin + 0.5 * (a + b) * dir;
    if (!OWNED(p)) return;
  #if MASK_NONFINITE
    if (!insideValidCell(p)) return;
  #endif
    float s = sampleVolume(p);
    vec4 rgba = applyTF(s);
    if (rgba.a <= 0.0) return;
    compositePremultiplied(color, alpha_acc, sampleSegmentOf(rgba, s, len * u_inv_unit, p, dir));
}
#endif

void PIXEL_MAIN() {
    vec3 origin, dir;
    pixelRay(origin, dir);
    PRECISE vec2 range = clipRange(origin, dir, intersectBox(origin, dir, vec3(0.0), u_extent));
#if BRICKED
    f_color = accumulatedSoFar();   // the bricks in front: this pass continues their sums
#else
    f_color = vec4(0.0);
#endif
#if GEOMETRY
    // the ray ends at its first surface, which is composited behind what it gathered
    vec4 surface = texelFetch(t_surface, ivec2(FRAG_COORD.xy), 0);
    bool on_surface = surface.a < 1e38;
    range.y = min(range.y, surface.a);
    if (range.y <= range.x) {
        if (on_surface) f_color = vec4(surface.rgb, 1.0);
        return;
    }
#else
    if (range.y <= range.x) return;
#endif
    float t0 = range.x, t1 = range.y;

#if JITTER
    ivec2 jsize = textureSize(t_jitter, 0);
    float jitter = texelFetch(t_jitter, ivec2(pixelCoord()) % jsize, 0).r;
#else
    float jitter = 0.0;
#endif

#if MODE_COMPOSITE
    PRECISE vec3 color = f_color.rgb;
    PRECISE float alpha_acc = f_color.a;
  #if SABELLA
    float s_peak = -1.0 / 0.0;  // the ray's largest sample and where it is first met
    float t_peak = 0.0;
  #endif
  #if PREINTEGRATE
    float s_front = 0.0;      // the field at the current segment's start (read below)
    bool have_front = true;
  #endif
#elif MODE_MIP
    // (precise: the single pass classifies its extreme here, the bricked ones in
    // bricks/resolve.frag; an NVIDIA GPU's compiler, left to itself, classified the same
    // extreme a few ulps differently here in 1.6 % of a mip image's pixels)
    PRECISE float s_best = -1.0 / 0.0;
#elif MODE_MINIP
    PRECISE float s_best = 1.0 / 0.0;
#elif MODE_AVERAGE
    PRECISE float s_sum = 0.0;
    PRECISE float len_sum = 0.0;
#elif MODE_ISOSURFACE
    float t_prev = t0;
    bool have_prev = false;
    bool above_prev = false;
    float t_hit = -1.0;
#endif

#if BRICKED && (MODE_MIP || MODE_MINIP)
    if (f_color.g > 0.5) s_best = f_color.r;   // the bricks in front: (extreme, 1 once a sample is taken)
#elif BRICKED && MODE_AVERAGE
    s_sum = f_color.r;                         // (sum of s len, sum of len)
    len_sum = f_color.g;
#endif

#if OCCUPIED_RANGE
    // Every segment wholly outside [t_enter, t_leave] lies in empty bricks and is exactly
    // zero; the loops below start and stop one segment beyond (t_leave < t_enter where
    // the ray meets no occupied brick).
    vec2 occupied = texelFetch(t_occupied_range, ivec2(FRAG_COORD.xy), 0).rg;
    float t_enter = occupied.x;
    float t_leave = -occupied.y;
#endif

#if STEP_TABLE
    // Full segments k = 0 .. n_full - 1 span [t0 + (jitter + k) * step, t0 + (jitter + k +
    // 1) * step] and read their corrected, premultiplied segment from the step table; the
    // partial ones in front (a jittered start) and behind (the last, shorter one) are
    // corrected for their own length once per ray, outside the loop: llvmpipe runs both
    // sides of a branch that differs between pixels, so a per-sample choice would cost
    // both ways for every sample.
    PRECISE float steps = (t1 - t0) / u_step - jitter;
    int n_full = max(int(floor(steps)), 0);
#if JITTER
    // (unjittered rays have no front partial: llvmpipe would run its body regardless, 8 %
    // of a Marschner-Lobb frame at the tolerance's step for VTK's one-voxel error)
    PRECISE float t_front = min(t0 + jitter * u_step, t1);
    compositePartial(origin, dir, t0, t_front, color, alpha_acc);
#endif
    bool ended = false;
    int k_first = 0;
    int k_stop = n_full;
  #if OCCUPIED_RANGE
    // sample k sits at t0 + (jitter + k + 0.5) step
    k_first = int(clamp(floor((t_enter - t0) / u_step - jitter - 0.5), 0.0, float(n_full)));
    k_stop = int(clamp(ceil((t_leave - t0) / u_step - jitter - 0.5) + 1.0, 0.0, float(n_full)));
  #endif
  #if BRICKED
    ended = alpha_acc >= 1.0;
    #if EARLY_RAY_TERMINATION
    ended = ended || 1.0 - alpha_acc < u_ert_transmittance;
    #endif
    ivec2 k_brick = brickSegments(origin, dir, t0, jitter, u_step);
    k_first = max(k_first, k_brick.x);
    k_stop = ended ? k_first : min(k_stop, k_brick.y + 1);
  #endif
    // Four segments per iteration: llvmpipe pays the loop's bookkeeping (its exit tests,
    // the breaks' masks) once per iteration (the CT head at the tolerance's one-voxel
    // step: 47 ms one at a time, 35 four at a time; docs/notes/raycast.md). A segment past the last reads
    // as empty. The end
    // is still decided after each segment (compositeUntilEnd), the loop left once per
    // group: the image is the one-at-a-time loop's whatever the groups' starts, so
    // skipping still changes no pixel.
    int k_end = min(k_stop, u_max_segments);
  #if SEGMENT_GROUP == 1
    // one at a time: the compute stage (raycast.draw; faster there on a GPU, docs/notes/gpu.md)
    for (int k = k_first; k < k_end; ++k) {
        vec3 p0 = segmentMidpoint(origin, dir, t0, jitter, k);
        vec4 piece0 = fullSegment(p0);
        if (piece0.a <= 0.0) {
    #if SKIP_EMPTY && !PREINTEGRATE
            k = skipEmptyBrick(p0, origin, dir, t0, jitter, k);
    #endif
            continue;
        }
        compositeUntilEnd(color, alpha_acc, litSegment(piece0, p0, dir), ended);
        if (ended) break;
    }
  #else
    for (int k = k_first; k < k_end; k += 4) {
        vec3 p0 = segmentMidpoint(origin, dir, t0, jitter, k);
        vec3 p1 = segmentMidpoint(origin, dir, t0, jitter, k + 1);
        vec3 p2 = segmentMidpoint(origin, dir, t0, jitter, k + 2);
        vec3 p3 = segmentMidpoint(origin, dir, t0, jitter, k + 3);
        vec4 piece0 = fullSegment(p0);
        vec4 piece1 = k + 1 < k_end ? fullSegment(p1) : vec4(0.0);
        vec4 piece2 = k + 2 < k_end ? fullSegment(p2) : vec4(0.0);
        vec4 piece3 = k + 3 < k_end ? fullSegment(p3) : vec4(0.0);
        if (max(max(piece0.a, piece1.a), max(piece2.a, piece3.a)) <= 0.0) {
  #if SKIP_EMPTY && !PREINTEGRATE
            // from the group's last segment, as one at a time would from each
            k = skipEmptyBrick(p3, origin, dir, t0, jitter, k + 3) - 3;
  #endif
            continue;
        }
        compositeUntilEnd(color, alpha_acc, litSegment(piece0, p0, dir), ended);
        compositeUntilEnd(color, alpha_acc, litSegment(piece1, p1, dir), ended);
        compositeUntilEnd(color, alpha_acc, litSegment(piece2, p2, dir), ended);
        compositeUntilEnd(color, alpha_acc, litSegment(piece3, p3, dir), ended);
        if (ended) break;
    }
  #endif
    if (!ended) {
        PRECISE float t_last = max(t0 + (jitter + float(n_full)) * u_step, t0);
        compositePartial(origin, dir, t_last, t1, color, alpha_acc);
    }
#else
    // Segment k spans [t0 + (jitter + k) * step, t0 + (jitter + k + 1) * step] clipped to
    // [t0, t1]; k = -1 is the partial segment in front of a jittered start. Positions come
    // from k, never from accumulation, so skipping segments cannot move a sample.
    int k_first = -1;
    int k_last = u_max_segments;
  #if OCCUPIED_RANGE
    k_first = int(clamp(floor((t_enter - t0) / u_step - jitter) - 1.0, -1.0, float(u_max_segments)));
    k_last = int(clamp(floor((t_leave - t0) / u_step - jitter) + 1.0, -1.0, float(u_max_segments)));
  #endif
  #if BRICKED && !PREINTEGRATE
    ivec2 k_brick = brickSegments(origin, dir, t0, jitter, u_step);
    k_first = max(k_first, k_brick.x);
    k_last = min(k_last, k_brick.y);
    #if MODE_COMPOSITE
    bool ended_before = alpha_acc >= 1.0;
      #if EARLY_RAY_TERMINATION
    ended_before = ended_before || 1.0 - alpha_acc < u_ert_transmittance;
      #endif
    if (ended_before) k_last = k_first - 1;
    #endif
  #endif
  #if MODE_COMPOSITE && PREINTEGRATE && CROSSING_WALK
    // (every cell outside the occupied range is empty: the walk starts and stops there)
    #if OCCUPIED_RANGE
    crossingWalk(origin, dir, max(t0, t_enter), min(t1, t_leave), color, alpha_acc);
    #else
    crossingWalk(origin, dir, t0, t1, color, alpha_acc);
    #endif
  #elif MODE_COMPOSITE && PREINTEGRATE && REFINE
    // One loop over pieces: a piece is a whole segment, or, where the segment may meet
    // TF detail, one part of its walk from cut to cut. Each round fetches one value and
    // reads one table: llvmpipe runs a round for a group of pixels as long as any of them
    // has pieces left, so pixels walking a refined segment cost their neighbours no more
    // than the rounds they take themselves (a walk nested in the segment loop made every
    // segment pay for the longest walk in its group).
    int k = k_first;
    bool walking = false;           // inside a refined segment [a_walk, b_walk]
    float a_walk = 0.0, b_walk = 0.0, part = 0.0;
    int even = 1;
    float g_walk = 0.0;             // the walked segment's gradient bound (REACH_WALK)
    vec3 t_face = vec3(0.0);        // the walk's next cell face along each axis
    vec3 inv_dir = 1.0 / dir;
    vec3 t_cell = mix(u_spacing * abs(inv_dir), vec3(0.0), equal(dir, vec3(0.0)));
    float t_prev = max(t0 + (jitter + float(k_first)) * u_step, t0);   // the next piece's front
    s_front = sampleVolume(origin + t_prev * dir);
    int rounds_left = u_max_segments * (u_refine_cuts + 2);
    for (; rounds_left > 0; --rounds_left) {
        float t_next;
        float t_even = even < u_refine ? a_walk + float(even) * part : b_walk;   // (walking)
        if (walking) {
    #if REACH_WALK
            t_next = reachPieceEnd(origin, dir, inv_dir, t_prev, s_front, g_walk, part, b_walk);
    #else
            t_next = min(min(t_even, min(t_face.x, min(t_face.y, t_face.z))), b_walk);
    #endif
        } else {
            if (k > k_last || k >= u_max_segments) break;
            float a = max(t0 + (jitter + float(k)) * u_step, t0);
            if (a >= t1) break;
            t_next = min(t0 + (jitter + float(k + 1)) * u_step, t1);
            if (!have_front || t_next <= a) {
                // after a skip (or a masked cell): read the front of segment k first
                t_next = a;
            }
            t_prev = a;
        }
        float len = t_next - t_prev;
        vec3 p = origin + (0.5 * (t_prev + t_next)) * dir;
    #if MASK_NONFINITE
        if (!walking && len > 0.0 && !insideValidCell(p)) {
            have_front = false;
            ++k;
            continue;
        }
    #endif
        float s_next = sampleVolume(origin + t_next * dir);
        bool priming = !walking && !have_front;
        bool empty_piece = !walking && len <= 0.0;
        if (!walking && have_front && len > 0.0) {
            // The field may leave the straight line between the ends by the gradient
            // bound times the distance: if the values it can reach touch a bend of the
            // TF's opacity (a narrow feature), the segment is walked instead, cut at its
            // u_refine - 1 even points and wherever it crosses a cell face (where the
            // trilinear field's slope jumps: between two cuts it is one smooth cubic, so
            // the straight line errs at second order), each part read from the table of
            // the parts' length.
            float mid = 0.5 * (s_front + s_next);
            ivec3 block = clamp(ivec3(floor(p / u_spacing / u_reach_block)), ivec3(0), textureSize(t_reach, 0) - 1);
            float g_here = texelFetch(t_reach, block, 0).r;
            float reach = 0.5 * max(g_here * len, abs(s_next - s_front));
            if (touchesDetail(mid - reach, mid + reach)) {
                walking = true;
                g_walk = g_here;
                a_walk = t_prev;
                b_walk = t_next;
                part = len / float(u_refine);
                even = 1;
                vec3 index_a = (origin + a_walk * dir) / u_spacing;
                vec3 face = mix(floor(index_a) + 1.0, ceil(index_a) - 1.0, lessThan(dir, vec3(0.0)));
                t_face = mix((face * u_spacing - origin) * inv_dir, vec3(3.0e38), equal(dir, vec3(0.0)));
                continue;   // its first part is the next round's
            }
        }
        // (one call with the table chosen: llvmpipe would run both calls of a choice)
        vec4 piece = preintegratedSegmentIn(walking ? 2 * u_pi_size : 0, s_front, s_next, len,
                                            walking ? u_pi_fine_length : u_pi_length);
        piece = litSegment(piece, p, dir);
        bool segment_done = true;
        bool whole = !walking;
        if (walking) {
            if (t_even <= t_next) even += 1;
            t_face += mix(vec3(0.0), t_cell, lessThanEqual(t_face, vec3(t_next)));
            segment_done = t_next >= b_walk;
            walking = !segment_done;
        }
        s_front = s_next;
        t_prev = t_next;
        have_front = true;
        if (priming) continue;
        if (segment_done) ++k;
        if (empty_piece) continue;
    #if SKIP_EMPTY
        if (piece.a <= 0.0 && whole) {
            int k_skip = lastSegmentInEmptyBrick(p, origin, dir, t0, jitter, k - 1);
            if (k_skip > k - 1) {
                k = k_skip + 1;   // its front is read first
                have_front = false;
            }
            continue;
        }
    #endif
        compositePremultiplied(color, alpha_acc, piece);
    #if EARLY_RAY_TERMINATION
        // (at a segment's end, as without refinement)
        if (segment_done && 1.0 - alpha_acc < u_ert_transmittance) break;
    #endif
        if (alpha_acc >= 1.0) break;
    }
  #else
  #if MODE_COMPOSITE && PREINTEGRATE
    s_front = sampleVolume(origin + max(t0 + (jitter + float(k_first)) * u_step, t0) * dir);
  #endif
    for (int k = k_first; k <= k_last && k < u_max_segments; ++k) {
        PRECISE float a = max(t0 + (jitter + float(k)) * u_step, t0);
        if (a >= t1) break;
        PRECISE float b = min(t0 + (jitter + float(k + 1)) * u_step, t1);
        PRECISE float len = b - a;
        if (len <= 0.0) continue;
        PRECISE float tm = 0.5 * (a + b);
        PRECISE vec3 p = origin + tm * dir;
        if (!OWNED(p)) continue;
#if MASK_NONFINITE
        if (!insideValidCell(p)) {
  #if PREINTEGRATE
            have_front = false;
  #endif
            continue;
        }
#endif
#if MODE_COMPOSITE && PREINTEGRATE
        // the whole segment from the field at its two ends (the end is the next start)
        float s_back = sampleVolume(origin + b * dir);
    #if MASK_NONFINITE
        if (!have_front) s_front = sampleVolume(origin + a * dir);
    #else
        // After a skip the segment only reads its end, the next one's front (below):
        // llvmpipe runs an if's body for every pixel, so a fetch of the front under
        // !have_front would cost every segment a second fetch.
        bool priming = !have_front;
    #endif
        vec4 segment = litSegment(preintegratedSegment(s_front, s_back, len), p, dir);
        s_front = s_back;
        have_front = true;
  #if !MASK_NONFINITE
        if (priming) continue;
  #endif
  #if SKIP_EMPTY
        if (segment.a <= 0.0) {
            int k_skip = lastSegmentInEmptyBrick(p, origin, dir, t0, jitter, k);
            if (k_skip > k) {
      #if MASK_NONFINITE
                k = k_skip;
      #else
                k = k_skip - 1;   // segment k_skip, inside the empty brick, reads the front
      #endif
                have_front = false;
            }
            continue;
        }
  #endif
        compositePremultiplied(color, alpha_acc, segment);
  #if EARLY_RAY_TERMINATION
        if (1.0 - alpha_acc < u_ert_transmittance) break;
  #endif
        if (alpha_acc >= 1.0) break;
        continue;
#endif
        float s = sampleVolume(p);
#if MODE_COMPOSITE
  #if SABELLA
        if (s > s_peak) {
            s_peak = s;
            t_peak = tm;
        }
  #endif
        vec4 rgba = applyTF(s);
        if (rgba.a <= 0.0) {
            // Nothing to composite. Only now look at the brick: occupied regions never
            // pay for the lookup, and an empty brick is crossed in one jump.
  #if SKIP_EMPTY && !PREINTEGRATE
            k = skipEmptyBrick(p, origin, dir, t0, jitter, k);
  #endif
            continue;
        }
        compositePremultiplied(color, alpha_acc, sampleSegmentOf(rgba, s, len * u_inv_unit, p, dir));
  #if EARLY_RAY_TERMINATION
        if (1.0 - alpha_acc < u_ert_transmittance) break;
  #endif
  #if !SABELLA
        if (alpha_acc >= 1.0) break;
  #endif
#elif MODE_MIP
        s_best = max(s_best, s);
#elif MODE_MINIP
        s_best = min(s_best, s);
#elif MODE_AVERAGE
        s_sum += s * len;
        len_sum += len;
#elif MODE_ISOSURFACE
        if (!have_prev) {
            // The status at the first point inside the domain is the reference.
            float s_entry = sampleVolume(origin + a * dir);
            above_prev = s_entry >= u_iso;
            t_prev = a;
            have_prev = true;
        }
        bool above = s >= u_iso;
        if (above != above_prev) {
            t_hit = tm;  // refined after the loop: keeps the loop body small
            break;
        }
        t_prev = tm;
#endif
    }
  #endif
#endif

#if SABELLA
    if (!isinf(s_peak) && alpha_acc > 0.0) {
        float depth = (dot(origin + t_peak * dir - u_eye, u_forward) - u_depth_range.x)
                      / (u_depth_range.y - u_depth_range.x);
        f_color = sabellaColor(applyTF(s_peak).rgb, alpha_acc, depth);
    }
#elif MODE_COMPOSITE
    f_color = vec4(color, alpha_acc);
#elif BRICKED && (MODE_MIP || MODE_MINIP)
    // the state for the next brick; the last is classified once (bricks/resolve.frag)
    f_color = isinf(s_best) ? vec4(0.0) : vec4(s_best, 1.0, 0.0, 0.0);
#elif BRICKED && MODE_AVERAGE
    f_color = vec4(s_sum, len_sum, 0.0, 0.0);
#elif MODE_MIP || MODE_MINIP
    if (!isinf(s_best)) {
        vec4 rgba = applyTF(s_best);
        f_color = vec4(rgba.rgb * rgba.a, rgba.a);
    }
#elif MODE_AVERAGE
    if (len_sum > 0.0) {
        vec4 rgba = applyTF(s_sum / len_sum);
        f_color = vec4(rgba.rgb * rgba.a, rgba.a);
    }
#elif MODE_ISOSURFACE
    if (t_hit >= 0.0) {
        t_hit = refineIsoBisection(origin, dir, t_prev, t_hit, u_iso);
        vec3 p_hit = origin + t_hit * dir;
        vec3 rgb = applyTF(u_iso).rgb;
        f_color = vec4(shadeBlinnPhong(rgb, gradient(p_hit), dir), 1.0);
    }
#endif
#if GEOMETRY
    // the surface under the over operator: C + (1 - A) colour, A = 1
    if (on_surface) f_color = vec4(f_color.rgb + (1.0 - f_color.a) * surface.rgb, 1.0);
#endif
}

#include "common/pixel_store.glsl"
