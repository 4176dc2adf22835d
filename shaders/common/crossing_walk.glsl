// The walk by crossings (raycast.frag, CROSSING_WALK with PREINTEGRATE; NumPy twin:
// reference.crossing_walk). The ray goes from cell to cell of the trilinear field. A cell
// whose corner values reach no value with opacity (a bound: the trilinear field stays
// within its corners' range) is passed over together with every cell ahead of it that
// is just as empty: t_walk_map holds, per cell and octant of ray directions, the largest
// empty cube with a corner at the cell lying towards that octant, so the ray leaves
// that whole cube in one round. In a cell that may show something the field along the ray is one cubic, made from the
// trilinear coefficients stored for that cell (two reads, not eight corners); its stretch
// of ray is cut where the cubic turns (so each piece is monotone) and where it crosses a
// knot of the TF (so the TF is one line over each piece), each piece at most u_cw_part
// long, and each read from the pre-integrated table of that length (the fine rows) with
// the cubic's values at its ends. A narrow opacity band is then crossed in a few exact
// places however large the step.
#ifndef DVR_CROSSING_WALK_GLSL
#define DVR_CROSSING_WALK_GLSL

#ifndef KNOT_COUNT
#define KNOT_COUNT 1
#endif
#define CW_HALLEY 2             // Halley steps to a crossing
#define CW_ULPS 4.8e-7          // four float32 steps, relative (beyond)

#ifndef CW_COEFFICIENT_ROW
#define CW_COEFFICIENT_ROW 2048  // cells per row of t_cell_coefficients (crossing_walk.COEFFICIENT_ROW)
#endif
uniform usampler3D t_walk_map;     // R32UI per cell: in an empty cell its eight octants' cube
                                   // codes, four bits each (cubeReach; octant o in bits 4o ..),
                                   // none 0; n << 4 in the n-th cell whose corners' range may
                                   // have opacity (crossing_walk.walk_cells)
uniform sampler2D t_cell_coefficients;   // RGBA32F, two texels per such cell: its trilinear
                                         // field's coefficients (crossing_walk.cell_coefficients)
uniform float u_knots[KNOT_COUNT]; // the TF's knots where opacity or the colour it weighs bends
uniform vec2 u_support;            // values outside (x, y) have zero opacity
uniform float u_cw_part;           // the longest piece, world units
uniform float u_cw_nominal;        // the fine table's nominal length
uniform int u_cw_rounds;           // a bound on the rounds of one ray (a safety net)
uniform float u_cw_tol;            // values this close to a knot are on it (float rounding)

// The cubic c.x + c.y u + c.z u^2 + c.w u^3.
float cubicAt(vec4 c, float u) {
    return c.x + u * (c.y + u * (c.z + u * c.w));
}

// The trilinear field of the n-th cell that may show something along x(u) = xa + u (xb -
// xa) (cell-local coordinates), u in [0, 1], as a cubic in u.
vec4 cellCubic(int n, vec3 xa, vec3 xb) {
    // f = c0 + cx X + cy Y + cz Z + cxy XY + cxz XZ + cyz YZ + cxyz XYZ (cell_coefficients)
    ivec2 at = ivec2(2 * (n % CW_COEFFICIENT_ROW), n / CW_COEFFICIENT_ROW);
    vec4 linear = texelFetch(t_cell_coefficients, at, 0);
    vec4 mixed = texelFetch(t_cell_coefficients, at + ivec2(1, 0), 0);
    float v000 = linear.x, cx = linear.y, cy = linear.z, cz = linear.w;
    float cxy = mixed.x, cxz = mixed.y, cyz = mixed.z, cxyz = mixed.w;
    vec3 d = xb - xa;
    // products of the linear X = xa.x + u d.x, ... as (u^0, u^1, u^2) and u^3
    vec3 xy = vec3(xa.x * xa.y, xa.x * d.y + d.x * xa.y, d.x * d.y);
    vec3 xz = vec3(xa.x * xa.z, xa.x * d.z + d.x * xa.z, d.x * d.z);
    vec3 yz = vec3(xa.y * xa.z, xa.y * d.z + d.y * xa.z, d.y * d.z);
    vec4 xyz = vec4(xy.x * xa.z, xy.x * d.z + xy.y * xa.z, xy.y * d.z + xy.z * xa.z, xy.z * d.z);
    vec4 c = vec4(v000 + cx * xa.x + cy * xa.y + cz * xa.z, cx * d.x + cy * d.y + cz * d.z, 0.0, 0.0);
    c.xyz += cxy * xy + cxz * xz + cyz * yz;
    c += cxyz * xyz;
    return c;
}

