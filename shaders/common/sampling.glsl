// Volume sampling: world positions (relative to the box's lower corner) to texture
// coordinates, trilinear lookups, the masked-cell test (NumPy twin: reference.common).
#ifndef DVR_SAMPLING_GLSL
#define DVR_SAMPLING_GLSL

#ifndef MASK_NONFINITE
#define MASK_NONFINITE 0
#endif
#ifndef PRECISE
#define PRECISE   // common/precise.glsl, where a shader includes it first
#endif
#ifndef TEXTURE_FILTER_EXACT
#define TEXTURE_FILTER_EXACT 0   // 1: the texture unit's linear filter has float weights (set
                                 // per context by the program cache); 0: interpolate fetches
#endif

#ifndef BRICK_INTEGER
#define BRICK_INTEGER 0          // bricks (bricks.py) of integer data: 1 unsigned, 2 signed texels
#endif
#ifndef BRICK_NORMALIZED
#define BRICK_NORMALIZED 0       // bricks of integer data as 16-bit normalised texels
#endif
#if BRICK_INTEGER == 1
uniform usampler3D t_volume;  // the data's own integers, exact
#elif BRICK_INTEGER == 2
uniform isampler3D t_volume;
#else
uniform sampler3D t_volume;   // float32 samples in data units; texel centres are samples
#endif
uniform vec3 u_dims;          // samples per axis (nx, ny, nz)
uniform vec3 u_spacing;       // world units per sample step
#if MASK_NONFINITE
uniform sampler3D t_cell_valid;  // one texel per cell: 1 if all 8 corners are finite
#endif

// p is measured from the first sample; texel centres sit at (i + 0.5) / n.
vec3 worldToTex(vec3 p_world) {
    return (p_world / u_spacing + 0.5) / u_dims;
}

// Trilinear interpolation from texel fetches, x in texel units (centres at integers),
// clamped to the edge as the texture unit would. GPUs commonly quantise the filter's
// weights to 8 bits, an error of up to 1/512 of the jump between neighbouring samples
// per axis; llvmpipe's weights are float and its texture() is used instead.
vec4 fetchTrilinear(sampler3D t, vec3 x) {
    ivec3 last = textureSize(t, 0) - 1;
    vec3 xc = clamp(x, vec3(0.0), vec3(last));
    vec3 lo = floor(xc);
    vec3 f = xc - lo;
    ivec3 a = ivec3(lo);
    ivec3 b = min(a + 1, last);
    // (precise: the same weights and values give the same number in every shader)
    PRECISE vec4 x00 = mix(texelFetch(t, a, 0), texelFetch(t, ivec3(b.x, a.y, a.z), 0), f.x);
    PRECISE vec4 x10 = mix(texelFetch(t, ivec3(a.x, b.y, a.z), 0), texelFetch(t, ivec3(b.x, b.y, a.z), 0), f.x);
    PRECISE vec4 x01 = mix(texelFetch(t, ivec3(a.x, a.y, b.z), 0), texelFetch(t, ivec3(b.x, a.y, b.z), 0), f.x);
    PRECISE vec4 x11 = mix(texelFetch(t, ivec3(a.x, b.y, b.z), 0), texelFetch(t, b, 0), f.x);
    PRECISE vec4 value = mix(mix(x00, x10, f.y), mix(x01, x11, f.y), f.z);
    return value;
}

// The same in a layer of a 2D array texture (2D slicing's stacks), x in texel units.
vec4 fetchBilinear(sampler2DArray t, vec2 x, int layer) {
    ivec2 last = textureSize(t, 0).xy - 1;
    vec2 xc = clamp(x, vec2(0.0), vec2(last));
    vec2 lo = floor(xc);
    vec2 f = xc - lo;
    ivec2 a = ivec2(lo);
    ivec2 b = min(a + 1, last);
    vec4 y0 = mix(texelFetch(t, ivec3(a, layer), 0), texelFetch(t, ivec3(b.x, a.y, layer), 0), f.x);
    vec4 y1 = mix(texelFetch(t, ivec3(a.x, b.y, layer), 0), texelFetch(t, ivec3(b, layer), 0), f.x);
    return mix(y0, y1, f.y);
}

