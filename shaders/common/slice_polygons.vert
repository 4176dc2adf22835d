// Slicing geometry made on the CPU (3D slicing polygons, 2D slicing quads), each vertex
// with its slice index; the fragment shader decides coverage from the index alone.
#version 330 core

in vec3 a_position;          // box-relative world position on slice a_slice
in int a_slice;              // 0 = farthest slice
uniform mat4 u_view_proj;
flat out int v_slice;

void main() {
    v_slice = a_slice;
    gl_Position = u_view_proj * vec4(a_position, 1.0);
}
