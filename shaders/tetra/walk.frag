// The cell walk (techniques/tetra_walk.py), one full-screen pass per layer of depth
// peeling: each pixel's ray starts in the cell the entry pass found for it (or, for a
// perspective eye inside the mesh, in the eye's cell), and goes from cell to cell through
// the face adjacency. WALK_TOPO: the exit face is the topology's (tetra/walk_topo.glsl),
// the segment from where the ray came in to that face's plane. Else the planes': the
// segment is the one tetra.frag finds (the same planes and arithmetic: entry at the
// largest entering crossing, exit at the smallest leaving one) and the ray steps to the
// neighbour across the exit face (the first of tied ones: through an edge or a vertex,
// the cells around it are passed with empty segments). Each segment is cut to the clip's
// kept interval and at the first surface, integrated exactly (common/linear_segment.glsl)
// and composited front to back. A neighbour of -1 (the boundary) ends this pass's walk;
// the next entry pass looks for a re-entry beyond it.
// mip / minip / average: the running extreme, or integral and length (tetra_classify.frag).
// By the planes, zero-volume cells (flatExit) and folded cells (foldedNext) have rules of their own.
// The pixel is done when its ray reaches the end of its kept interval, when composite
// opacity reaches ERT_ALPHA, or at a guard against cycles (MAX_STALLED, u_max_steps).
#version 330 core
#include "common/precise.glsl"
#ifdef GL_ARB_shader_group_vote
#extension GL_ARB_shader_group_vote : enable    // anyInvocationARB (WALK_LIGHT)
#endif
#if defined(IN_PLACE) && IN_PLACE
#extension GL_ARB_shader_image_load_store : require
#endif

#ifndef ORTHO
#define ORTHO 0
#endif
#ifndef MODE_COMPOSITE
#define MODE_COMPOSITE 1
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
#ifndef SAMPLE_TERMS
#define SAMPLE_TERMS 0   // lights or illustration terms, each constant in a cell
#endif
#ifndef GEOMETRY
#define GEOMETRY 0       // opaque surfaces: nothing behind the pixel's first one
#endif
#ifndef SEGMENT_TABLE
#define SEGMENT_TABLE 0  // segments="table": the approximate integral of model/segment_table.py
#endif
// The rare paths, compiled in only for meshes that have them (tetra_walk.rare_paths):
// llvmpipe runs both sides of a branch whose condition differs from pixel to pixel, so
// code for zero-volume cells or folded faces costs every step when present (15-25 %
// of the frame on the NASA meshes)
#ifndef WALK_FLAT
#define WALK_FLAT 1      // flat cells among the walked ones (zero volume or too thin: walk_flat; flatExit)
#endif
#ifndef WALK_FOLDS
#define WALK_FOLDS 1     // folded faces (foldedNext)
#endif
#ifndef WALK_TOPO
#define WALK_TOPO 0      // exit faces by topology (tetra/walk_topo.glsl): thin cells need no rule of their own
#endif
#if WALK_TOPO             // (tetra_walk.rare_paths: only for meshes without folded faces)
#undef WALK_FLAT
#define WALK_FLAT 0
#undef WALK_FOLDS
#define WALK_FOLDS 0
#endif
#ifndef LOCKSTEP_LANES
#define LOCKSTEP_LANES 0 // the context's: pixels shaded in lockstep pay for branches none takes
#endif
#ifndef OPTICAL_MODEL
#define OPTICAL_MODEL 0
#endif
// Light segments first (lightSegment), the others in the outer loop: with lanes in lockstep
// every segment would otherwise pay for linearSegment's loops and branches
#define WALK_LIGHT (LOCKSTEP_LANES && MODE_COMPOSITE && !SAMPLE_TERMS && !SEGMENT_TABLE && OPTICAL_MODEL == 0)
#define WALK_OUTER (WALK_FLAT || WALK_FOLDS || WALK_LIGHT)
// In place (the fragment stage, with image load/store): the accumulation and state are
// read and written in one pair of images, so a layer shades only the pixels that have an
// entry in it; else they are read from the last layer's targets and written to the
// others, and the pixels that ended in the last layer are copied across.
#ifndef IN_PLACE
#define IN_PLACE 0
#endif
#if IN_PLACE
layout(early_fragment_tests) in;    // the marks' test, before the shader (it has side effects)
layout(rgba32f) uniform coherent image2D u_acc_image;
layout(rgba32f) uniform coherent image2D u_state_image;
#endif

