// Sabella (1988) colouring (NumPy twin: reference.common.sabella_color): the ray's
// brightness is its integrated intensity I (a white emitter: the opacity 1 - T), its hue
// that of the TF colour at the ray's peak value, its saturation that colour's, fading
// with the peak's depth d in [0, 1].
#ifndef DVR_SABELLA_GLSL
#define DVR_SABELLA_GLSL

vec3 rgbToHsv(vec3 c) {
    float mx = max(c.r, max(c.g, c.b));
    float mn = min(c.r, min(c.g, c.b));
    float delta = mx - mn;
    float h = 0.0;
    if (delta > 0.0) {
        if (mx == c.r) h = (c.g - c.b) / delta;
        else if (mx == c.g) h = 2.0 + (c.b - c.r) / delta;
        else h = 4.0 + (c.r - c.g) / delta;
        h = fract(h / 6.0);
    }
    return vec3(h, mx > 0.0 ? delta / mx : 0.0, mx);
}

vec3 hsvToRgb(vec3 hsv) {
    vec3 k = clamp(abs(fract(hsv.x + vec3(0.0, 2.0, 1.0) / 3.0) * 6.0 - 3.0) - 1.0, 0.0, 1.0);
    return hsv.z * mix(vec3(1.0), k, hsv.y);
}

vec4 sabellaColor(vec3 peak_color, float intensity, float depth) {
    vec3 hsv = rgbToHsv(peak_color);
    vec3 rgb = hsvToRgb(vec3(hsv.x, hsv.y * (1.0 - clamp(depth, 0.0, 1.0)), 1.0));
    return vec4(rgb * intensity, intensity);
}

#endif
