// The emission-absorption integral of a segment along which the field is linear
// (NumPy twin: reference.linear_segment, whose docstring derives it): cut at the transfer
// function's knots; per piece the optical depth in closed form and the colour by parts,
// its one integral by Gauss-Legendre (2 to 8 points); pieces composited front to back.
// Absorption only keeps the opacity; emission only adds each piece's closed-form
// integral of c tau and returns (that colour, the segment's optical depth): the caller
// weighs colour terms by the depth, then sets alpha to 0 (nothing absorbs).
#ifndef DVR_LINEAR_SEGMENT_GLSL
#define DVR_LINEAR_SEGMENT_GLSL

#include "common/compositing.glsl"

#ifndef KNOT_CAPACITY
#define KNOT_CAPACITY 4
#endif
#ifndef OPTICAL_MODEL
#define OPTICAL_MODEL 0   // 0 emission-absorption, 1 absorption only, 2 emission only
#endif
// 0 where no knot has opacity 1 (techniques.tetra.opaque_knots, per TF): the code for
// a piece that reaches opacity 1 (the ray ends there; graded parts) is then left out. A
// GPU of SIMD lanes (llvmpipe) runs a branch taken by any pixel of a group for all of
// them, so code that is never taken still costs where the compiler cannot see it is not.
#ifndef SEG_OPAQUE
#define SEG_OPAQUE 1
#endif

// The transfer function's knots as uniforms (cheaper to index than a texture):
// u_knot_color[k] = (s, r, g, b), u_knot_opacity[k] = (alpha, 1 - alpha, 0, 0)
uniform vec4 u_knot_color[KNOT_CAPACITY];
uniform vec4 u_knot_opacity[KNOT_CAPACITY];
uniform int u_knot_count;    // 2 <= count <= KNOT_CAPACITY
uniform float u_inv_unit;    // 1 / unit_distance

const int SEG_MAX_PARTS = 16;
const int SEG_GRADED_PARTS = 24;
const float SEG_DEEP = 30.0;
// Gauss-Legendre rules on [0, 1], 2, 3, 4 and 8 points, one after the other
const float GL_X[17] = float[17](0.21132486540518713, 0.78867513459481287,
    0.1127016653792583, 0.5, 0.8872983346207417,
    0.069431844202973714, 0.33000947820757187, 0.66999052179242813, 0.93056815579702623,
    0.019855071751231912, 0.10166676129318664, 0.2372337950418355, 0.40828267875217511,
    0.59171732124782483, 0.7627662049581645, 0.89833323870681336, 0.98014492824876809);
const float GL_W[17] = float[17](0.5, 0.5,
    0.27777777777777785, 0.44444444444444442, 0.27777777777777785,
    0.17392742256872679, 0.32607257743127321, 0.32607257743127321, 0.17392742256872679,
    0.050614268145188532, 0.11119051722668721, 0.15685332293894344, 0.18134189168918083,
    0.18134189168918083, 0.15685332293894344, 0.11119051722668721, 0.050614268145188532);

float knotValue(int k) { return u_knot_color[k].r; }

// Colour, alpha and transparency at a and at b on the line of interval j (constant beyond
// the ends), its knots read once.
void knotLines(int j, float a, float b, out vec3 ca, out float aa, out float wa, out vec3 cb, out float ab,
               out float wb) {
    int jj = clamp(j, 0, u_knot_count - 2);
    vec4 r0 = u_knot_color[jj];
    vec4 r1 = u_knot_color[jj + 1];
    vec4 q0 = u_knot_opacity[jj];
    vec4 q1 = u_knot_opacity[jj + 1];
    float fa = j < 0 ? 0.0 : (j >= u_knot_count - 1 ? 1.0 : clamp((a - r0.r) / (r1.r - r0.r), 0.0, 1.0));
    float fb = j < 0 ? 0.0 : (j >= u_knot_count - 1 ? 1.0 : clamp((b - r0.r) / (r1.r - r0.r), 0.0, 1.0));
    ca = mix(r0.gba, r1.gba, fa);
    aa = mix(q0.r, q1.r, fa);
    wa = mix(q0.g, q1.g, fa);
    cb = mix(r0.gba, r1.gba, fb);
    ab = mix(q0.r, q1.r, fb);
    wb = mix(q0.g, q1.g, fb);
}

// Colour, alpha and transparency at s on the line of interval j (constant beyond the ends).
void knotLine(int j, float s, out vec3 c, out float a, out float w) {
    vec3 c_unused;
    float a_unused, w_unused;
    knotLines(j, s, s, c, a, w, c_unused, a_unused, w_unused);
}

