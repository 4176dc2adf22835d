// Projected tetrahedra, the outline pass (one fragment per draw slot, drawn over two
// TEXEL_ROW_WIDTH-wide targets): the window positions of the cell's four corners, each
// corner of the projected outline (convex hull) moved out so that the outline grows by
// u_inflate pixels (tetra.vert says why). Done here, in parallel, rather than in the
// vertex shader, which llvmpipe runs on one thread. Texel k of the first target holds
// corners 0 and 1 of slot k (x, y, x, y), of the second corners 2 and 3.
#version 330 core
#include "common/precise.glsl"

#include "common/texel_rows.glsl"

uniform isampler2D t_order;   // R32I: draw slot -> cell
uniform isampler2D t_tets;    // RGBA32I: cell -> its four points
uniform sampler2D t_points;   // RGBA32F: point -> position relative to the mesh's lower corner
uniform mat4 u_view_proj;
uniform vec2 u_target_size;   // pixels of the image target (a tile's, with tiles)
uniform float u_inflate;      // pixels the outline grows by: twice the vertex snapping
uniform int u_slots;          // cells drawn

const float MITER_CAP = 1024.0;   // pixels

layout(location = 0) out vec4 f_corners01;
layout(location = 1) out vec4 f_corners23;

// Both precise (common/precise.glsl): corners that project onto one line must give a
// cross product of exactly 0, as they do unfused, or a face seen edge-on is not found
// collinear and its outline does not grow.
vec2 toWindow(vec4 clip) {
    PRECISE vec2 window = (clip.xy / clip.w * 0.5 + 0.5) * u_target_size;
    return window;
}

float cross2(vec2 a, vec2 b) {
    PRECISE float area = a.x * b.y - a.y * b.x;
    return area;
}

// Window-space move of corner a of the outline (convex hull) of a and the cell's three
// other projected corners b, c, d: along the outward normals of the two hull edges at a,
// by u_inflate, to where the moved edges meet (a miter); none for a corner inside the
// outline or an outline without area. Written out for the three candidate edges (no
// arrays indexed at run time: llvmpipe spills those to memory).
// The miter is long at a sharp corner (u_inflate / sin(half the angle)), and it must be:
// a cell seen grazing projects to a needle (0.004 by 7 pixels), and only the miters at
// its two tips move its long edges out; capped at 2.8 u_inflate they hardly moved, and
// pixel centres just inside the needle were lost (a thin slab dropped cells). The cap is
// MITER_CAP pixels: the spike a long miter adds is a sliver with few pixel centres, each
// discarded by the fragment's own clipping.
vec2 hullEdgeNormal(vec2 a, vec2 q, vec2 r1, vec2 r2, inout int found) {
    vec2 edge = q - a;
    // q projects onto a (within far less than the growth): a's edges go to the others
    if (dot(edge, edge) <= 1e-6 * u_inflate * u_inflate) return vec2(0.0);
    float c1 = cross2(edge, r1 - a), c2 = cross2(edge, r2 - a);
    if (c1 * c2 < 0.0) return vec2(0.0);          // corners on both sides: not a hull edge
    if (c1 == 0.0 && c2 == 0.0) {                 // all on a line: no area to grow
        found = 3;
        return vec2(0.0);
    }
    found += 1;
    vec2 n = vec2(edge.y, -edge.x) / max(length(edge), 1e-30);
    return c1 + c2 > 0.0 ? n : -n;                // away from the other corners
}

vec2 outlineShift(vec2 a, vec2 b, vec2 c, vec2 d) {
    int found = 0;
    vec2 nb = hullEdgeNormal(a, b, c, d, found);
    vec2 nc = hullEdgeNormal(a, c, b, d, found);
    vec2 nd = hullEdgeNormal(a, d, b, c, found);
    if (found != 2) return vec2(0.0);
    vec2 n1 = nb != vec2(0.0) ? nb : nc;
    vec2 n2 = nd != vec2(0.0) ? nd : nc;
    vec2 miter = u_inflate * (n1 + n2) / max(1.0 + dot(n1, n2), 1e-12);
    float reach = length(miter);
    return reach > MITER_CAP ? miter * (MITER_CAP / reach) : miter;
}

void main() {
    int slot = int(gl_FragCoord.y) * TEXEL_ROW_WIDTH + int(gl_FragCoord.x);
    if (slot >= u_slots) discard;
    int cell = texelFetch(t_order, texelRow(slot), 0).r;
    ivec4 corners = texelFetch(t_tets, texelRow(cell), 0);
    PRECISE vec4 c0 = u_view_proj * vec4(texelFetch(t_points, texelRow(corners.x), 0).xyz, 1.0);
    vec2 w0 = toWindow(c0);
    PRECISE vec4 c1 = u_view_proj * vec4(texelFetch(t_points, texelRow(corners.y), 0).xyz, 1.0);
    vec2 w1 = toWindow(c1);
    PRECISE vec4 c2 = u_view_proj * vec4(texelFetch(t_points, texelRow(corners.z), 0).xyz, 1.0);
    vec2 w2 = toWindow(c2);
    PRECISE vec4 c3 = u_view_proj * vec4(texelFetch(t_points, texelRow(corners.w), 0).xyz, 1.0);
    vec2 w3 = toWindow(c3);
    f_corners01 = vec4(w0 + outlineShift(w0, w1, w2, w3), w1 + outlineShift(w1, w2, w3, w0));
    f_corners23 = vec4(w2 + outlineShift(w2, w3, w0, w1), w3 + outlineShift(w3, w0, w1, w2));
}
