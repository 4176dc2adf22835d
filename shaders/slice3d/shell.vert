// 3D slicing along spherical shells: each instance (0 = farthest shell) draws the box's
// back faces (or a full-screen triangle); the fragment shader finds the shell on its ray.
#version 330 core

in vec3 a_position;          // unit-cube corner, or NDC for the full-screen triangle
uniform mat4 u_view_proj;    // identity for the full-screen triangle
flat out int v_slice;

void main() {
    v_slice = gl_InstanceID;
    gl_Position = u_view_proj * vec4(a_position, 1.0);
}