// The first turning point of the cubic beyond u (1 if none before the cell's end).
float nextTurn(vec4 c, float u) {
    // c.y + 2 c.z x + 3 c.w x^2 = 0
    float qa = 3.0 * c.w, qb = 2.0 * c.z, qc = c.y;
    float r1 = 2.0, r2 = 2.0;
    float scale = max(abs(qb), abs(qc));
    if (abs(qa) <= 1e-7 * scale) {
        if (abs(qb) > 0.0) r1 = -qc / qb;
    } else {
        float disc = qb * qb - 4.0 * qa * qc;
        if (disc >= 0.0) {
            float q = -0.5 * (qb + (qb >= 0.0 ? 1.0 : -1.0) * sqrt(disc));
            r1 = q / qa;
            r2 = q != 0.0 ? qc / q : 2.0;
        }
    }
    float next = 1.0;
    if (r1 > u && r1 < next) next = r1;
    if (r2 > u && r2 < next) next = r2;
    return next;
}

// Where the cubic, monotone on [u, u_end] from s to s_end, reaches `target` (between
// them): Halley's method from the chord's crossing, CW_HALLEY steps kept in [u, u_end]
// (cubic convergence), and at least a hundred-thousandth of the stretch beyond u, so
// that the walk always moves on. (Each step is a chain of dependent operations ending in
// a division, which llvmpipe waits for: two of Halley's are 7 % of a Marschner-Lobb
// spike's frame faster than three of Newton's, and as accurate.)
float crossingOf(vec4 c, float u, float s, float u_end, float s_end, float target) {
    float x = u + (u_end - u) * clamp((target - s) / (s_end - s), 0.0, 1.0);
    for (int i = 0; i < CW_HALLEY; ++i) {
        float f = cubicAt(c, x) - target;
        float slope = c.y + x * (2.0 * c.z + x * 3.0 * c.w);
        float curve = 2.0 * c.z + 6.0 * c.w * x;
        float den = 2.0 * slope * slope - f * curve;
        float step = den != 0.0 ? 2.0 * f * slope / den : 0.0;
        x = clamp(x - step, u, u_end);
    }
    return min(max(x, u + 1e-5), u_end);
}

// The end of the piece from u (value s) that stops at the first knot the cubic crosses
// before u_end (monotone on [u, u_end], value s_end there; crossingOf); u_end if none.
// s_at: the value there, the knot itself where one was crossed (not the cubic evaluated
// in float there, which may miss the knot by more than u_cw_tol and make a piece that
// left the support look inside it).
float nextCrossing(vec4 c, float u, float s, float u_end, float s_end, out float s_at) {
    float up = s_end >= s ? 1.0 : -1.0;
    float target = 0.0;
    bool found = false;
    for (int k = 0; k < KNOT_COUNT; ++k) {
        float knot = u_knots[k];
        bool ahead = (knot - s) * up > u_cw_tol && (s_end - knot) * up >= 0.0;
        if (ahead && (!found || (knot - target) * up < 0.0)) {
            target = knot;
            found = true;
        }
    }
    s_at = found ? target : s_end;
    return found ? crossingOf(c, u, s, u_end, s_end, target) : u_end;
}

// The cell the ray is in just beyond t (a ten-thousandth of a cell ahead, so that a
// point on a face counts in the cell it enters).
ivec3 cellAhead(vec3 origin_c, vec3 dir_c, float t) {
    vec3 index = origin_c + t * dir_c + 1e-4 * sign(dir_c);
    return clamp(ivec3(floor(index)), ivec3(0), ivec3(u_dims) - 2);
}

// A little beyond t, so that the walk always moves on: a hundred-thousandth of a cell, or
// four float32 steps of t where those are longer (far from the eye a hundred-thousandth
// of a cell is below float32's resolution of t, and t + it == t: the walk stood still).
float beyond(float t, float nudge) {
    return t + max(nudge, abs(t) * CW_ULPS);
}

