// The cell walk's pixel pass after the first layer (techniques/tetra_walk.py): one
// triangle covering the viewport at window depth u_layer_depth, so that the depth test
// (early, before walk.frag runs) keeps only the pixels the last entry pass marked.
#version 330 core

uniform float u_layer_depth;   // window depth, 0 to 1

void main() {
    vec2 p = vec2(gl_VertexID == 1 ? 3.0 : -1.0, gl_VertexID == 2 ? 3.0 : -1.0);
    gl_Position = vec4(p, 2.0 * u_layer_depth - 1.0, 1.0);
}
