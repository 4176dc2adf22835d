// Isosurface hit refinement (NumPy twin: reference.raycast.refine_iso_bisection).
#ifndef DVR_ISOSURFACE_GLSL
#define DVR_ISOSURFACE_GLSL
#include "common/sampling.glsl"

#ifndef ISO_BISECTION_STEPS
#define ISO_BISECTION_STEPS 16
#endif

// The field's status (s >= iso) differs between ta and tb; halve the interval, keeping
// the half whose ends still differ, and return its midpoint.
float refineIsoBisection(vec3 origin, vec3 dir, float ta, float tb, float iso) {
    bool above_a = sampleVolume(origin + ta * dir) >= iso;
    for (int i = 0; i < ISO_BISECTION_STEPS; ++i) {
        float tm = 0.5 * (ta + tb);
        bool above_m = sampleVolume(origin + tm * dir) >= iso;
        if (above_m == above_a) ta = tm; else tb = tm;
    }
    return 0.5 * (ta + tb);
}

#endif
