// Planes perpendicular to the view direction (or, with SHELLS, spheres about the eye),
// u_step apart: plane k at depth u_far_depth - k * u_step, k = 0 the farthest (NumPy twins:
// reference.common.plane_inside and slab_segment). Each plane stands for the piece of a
// pixel's ray from halfway to its nearer neighbour to halfway to its farther one, or to the
// box where that neighbour does not meet the ray inside it. 3D slicing samples these
// pieces at their midpoints; sheet-buffer splatting classifies its sheets with them.
#ifndef DVR_SLABS_GLSL
#define DVR_SLABS_GLSL

#ifndef SHELLS
#define SHELLS 0
#endif

uniform float u_far_depth;    // depth (radius for shells) of plane 0, the farthest
uniform float u_step;         // distance between planes
uniform int u_slice_count;

// Ray distance of plane k's point. Neighbours call this with k +- 1 and get exactly the
// value that plane's own fragments compute, so the pieces tile the ray without gaps.
float sliceT(int k, float cos_theta) {
    float depth = u_far_depth - float(k) * u_step;
#if SHELLS
    return depth;
#else
    return depth / cos_theta;
#endif
}

// Does plane k exist and meet this ray inside the box (and in front of the ray start)?
bool sliceInside(int k, float t, vec2 range) {
    return k >= 0 && k < u_slice_count && t > 0.0 && t >= range.x && t <= range.y;
}

// The piece [a, b] of the ray that plane k, met at t, stands for.
vec2 slabSegment(int k, float t, float cos_theta, vec2 range) {
    float t_near = sliceT(k + 1, cos_theta);
    float t_far = sliceT(k - 1, cos_theta);
    float a = sliceInside(k + 1, t_near, range) ? 0.5 * (t_near + t) : range.x;
    float b = sliceInside(k - 1, t_far, range) ? 0.5 * (t + t_far) : range.y;
    return vec2(a, b);
}

#endif
