// Opacity correction and front-to-back compositing (NumPy twins: reference.common).
#ifndef DVR_COMPOSITING_GLSL
#define DVR_COMPOSITING_GLSL

// log(1 + x) and exp(x) - 1 keeping relative precision for small x (GLSL has neither);
// the classic tricks divide out the rounding of 1 + x and of exp(x).
float log1pAccurate(float x) {
    float u = 1.0 + x;
    return (u == 1.0) ? x : log(u) * (x / (u - 1.0));
}

float expm1Accurate(float x) {
    float u = exp(x);
    if (u == 1.0) return x;
    float um1 = u - 1.0;
    return (um1 == -1.0) ? -1.0 : um1 * (x / log(u));
}

// Opacity of a segment length_over_unit unit distances long: 1 - (1 - alpha)^(L/u).
// alpha = 1 gives 1 for any positive length; zero length gives 0.
float correctOpacity(float alpha, float length_over_unit) {
    if (length_over_unit <= 0.0) return 0.0;
    if (alpha >= 1.0) return 1.0;
    return -expm1Accurate(length_over_unit * log1pAccurate(-alpha));
}

// The over operator on associated colour, front to back; transmittance = 1 - alpha_acc.
void compositeFrontToBack(inout vec3 color, inout float transmittance, vec3 rgb, float alpha) {
    color += (transmittance * alpha) * rgb;
    transmittance *= 1.0 - alpha;
}

#endif