// H(x) by the first `terms` terms of its series (x^k / (k (k + 1)), alternating): 8 for
// |x| < 0.1, 12 for |x| <= 0.3 leave under 1e-9 (a constant count: the loop unrolls).
float meanLog1pSeries(float x, int terms) {
    float acc = 0.0;
    for (int k = terms; k >= 1; k--) acc = x * (1.0 / float(k * (k + 1)) - acc);
    return acc;
}

// H(x): the mean of ln(1 + x g) over g in [0, 1], x >= -1 (the series below |x| = 0.1).
float meanLog1p(float x) {
    if (abs(x) < 0.1) return meanLog1pSeries(x, 8);
    if (x <= -1.0) return -1.0;
    return (1.0 + x) * log(1.0 + x) / x - 1.0;
}

// G(x): the integral of g ln(1 + x g) over g in [0, 1], x > -1 (series below |x| = 0.1).
float meanFLog1p(float x) {
    if (abs(x) < 0.1) {
        float acc = 0.0;
        for (int k = 8; k >= 1; k--) acc = x * (1.0 / float(k * (k + 2)) - acc);
        return acc;
    }
    float l1 = log(1.0 + x);
    return 0.5 * l1 - (0.5 * x * x - x + l1) / (2.0 * x * x);
}

// Optical depth from a piece's start to fraction f of it (w = 1 - alpha going linearly
// from w_a to w_a (1 + r); nlw = -ln w_a; l_over_u = piece length / unit distance).
float opticalDepthTo(float f, float nlw, float r, float l_over_u) {
    return l_over_u * f * (nlw - meanLog1p(r * f));
}

// T(f) - T(1) at fraction f of a piece of optical depth od (0 beyond SEG_DEEP).
float nodeTerm(float f, float nlw, float r, float lu, float od) {
    float od_to = opticalDepthTo(f, nlw, r, lu);
    return od_to < SEG_DEEP ? exp(-od_to) * -expm1Accurate(-max(od - od_to, 0.0)) : 0.0;
}

// nodeTerm where |r| <= 0.01 and od <= 0.01: the same quantities by short series
// (each truncation below 1e-12 relative there).
float thinNodeTerm(float f, float nlw, float r, float lu, float od) {
    float x = r * f;
    float h = x * (0.5 - x * (1.0 / 6.0 - x * (1.0 / 12.0 - x * (1.0 / 20.0))));
    float od_to = lu * f * (nlw - h);
    float d = max(od - od_to, 0.0);
    float t = 1.0 - od_to * (1.0 - od_to * (0.5 - od_to * (1.0 / 6.0 - od_to * (1.0 / 24.0))));
    float e = d * (1.0 - d * (0.5 - d * (1.0 / 6.0 - d * (1.0 / 24.0))));
    return t * e;
}

// Count of knots <= s (strict = false) or < s (strict = true): binary search.
int knotsBelow(float s, bool strict) {
    int lo = 0, hi = u_knot_count;
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        float k = knotValue(mid);
        if (strict ? k < s : k <= s) lo = mid + 1; else hi = mid;
    }
    return lo;
}

// Where the piece of interval j ends on a segment going up (or down) to s_back: at the
// interval's next knot in that direction, or at s_back if it comes first.
float pieceEnd(int j, bool up, float s_back) {
    if (up) return j + 1 <= u_knot_count - 1 ? min(knotValue(j + 1), s_back) : s_back;
    return j >= 0 ? max(knotValue(j), s_back) : s_back;
}