#ifndef BRICKED
#define BRICKED 0
#endif
#if BRICKED
uniform vec3 u_brick_origin;  // the brick texture's first sample (whole numbers; bricks.py)
uniform vec3 u_brick_texels;  // its samples per axis
#endif

// The volume's texel coordinate of a world point and a brick's (a whole number less,
// exactly), both precise (common/precise.glsl): a GPU compiler left to itself fuses the
// brick's p / spacing - origin into one FMA, which rounds p / spacing's product once
// instead of twice and moves the brick's coordinate off the volume's by its rounding.
vec3 volumeTexel(vec3 p_world) {
    PRECISE vec3 x = p_world / u_spacing;
    return x;
}
#if BRICKED
vec3 brickTexel(vec3 p_world) {
    PRECISE vec3 x_volume = p_world / u_spacing;
    PRECISE vec3 x = x_volume - u_brick_origin;
    return x;
}
#endif

// A 3D texture whose texel centres are the samples, at a world point.
vec4 filteredAt(sampler3D t, vec3 p_world) {
#if BRICKED
    vec3 x = brickTexel(p_world);
  #if TEXTURE_FILTER_EXACT
    return texture(t, (x + 0.5) / u_brick_texels);
  #else
    return fetchTrilinear(t, x);
  #endif
#elif TEXTURE_FILTER_EXACT
    return texture(t, worldToTex(p_world));
#else
    return fetchTrilinear(t, volumeTexel(p_world));
#endif
}

#if BRICK_INTEGER
// fetchTrilinear over an integer brick: the same arithmetic on the same (exactly
// converted) values, so the same numbers as a float texture read by fetches
float sampleVolume(vec3 p_world) {
    ivec3 last = textureSize(t_volume, 0) - 1;
    vec3 xc = clamp(brickTexel(p_world), vec3(0.0), vec3(last));
    vec3 lo = floor(xc);
    vec3 f = xc - lo;
    ivec3 a = ivec3(lo);
    ivec3 b = min(a + 1, last);
#define BRICK_TEXEL(i, j, k) vec4(texelFetch(t_volume, ivec3(i, j, k), 0))
    PRECISE vec4 x00 = mix(BRICK_TEXEL(a.x, a.y, a.z), BRICK_TEXEL(b.x, a.y, a.z), f.x);
    PRECISE vec4 x10 = mix(BRICK_TEXEL(a.x, b.y, a.z), BRICK_TEXEL(b.x, b.y, a.z), f.x);
    PRECISE vec4 x01 = mix(BRICK_TEXEL(a.x, a.y, b.z), BRICK_TEXEL(b.x, a.y, b.z), f.x);
    PRECISE vec4 x11 = mix(BRICK_TEXEL(a.x, b.y, b.z), BRICK_TEXEL(b.x, b.y, b.z), f.x);
#undef BRICK_TEXEL
    PRECISE vec4 value = mix(mix(x00, x10, f.y), mix(x01, x11, f.y), f.z);
    return value.r;
}
#elif BRICK_NORMALIZED
// bricks of 8- or 16-bit integers as 16-bit normalised texels of the sample less the
// brick's least: the texture unit filters them with float weights where this is used
uniform float u_brick_offset;
float sampleVolume(vec3 p_world) {
    return filteredAt(t_volume, p_world).r * 65535.0 + u_brick_offset;
}
#else
float sampleVolume(vec3 p_world) {
    return filteredAt(t_volume, p_world).r;
}
#endif

#if MASK_NONFINITE
bool insideValidCell(vec3 p_world) {
    ivec3 cell = clamp(ivec3(floor(p_world / u_spacing)), ivec3(0), ivec3(u_dims) - 2);
    return texelFetch(t_cell_valid, cell, 0).r > 0.5;
}
#endif

#endif
