// The cell walk's entry pass, per fragment of a boundary face: the pixel's ray crosses
// the face's plane (the cell's own plane, tetra's arithmetic: tetra/walk_cell.glsl)
// going into the cell, at t. Of the entries beyond where the pixel's last walk stopped,
// the target keeps the nearest (MIN blending of t, exact in float32), and a second draw of
// the same faces keeps, among those at exactly that t, the smallest cell (MIN blending of
// the cell number). "Beyond" is in the order of (t, cell): t greater than the last stop,
// or equal to it with a larger cell than the last entry when that walk made no progress;
// each pass thus takes a strictly later entry, and depth peeling ends.
#version 330 core
#extension GL_ARB_shader_image_load_store : enable
#include "common/precise.glsl"

#ifndef ORTHO
#define ORTHO 0
#endif

#include "common/camera_ray.glsl"
#include "tetra/walk_cell.glsl"
#ifndef WALK_TOPO
#define WALK_TOPO 0            // the walk's exits by topology: its entries too (walk_topo.glsl)
#endif
#if WALK_TOPO
#include "tetra/walk_topo.glsl"
#endif

flat in int v_slot;
flat in vec3 v_corner0;        // the face's corners (walk_entry.geom)
flat in vec3 v_corner1;
flat in vec3 v_corner2;
uniform sampler2D t_state;     // per pixel: (t of the last stop (>= 1e38: done), the cell entered last
                               // when that walk made no progress (else -1; -2: walk.frag), 0, guard hits)
uniform sampler2D t_nearest;   // the first draw's result: the nearest eligible entry t
uniform bool u_pick_cell;      // false: write t; true: write the cell, where t is the nearest
uniform float u_tie_window;    // the layer after DEPTH_PICK's: how close its depth test ties t
uniform float u_touch_window;  // how far before a stop another part's entry is taken (rounding)
uniform usampler2D t_flags;    // R8UI per cell: bit 1 (2): zero volume or too thin (tetra/walk.frag)
#ifndef START_FACES
#define START_FACES 0          // the faces of cells the orthographic start plane cuts: an
#endif                         // entry at t = 0 where the pixel's ray starts inside the cell
uniform float u_start_margin;  // how far outside a cell a start still counts (float32 rounding)

out vec4 frag_value;
// DEPTH_PICK (the first layer, where no pixel is marked yet): one draw finds both the
// nearest entry's t and its cell. The depth test keeps the fragment of least t (window
// depth t * u_depth_scale, a power of two below 1 / the farthest t) and, among equal
// depths, the first drawn: the faces are in the order of their cells, so the smallest.
// The depth buffer's 24 bits may tie entries less than 2^-24 of the scale apart, whose
// chord between them is then as short (the float32 image does not see it).
#ifndef DEPTH_PICK
#define DEPTH_PICK 0
#endif
#if DEPTH_PICK
layout(location = 1) out vec4 frag_cell;
uniform float u_depth_scale;
#else                          // the re-entry layers' hull faces (not in the first layer's pick)
uniform isampler2D t_neighbours; // per cell: the cell across each face (-2: HULL, a face on the convex hull)
uniform float u_hull_window;   // re-entry layers: how near a stop of no progress a hull face is tried (else -1)
const int HULL = -2;           // t_neighbours across a face on the convex hull (tetra_walk.HULL)
#endif
// The depth test before the shader, though it discards (it writes no depth): after the
// first layer only the pixels marked (techniques/tetra_walk.py) are shaded. Without the
// extension the same test comes after the shader: the same image, more fragments shaded.
// No occlusion query counts this pass's fragments (early tests would count the discarded
// ones too): the marking pass after it counts the pixels with an entry.
#if !DEPTH_PICK && defined(GL_ARB_shader_image_load_store)
layout(early_fragment_tests) in;
#endif