#include "common/camera_ray.glsl"
#include "common/linear_segment.glsl"
#include "common/clip.glsl"
#include "tetra/walk_cell.glsl"
#if SAMPLE_TERMS
#define DEPTH_CUE_ALONG_SEGMENT 1
#include "common/shading.glsl"
#endif

uniform sampler2D t_field;        // RGBA32F, 2 per cell: (gradient, value at the origin), range (model.mesh.cell_fields)
uniform isampler2D t_neighbours;  // RGBA32I per cell: the cell across local face k (-1: boundary)
uniform usampler2D t_flags;       // R8UI per cell: SHOWN (the TF gives some of its value range
                                  // opacity), FLAT (zero volume, or too thin: tetra_walk.walk_flat)
uniform sampler2D t_acc;          // the previous pass's accumulation
uniform sampler2D t_state;        // the previous pass's state (tetra/walk_entry.frag)
uniform sampler2D t_entry_t;      // the entry pass: nearest eligible entry t (3e38: none)
uniform sampler2D t_entry_cell;   // and its cell
uniform int u_start_cell;         // >= 0: every ray starts in this cell at t = 0
#if WALK_TOPO
// an eye on an edge or a vertex: each ray starts in the first of these cells that holds
// it by the topology's signs (tetra_walk.cells_around_eye; EYE_CELLS: 64)
uniform int u_start_cells[64];
uniform int u_start_count;
uniform float u_reach;            // the mesh's diagonal: no segment is longer
#endif
// t_tets, t_points; the topology's exits (WALK_TOPO)
#include "tetra/walk_topo.glsl"
uniform int u_max_steps;
#if GEOMETRY
uniform sampler2D t_surface;      // the first surface's lit colour and t (3e38: none)
#endif

#if SEGMENT_TABLE
// segments="table" (NumPy twin: model.segment_table.table_segment): the TF's cumulative
// extinction and tau-weighted colour (row 0) and point values (row 1), ENTRIES wide
uniform sampler2D t_segment_table;
uniform float u_table_lo;         // value of entry 0
uniform float u_table_hi;         // value of the last entry
uniform float u_table_scale;      // entries per value unit
uniform int u_table_size;

vec4 tableRow(float s, int row) {
    float u = clamp((s - u_table_lo) * u_table_scale, 0.0, float(u_table_size - 1));
    int i0 = min(int(floor(u)), u_table_size - 2);
    float f = u - float(i0);
    return mix(texelFetch(t_segment_table, ivec2(i0, row), 0), texelFetch(t_segment_table, ivec2(i0 + 1, row), 0), f);
}

// row 0, continued linearly beyond the ends (the TF is constant there)
vec4 tableCumulative(float s) {
    vec4 inside = tableRow(s, 0);
    float beyond = s - clamp(s, u_table_lo, u_table_hi);
    if (beyond == 0.0) return inside;
    vec4 end = texelFetch(t_segment_table, ivec2(beyond < 0.0 ? 0 : u_table_size - 1, 1), 0);
    return inside + beyond * vec4(end.rgb * end.a, end.a);
}

