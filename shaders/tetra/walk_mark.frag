// The cell walk's marks (techniques/tetra_walk.py): after a layer's entry pass, the
// pixels that have an entry get the layer's window depth (walk_layer.vert); the rest
// keep theirs. Drawn with an occlusion query: its count is the pixels with an entry.
#version 330 core

uniform sampler2D t_entry_t;   // the entry pass: nearest eligible entry t (3e38: none)

void main() {
    if (texelFetch(t_entry_t, ivec2(gl_FragCoord.xy), 0).r >= 1.0e38) discard;
}
