// View-aligned slice polygons made in the vertex shader (after Rezk-Salama and Kolb,
// 2005): every slice is one instance of 12 vertices, the fan triangles (0,1,2), (0,2,3),
// (0,3,4), (0,4,5) over six polygon slots. Draw all slices at once with
//     vao.render(TRIANGLES, vertices=12, instances=count)
// (no index buffer, first vertex 0). Instance k is the plane at depth
//     dot(u_normal, x - u_eye) = u_far_depth - k * u_step,   k = 0 the farthest.
//
// The nearest and the farthest box corners are joined by three disjoint paths of three
// edges (A, B, C); a plane between them meets each path once, and may meet the "cross"
// edge between two neighbouring paths. Slots: 0 = path A, 1 = cross A-B, 2 = path B,
// 3 = cross B-C, 4 = path C, 5 = cross C-A; a missed cross edge repeats the path point
// before it, giving a zero-length polygon edge. The slots run counter-clockwise as seen
// from the eye. A plane outside the box puts every slot on the nearest corner: a
// zero-area polygon that draws nothing.
//
// The NumPy twin is dvr_gl.techniques.proxy.path_slots; the edge table comes from
// dvr_gl.techniques.proxy.vertex_path_tables, once per frame.
#version 330 core

uniform vec3 u_corners[8];     // box corners, box-relative world units; corner i takes the
                               // upper bound on axis a where bit a of i is set
uniform vec3 u_normal;         // unit view direction (towards the far side)
uniform vec3 u_eye;            // eye, box-relative
uniform float u_far_depth;     // depth of slice 0
uniform float u_step;          // distance between slices
uniform ivec2 u_edges[12];     // (corner, corner) pairs: rows 0-2 path A, 3-5 path B,
                               // 6-8 path C, each from the nearest corner to the farthest;
                               // 9, 10, 11 the cross edges A-B, B-C, C-A
uniform mat4 u_view_proj;
uniform int u_slice_base;      // slice of instance 0 (0; bricks draw a run of slices)

flat out int v_slice;          // the slice index, gl_InstanceID
out vec3 v_point;              // the vertex, box-relative world units (also captured by
                               // the tests with transform feedback)

const int FAN[12] = int[12](0, 1, 2, 0, 2, 3, 0, 3, 4, 0, 4, 5);

float cornerDepth(int i) {
    return dot(u_normal, u_corners[i] - u_eye);
}

// Where the plane at `depth` meets edge `e`; false for an edge parallel to the planes or
// one the plane misses. Both ends count as part of the edge.
bool edgeHit(int e, float depth, out vec3 point) {
    ivec2 ends = u_edges[e];
    float da = cornerDepth(ends.x);
    float db = cornerDepth(ends.y);
    point = u_corners[ends.x];
    if (da == db || depth < min(da, db) || depth > max(da, db)) {
        return false;
    }
    float t = clamp((depth - da) / (db - da), 0.0, 1.0);
    point = u_corners[ends.x] * (1.0 - t) + u_corners[ends.y] * t;
    return true;
}

void main() {
    int slot = FAN[gl_VertexID % 12];
    int path = slot / 2;
    float depth = u_far_depth - float(gl_InstanceID + u_slice_base) * u_step;

    vec3 point = u_corners[u_edges[0].x];
    bool inside = depth >= cornerDepth(u_edges[0].x) && depth <= cornerDepth(u_edges[2].y);
    if (inside) {
        // the path's depths run from the nearest corner's to the farthest's, so one of
        // its edges contains `depth`: the first one found wins
        vec3 hit;
        bool found = false;
        for (int i = 0; i < 3; ++i) {
            if (!found && edgeHit(3 * path + i, depth, hit)) {
                point = hit;
                found = true;
            }
        }
        if (slot % 2 == 1 && edgeHit(9 + path, depth, hit)) {
            point = hit;
        }
    }
    v_slice = gl_InstanceID;
    v_point = point;
    gl_Position = u_view_proj * vec4(point, 1.0);
}