void main() {
    vec4 state = texelFetch(t_state, ivec2(gl_FragCoord.xy), 0);
    if (state.x >= 1.0e38) discard;            // this pixel's ray has ended
    vec3 origin, dir;
    pixelRay(origin, dir);
    int cell = v_slot / 4;
    mat3x4 normals;
    vec4 room_at_eye, along, room, t;
#if START_FACES
    cellPlanes(cell, u_eye, normals, room_at_eye);
    cellCrossings(normals, room_at_eye, origin, dir, u_eye, along, room, t);
    if (any(lessThan(room, vec4(-u_start_margin)))) discard;
#if WALK_TOPO
    // and the walk's signs say the cell holds the ray (a start in a face shared by two
    // cells: the one the ties are broken towards)
    vec3 start_x, start_y;
    rayFrame(origin, dir, start_x, start_y);
    if (!cellHoldsRay(texelFetch(t_tets, texelRow(cell), 0), origin, start_x, start_y)) discard;
#endif
    frag_value = vec4(u_pick_cell ? float(cell) : 0.0, 0.0, 0.0, 1.0);
    if (u_pick_cell && texelFetch(t_nearest, ivec2(gl_FragCoord.xy), 0).r != 0.0) discard;
    return;
#endif
    // the face's own plane is all it needs (in every component: take the first), by the
    // walk's arithmetic for its exits
#if WALK_TOPO
    float face_along;
    float t_entry = faceCrossing(v_slot, u_eye, origin, dir, face_along);
#else
    facePlane(v_slot, u_eye, normals, room_at_eye);
    cellCrossings(normals, room_at_eye, origin, dir, u_eye, along, room, t);
    float face_along = along.x;
    float t_entry = t.x;
#endif
    // the ray goes in here where it crosses the plane inwards; a zero-volume cell's planes
    // have no side, so crossing one of its boundary faces at all is an entry
    bool zero_volume = (texelFetch(t_flags, texelRow(cell), 0).r & 2u) != 0u;
    if (!(zero_volume ? face_along != 0.0 : face_along < 0.0)) discard;
    // the crossing inside the face's triangle (closed, with a margin of float32 rounding:
    // the faces that share an edge overlap by it rather than leave a gap between them)
    vec3 x = origin + t_entry * dir;
    vec3 ab = v_corner1 - v_corner0, bc = v_corner2 - v_corner1, ca = v_corner0 - v_corner2;
    vec3 m = cross(ab, -ca);
    float mm = dot(m, m);
    float margin = ENTRY_MARGIN * mm;
    float inside = min(min(dot(cross(ab, x - v_corner0), m), dot(cross(bc, x - v_corner1), m)), dot(cross(ca, x - v_corner2), m));
#if WALK_TOPO
    // The float32 rounding of the crossing x (of its reach, and of t over the rate the ray
    // crosses the plane at) moves `inside` by up to |edge| |x's error| |m|: on a needle's
    // face (|m| tiny against its edges, such as a flat cell along an edge of the hull) far
    // more than the margin, so that the test alone could drop the face the ray enters by.
    // Within that too the walk's signs decide.
    float longest = sqrt(max(dot(ab, ab), max(dot(bc, bc), dot(ca, ca))));
    float x_error = 16.0 * 1.2e-7 * (length(origin) + abs(t_entry)) * (1.0 + 1.0 / abs(face_along));
    margin += x_error * longest * sqrt(mm);
#endif
    if (inside < -margin) discard;
#if WALK_TOPO
    // within the margin of an edge, the walk's own signs decide: faces that share an edge
    // then neither overlap nor leave a gap, and the walk's first cell is entered by a face
    // it agrees holds the ray (a sliver's faces on the boundary, for one)
    if (inside <= margin) {
        vec3 across_x, across_y;
        rayFrame(origin, dir, across_x, across_y);
        int k = v_slot - 4 * cell;
        ivec4 v = texelFetch(t_tets, texelRow(cell), 0);
        if (!faceHolds(ivec3(v[(k + 1) & 3], v[(k + 2) & 3], v[(k + 3) & 3]), origin, across_x, across_y)) discard;
    }
#endif
    // After the first layer's one draw (DEPTH_PICK), whose depth test ties entries closer
    // than its resolution (u_tie_window; 0 in the other layers) and takes the smallest
    // cell of them, not the least t: after a walk of no progress from there (state.y: its
    // cell), the entries it was tied with, of larger cells, are still to be tried.
    bool tied = state.y >= 0.0 && float(cell) > state.y && abs(t_entry - state.x) <= u_tie_window;
    // A part that touches the one the last walk left (state.y -1: it made progress) by a
    // face of its own, not shared (a crack, or a flat cell taken out between them), is
    // entered by another plane than the one left, which rounding may put a few ulps
    // before the stop: its faces the ray enters are taken that close before it too, once
    // a stop (a try that gets no further leaves state.y -2: walk.frag).
    bool touching = state.y == -1.0 && state.x > 0.0 && face_along < 0.0 && t_entry >= state.x - u_touch_window;
    if (!(t_entry > state.x || (t_entry == state.x && float(cell) > state.y) || tied || touching)) discard;
    // A ray that left the hull cannot cross it again; but by the topology a walk through
    // flat cells alone (no progress: state.y its entry cell) may have come out where it
    // went in, at a fold of the hull's needle faces: the hull faces there
    // (tetra_walk.reentry_faces) are tried again, at that t only.
#if !DEPTH_PICK
    if (u_hull_window >= 0.0 && texelFetch(t_neighbours, texelRow(cell), 0)[v_slot - 4 * cell] == HULL &&
        !(WALK_TOPO == 1 && state.y >= 0.0 && abs(t_entry - state.x) <= u_hull_window)) discard;
#endif
#if DEPTH_PICK
    frag_value = vec4(t_entry, 0.0, 0.0, 1.0);
    frag_cell = vec4(float(cell), 0.0, 0.0, 1.0);
    gl_FragDepth = t_entry * u_depth_scale;
    return;
#endif
    if (u_pick_cell) {
        if (t_entry != texelFetch(t_nearest, ivec2(gl_FragCoord.xy), 0).r) discard;
        frag_value = vec4(float(cell), 0.0, 0.0, 1.0);
    } else {
        frag_value = vec4(t_entry, 0.0, 0.0, 1.0);
    }
}
