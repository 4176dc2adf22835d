#version 330 core
// The viewer's full-screen triangle, made from gl_VertexID alone (no vertex buffer):
// vertices (-1,-1), (3,-1), (-1,3) cover the whole viewport.

void main() {
    vec2 pos_ndc = vec2(float((gl_VertexID & 1) << 2) - 1.0, float((gl_VertexID & 2) << 1) - 1.0);
    gl_Position = vec4(pos_ndc, 0.0, 1.0);
}
