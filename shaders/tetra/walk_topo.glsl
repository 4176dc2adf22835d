// The walk's exit faces decided by topology (walk.frag, WALK_TOPO; after Marmitt and
// Slusallek 2006): seen along the ray, the ray is a point and every corner of the mesh a
// point of the plane across it; which side of an edge the ray passes is then the sign
// of a 2x2 determinant of the edge's two corners. Each corner's position across the ray
// is computed by one function of the corner alone, and each edge's sign exactly from
// those positions, so every cell that shares an edge sees the ray on the same side of
// it, and the signs are those of a true plane figure (the rounded positions): a cell
// entered by a face that holds the ray (the ray on one side of its three edges) has
// exactly one other face that holds it, which the walk leaves by. Slivers and cells of
// zero volume need no rule of their own (their plane crossings come out of order; the
// signs do not), nor do rays through edges and vertices (ties are broken symbolically).
#ifndef DVR_WALK_TOPO_GLSL
#define DVR_WALK_TOPO_GLSL

#include "common/texel_rows.glsl"

#ifndef PRECISE
#define PRECISE
#endif

uniform isampler2D t_tets;        // RGBA32I per cell: its four points (model.mesh.topology's order)
uniform sampler2D t_points;       // RGBA32F per point: position relative to the mesh's lower corner

uniform vec3 u_centre;            // the mean of the mesh's points (relative to its lower corner)

// Two unit vectors across the ray, each turned to point towards the mesh's centre (where
// it is not square to it): edgeSide's ties move the ray by e along the first and e^2
// along the second, so a ray in a face on the boundary of a convex part goes in (as
// tetra.frag leans such rays). They are built from the axis least along the ray, so
// that a ray along an axis keeps exact zeros (its ties stay ties), and turned by sign.
void rayFrame(vec3 origin, vec3 dir, out vec3 across_x, out vec3 across_y) {
    vec3 a = abs(dir);
    vec3 other = a.x <= a.y && a.x <= a.z ? vec3(1.0, 0.0, 0.0) : a.y <= a.z ? vec3(0.0, 1.0, 0.0) : vec3(0.0, 0.0, 1.0);
    // PRECISE: the entry passes and the walk, compiled apart, build it bit for bit alike
    PRECISE vec3 x = normalize(cross(dir, other));
    PRECISE vec3 y = cross(dir, x);
    PRECISE vec3 towards = u_centre - origin;
    PRECISE float towards_x = dot(towards, x);
    PRECISE float towards_y = dot(towards, y);
    across_x = towards_x < 0.0 ? -x : x;
    across_y = towards_y < 0.0 ? -y : y;
}

// (x, y) as (x_high, x_rest, y_high, y_rest): each the sum of a high part of 12 bits and
// the rest (Veltkamp), so that products of parts are exact in float32 (exactProduct)
vec4 splitHalves(vec2 r) {
    PRECISE vec2 c = 4097.0 * r;
    PRECISE vec2 high = c - (c - r);
    PRECISE vec2 rest = r - high;
    return vec4(high.x, rest.x, high.y, rest.y);
}

// Corner `id` seen along the ray: its position (x, y) in the plane across it, the ray at
// (0, 0), each coordinate split into a high part of 12 bits and the rest (Veltkamp), as
// (x_high, x_rest, y_high, y_rest), for exactProduct. PRECISE keeps the compiler from
// folding the split away.
vec4 acrossRay(int id, vec3 origin, vec3 across_x, vec3 across_y) {
    PRECISE vec3 q = texelFetch(t_points, texelRow(id), 0).xyz - origin;
    PRECISE vec2 r = vec2(dot(q, across_x), dot(q, across_y));
    return splitHalves(r);
}

// a * b as product + error exactly (Dekker), from their splits (high, rest): products of
// 12-bit halves are exact in float32
vec2 exactProduct(float a_high, float a_rest, float b_high, float b_rest) {
    PRECISE float a = a_high + a_rest;
    PRECISE float b = b_high + b_rest;
    PRECISE float p = a * b;
    PRECISE float e = ((a_high * b_high - p) + a_high * b_rest + a_rest * b_high) + a_rest * b_rest;
    return vec2(p, e);
}