// The tau-weighted mean colour over [s_front, s_back] times 1 - exp(-depth): no
// attenuation inside the segment (its error is measured by the mesh pilot).
vec4 tableSegment(float s_front, float s_back, float len) {
    float ds = s_back - s_front;
    vec3 c;
    float tau;
    if (abs(ds) * u_table_scale >= 1.0) {
        vec4 mean = (tableCumulative(s_back) - tableCumulative(s_front)) / ds;
        tau = mean.a;
        c = mean.a > 0.0 ? mean.rgb / mean.a : vec3(0.0);
    } else {                              // within an entry: the point value at the middle
        vec4 point = tableRow(0.5 * (s_front + s_back), 1);
        tau = point.a;
        c = point.rgb;
    }
    float alpha = 1.0 - exp(-max(tau, 0.0) * len * u_inv_unit);
    return vec4(c * alpha, alpha);
}
#endif

#if COMPUTE_PIXELS || IN_PLACE
vec4 frag_acc;                    // stored by main() at the end
vec4 frag_state;
#undef PIXEL_MAIN
#define PIXEL_MAIN shadePixel
#else
layout(location = 0) out vec4 frag_acc;
layout(location = 1) out vec4 frag_state;
#endif

const float ERT_ALPHA = 1.0 - 1.0 / 1048576.0;   // the rest of the ray adds at most 2^-20
const float DONE = 3.0e38;
// The guards: a walk that makes progress meets each cell at most once (u_max_steps: the
// cell count), and goes further along the ray but for the cells around an edge or a vertex
// it passes through, and layers of zero-volume cells; more steps in a row than
// MAX_STALLED without going further are a cycle (made by rounding, or by folded cells).
const int MAX_STALLED = 512;
const uint SHOWN = 1u;
const uint FLAT = 2u;
const uint FOLDS = 60u;      // 4 << k: local face k is shared with a folded cell
const int RARE_FLAT = 1;
const int RARE_FOLD = 2;
const int HULL = -2;         // t_neighbours: across a boundary face on the convex hull (tetra_walk.HULL)
// A ray leaving through the hull has nothing left to enter, but for rounding where it
// grazes the face: at least this rate outwards (the cosine to the face's normal)
const float HULL_ALONG = 1e-3;
// WALK_TOPO: a ray leaving a cell at less than this rate (the cosine to the face's normal)
// is taken as running in the face's plane (no segment in the cell; the next one takes it)
const float GRAZING = 1e-4;

// A cell with folded faces (a neighbour on the same side of their shared face, as some
// curvilinear grids have) that offers the ray no way on: the ray may go on in a folded
// neighbour, whose own planes (not this cell's) say where it is; the first such
// neighbour whose segment reaches beyond t_cur. -1: none.
int foldedNext(uint flags, ivec4 nb, int prev, vec3 origin, vec3 dir, float t_cur) {
    for (int k = 0; k < 4; ++k) {
        if ((flags & (4u << uint(k))) == 0u || nb[k] < 0 || nb[k] == prev) continue;
        mat3x4 normals;
        vec4 room_at_eye, along, room, t;
        cellPlanes(nb[k], u_eye, normals, room_at_eye);
        cellCrossings(normals, room_at_eye, origin, dir, u_eye, along, room, t);
        vec4 exits = mix(vec4(DONE), t, greaterThan(along, vec4(0.0)));
        vec4 entries = mix(vec4(0.0), t, lessThan(along, vec4(0.0)));
        float t_end = min(min(exits.x, exits.y), min(exits.z, exits.w));
        if (t_end > max(t_cur, max(max(entries.x, entries.y), max(entries.z, entries.w)))) return nb[k];
    }
    return -1;
}

// Does the ray go into cell `into` across its face shared with cell `from` (its own
// plane there, which has a side: `into` has a volume)?
bool goesInto(int into, int from, vec3 dir) {
    ivec4 nb = texelFetch(t_neighbours, texelRow(into), 0);
    int k = nb.x == from ? 0 : nb.y == from ? 1 : nb.z == from ? 2 : 3;
    return dot(texelFetch(t_planes, texelRow(4 * into + k), 0).xyz, dir) < 0.0;
}

