// Ray against an axis-aligned box: entry and exit distances (NumPy twin: reference.common.ray_box).
#ifndef DVR_RAY_BOX_GLSL
#define DVR_RAY_BOX_GLSL

// Returns (t_enter, t_exit); rays start at their origin, so t_enter >= 0. The ray misses
// where t_exit <= t_enter. A direction component of exactly 0 is resolved by whether the
// origin lies inside that slab (IEEE 0 * inf would give NaN).
vec2 intersectBox(vec3 origin, vec3 dir, vec3 lo, vec3 hi) {
    vec3 inv = 1.0 / dir;
    vec3 ta = (lo - origin) * inv;
    vec3 tb = (hi - origin) * inv;
    vec3 tmin = min(ta, tb);
    vec3 tmax = max(ta, tb);
    for (int i = 0; i < 3; ++i) {
        if (dir[i] == 0.0) {
            bool inside = origin[i] >= lo[i] && origin[i] <= hi[i];
            tmin[i] = inside ? -1.0 / 0.0 : 1.0 / 0.0;
            tmax[i] = inside ? 1.0 / 0.0 : -1.0 / 0.0;
        }
    }
    float t0 = max(max(max(tmin.x, tmin.y), tmin.z), 0.0);
    float t1 = min(min(tmax.x, tmax.y), tmax.z);
    return vec2(t0, t1);
}

#endif