// > 0 where the ray passes on the left of the edge from corner ia (at a) to corner ib (at
// b), < 0 on its right, never 0. det(a, b) is two exact products and their difference,
// exact where it is small, so its sign is exact (but for ties closer than 2^-45 of its
// terms) and det(b, a) is its negative bit for bit. A ray through the edge's line
// (determinant 0) is taken as moved by (e, e^2) across it for an e too small to matter
// otherwise (simulation of simplicity): the sign of e (a.y - b.y) + e^2 (b.x - a.x),
// also antisymmetric; an edge along the ray (a = b) by the order of the corner ids.
float edgeSide(int ia, vec4 a, int ib, vec4 b) {
    vec2 first = exactProduct(a.x, a.y, b.z, b.w);
    vec2 second = exactProduct(a.z, a.w, b.x, b.y);
    PRECISE float det = (first.x - second.x) + (first.y - second.y);
    // PRECISE: in the order written, so that the ties are antisymmetric bit for bit too
    PRECISE float down = (a.z + a.w) - (b.z + b.w);
    PRECISE float right = (b.x + b.y) - (a.x + a.y);
    return det != 0.0 ? det : down != 0.0 ? down : right != 0.0 ? right : ia < ib ? 1.0 : -1.0;
}

// A face's three edge sides (edgeSide, in the face's order): +1 where the ray is on the
// left of all three, -1 on the right of all three, 0 where the face does not hold it
float holding(vec3 sides) {
    return all(greaterThan(sides, vec3(0.0))) ? 1.0 : all(lessThan(sides, vec3(0.0))) ? -1.0 : 0.0;
}

// Per local face k of a cell with corners v at q[0..3] (acrossRay): +1 where the ray is
// on the left of the face's edges in the order (k+1, k+2, k+3), -1 on their right, 0
// where the face does not hold the ray
vec4 facesHolding(ivec4 v, vec4 q[4]) {
    // the six edges, once each: 01 02 03 12 13 23
    float e01 = edgeSide(v.x, q[0], v.y, q[1]), e02 = edgeSide(v.x, q[0], v.z, q[2]);
    float e03 = edgeSide(v.x, q[0], v.w, q[3]), e12 = edgeSide(v.y, q[1], v.z, q[2]);
    float e13 = edgeSide(v.y, q[1], v.w, q[3]), e23 = edgeSide(v.z, q[2], v.w, q[3]);
    // face k's edges in the order (k+1, k+2, k+3): 0: 12 23 31; 1: 23 30 02; 2: 30 01 13; 3: 01 12 20
    return vec4(holding(vec3(e12, e23, -e13)), holding(vec3(e23, -e03, e02)), holding(vec3(-e03, e01, e13)),
                holding(vec3(e01, e12, -e02)));
}

void cellAcrossRay(ivec4 v, vec3 origin, vec3 across_x, vec3 across_y, out vec4 q[4]) {
    q[0] = acrossRay(v.x, origin, across_x, across_y);
    q[1] = acrossRay(v.y, origin, across_x, across_y);
    q[2] = acrossRay(v.z, origin, across_x, across_y);
    q[3] = acrossRay(v.w, origin, across_x, across_y);
}

// Does the cell with corners v hold the ray (some face of it does)?
bool cellHoldsRay(ivec4 v, vec3 origin, vec3 across_x, vec3 across_y) {
    vec4 q[4];
    cellAcrossRay(v, origin, across_x, across_y, q);
    return any(notEqual(facesHolding(v, q), vec4(0.0)));
}

// Does the face with corners ids hold the ray?
bool faceHolds(ivec3 ids, vec3 origin, vec3 across_x, vec3 across_y) {
    vec4 a = acrossRay(ids.x, origin, across_x, across_y);
    vec4 b = acrossRay(ids.y, origin, across_x, across_y);
    vec4 c = acrossRay(ids.z, origin, across_x, across_y);
    return holding(vec3(edgeSide(ids.x, a, ids.y, b), edgeSide(ids.y, b, ids.z, c), edgeSide(ids.z, c, ids.x, a))) != 0.0;
}

