// Faces of the occupied bricks (dvr_gl.techniques.raycast.occupied_faces).
#version 330 core

in vec3 a_position;          // face corner, relative to the volume box's lower corner
in vec3 a_normal;            // the face's outward normal
uniform mat4 u_view_proj;
out vec3 v_position;
flat out vec3 v_normal;

void main() {
    v_position = a_position;
    v_normal = a_normal;
    gl_Position = u_view_proj * vec4(a_position, 1.0);
}