// A zero-volume cell has no inside and its planes no side (its four points lie in one
// plane, so the neighbours it joins lie on both sides of it): the ray, crossing that plane
// at x, leaves through the face whose triangle holds x (the largest of its smallest
// barycentric coordinate; scale-free), other than the face it came in by (across which
// lies prev; entered from the boundary, prev < 0: not a boundary face), and only into a
// cell it enters there (another zero-volume cell, or one whose own plane says so: not
// back to the side it came from). -1: none.
int flatExit(int cell, vec3 x, vec3 dir, ivec4 nb, int prev) {
    ivec4 v = texelFetch(t_tets, texelRow(cell), 0);
    vec3 p[4] = vec3[4](texelFetch(t_points, texelRow(v.x), 0).xyz, texelFetch(t_points, texelRow(v.y), 0).xyz,
                        texelFetch(t_points, texelRow(v.z), 0).xyz, texelFetch(t_points, texelRow(v.w), 0).xyz);
    float best = -DONE;
    int pick = -1;
    for (int k = 0; k < 4; ++k) {
        if (prev >= 0 ? nb[k] == prev : nb[k] < 0) continue;
        bool solid = nb[k] >= 0 && (texelFetch(t_flags, texelRow(nb[k]), 0).r & FLAT) == 0u;
        if (solid && !goesInto(nb[k], cell, dir)) continue;
        vec3 a = p[(k + 1) % 4], b = p[(k + 2) % 4], c = p[(k + 3) % 4];
        vec3 m = cross(b - a, c - a);
        float mm = dot(m, m);
        if (mm <= 0.0) continue;
        float la = dot(cross(c - b, x - b), m), lb = dot(cross(a - c, x - c), m), lc = dot(cross(b - a, x - a), m);
        float score = min(la, min(lb, lc)) / mm;
        if (score > best) {
            best = score;
            pick = k;
        }
    }
    return pick;
}

// Lockstep lanes: a pending segment's integral, then what gathered behind it, under `acc`;
// true where the ray is opaque with them (the next segment waiting is then not added)
bool addPending(inout vec4 acc, vec4 pending_rgba, inout vec4 behind) {
    acc += (1.0 - acc.a) * pending_rgba;
    acc += (1.0 - acc.a) * behind;
    behind = vec4(0.0);
    return acc.a >= ERT_ALPHA;
}

