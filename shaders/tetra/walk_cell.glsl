// The cell walk (techniques/tetra_walk.py): a pixel's ray against one cell's four planes,
// computed as tetra.vert and tetra.frag compute them (the same planes, the same
// arithmetic), so a ray leaves one cell at exactly the distance where it enters the
// next, and a boundary face's entry distance here is bitwise the walk's own.
#ifndef DVR_WALK_CELL_GLSL
#define DVR_WALK_CELL_GLSL

#include "common/texel_rows.glsl"

#ifndef ORTHO
#define ORTHO 0
#endif
#ifndef PRECISE
#define PRECISE
#endif

uniform sampler2D t_planes;   // RGBA32F, 4 per cell: outward unit normal, offset (n.x = d)

// The entry pass's margin around a boundary face's triangle, of its barycentric
// coordinates (walk_entry.frag tests the crossing with it; walk_entry.geom grows the
// drawn triangle by as much)
const float ENTRY_MARGIN = 1e-5;

// The cell's outward normals by component (column k: component k of the four normals)
// and the planes' offsets from the eye (d - n . eye), as tetra.vert has them.
void cellPlanes(int cell, vec3 eye, out mat3x4 normals, out vec4 room_at_eye) {
    vec4 p0 = texelFetch(t_planes, texelRow(4 * cell), 0);
    vec4 p1 = texelFetch(t_planes, texelRow(4 * cell + 1), 0);
    vec4 p2 = texelFetch(t_planes, texelRow(4 * cell + 2), 0);
    vec4 p3 = texelFetch(t_planes, texelRow(4 * cell + 3), 0);
    normals = mat3x4(vec4(p0.x, p1.x, p2.x, p3.x), vec4(p0.y, p1.y, p2.y, p3.y), vec4(p0.z, p1.z, p2.z, p3.z));
    PRECISE vec4 room = vec4(p0.w, p1.w, p2.w, p3.w) - normals * eye;
    room_at_eye = room;
}

// One face's plane (``slot``: 4 * cell + local face) in all four places: what cellPlanes
// gives for that face, by the same arithmetic component for component, from one fetch
// (the entry pass needs only the face's own crossing).
void facePlane(int slot, vec3 eye, out mat3x4 normals, out vec4 room_at_eye) {
    vec4 p = texelFetch(t_planes, texelRow(slot), 0);
    normals = mat3x4(vec4(p.x), vec4(p.y), vec4(p.z));
    PRECISE vec4 room = vec4(p.w) - normals * eye;
    room_at_eye = room;
}

// Per plane: the ray's rate towards the outside (n . dir) and its distance t where it
// crosses (inf where parallel); room: how far inside the ray's start is (d - n . origin).
void cellCrossings(mat3x4 normals, vec4 room_at_eye, vec3 origin, vec3 dir, vec3 eye,
                   out vec4 along, out vec4 room, out vec4 t) {
    PRECISE vec4 a = normals * dir;
#if ORTHO
    PRECISE vec3 offset = origin - eye;     // orthographic rays start off the eye
    PRECISE vec4 r = room_at_eye - normals * offset;
#else
    vec4 r = room_at_eye;
#endif
    along = a;
    room = r;
    t = r / a;
}

// One face's plane (slot: 4 * cell + local face): where the ray crosses it, and its rate
// outwards (along). The walk by topology (tetra/walk_topo.glsl) ends a cell's segment
// here and its entry pass finds entries here: the same function, so a ray leaving by a
// boundary face enters a cell across the same plane (not joined) at the same t.
float faceCrossing(int slot, vec3 eye, vec3 origin, vec3 dir, out float along) {
    vec4 p = texelFetch(t_planes, texelRow(slot), 0);
    PRECISE float rate = dot(p.xyz, dir);
    PRECISE float room = p.w - dot(p.xyz, eye);
#if ORTHO
    PRECISE vec3 offset = origin - eye;
    room = room - dot(p.xyz, offset);
#endif
    along = rate;
    return room / rate;
}

#endif
