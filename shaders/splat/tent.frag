// Sheet-buffer splatting, the splat pass: one run's tents at the point where this pixel's
// ray crosses the sheet, added into the sheet buffer (blending ONE, ONE). Of a run along
// u_axis only the two samples around the point can reach it; each adds its tent weight w
// (the product over the axes of 1 - |offset| / spacing). Channel 0: (sum w value, sum w,
// sum w over non-finite samples, 0); with SHADING, channel 1: (sum w gradient, 0).
#version 330 core

#include "common/camera_ray.glsl"
#include "common/slabs.glsl"
#include "common/texel_rows.glsl"

#ifndef SHADING
#define SHADING 0
#endif
#ifndef MASK_NONFINITE
#define MASK_NONFINITE 0
#endif

uniform int u_slice;
uniform int u_axis;
uniform vec3 u_spacing;           // the tent's half-width per axis: one sample spacing
uniform sampler2D t_values;       // per sample in run order: value, 1 if non-finite
#if SHADING
uniform sampler2D t_gradients;    // per sample in run order: gradient
#endif

flat in vec3 v_first;
flat in int v_row;
flat in int v_count;

layout(location = 0) out vec4 f_sheet;
#if SHADING
layout(location = 1) out vec4 f_gradient;
#endif

void addSample(int index, float w, inout vec4 sheet, inout vec3 grad) {
    vec2 record = texelFetch(t_values, texelRow(v_row + index), 0).xy;
#if MASK_NONFINITE
    if (record.y > 0.5) {
        sheet.z += w;
        return;
    }
#endif
    sheet.xy += vec2(w * record.x, w);
#if SHADING
    grad += w * texelFetch(t_gradients, texelRow(v_row + index), 0).xyz;
#endif
}

void main() {
    vec3 origin, dir;
    pixelRay(origin, dir);
    vec3 p = origin + sliceT(u_slice, dot(dir, u_forward)) * dir;   // the sheet pass's own point
    vec3 q = (p - v_first) / u_spacing;        // in spacings from the run's first sample
    float m = q[u_axis];
    q[u_axis] = 0.0;
    vec3 d = abs(q);
    if (any(greaterThanEqual(d, vec3(1.0))) || m <= -1.0 || m >= float(v_count)) discard;
    vec3 across = 1.0 - d;
    float w = across.x * across.y * across.z;  // the other two axes' tent factors
    int i = int(floor(m));
    float f = m - float(i);
    vec4 sheet = vec4(0.0);
    vec3 grad = vec3(0.0);
    if (i >= 0) addSample(i, w * (1.0 - f), sheet, grad);
    if (i + 1 < v_count) addSample(i + 1, w * f, sheet, grad);
    f_sheet = sheet;
#if SHADING
    f_gradient = vec4(grad, 0.0);
#endif
}
