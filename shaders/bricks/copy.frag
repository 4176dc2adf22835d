// Bricked ray casting: copy a brick pass's pixels back into the running image (drawn
// over the same proxy as the pass, so exactly its pixels).
#version 330 core

uniform sampler2D t_source;
out vec4 f_color;

void main() {
    f_color = texelFetch(t_source, ivec2(gl_FragCoord.xy), 0);
}
