// Opacity correction and front-to-back compositing (NumPy twins: reference.common).
#ifndef DVR_COMPOSITING_GLSL
#define DVR_COMPOSITING_GLSL
#ifndef PRECISE
#define PRECISE   // common/precise.glsl, where a shader includes it first
#endif

// log(1 + x) and exp(x) - 1 keeping relative precision for small x. GLSL has neither,
// and its log/exp are only absolutely accurate near 1 (llvmpipe's are), so the
// classic division tricks do not help: short series are used near 0 instead.

// For x in [-0.5, 0.5]: log(1 + x) = 2 atanh(z), z = x / (2 + x), |z| <= 1/3; eight odd
// terms leave a relative error below (1/3)^16 / 17 ~ 1e-9.
float log1pSeries(float x) {
    float z = x / (2.0 + x);
    float z2 = z * z;
    float p = 1.0 / 15.0 + z2 * (1.0 / 17.0);
    p = 1.0 / 13.0 + z2 * p;
    p = 1.0 / 11.0 + z2 * p;
    p = 1.0 / 9.0 + z2 * p;
    p = 1.0 / 7.0 + z2 * p;
    p = 1.0 / 5.0 + z2 * p;
    p = 1.0 / 3.0 + z2 * p;
    p = 1.0 + z2 * p;
    return 2.0 * z * p;
}

float log1pAccurate(float x) {
    if (abs(x) > 0.5) return log(1.0 + x);
    return log1pSeries(x);
}

// For |x| <= 0.5: Taylor series to x^10 / 10!, relative error below 0.5^10 / 11! ~ 2.5e-11.
float expm1Series(float x) {
    float p = 1.0 / 3628800.0;
    p = 1.0 / 362880.0 + x * p;
    p = 1.0 / 40320.0 + x * p;
    p = 1.0 / 5040.0 + x * p;
    p = 1.0 / 720.0 + x * p;
    p = 1.0 / 120.0 + x * p;
    p = 1.0 / 24.0 + x * p;
    p = 1.0 / 6.0 + x * p;
    p = 0.5 + x * p;
    p = 1.0 + x * p;
    return x * p;
}

// The same series to x^terms / terms! (x >= 0, a constant count: the loop unrolls), for
// callers that know their argument's bound (common/linear_segment.glsl's lightSegment).
float expm1Short(float x, int terms) {
    float p = 1.0;
    for (int k = terms; k >= 2; k--) p = 1.0 + x * (1.0 / float(k)) * p;
    return x * p;
}

float expm1Accurate(float x) {
    if (abs(x) > 0.5) return exp(x) - 1.0;
    return expm1Series(x);
}

// Opacity of a segment length_over_unit unit distances long: 1 - (1 - alpha)^(L/u),
// as -expm1(L/u * log(1 - alpha)). log(1 - alpha) comes from alpha while alpha <= 0.5
// and from the transparency 1 - alpha above (each where it is precise).
// alpha = 1 gives 1 for any positive length; zero length gives 0.
float correctOpacity(float alpha, float transparency, float length_over_unit) {
    if (length_over_unit <= 0.0) return 0.0;
    if (alpha >= 1.0 || transparency <= 0.0) return 1.0;
    float log_transparency = alpha <= 0.5 ? log1pAccurate(-alpha) : log(transparency);
    return -expm1Accurate(length_over_unit * log_transparency);
}

// The over operator on associated colour, front to back. Accumulating opacity (not
// transmittance) keeps faint pixels' relative precision; with alpha = 1 the sum
// alpha_acc + (1 - alpha_acc) rounds to exactly 1 for any alpha_acc in [0, 1].
void compositeFrontToBack(inout vec3 color, inout float alpha_acc, vec3 rgb, float alpha) {
    float weight = (1.0 - alpha_acc) * alpha;
    color += weight * rgb;
    alpha_acc += weight;
}

// The over operator on premultiplied colours: `front` seen in front of `back` (the
// blending the slicing techniques ask of GL, done in the shader).
vec4 over(vec4 front, vec4 back) {
    PRECISE vec4 seen = front + (1.0 - front.a) * back;   // (fused alike in every pass)
    return seen;
}

// A ray's gathered colour and opacity with a premultiplied piece (a segment's colour
// integral and opacity) behind them.
void compositePremultiplied(inout vec3 color, inout float alpha_acc, vec4 piece) {
    vec4 gathered = over(vec4(color, alpha_acc), piece);
    color = gathered.rgb;
    alpha_acc = gathered.a;
}

#endif