// Premultiplied (C, A) of a segment len long, the field going linearly from s_front
// (nearest the eye) to s_back, with the colour times a factor going linearly from
// q_front to q_back along it (a depth cue; 1 and 1 without one). cued_alpha is the
// opacity weighted the same way: what a colour added along the segment is multiplied by.
vec4 linearSegmentCued(float s_front, float s_back, float len, float q_front, float q_back, out float cued_alpha) {
    cued_alpha = 0.0;
    if (len <= 0.0) return vec4(0.0);
    bool up = s_back >= s_front;
    int j = up ? knotsBelow(s_front, false) - 1 : knotsBelow(s_front, true) - 1;
    float ds = abs(s_back - s_front);
    vec3 color = vec3(0.0);
    float alpha_acc = 0.0;
    float a = s_front;
    for (int piece = 0; piece <= u_knot_count; piece++) {
        float b = pieceEnd(j, up, s_back);
        float l = ds > 0.0 ? len * (abs(b - a) / ds) : len;
        vec3 ca, cb;
        float aa, wa, ab, wb;
        knotLines(j, a, b, ca, aa, wa, cb, ab, wb);
        // the factor at the piece's ends (linear along the segment, as the field is)
        float qa = ds > 0.0 ? mix(q_front, q_back, abs(a - s_front) / ds) : q_front;
        float qb = ds > 0.0 ? mix(q_front, q_back, abs(b - s_front) / ds) : q_back;
#if SEG_OPAQUE
        if (wa <= 0.0) {                       // alpha = 1 here: the ray ends
            cued_alpha += (1.0 - alpha_acc) * qa;
            compositeFrontToBack(color, alpha_acc, ca * qa, 1.0);
            break;
        }
#endif
#if OPTICAL_MODEL == 2
        // emission only: the integral of c tau over the piece, nothing absorbed (alpha < 1
        // everywhere: the scene refuses opacity 1)
        if (l > 0.0 && (aa > 0.0 || ab > 0.0)) {
            float nlw = aa <= 0.5 ? -log1pAccurate(-aa) : -log(wa);
            float r = (wb - wa) / wa;
            color += l * u_inv_unit * (nlw * (ca + 0.5 * (cb - ca)) - ca * meanLog1p(r) - (cb - ca) * meanFLog1p(r));
            float od = opticalDepthTo(1.0, nlw, r, l * u_inv_unit);
            alpha_acc += od;           // the weight of an added colour (the caller zeroes alpha)
            cued_alpha += od;
        }
        a = b;
        if ((up && a >= s_back) || (!up && a <= s_back)) break;
        j += up ? 1 : -1;
        continue;
#endif
        if (l > 0.0 && (aa > 0.0 || ab > 0.0)) {
            float lu = l * u_inv_unit;
            float nlw = aa <= 0.5 ? -log1pAccurate(-aa) : -log(wa);
            float r = (wb - wa) / wa;
            float od = opticalDepthTo(1.0, nlw, r, lu);
            float A = -expm1Accurate(-od);
#if SEG_OPAQUE
            bool graded = wb <= 0.0;
#else
            const bool graded = false;         // no knot of opacity 1: wb > 0
#endif
            int parts = graded ? SEG_GRADED_PARTS : int(clamp(ceil(od), 1.0, float(SEG_MAX_PARTS)));
            // points per part: fewer on thin pieces of nearly constant opacity (NumPy: node_count)
            float ar = abs(r);
            int first = 9, count = 8;
            if (!graded && od <= 0.01 && ar <= 0.01) { first = 0; count = 2; }
            else if (!graded && od <= 0.1 && ar <= 0.1) { first = 2; count = 3; }
            else if (!graded && od <= 0.3 && ar <= 0.3) { first = 5; count = 4; }
            float mean = 0.0;              // the mean of T(f) - T(1) over the piece
            float mean_f = 0.0;            // ... of f (T(f) - T(1)), for a depth cue
            if (count == 2) {              // the common thin piece: straight-line code
                float n0 = thinNodeTerm(GL_X[0], nlw, r, lu, od), n1 = thinNodeTerm(GL_X[1], nlw, r, lu, od);
                mean = 0.5 * (n0 + n1);
                mean_f = 0.5 * (GL_X[0] * n0 + GL_X[1] * n1);
            } else {
                // the parts' nodes in one loop, part by part: pixels shaded together (in
                // lockstep, as llvmpipe's lanes are) then wait for the most nodes any of
                // them has, not for the most parts times the most points per part
                int p = 0, i = first;
                for (int n = 0; n < parts * count; n++, i++) {
                    if (i == first + count) {      // the next part
                        i = first;
                        p++;
                    }
                    float f0 = graded ? 1.0 - exp2(-float(p)) : float(p) / float(parts);
                    float f1 = graded ? (p == parts - 1 ? 1.0 : 1.0 - exp2(-float(p + 1))) : float(p + 1) / float(parts);
                    float f = f0 + GL_X[i] * (f1 - f0);
                    float term = GL_W[i] * (f1 - f0) * nodeTerm(f, nlw, r, lu, od);
                    mean += term;
                    mean_f += f * term;
                }
            }
            // by parts, with g = c q along the piece: C = g(0) A + integral g'(f) (T(f) - T(1))
            float dq = qb - qa;
            vec3 C = ca * qa * A + ((cb - ca) * qa + ca * dq) * mean + 2.0 * (cb - ca) * dq * mean_f;
            float Q = qa * A + dq * mean;          // the same for the opacity weighted by q
#if SEG_OPAQUE
            if (graded) {                      // alpha = 1 at the far end: the ray ends there
                C += exp(-od) * cb * qb;
                Q += exp(-od) * qb;
                A = 1.0;
            }
#endif
            // C is already associated: composite it with the piece's opacity
            float weight = 1.0 - alpha_acc;
            color += weight * C;
            cued_alpha += weight * Q;
            alpha_acc += weight * A;
#if SEG_OPAQUE
            if (graded) break;
#endif
        }
        a = b;
        if ((up && a >= s_back) || (!up && a <= s_back)) break;
        j += up ? 1 : -1;
    }
#if OPTICAL_MODEL == 1
    color = vec3(0.0);      // absorption only
#endif
    return vec4(color, alpha_acc);
}

