// Adds one repetition's image, divided by their count, into the output (blended ONE, ONE).
#version 330 core

uniform sampler2D t_image;
uniform float u_weight;        // 1 / repetitions

out vec4 frag_color;

void main() {
    frag_color = u_weight * texelFetch(t_image, ivec2(gl_FragCoord.xy), 0);
}
