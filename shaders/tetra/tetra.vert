// Projected tetrahedra: every visible cell's four faces, in the plan's back-to-front
// order: vertex 4k + i is corner i of the k-th cell drawn, and a fixed index buffer makes
// each cell's four triangles from its four vertices (each shaded once); front faces are
// culled, and the back faces cover the cell's outline. The fragment shader finds the
// cell's segment on the pixel's ray exactly, so coverage is decided there, not by
// rasterisation:
//  - the outline is grown by twice the rasteriser's vertex snapping (2^-GL_SUBPIXEL_BITS
//    pixel; each corner of the outline moved out along its two edges' normals, in
//    outline.frag), so that a pixel whose ray crosses the cell is covered even where the
//    ray passes within rounding of an edge or the cell is a sliver seen edge-on;
//  - every fragment of a cell has the one depth (k + 1) / 2^22 of its draw slot, and the
//    depth test (GREATER) lets only the first fragment of a cell through at a pixel, so
//    a cell counts once where its faces overlap after rounding (a face seen edge-on
//    turning over). Positions are given with w = 1 (outline.frag divides), so that the
//    depth is exactly constant over the cell.
// A cell that reaches behind the eye's plane has no finite outline; such cells (only
// near the eye) are drawn in their own draw calls (u_exact_faces) with their faces as
// they are, the near plane clipped by GL.
#version 330 core
#include "common/precise.glsl"

#include "common/texel_rows.glsl"

uniform isampler2D t_order;   // R32I: draw slot -> cell
uniform isampler2D t_tets;    // RGBA32I: cell -> its four points (positively oriented)
uniform sampler2D t_points;   // RGBA32F: point -> position relative to the mesh's lower corner
uniform sampler2D t_planes;   // RGBA32F, 4 per cell: outward unit normal, offset (n.x = d)
uniform sampler2D t_field;    // RGBA32F, 2 per cell: (gradient, value at the origin),
                              // (smallest, largest vertex value) (model.mesh.cell_fields)
uniform sampler2D t_outline01;  // RGBA32F, 1 per draw slot: the grown outline's corners
uniform sampler2D t_outline23;  // 0, 1 and 2, 3 in window coordinates (outline.frag)
uniform mat4 u_view_proj;
uniform vec2 u_target_size;   // pixels of the target drawn into (a tile's, with tiles)
uniform int u_first_slot;     // the first draw slot of this draw call (depths start there)
uniform bool u_exact_faces;   // the cells of this call reach behind the eye's plane

uniform vec3 u_eye;           // the eye, relative to the mesh's lower corner (common/camera_ray.glsl)

// The cell, fetched once per vertex rather than per fragment: its outward plane normals
// (column k holds component k of the four normals, so normals * dir gives the four dot
// products), the planes' offsets from the eye (d - n . eye; orthographic rays start off
// the eye and subtract their own offset), the field's gradient and its value at the eye.
flat out mat3x4 v_normals;
flat out vec4 v_room;
flat out vec4 v_field;
flat out vec2 v_range;        // the cell's smallest and largest vertex value

const float DEPTH_STEP = 1.0 / 4194304.0;   // 2^-22: four 24-bit depth levels apart

void main() {
    int slot = gl_VertexID / 4;
    int me = gl_VertexID % 4;   // the cell's corner this vertex is
    int cell = texelFetch(t_order, texelRow(slot), 0).r;
    vec4 p0 = texelFetch(t_planes, texelRow(4 * cell), 0);
    vec4 p1 = texelFetch(t_planes, texelRow(4 * cell + 1), 0);
    vec4 p2 = texelFetch(t_planes, texelRow(4 * cell + 2), 0);
    vec4 p3 = texelFetch(t_planes, texelRow(4 * cell + 3), 0);
    v_normals = mat3x4(vec4(p0.x, p1.x, p2.x, p3.x), vec4(p0.y, p1.y, p2.y, p3.y), vec4(p0.z, p1.z, p2.z, p3.z));
    PRECISE vec4 room = vec4(p0.w, p1.w, p2.w, p3.w) - v_normals * u_eye;   // common/precise.glsl
    v_room = room;
    vec4 field = texelFetch(t_field, texelRow(2 * cell), 0);
    v_range = texelFetch(t_field, texelRow(2 * cell + 1), 0).xy;
    v_field = vec4(field.xyz, field.w + dot(field.xyz, u_eye));

    if (u_exact_faces) {
        ivec4 corners = texelFetch(t_tets, texelRow(cell), 0);
        int own = me == 0 ? corners.x : me == 1 ? corners.y : me == 2 ? corners.z : corners.w;
        gl_Position = u_view_proj * vec4(texelFetch(t_points, texelRow(own), 0).xyz, 1.0);
        return;
    }
    vec4 pair = me < 2 ? texelFetch(t_outline01, texelRow(slot), 0) : texelFetch(t_outline23, texelRow(slot), 0);
    vec2 window = me % 2 == 0 ? pair.xy : pair.zw;
    float depth = float(slot - u_first_slot + 1) * DEPTH_STEP;
    gl_Position = vec4(window / u_target_size * 2.0 - 1.0, 2.0 * depth - 1.0, 1.0);
}
