// The entry pass's coverage is decided by the fragment (walk_entry.frag: does the pixel's
// ray meet the face's triangle?), not by rasterisation, which snaps vertices to a grid
// and misses pixel centres within that of a face seen edge-on (a grazing view of a thin
// slab lost whole chords). So each face is drawn as its outline's bounding box in window
// coordinates grown by u_inflate pixels (twice the snapping; techniques.common.grow_pixels).
// A face reaching to or behind the eye's plane (perspective) is drawn as it is, clipped by GL.
// Faces no ray can enter are not drawn: the eye strictly inside the cell's plane
// (perspective) or the view leaving through it (orthographic), beyond float32 rounding;
// a zero-volume cell's planes have no side, so its faces are all drawn.
#version 330 core
#include "common/texel_rows.glsl"

#ifndef ORTHO
#define ORTHO 0
#endif

layout(triangles) in;
layout(triangle_strip, max_vertices = 4) out;

flat in int g_slot[];
in vec3 g_position[];
uniform vec2 u_target_size;
uniform float u_inflate;
uniform sampler2D t_planes;    // RGBA32F, 4 per cell: outward unit normal, offset
uniform usampler2D t_flags;    // R8UI per cell: bit 1 (2): zero volume
uniform vec3 u_eye;            // relative to the mesh's lower corner
uniform vec3 u_forward;
uniform bool u_start_faces;    // faces of cells the start plane cuts (walk_entry.frag): all drawn
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
    if (!u_start_faces && (texelFetch(t_flags, texelRow(cell), 0).r & 2u) == 0u) {
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
    vec2 q0 = (p0.xy / p0.w * 0.5 + 0.5) * u_target_size;
    vec2 q1 = (p1.xy / p1.w * 0.5 + 0.5) * u_target_size;
    vec2 q2 = (p2.xy / p2.w * 0.5 + 0.5) * u_target_size;
    vec2 lo = (min(q0, min(q1, q2)) - u_inflate) / u_target_size * 2.0 - 1.0;
    vec2 hi = (max(q0, max(q1, q2)) + u_inflate) / u_target_size * 2.0 - 1.0;
    emit(vec4(lo.x, lo.y, 0.0, 1.0));
    emit(vec4(hi.x, lo.y, 0.0, 1.0));
    emit(vec4(lo.x, hi.y, 0.0, 1.0));
    emit(vec4(hi.x, hi.y, 0.0, 1.0));
    EndPrimitive();
}
