// Projected tetrahedra, per fragment (tetra.vert says how each pixel gets one fragment
// per cell): the pixel's ray clipped against the cell's four
// planes gives the exact segment through the cell (front and back distance), the cell's
// linear field gives the scalar at both ends, and the segment is integrated exactly for
// the piecewise-linear transfer function (common/linear_segment.glsl). GL blends the
// premultiplied result over what is behind it (cells arrive back to front).
// mip / minip / average: the fragment writes what GL's blending reduces in any order
// (the larger or smaller end value, or the segment's integral and length), and
// tetra_classify.frag classifies the result.
#version 330 core
#include "common/precise.glsl"

#ifndef ORTHO
#define ORTHO 0
#endif
#ifndef MODE_COMPOSITE
#define MODE_COMPOSITE 1
#endif
#ifndef MODE_MIP
#define MODE_MIP 0
#endif
#ifndef MODE_MINIP
#define MODE_MINIP 0
#endif
#ifndef MODE_AVERAGE
#define MODE_AVERAGE 0
#endif

#ifndef SAMPLE_TERMS
#define SAMPLE_TERMS 0   // lights or illustration terms, each constant in a cell
#endif
#ifndef GEOMETRY
#define GEOMETRY 0       // opaque surfaces: nothing of a cell behind the pixel's first one
#endif

#include "common/camera_ray.glsl"
#include "common/linear_segment.glsl"
// N_CLIP_PLANES, CROP_BOX (common/clip.glsl): both 0 unless the scene clips
#include "common/clip.glsl"
#if SAMPLE_TERMS
#define DEPTH_CUE_ALONG_SEGMENT 1   // the cue varies along a segment: integrated with it
#include "common/shading.glsl"
#endif

flat in mat3x4 v_normals;      // the cell's outward plane normals, by component (tetra.vert)
flat in vec4 v_room;           // plane offsets from the eye: d - n . eye
flat in vec4 v_field;          // gradient of the linear field, value at the eye
flat in vec2 v_range;          // the cell's smallest and largest vertex value
uniform vec3 u_centre;          // the mean of the mesh's points (relative to its lower corner)
#if GEOMETRY
uniform sampler2D t_surface;    // per pixel: the first surface's lit colour and its ray
                                // parameter t (3e38: none), techniques.geometry.surface_pass
#endif

out vec4 frag_color;

// Is the ray, moved towards the mesh's centre (across the ray; if that is no move at
// all, by a fixed tiny offset), inside the plane with outward normal n that it lies in?
bool movedInside(vec3 n, vec3 origin, vec3 dir) {
    PRECISE vec3 across = u_centre - origin;
    across -= dot(across, dir) * dir;
    PRECISE float towards = dot(n, across);
    if (towards != 0.0) return towards < 0.0;
    return n.x != 0.0 ? n.x > 0.0 : n.y != 0.0 ? n.y > 0.0 : n.z > 0.0;
}

void main() {
    vec3 origin, dir;
    pixelRay(origin, dir);
    // exact zeros stay exact zeros (common/precise.glsl): the ties below depend on it
    PRECISE vec4 along = v_normals * dir;
#if ORTHO
    PRECISE vec3 offset = origin - u_eye;     // orthographic rays start off the eye
    PRECISE vec4 room = v_room - v_normals * offset;
#else
    vec3 offset = vec3(0.0);
    vec4 room = v_room;
#endif
    // A ray parallel to a plane is inside where room > 0. One lying in the plane
    // (room == 0: views along faces and edges) is decided as if it were moved by an
    // infinitesimal step towards the mesh's centre: the two cells of a shared face hold
    // exactly opposite planes, so exactly one of them keeps it, and a ray in the boundary
    // of a convex mesh is kept (closed cells, as the grid's box is).
    vec4 parallel_room = mix(vec4(1.0), room, equal(along, vec4(0.0)));
    if (any(lessThan(parallel_room, vec4(0.0)))) discard;
    if (any(equal(parallel_room, vec4(0.0)))) {    // rare: rays in a face's plane
        vec4 nx = v_normals[0], ny = v_normals[1], nz = v_normals[2];
        for (int k = 0; k < 4; ++k) {
            if (parallel_room[k] == 0.0 && !movedInside(vec3(nx[k], ny[k], nz[k]), origin, dir)) discard;
        }
    }
    vec4 t = room / along;
    vec4 exits = mix(vec4(3.0e38), t, greaterThan(along, vec4(0.0)));
    vec4 entries = mix(vec4(0.0), t, lessThan(along, vec4(0.0)));
    float t_in = max(max(entries.x, entries.y), max(entries.z, entries.w));   // >= 0: rays start here
    float t_out = min(min(exits.x, exits.y), min(exits.z, exits.w));
    if (t_out <= t_in) discard;
#if N_CLIP_PLANES > 0 || CROP_BOX
    // the segment cut to the part of the pixel's ray the clip planes and crop box keep;
    // the end values below follow from the cut ends (the field is linear along it)
    vec2 kept = clipRange(origin, dir, vec2(t_in, t_out));
    t_in = kept.x;
    t_out = kept.y;
    if (t_out <= t_in) discard;      // nothing of this cell is kept on this ray
#endif
#if GEOMETRY
    // nothing behind the pixel's first surface: the segment cut at its t, the end value
    // below following from the cut end (the surface itself is the target's backmost layer)
    t_out = min(t_out, texelFetch(t_surface, ivec2(gl_FragCoord.xy), 0).a);
    if (t_out <= t_in) discard;
#endif
    float rate = dot(v_field.xyz, dir);
    float s_at_start = v_field.w + dot(v_field.xyz, offset);
    // a linear field takes its extremes at the vertices: float32 extrapolation from the
    // eye may not (slivers have huge gradients), so the ends are clamped to the range
    float s_front = clamp(s_at_start + t_in * rate, v_range.x, v_range.y);
    float s_back = clamp(s_at_start + t_out * rate, v_range.x, v_range.y);
#if MODE_MIP
    frag_color = vec4(max(s_front, s_back), 0.0, 0.0, 1.0);           // blended with MAX
#elif MODE_MINIP
    frag_color = vec4(-min(s_front, s_back), 0.0, 0.0, 1.0);          // MAX of the negation
#elif MODE_AVERAGE
    float len = t_out - t_in;
    frag_color = vec4(0.5 * (s_front + s_back) * len, len, 0.0, 1.0);  // blended by addition
#else
  #if SAMPLE_TERMS
    // the cell's gradient is constant, so are its terms along the segment: an extinction
    // scale m is the same integral over a segment m times as long (s still linear along
    // it), and the colour integral is the plain one times the factor plus the added
    // colour times the segment's opacity
    float factor, scale;
    vec3 added;
    termsFor(v_field.xyz, origin, dir, factor, added, scale);
    float q_front = 1.0, q_back = 1.0;
    #if DEPTH_CUE      // linear in depth, so along the segment: C = integral c q tau T
    q_front = depthCue(origin + t_in * dir);
    q_back = depthCue(origin + t_out * dir);
    #endif
    float cued_alpha;
    frag_color = linearSegmentCued(s_front, s_back, (t_out - t_in) * scale, q_front, q_back, cued_alpha);
    frag_color.rgb = frag_color.rgb * factor + added * cued_alpha;
  #else
    frag_color = linearSegment(s_front, s_back, t_out - t_in);
  #endif
  #if OPTICAL_MODEL == 2
    frag_color.a = 0.0;     // emission only: the alpha channel held the optical depth
  #endif
#endif
}
