// Bricked ray casting, modes mip, minip and average: classify the state the brick passes
// left (raycast.frag under BRICKED) as the single pass classifies its own at the end.
#version 330 core
#include "common/precise.glsl"

#ifndef MODE_AVERAGE
#define MODE_AVERAGE 0
#endif

#include "common/classification.glsl"

uniform sampler2D t_source;   // mip, minip: (extreme, 1 once a sample is taken); average: (sum of s len, sum of len)
out vec4 f_color;

void main() {
    vec4 state = texelFetch(t_source, ivec2(gl_FragCoord.xy), 0);
    f_color = vec4(0.0);
#if MODE_AVERAGE
    if (state.g > 0.0) {
        PRECISE float mean = state.r / state.g;
        vec4 rgba = applyTF(mean);
        f_color = vec4(rgba.rgb * rgba.a, rgba.a);
    }
#else
    if (state.g > 0.5) {
        vec4 rgba = applyTF(state.r);
        f_color = vec4(rgba.rgb * rgba.a, rgba.a);
    }
#endif
}
