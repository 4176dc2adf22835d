// Ray-casting proxy: the volume box's back faces, or a full-screen triangle when the
// eye is inside the box. The fragment shader ignores the geometry: it builds its ray
// from gl_FragCoord, so both proxies give identical pixels.
#version 330 core

in vec3 a_position;          // box corner relative to the box's lower corner, or NDC
uniform mat4 u_view_proj;    // identity for the full-screen triangle

void main() {
    gl_Position = u_view_proj * vec4(a_position, 1.0);
}