void PIXEL_MAIN() {
    ivec2 px = ivec2(FRAG_COORD.xy);
#if IN_PLACE
    vec4 acc = imageLoad(u_acc_image, px);
    vec4 state = imageLoad(u_state_image, px);
#else
    vec4 acc = texelFetch(t_acc, px, 0);
    vec4 state = texelFetch(t_state, px, 0);
#endif
    frag_acc = acc;
    frag_state = vec4(DONE, -1.0, state.z, state.w);
    if (state.x >= 1.0e38) return;
    int cell;
    float t_cur;
    if (u_start_cell >= 0) {
        cell = u_start_cell;
        t_cur = 0.0;
    } else {
        t_cur = texelFetch(t_entry_t, px, 0).r;
        if (t_cur >= 1.0e38) return;               // no entry left on this ray
        cell = int(texelFetch(t_entry_cell, px, 0).r);
    }
    float entry_t = t_cur;
    int entry_cell = cell;
    vec3 origin, dir;
    pixelRay(origin, dir);
    vec2 kept = vec2(0.0, DONE);
#if N_CLIP_PLANES > 0 || CROP_BOX
    kept = clipRange(origin, dir, kept);
#endif
#if GEOMETRY
    kept.y = min(kept.y, texelFetch(t_surface, px, 0).a);
#endif
    if (kept.y <= kept.x || t_cur >= kept.y) return;
#if ORTHO
    PRECISE vec3 offset = origin - u_eye;
#else
    vec3 offset = vec3(0.0);
#endif
    // The walk steps through cells in an inner loop until it has a segment to add (or the
    // ray ends or leaves), and adds it in the middle loop: neighbouring pixels then add
    // their segments together (the integral is the costly part, and pixels that run in
    // lockstep would otherwise each wait through the others' integrals at every step).
    // The rare steps (into a zero-volume cell, out by a folded face) and, with lanes in
    // lockstep, the segments that are not light are taken in the outer loop, which a group
    // of pixels enters again only when one of them needs it: llvmpipe runs the code of an
    // if for every pixel, taken or not, so in the inner loops that code would cost every
    // step (the rare steps' alone a quarter of the blunt fin's frame).
#if WALK_TOPO
    vec3 across_x, across_y;
    rayFrame(origin, dir, across_x, across_y);
    ivec3 face_ids;         // the face the ray came into `cell` by (walk_topo.glsl)
    vec4 face_s0, face_s1, face_s2;   // its corners across the ray (acrossRay)
    bool start_held = u_start_count == 0;
    for (int i = 0; i < u_start_count; ++i) {
        if (cellHoldsRay(texelFetch(t_tets, texelRow(u_start_cells[i]), 0), origin, across_x, across_y)) {
            cell = u_start_cells[i];
            start_held = true;
            break;
        }
    }
    if (!start_held) {            // an eye on the boundary, the ray going out: left at the eye
        frag_state = vec4(0.0, -1.0, state.z, state.w);
        return;
    }
    {
        mat3x4 normals;
        vec4 room_at_eye, along, room, t;
        cellPlanes(cell, u_eye, normals, room_at_eye);
        cellCrossings(normals, room_at_eye, origin, dir, u_eye, along, room, t);
        startFace(cell, texelFetch(t_neighbours, texelRow(cell), 0), u_start_cell < 0 && t_cur > 0.0,
                  origin, across_x, across_y, along, face_ids, face_s0, face_s1, face_s2);
    }
#endif
    bool done = false;      // the ray has ended (kept interval, opacity); else it left the mesh
    bool left = false;
    int steps = 0;
    int prev = -1;          // the cell the walk came from (-1: entered from the boundary or the eye)
    int stalled = 0;        // steps in a row that took the ray no further
#if WALK_TOPO
    // A cell with a volume walked in this layer. Where none is (only flat cells, as along a
    // hull's edge of collinear points, whose faces are needles: their rounded positions
    // across the ray may fold the hull's surface there), the ray can leave by a boundary
    // face next to the one it came in by with no length between: such a walk is taken as
    // no progress, so that the next layer tries the other entries at that t (depth peeling
    // in the order of (t, cell)) rather than only those beyond.
    bool solid = false;
#endif
#if WALK_OUTER
    int rare = 0;           // RARE_FLAT: at zero-volume `cell`; RARE_FOLD: `cell` left by a folded face
    // With lanes in lockstep, the segments that are not light wait for the outer loop: the
    // first in `pending`, while the light ones behind it gather in `behind` (front to back;
    // compositing is associative, so they join it there), a second in `held`, which sends
    // the group there. There every pending segment of the group is integrated (the group
    // is there for one pixel's: the others' take no longer), and a pixel whose pending one
    // is integrated adds it where its next comes, in the stepping loop. Each pixel adds
    // its segments in the same order and at the same points whoever's integral took the
    // group to the outer loop, so its last bits do not depend on its neighbours; where
    // adding a pending one turns the ray opaque, the next one waiting is dropped, in
    // either place (tests/test_walk_lockstep.py: tiles and the compute stage).
    bool pending = false;
    vec3 pending_segment;   // (s_front, s_back, length)
    bool integrated = false;
    vec4 pending_rgba;      // its integral, once integrated
    vec4 behind = vec4(0.0);
    bool held = false;
    vec3 held_segment;
    while (true) {          // the outer loop (its body is not indented)
#endif
    while (!done && !left && steps < u_max_steps && stalled < MAX_STALLED) {
        bool found = false;
        int seg_cell = -1;
        float a = 0.0, b = 0.0;
        while (steps < u_max_steps && stalled < MAX_STALLED) {
            ++steps;
            uint flags = texelFetch(t_flags, texelRow(cell), 0).r;
#if WALK_TOPO
            solid = solid || (flags & FLAT) == 0u;
#endif
            ivec4 nb = texelFetch(t_neighbours, texelRow(cell), 0);
            int next;
#if WALK_FLAT
            if ((flags & FLAT) != 0u) {    // no segment: the outer loop passes it
                rare = RARE_FLAT;
                break;
            }
#endif
#if WALK_TOPO
            {
                // The topology says the ray is in this cell from t_cur (where it came in)
                // and leaves by `face`: the segment ends where it crosses that face's plane,
                // from t_cur (segments tile the ray whatever the rounding). None where the
                // crossing is not ahead (a sliver's crossings out of order, a zero-volume
                // cell) or the ray nearly in the face's plane (its crossing
                // ill-conditioned): the next cell's segment then starts at t_cur, and its
                // field is this one's on the face between them. Out of the walked cells
                // no next cell takes that stretch: this one does, as far as the mesh reaches.
                int face = topoExit(cell, origin, across_x, across_y, face_ids, face_s0, face_s1, face_s2);
                float along_face;
                float t_face = faceCrossing(4 * cell + face, u_eye, origin, dir, along_face);
                next = nb[face];
                bool ends_here = along_face > GRAZING || (next < 0 && along_face > 0.0 && t_face - t_cur <= u_reach);
                float t_end = t_face > t_cur && ends_here ? t_face : t_cur;
                a = max(t_cur, kept.x);
                b = min(t_end, kept.y);
                if (b > a && (MODE_COMPOSITE == 0 || (flags & SHOWN) != 0u)) {
                    found = true;
                    seg_cell = cell;
                }
                stalled = t_end > t_cur ? 0 : stalled + 1;
                t_cur = max(t_cur, t_end);
                if (next == HULL && along_face > HULL_ALONG && solid) done = true;   // no re-entry: no next layer
                if (t_cur >= kept.y) {
                    done = true;
                    break;
                }
            }
#else
            {
                mat3x4 normals;
                vec4 room_at_eye, along, room, t;
                cellPlanes(cell, u_eye, normals, room_at_eye);
                cellCrossings(normals, room_at_eye, origin, dir, u_eye, along, room, t);
                // never back across the face the walk came in by: with the cell's own planes
                // it is an entering one, except between folded cells (both on one side of
                // their shared face, as some curvilinear grids have), which would pass the
                // ray back and forth there
                bvec4 back = prev >= 0 ? equal(nb, ivec4(prev)) : bvec4(false);
                vec4 exits = mix(vec4(DONE), t, greaterThan(along, vec4(0.0)));
                // the segment is tetra's (all four planes); the step leaves by another face
                float t_end = min(min(exits.x, exits.y), min(exits.z, exits.w));
                exits = mix(exits, vec4(DONE), back);
                vec4 entries = mix(vec4(0.0), t, lessThan(along, vec4(0.0)));
                float t_out = min(min(exits.x, exits.y), min(exits.z, exits.w));
                int face = t_out == exits.x ? 0 : t_out == exits.y ? 1 : t_out == exits.z ? 2 : 3;
                float t_in = max(t_cur, max(max(entries.x, entries.y), max(entries.z, entries.w)));
                // a plane parallel to the ray with the ray outside it: the ray runs in the
                // plane of a face this cell shares, and rounding put it on this side of the
                // tie. The cell across that face holds it (the shared plane is stored once
                // and negated, so there it is inside): the walk crosses to it at the same t.
                // On the boundary (no cell across) the ray misses this cell and goes on.
                vec4 parallel_room = mix(vec4(1.0), room, equal(along, vec4(0.0)));
                float worst = min(min(parallel_room.x, parallel_room.y), min(parallel_room.z, parallel_room.w));
                int side = worst == parallel_room.x ? 0 : worst == parallel_room.y ? 1 : worst == parallel_room.z ? 2 : 3;
                bool outside = worst < 0.0;
                if (outside && nb[side] >= 0) {
                    next = nb[side];
                    ++stalled;
                } else {
                    a = max(t_in, kept.x);
                    b = min(t_end, kept.y);
                    // composite: cells the TF makes fully transparent add nothing (once per TF)
                    if (!outside && b > a && (MODE_COMPOSITE == 0 || (flags & SHOWN) != 0u)) {
                        found = true;
                        seg_cell = cell;
                    }
                    stalled = t_end > t_cur ? 0 : stalled + 1;
                    t_cur = max(t_cur, t_end);
                    next = t_out < 1.0e38 ? nb[face] : -1;     // none: no leaving plane but the way back
                    if (next == HULL && along[face] > HULL_ALONG) done = true;   // no re-entry: no next layer
#if WALK_FOLDS
                    if (next < 0 && (flags & FOLDS) != 0u) rare = RARE_FOLD;   // the outer loop finds the way on
#endif
                }
                if (t_cur >= kept.y) {
                    done = true;
                    break;
                }
            }
#endif
#if WALK_FOLDS
            if (rare != 0) break;
#endif
            if (next < 0) {                        // left the mesh: a re-entry is the next layer's
                left = true;
                break;
            }
            prev = cell;
            cell = next;
            if (found) break;
        }
        if (!found) break;
        vec4 field = texelFetch(t_field, texelRow(2 * seg_cell), 0);
        vec2 range = texelFetch(t_field, texelRow(2 * seg_cell + 1), 0).xy;
        float at_eye = field.w + dot(field.xyz, u_eye);
        float rate = dot(field.xyz, dir);
        float s_at_start = at_eye + dot(field.xyz, offset);
        float s_front = clamp(s_at_start + a * rate, range.x, range.y);
        float s_back = clamp(s_at_start + b * rate, range.x, range.y);
#if MODE_MIP
        acc = vec4(max(acc.r, max(s_front, s_back)), 0.0, 0.0, 1.0);
#elif MODE_MINIP
        acc = vec4(max(acc.r, -min(s_front, s_back)), 0.0, 0.0, 1.0);
#elif MODE_AVERAGE
        float len = b - a;
        acc = vec4(acc.r + 0.5 * (s_front + s_back) * len, acc.g + len, 0.0, 1.0);
#else
  #if SAMPLE_TERMS
        float factor, scale;
        vec3 added;
        termsFor(field.xyz, origin, dir, factor, added, scale);
        float q_front = 1.0, q_back = 1.0;
    #if DEPTH_CUE
        q_front = depthCue(origin + a * dir);
        q_back = depthCue(origin + b * dir);
    #endif
        float cued_alpha;
        vec4 seg = linearSegmentCued(s_front, s_back, (b - a) * scale, q_front, q_back, cued_alpha);
        seg.rgb = seg.rgb * factor + added * cued_alpha;
  #else
    #if SEGMENT_TABLE
        vec4 seg = tableSegment(s_front, s_back, b - a);
    #elif WALK_LIGHT
        bool light;
        vec4 seg = lightSegment(s_front, s_back, b - a, light);
        if (!light) {
            if (pending && !integrated) {
                held = true;
                held_segment = vec3(s_front, s_back, b - a);
            } else {
                // the last one, integrated, added now; opaque with it: this one is not added,
                // as where the outer loop adds the last
                bool opaque = pending && addPending(acc, pending_rgba, behind);
                done = done || opaque;
                pending = !opaque;
                integrated = false;
                pending_segment = vec3(s_front, s_back, b - a);
            }
            seg = vec4(0.0);
        }
    #else
        vec4 seg = linearSegment(s_front, s_back, b - a);
    #endif
  #endif
  #if OPTICAL_MODEL == 2
        seg.a = 0.0;          // emission only: colours add, nothing absorbs
  #endif
  #if WALK_LIGHT
        if (pending) {                           // behind the pending segment
            behind += (1.0 - behind.a) * seg;
        } else {
            acc += (1.0 - acc.a) * seg;
        }
        if (acc.a + (1.0 - acc.a) * behind.a >= ERT_ALPHA) done = true;   // the pending one adds more
  #else
        acc += (1.0 - acc.a) * seg;              // front to back: the segment under what is in front
        if (acc.a >= ERT_ALPHA) done = true;
  #endif
#endif
#if WALK_FOLDS
        if (rare != 0) break;
#endif
#if WALK_LIGHT
  #ifdef GL_ARB_shader_group_vote
        if (anyInvocationARB(held)) break;      // the whole group to the outer loop
  #else
        if (held) break;
  #endif
#endif
    }
#if WALK_OUTER
#if WALK_FLAT || WALK_FOLDS
    if (rare != 0 && !done) {
        int next = -1;
        ivec4 nb = texelFetch(t_neighbours, texelRow(cell), 0);
  #if WALK_FLAT
        if (rare == RARE_FLAT) {                 // out through the face holding the crossing
            int face = flatExit(cell, origin + t_cur * dir, dir, nb, prev);
            next = face < 0 ? -1 : nb[face];
            ++stalled;
        }
  #endif
  #if WALK_FOLDS
        if (rare == RARE_FOLD) next = foldedNext(texelFetch(t_flags, texelRow(cell), 0).r, nb, prev, origin, dir, t_cur);
  #endif
        if (next < 0) {
            left = true;
        } else {
            prev = cell;
            cell = next;
        }
    }
    rare = 0;
#endif
#if WALK_LIGHT
    // every pending segment not yet integrated; added, with what gathered behind it, where
    // a second waits or the ray ends (a ray that ends holding a second: in a second round)
    bool ending = done || left || steps >= u_max_steps || stalled >= MAX_STALLED;
    bool first = true;
    while (pending && ((first && (!integrated || held)) || ending)) {
        first = false;
        if (!integrated) {
            pending_rgba = linearSegment(pending_segment.x, pending_segment.y, pending_segment.z);
            integrated = true;
        }
        if (held || ending) {
            bool opaque = addPending(acc, pending_rgba, behind);
            done = done || opaque;
            pending = held && !opaque;   // opaque: a held one is not added (as in the stepping loop)
            integrated = false;
            pending_segment = held_segment;
            held = false;
        }
    }
#endif
    if (done || left || steps >= u_max_steps || stalled >= MAX_STALLED) break;
    }
#endif
    frag_acc = acc;
    float walked = state.z + float(steps);       // cells visited so far (diagnostics)
    if (done) {
        frag_state = vec4(DONE, -1.0, walked, state.w);
    } else if (!left) {                          // the guard: counted, the ray ended
        frag_state = vec4(DONE, -1.0, walked, state.w + 1.0);
    } else {
        // progress: beyond the entry and beyond the last stop, so that the stops only go
        // further. An entry taken a rounding before the last stop (walk_entry.frag's
        // touching: state.y -1) that got no further keeps that stop, with no second such
        // try (-2); other walks of no progress leave their entry (t, cell) to go on from.
        bool progress = t_cur > max(entry_t, state.x);
#if WALK_TOPO
        progress = progress && solid;
#endif
        bool touched = state.y == -1.0 && entry_t < state.x;
        frag_state = progress ? vec4(t_cur, -1.0, walked, state.w)
                   : touched ? vec4(state.x, -2.0, walked, state.w) : vec4(entry_t, float(entry_cell), walked, state.w);
    }
}

#if IN_PLACE
void main() {
    shadePixel();
    ivec2 px = ivec2(gl_FragCoord.xy);
    imageStore(u_acc_image, px, frag_acc);
    imageStore(u_state_image, px, frag_state);
}
#elif COMPUTE_PIXELS
// the compute stage (common/pixel_stage.glsl): one invocation per pixel, both outputs stored
layout(local_size_x = 8, local_size_y = 8) in;
layout(rgba32f, binding = 0) uniform writeonly image2D u_acc_out;
layout(rgba32f, binding = 1) uniform writeonly image2D u_state_out;
uniform ivec2 u_target_size;

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(px, u_target_size))) return;
    PIXEL_MAIN();
    imageStore(u_acc_out, px, frag_acc);
    imageStore(u_state_out, px, frag_state);
}
#endif