// The common segment, light: each of its pieces (cut at the knots) of optical depth and
// relative change of transparency at most 0.3, and none reaching opacity 1. Integrated as
// linearSegment does, but each piece by 4 Gauss-Legendre points (linearSegment takes 2 to
// 4 there, by the rule of node_count, which keeps the rule's error below ~5e-8) in
// straight-line code: no parts, no choice of rule, no series-or-function branches, which
// lanes shaded in lockstep (llvmpipe) pay for whether any takes them or not. light =
// false: not such a segment (use linearSegment; the value returned is not used).
vec4 lightSegment(float s_front, float s_back, float len, out bool light) {
    bool up = s_back >= s_front;
#if KNOT_CAPACITY <= 8
    int below = 0;                          // knotsBelow(s_front, !up), the knots unrolled
    for (int k = 0; k < KNOT_CAPACITY; ++k) {
        float v = knotValue(k);
        below += k < u_knot_count && (up ? v <= s_front : v < s_front) ? 1 : 0;
    }
    int j = below - 1;
#else
    int j = knotsBelow(s_front, !up) - 1;
#endif
    float ds = abs(s_back - s_front);
    vec3 color = vec3(0.0);
    float alpha_acc = 0.0;
    float a = s_front;
    light = len > 0.0;
    for (int piece = 0; piece <= u_knot_count; piece++) {     // as linearSegment's pieces
        float b = pieceEnd(j, up, s_back);
        float l = ds > 0.0 ? len * (abs(b - a) / ds) : len;
        vec3 ca, cb;
        float aa, wa, ab, wb;
        knotLines(j, a, b, ca, aa, wa, cb, ab, wb);
        float lu = l * u_inv_unit;
        float nlw = aa <= 0.5 ? -log1pSeries(-aa) : -log(wa);
        float r = (wb - wa) / wa;
        float od = lu * (nlw - meanLog1pSeries(r, 12));
        bool adds = l > 0.0 && (aa > 0.0 || ab > 0.0);
        light = light && (!adds || (wb > 0.0 && od <= 0.3 && abs(r) <= 0.3));
        float A = adds ? -expm1Series(-od) : 0.0;
        // the mean of T(f) - T(1) = T(1) (exp(od - od(f)) - 1) over the piece: no exponential
        // per point, and each point's series only as long as its arguments need for 1e-9
        // (|r f| <= 0.3 f; od - od(f) at most 1.0, 0.9, 0.57, 0.14 of od <= 0.3)
        float mean = GL_W[5] * expm1Short(max(od - lu * GL_X[5] * (nlw - meanLog1pSeries(r * GL_X[5], 4)), 0.0), 8)
                   + GL_W[6] * expm1Short(max(od - lu * GL_X[6] * (nlw - meanLog1pSeries(r * GL_X[6], 7)), 0.0), 7)
                   + GL_W[7] * expm1Short(max(od - lu * GL_X[7] * (nlw - meanLog1pSeries(r * GL_X[7], 10)), 0.0), 6)
                   + GL_W[8] * expm1Short(max(od - lu * GL_X[8] * (nlw - meanLog1pSeries(r * GL_X[8], 12)), 0.0), 4);
        mean *= 1.0 - A;
        float weight = 1.0 - alpha_acc;
        color += adds ? weight * (ca * A + (cb - ca) * mean) : vec3(0.0);
        alpha_acc += weight * A;
        a = b;
        if ((up && a >= s_back) || (!up && a <= s_back)) break;
        j += up ? 1 : -1;
    }
    return vec4(color, alpha_acc);
}

// Without a factor along the segment.
vec4 linearSegment(float s_front, float s_back, float len) {
    float unused;
    return linearSegmentCued(s_front, s_back, len, 1.0, 1.0, unused);
}

#endif