// The face of `cell` the ray came in by, its corners in `ids` and their positions across
// the ray (s0, s1, s2: acrossRay), ordered so that the ray is on the left of each edge
// ids[k] -> ids[k+1]. Of the faces that hold the ray (two, in a cell that holds it): one
// on the boundary where the ray comes from the entry pass (`from_boundary`; not for a
// ray that starts inside the cell), then the one the ray goes into the cell by (the
// least `along`, the rate outwards: a face whose plane holds the ray may hold it by the
// signs too). A zero-volume cell on the boundary
// holds the ray in two faces, the boundary's and the inside's, whose planes are one.
// Where no face holds it (the start's cell chosen by its planes), the best of the others.
void startFace(int cell, ivec4 nb, bool from_boundary, vec3 origin, vec3 across_x, vec3 across_y, vec4 along,
               out ivec3 ids, out vec4 s0, out vec4 s1, out vec4 s2) {
    ivec4 v = texelFetch(t_tets, texelRow(cell), 0);
    vec4 q[4];
    cellAcrossRay(v, origin, across_x, across_y, q);
    vec4 held = facesHolding(v, q);
    float best = 3.0e38;
    int pick = 0;
    for (int k = 0; k < 4; ++k) {
        bool entered = !from_boundary || nb[k] < 0;
        float score = (held[k] != 0.0 ? 0.0 : 8.0) + (entered ? 0.0 : 4.0) + clamp(along[k], -1.0, 1.0);
        if (score < best) {
            best = score;
            pick = k;
        }
    }
    int i = (pick + 1) & 3, j = (pick + 2) & 3, l = (pick + 3) & 3;
    if (held[pick] < 0.0) {
        int swap = i;
        i = j;
        j = swap;
    }
    ids = ivec3(v[i], v[j], v[l]);
    s0 = q[i];
    s1 = q[j];
    s2 = q[l];
}

// The local face by which the ray leaves `cell`, entered by the face (ids; s0, s1, s2:
// see startFace), which becomes that exit face (the next cell's entry face, in order).
// With d the cell's fourth corner, the exit is the face (ids[m], ids[m+1], d) with the
// ray on the left of d -> ids[m] and on the right of d -> ids[m+1]: exactly one m where
// the entry face holds the ray. Where it does not (a start's face chosen by its planes),
// all three signs can agree; the smallest determinant is then taken as turned.
int topoExit(int cell, vec3 origin, vec3 across_x, vec3 across_y, inout ivec3 ids, inout vec4 s0, inout vec4 s1,
             inout vec4 s2) {
    ivec4 v = texelFetch(t_tets, texelRow(cell), 0);
    int d = ((v.x + v.y) + (v.z + v.w)) - ((ids.x + ids.y) + ids.z);    // the corner not in the entry face
    vec4 sd = acrossRay(d, origin, across_x, across_y);
    vec3 s = vec3(edgeSide(d, sd, ids.x, s0), edgeSide(d, sd, ids.y, s1), edgeSide(d, sd, ids.z, s2));
    bvec3 left = greaterThan(s, vec3(0.0));
    vec3 size = abs(s);
    int least = size.x <= size.y && size.x <= size.z ? 0 : size.y <= size.z ? 1 : 2;
    bool agree = all(left) || !any(left);
    left[least] = left[least] != agree;
    int m = left.x && !left.y ? 0 : left.y && !left.z ? 1 : 2;
    int gone = m == 0 ? ids.z : m == 1 ? ids.x : ids.y;       // the corner the exit face lacks
    vec4 sa = m == 0 ? s0 : m == 1 ? s1 : s2;
    vec4 sb = m == 0 ? s1 : m == 1 ? s2 : s0;
    ids = m == 0 ? ivec3(ids.x, ids.y, d) : m == 1 ? ivec3(ids.y, ids.z, d) : ivec3(ids.z, ids.x, d);
    s0 = sa;
    s1 = sb;
    s2 = sd;
    return v.x == gone ? 0 : v.y == gone ? 1 : v.z == gone ? 2 : 3;
}

#endif
