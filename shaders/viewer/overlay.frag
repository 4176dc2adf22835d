#version 330 core
// The overlay's colour, straight (not premultiplied) alpha, blended over the picture.

in vec4 v_color;
out vec4 f_color;

void main() {
    f_color = v_color;
}
