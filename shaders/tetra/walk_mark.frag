// The cell walk's marks (techniques/tetra_walk.py): after a layer's entry pass, the
// pixels that have an entry get the layer's window depth (walk_layer.vert); the rest
// keep theirs. Drawn with an occlusion query: its count is the pixels with an entry.
// u_alive (after a layer's walk): of those, only the pixels whose ray goes on.
#version 330 core

uniform sampler2D t_entry_t;   // the entry pass: nearest eligible entry t (3e38: none)
uniform sampler2D t_state;     // u_alive: the walk's state (t of its last stop; >= 1e38: done)
uniform bool u_alive;

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    if (texelFetch(t_entry_t, px, 0).r >= 1.0e38) discard;
    if (u_alive && texelFetch(t_state, px, 0).r >= 1.0e38) discard;
}
