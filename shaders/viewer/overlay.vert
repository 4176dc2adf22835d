#version 330 core
// The viewer's overlay (transfer-function editor): coloured triangles given in window
// coordinates (pixels, y down), mapped to NDC here.

uniform vec2 u_window;      // window size in the units of a_pos

in vec2 a_pos;
in vec4 a_color;
out vec4 v_color;

void main() {
    vec2 pos_ndc = vec2(2.0 * a_pos.x / u_window.x - 1.0, 1.0 - 2.0 * a_pos.y / u_window.y);
    gl_Position = vec4(pos_ndc, 0.0, 1.0);
    v_color = a_color;
}