// How far (cells) an empty cube reaches from the cell, from its code 1 .. 15
// (crossing_walk.cube_reach): sides 1, 3, 5, 7, 9, 13, 17, 25, 33, ..., 257.
int cubeReach(int code) {
    return code <= 5 ? 2 * code - 2 : (12 + 4 * (code & 1)) << ((code - 6) >> 1);
}

// Where the ray leaves the box of cells [lo, hi] (cell indices, inclusive).
float boxExit(vec3 origin, vec3 inv_dir, vec3 dir, ivec3 lo, ivec3 hi) {
    vec3 far_face = mix(vec3(lo), vec3(hi + 1), greaterThan(dir, vec3(0.0))) * u_spacing;
    vec3 t_far = mix((far_face - origin) * inv_dir, vec3(3.0e38), equal(dir, vec3(0.0)));
    return min(t_far.x, min(t_far.y, t_far.z));
}

// Whether the value s lies where the TF may have opacity (the support, ends included).
bool inSupport(float s) {
    return s >= u_support.x - u_cw_tol && s <= u_support.y + u_cw_tol;
}

// Composite the ray's [t0, t1] front to back into (color, alpha_acc). A round of the
// outer loop takes one cell whose corners may show something: a loop of its own first
// passes over the cubes of empty cells in front of it; the cell's cubic is made; and
// a third loop reads the cell's pieces with opacity, each round passing first over the
// stretch outside the support in front of its piece (from turning point or cell entry
// to the crossing into the support). llvmpipe runs a loop's body for a group of pixels
// while any of them is in it, every branch of it for all of them: each loop holds only
// its own work, and the pieces of a cell are read together. (A round per cell, with its
// pieces in a loop inside it and the rest of the cell's work in loops of at most one
// round, which llvmpipe passes over when no pixel of the group enters, was slower.)
void crossingWalk(vec3 origin, vec3 dir, float t0, float t1, inout vec3 color, inout float alpha_acc) {
    vec3 inv_dir = 1.0 / dir;
    vec3 origin_c = origin / u_spacing, dir_c = dir / u_spacing;   // in cells
    float t = t0;                 // the next cell's entry
    int r = 0;
    float nudge = 1e-5 * min(u_spacing.x, min(u_spacing.y, u_spacing.z));
    // the ray's octant: its cubes' codes, and the axes along which they lie below the cell
    ivec3 falls = ivec3(lessThan(dir, vec3(0.0)));
    uint octant_bits = uint(4 * (falls.x + 2 * falls.y + 4 * falls.z));
    for (; t < t1 && r < u_cw_rounds; ++r) {
        // find the next cell whose cubic reaches the support
        bool shows = false;
        vec4 cubic = vec4(0.0);
        float t_a = 0.0, span = 0.0;   // its stretch of ray [t_a, t_a + span]
        float u1 = 1.0, u2 = 1.0;      // the cubic's turning points in it (1: none)
        float e1 = 0.0, e2 = 0.0, e_end = 0.0;   // its values there and at the end
        for (; !shows && t < t1 && r < u_cw_rounds; ++r) {
            ivec3 cell = cellAhead(origin_c, dir_c, t);
            uint word = texelFetch(t_walk_map, cell, 0).r;
            // (a loop behind an if: llvmpipe runs a loop's body once even where no pixel of
            // the group enters it, but passes over an if none of them takes)
            if ((word & 15u) != 0u) for (; (word & 15u) != 0u && t < t1 && r < u_cw_rounds; ++r) {
                // the cube of cells from this one towards the ray's octant is empty (at
                // least a hundred-thousandth of a cell on: rounding at the cube's faces)
                int reach = cubeReach(int((word >> octant_bits) & 15u));
                t = max(boxExit(origin, inv_dir, dir, cell - reach * falls, cell + reach * (1 - falls)), beyond(t, nudge));
                cell = cellAhead(origin_c, dir_c, t);
                word = texelFetch(t_walk_map, cell, 0).r;
            }
            if (t >= t1) break;
            float t_out = boxExit(origin, inv_dir, dir, cell, cell);
            t_a = t;
            float t_b = min(t_out, t1);
            t = t_b > t_a ? t_b : max(t_out, beyond(t, nudge));
            span = t_b - t_a;
            if (span <= 0.0) continue;
            cubic = cellCubic((word & 15u) == 0u ? int(word >> 4u) : 0, origin_c + t_a * dir_c - vec3(cell),
                              origin_c + t_b * dir_c - vec3(cell));
            // the cubic lies within the range of its Bernstein coefficients on [0, 1]
            vec4 bern = vec4(cubic.x, cubic.x + cubic.y / 3.0, cubic.x + (2.0 * cubic.y + cubic.z) / 3.0,
                             cubic.x + cubic.y + cubic.z + cubic.w);
            shows = max(max(bern.x, bern.y), max(bern.z, bern.w)) >= u_support.x
                    && min(min(bern.x, bern.y), min(bern.z, bern.w)) <= u_support.y;
        }
        if (!shows) break;
        // its turning points, and its values there and at the end: its range over the
        // stretch and over what is left of it after a piece
        u1 = nextTurn(cubic, 0.0);
        u2 = nextTurn(cubic, u1);
        e1 = cubicAt(cubic, u1);
        e2 = cubicAt(cubic, u2);
        e_end = cubicAt(cubic, 1.0);
        float u = 0.0, s = cubic.x;    // the next piece's front, in the stretch, and its value
        if (shows) for (; u < 1.0 && r < u_cw_rounds; ++r) {
            float u_turn = u1 > u ? u1 : (u2 > u ? u2 : 1.0);
            float s_turn = u1 > u ? e1 : (u2 > u ? e2 : e_end);
            if (!inSupport(s)) {
                // outside the support: on to where the cubic next enters it, else its turn
                float edge = s < u_support.x ? u_support.x : u_support.y;
                bool enters = (s_turn - edge) * (s - edge) <= 0.0;
                u = enters ? crossingOf(cubic, u, s, u_turn, s_turn, edge) : u_turn;
                s = enters ? edge : s_turn;
                if (!enters) continue;
                u_turn = u1 > u ? u1 : (u2 > u ? u2 : 1.0);
                s_turn = u1 > u ? e1 : (u2 > u ? e2 : e_end);
            }
            float u_end = min(u_turn, u + u_cw_part / span);
            float s_end = u_end == u_turn ? s_turn : cubicAt(cubic, u_end);
            float s_next;
            float u_next = nextCrossing(cubic, u, s, u_end, s_end, s_next);
            float len = (u_next - u) * span;
            // the table's straight line moved to the cubic's mean over the piece (Simpson's
            // rule, exact for a cubic): over a piece where the TF is one line the opacity
            // then depends only on that mean, so the piece's opacity is exact
            float shift = (4.0 * cubicAt(cubic, 0.5 * (u + u_next)) - 2.0 * (s + s_next)) / 6.0;
            vec4 piece = preintegratedSegmentIn(2 * u_pi_size, s + shift, s_next + shift, len, u_cw_nominal);
            vec3 p = origin + (t_a + 0.5 * (u + u_next) * span) * dir;
            compositePremultiplied(color, alpha_acc, litSegment(piece, p, dir));
            u = u_next;
            s = s_next;
            // left the support, and no value still ahead (at a turn or the end) is back in
            // it: the cell is done
            float ahead_hi = max(e_end, max(u2 > u ? e2 : e_end, u1 > u ? e1 : e_end));
            float ahead_lo = min(e_end, min(u2 > u ? e2 : e_end, u1 > u ? e1 : e_end));
            bool returns = s < u_support.x ? ahead_hi >= u_support.x : ahead_lo <= u_support.y;
            // on an edge of the support and moving out of it (a piece cut at the crossing
            // ends there): what follows up to the next turn has no opacity
            float s_ahead = u1 > u ? e1 : (u2 > u ? e2 : e_end);
            bool leaving = (s >= u_support.y - u_cw_tol && s_ahead > s) || (s <= u_support.x + u_cw_tol && s_ahead < s);
            u = (inSupport(s) && !leaving) || returns ? u : 1.0;
        }
  #if EARLY_RAY_TERMINATION
        if (1.0 - alpha_acc < u_ert_transmittance) break;
  #endif
        if (alpha_acc >= 1.0) break;
    }
}

#endif
