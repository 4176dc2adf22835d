// Volume sampling: world positions (relative to the box's lower corner) to texture
// coordinates, trilinear lookups, the masked-cell test (NumPy twin: reference.common).
#ifndef DVR_SAMPLING_GLSL
#define DVR_SAMPLING_GLSL

#ifndef MASK_NONFINITE
#define MASK_NONFINITE 0
#endif

uniform sampler3D t_volume;   // float32 samples in data units; texel centres are samples
uniform vec3 u_dims;          // samples per axis (nx, ny, nz)
uniform vec3 u_spacing;       // world units per sample step
#if MASK_NONFINITE
uniform sampler3D t_cell_valid;  // one texel per cell: 1 if all 8 corners are finite
#endif

// p is measured from the first sample; texel centres sit at (i + 0.5) / n.
vec3 worldToTex(vec3 p_world) {
    return (p_world / u_spacing + 0.5) / u_dims;
}

float sampleVolume(vec3 p_world) {
    return texture(t_volume, worldToTex(p_world)).r;
}

#if MASK_NONFINITE
bool insideValidCell(vec3 p_world) {
    ivec3 cell = clamp(ivec3(floor(p_world / u_spacing)), ivec3(0), ivec3(u_dims) - 2);
    return texelFetch(t_cell_valid, cell, 0).r > 0.5;
}
#endif

#endif
