// The refined segment's walk by reach (raycast.frag, REFINE with REACH_WALK; NumPy twin:
// reference.raycast._reach_pieces). Included inside raycast.frag's REFINE block, after
// u_detail, u_spacing and touchesDetail.
#ifndef DVR_REACH_WALK_GLSL
#define DVR_REACH_WALK_GLSL

#ifndef REACH_WALK
#define REACH_WALK 0      // 1: a refined segment's pieces are as long as the field's reach allows
#endif

// How far in value s lies from the TF's detail (0 inside an interval of it).
float detailDistance(float s) {
    float d = 3.0e38;
    for (int k = 0; k < DETAIL_COUNT; ++k) {
        d = min(d, max(max(u_detail[k].x - s, s - u_detail[k].y), 0.0));
    }
    return d;
}

// The end of the piece that starts at t (field value s) in a refined segment ending at b:
// the field moves at most g (the segment's gradient bound) per unit length, so no value
// within detailDistance(s) / g of t lies on detail, and the TF is one line over all the
// piece sees: the piece is that long (at least `part`, at most to b). Where it is
// shorter than `part` (the piece may cross detail) it also ends at the next cell face,
// where the trilinear field's slope jumps. (The faces are found from t's own cell, a
// ten-thousandth of a cell beyond, so that a piece ending on a face never ends there again.)
float reachPieceEnd(vec3 origin, vec3 dir, vec3 inv_dir, float t, float s, float g, float part, float b) {
    float free_len = detailDistance(s) / max(g, 1e-30);
    float t_end = min(t + max(free_len, part), b);
    vec3 index = (origin + t * dir) / u_spacing;
    vec3 face = mix(floor(index + 1e-4) + 1.0, ceil(index - 1e-4) - 1.0, lessThan(dir, vec3(0.0)));
    vec3 t_face = mix((face * u_spacing - origin) * inv_dir, vec3(3.0e38), equal(dir, vec3(0.0)));
    float t_cut = min(t_face.x, min(t_face.y, t_face.z));
    return free_len < part ? min(t_end, t_cut) : t_end;
}

#endif
