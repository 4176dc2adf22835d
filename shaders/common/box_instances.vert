// The volume box's back faces (or, with the eye inside, a full-screen triangle), drawn
// once per instance: 3D slicing along shells draws one instance per shell and finds the
// shell on each pixel's ray; the slicing techniques' gap pass draws one.
#version 330 core

in vec3 a_position;          // unit-cube corner, or NDC for the full-screen triangle
uniform mat4 u_view_proj;    // identity for the full-screen triangle
flat out int v_slice;

void main() {
    v_slice = gl_InstanceID;
    gl_Position = u_view_proj * vec4(a_position, 1.0);
}
