// Gap fragments of the slicing techniques (NumPy twin: reference.common.chord_color).
// A ray whose chord through the box is shorter than the distance between slices may meet
// no slice inside the box (at the silhouette, through edges and corners): no slice
// fragment stands for its segment, so a second pass over the box's back faces integrates
// the whole chord for exactly those pixels. The including shader defines
// segmentColor(origin, dir, a, b), the premultiplied colour of the segment [a, b].
#ifndef DVR_SLICE_GAP_GLSL
#define DVR_SLICE_GAP_GLSL

// more sub-segments than this (a chord nearly parallel to 2D slices, longer than 4096
// slice distances) take longer ones
#define MAX_CHORD_SEGMENTS 4096

// The chord [a, b] in equal sub-segments of at most max_step, front to back.
vec4 chordColor(vec3 origin, vec3 dir, float a, float b, float max_step) {
    int n = int(clamp(ceil((b - a) / max_step), 1.0, float(MAX_CHORD_SEGMENTS)));
    float h = (b - a) / float(n);
    vec4 acc = vec4(0.0);
    for (int i = 0; i < n; ++i) {
        float end = i == n - 1 ? b : a + float(i + 1) * h;
        acc = over(acc, segmentColor(origin, dir, a + float(i) * h, end));
    }
    return acc;
}

#endif
