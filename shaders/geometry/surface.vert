// Opaque surfaces (dvr_gl.techniques.geometry): triangles drawn before the ray casting,
// three vertices each (not shared), every one carrying its face's normal and colour.
#version 330 core

in vec3 a_position;          // corner, relative to the volume box's lower corner
in vec3 a_normal;            // the face's unit normal (flat)
in vec3 a_color;             // the surface's colour
uniform mat4 u_view_proj;
out vec3 v_position;
flat out vec3 v_normal;
flat out vec3 v_color;

void main() {
    v_position = a_position;
    v_normal = a_normal;
    v_color = a_color;
    gl_Position = u_view_proj * vec4(a_position, 1.0);
}
