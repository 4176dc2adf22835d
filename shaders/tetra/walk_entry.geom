// The entry pass's coverage is decided by the fragment (walk_entry.frag: does the pixel's
// ray meet the face's triangle?), not by rasterisation, which snaps vertices to a grid
// and misses pixel centres within that of a face seen edge-on (a grazing view of a thin
// slab lost whole chords). So each face is drawn as its triangle in window coordinates
// with every edge moved out by u_inflate pixels (twice the snapping;
// techniques.common.grow_pixels) and by the fragment's margin (ENTRY_MARGIN of the
// triangle's size, doubled, times the ratio of its corners' depths); where a corner is
// too sharp for that (the moved edges meet more than a pixel away: a face seen nearly
// edge-on), as its outline's bounding box grown by as much. Half the box's fragments, on
// average.
// A face reaching to or behind the eye's plane (perspective) is drawn as it is, clipped by GL.
// Faces no ray can enter are not drawn: the eye strictly inside the cell's plane
// (perspective) or the view leaving through it (orthographic), beyond float32 rounding;
// a zero-volume cell's planes have no side, so its faces are all drawn.
#version 330 core
#include "tetra/walk_cell.glsl"

#ifndef ORTHO
#define ORTHO 0
#endif

layout(triangles) in;
layout(triangle_strip, max_vertices = 4) out;

flat in int g_slot[];
in vec3 g_position[];
uniform vec2 u_target_size;
uniform float u_inflate;
uniform usampler2D t_flags;    // R8UI per cell: bit 1 (2): zero volume or too thin (tetra_walk.walk_flat)
uniform vec3 u_eye;            // relative to the mesh's lower corner
uniform vec3 u_forward;
#ifndef START_FACES
#define START_FACES 0          // faces of cells the start plane cuts (walk_entry.frag): all drawn
#endif
uniform float u_test_depth;    // window depth, 0 to 1, of every fragment: the marks' early test (tetra_walk.py)
flat out int v_slot;
flat out vec3 v_corner0;     // the face's corners (relative to the mesh's lower corner)
flat out vec3 v_corner1;
flat out vec3 v_corner2;

void emit(vec4 position) {
    v_slot = g_slot[0];
    v_corner0 = g_position[0];
    v_corner1 = g_position[1];
    v_corner2 = g_position[2];
    // every fragment at the test depth: the marked pixels pass (walk_entry.frag)
    gl_Position = vec4(position.xy, (2.0 * u_test_depth - 1.0) * position.w, position.w);
    EmitVertex();
}

void main() {
    int cell = g_slot[0] / 4;
    if (START_FACES == 0 && (texelFetch(t_flags, texelRow(cell), 0).r & 2u) == 0u) {
        vec4 plane = texelFetch(t_planes, texelRow(g_slot[0]), 0);
#if ORTHO
        if (dot(plane.xyz, u_forward) > 1e-6) return;
#else
        float eye_height = dot(plane.xyz, u_eye);
        if (plane.w - eye_height > 1e-6 * (abs(plane.w) + abs(eye_height))) return;
#endif
    }
    vec4 p0 = gl_in[0].gl_Position, p1 = gl_in[1].gl_Position, p2 = gl_in[2].gl_Position;
    float w_max = max(p0.w, max(p1.w, p2.w));
    if (min(p0.w, min(p1.w, p2.w)) <= 1e-6 * w_max) {
        emit(p0);
        emit(p1);
        emit(p2);
        EndPrimitive();
        return;
    }
    vec2 q[3];
    q[0] = (p0.xy / p0.w * 0.5 + 0.5) * u_target_size;
    q[1] = (p1.xy / p1.w * 0.5 + 0.5) * u_target_size;
    q[2] = (p2.xy / p2.w * 0.5 + 0.5) * u_target_size;
    vec2 ab = q[1] - q[0], ac = q[2] - q[0];
    float longest = max(length(ab), max(length(ac), length(q[2] - q[1])));
    // the margin's line beyond an edge, in window coordinates: at most ENTRY_MARGIN of the
    // triangle's height there, times the ratio of its corners' depths (perspective)
    float w_min = min(p0.w, min(p1.w, p2.w));
    float grow = u_inflate + 2.0 * ENTRY_MARGIN * longest * (w_max / w_min);
    float turn = ab.x * ac.y - ab.y * ac.x;        // > 0: counter-clockwise
    vec2 outward[3];                               // edge k (q[k] to q[k + 1]): its outer unit normal
    bool sharp = turn == 0.0;                      // (so too where an edge has no length)
    for (int k = 0; k < 3; ++k) {
        vec2 e = q[(k + 1) % 3] - q[k];
        outward[k] = (turn > 0.0 ? vec2(e.y, -e.x) : vec2(-e.y, e.x)) / max(length(e), 1e-30);
    }
    vec2 moved[3];
    for (int k = 0; k < 3; ++k) {                  // where the moved edges k - 1 and k meet
        vec2 n0 = outward[(k + 2) % 3], n1 = outward[k];
        float meet = 1.0 + dot(n0, n1);            // the corner's offset is grow * sqrt(2 / meet)
        sharp = sharp || meet * 0.5 < grow * grow; // more than a pixel out
        moved[k] = q[k] + grow * (n0 + n1) / max(meet, 1e-30);
    }
    if (!sharp) {
        for (int k = 0; k < 3; ++k) emit(vec4(moved[k] / u_target_size * 2.0 - 1.0, 0.0, 1.0));
        EndPrimitive();
        return;
    }
    vec2 lo = (min(q[0], min(q[1], q[2])) - grow) / u_target_size * 2.0 - 1.0;
    vec2 hi = (max(q[0], max(q[1], q[2])) + grow) / u_target_size * 2.0 - 1.0;
    emit(vec4(lo.x, lo.y, 0.0, 1.0));
    emit(vec4(hi.x, lo.y, 0.0, 1.0));
    emit(vec4(lo.x, hi.y, 0.0, 1.0));
    emit(vec4(hi.x, hi.y, 0.0, 1.0));
    EndPrimitive();
}
