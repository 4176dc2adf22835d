// The cell walk's entry pass (techniques/tetra_walk.py): the mesh's boundary faces, each
// vertex placed by the view's projection; the face's cell and its local face number
// ride along (walk_entry.geom grows each face's outline, walk_entry.frag decides).
#version 330 core

in vec3 a_position;          // relative to the mesh's lower corner
in int a_slot;               // 4 * cell + local face (the face opposite corner slot % 4)
uniform mat4 u_view_proj;
flat out int g_slot;
out vec3 g_position;

void main() {
    g_slot = a_slot;
    g_position = a_position;
    gl_Position = u_view_proj * vec4(a_position, 1.0);
}
