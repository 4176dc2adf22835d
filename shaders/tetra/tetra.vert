// Projected tetrahedra: every visible cell's four faces, in the plan's back-to-front
// order: vertex 4k + i is corner i of the k-th cell drawn, and a fixed index buffer makes
// each cell's four triangles from its four vertices (each shaded once). Front faces are
// culled: the back
// faces that remain cover the cell's projected silhouette exactly once (Shirley and
// Tuchman's 3 or 4 triangles, split along the cell's own back faces instead of the thick
// vertex), and the fragment shader finds the thick part exactly, per pixel.
#version 330 core

#include "common/texel_rows.glsl"

uniform isampler2D t_order;   // R32I: draw slot -> cell
uniform isampler2D t_tets;    // RGBA32I: cell -> its four points (positively oriented)
uniform sampler2D t_points;   // RGBA32F: point -> position relative to the mesh's lower corner
uniform sampler2D t_planes;   // RGBA32F, 4 per cell: outward unit normal, offset (n.x = d)
uniform sampler2D t_field;    // RGBA32F, 2 per cell: (gradient, value at centroid), centroid
uniform mat4 u_view_proj;

uniform vec3 u_eye;           // the eye, relative to the mesh's lower corner (common/camera_ray.glsl)

// The cell, fetched once per vertex rather than per fragment: its outward plane normals
// (column k holds component k of the four normals, so normals * dir gives the four dot
// products), the planes' offsets from the eye (d - n . eye; orthographic rays start off
// the eye and subtract their own offset), the field's gradient and its value at the eye.
flat out mat3x4 v_normals;
flat out vec4 v_room;
flat out vec4 v_field;

void main() {
    int cell = texelFetch(t_order, texelRow(gl_VertexID / 4), 0).r;
    ivec4 corners = texelFetch(t_tets, texelRow(cell), 0);
    int point = corners[gl_VertexID % 4];
    vec3 p = texelFetch(t_points, texelRow(point), 0).xyz;
    gl_Position = u_view_proj * vec4(p, 1.0);
    vec4 p0 = texelFetch(t_planes, texelRow(4 * cell), 0);
    vec4 p1 = texelFetch(t_planes, texelRow(4 * cell + 1), 0);
    vec4 p2 = texelFetch(t_planes, texelRow(4 * cell + 2), 0);
    vec4 p3 = texelFetch(t_planes, texelRow(4 * cell + 3), 0);
    v_normals = mat3x4(vec4(p0.x, p1.x, p2.x, p3.x), vec4(p0.y, p1.y, p2.y, p3.y), vec4(p0.z, p1.z, p2.z, p3.z));
    v_room = vec4(p0.w, p1.w, p2.w, p3.w) - v_normals * u_eye;
    vec4 field = texelFetch(t_field, texelRow(2 * cell), 0);
    vec3 centre = texelFetch(t_field, texelRow(2 * cell + 1), 0).xyz;
    v_field = vec4(field.xyz, field.w + dot(field.xyz, u_eye - centre));
}
