// Ray casting several volumes (Scene.layers): each layer meets the pixel-centre ray in its
// own frame; the ray is cut at every layer's entry and exit, each stretch between cuts
// divided into equal segments no longer than u_step and sampled at their midpoints
// (techniques/raycast_layers.py; NumPy twin: reference/raycast_layers.py).
#version 330 core

#ifndef N_LAYERS
#define N_LAYERS 2        // volumes in the scene, its own first (at most 4)
#endif
#ifndef BLEND_ADD
#define BLEND_ADD 0       // 0: one mixed medium; 1: each layer's own image, added
#endif
#ifndef MODE_COMPOSITE
#define MODE_COMPOSITE 0
#endif
#ifndef MODE_MIP
#define MODE_MIP 0
#endif
#ifndef MODE_MINIP
#define MODE_MINIP 0
#endif
#ifndef MODE_AVERAGE
#define MODE_AVERAGE 0
#endif
#ifndef EARLY_RAY_TERMINATION
#define EARLY_RAY_TERMINATION 0
#endif
#ifndef GEOMETRY
#define GEOMETRY 0
#endif
#ifndef SKIP_EMPTY
#define SKIP_EMPTY 0      // composite: jump over bricks empty in every layer holding the ray
#endif
#ifndef LAYER0_OCCUPIED
#define LAYER0_OCCUPIED 0 // layer k has no empty brick (skipping never looks it up)
#endif
#ifndef LAYER1_OCCUPIED
#define LAYER1_OCCUPIED 0
#endif
#ifndef LAYER2_OCCUPIED
#define LAYER2_OCCUPIED 0
#endif
#ifndef LAYER3_OCCUPIED
#define LAYER3_OCCUPIED 0
#endif
#ifndef LAYER0_LABELS
#define LAYER0_LABELS 0   // layer k is a label volume (nearest sample, label table)
#endif
#ifndef LAYER1_LABELS
#define LAYER1_LABELS 0
#endif
#ifndef LAYER2_LABELS
#define LAYER2_LABELS 0
#endif
#ifndef LAYER3_LABELS
#define LAYER3_LABELS 0
#endif

#include "common/camera_ray.glsl"
#include "common/ray_box.glsl"
#include "common/clip.glsl"
#include "common/sampling.glsl"
#include "common/compositing.glsl"

#define N_CUTS (2 * N_LAYERS)

uniform mat3 u_to_layer[N_LAYERS];       // box-relative world to the layer's own frame:
uniform vec3 u_layer_offset[N_LAYERS];   //   q = M p + m, q from the layer's first sample
uniform vec3 u_layer_extent[N_LAYERS];   // its box is [0, extent]
uniform vec3 u_layer_dims[N_LAYERS];     // samples per axis
uniform vec3 u_layer_spacing[N_LAYERS];
uniform vec3 u_layer_class[N_LAYERS];    // table: (value of entry 0, entries per unit, entries)
uniform float u_layer_inv_unit[N_LAYERS];
uniform float u_step;
uniform int u_max_segments;
#if EARLY_RAY_TERMINATION
uniform float u_ert_transmittance;
#endif
#if GEOMETRY
uniform sampler2D t_surface;             // first surface's lit colour and t (techniques.geometry)
#endif

uniform sampler3D t_layer0;
uniform sampler2D t_class0;              // (n, 2) rows: RGBA, then transparency 1 - alpha
#if N_LAYERS > 1
uniform sampler3D t_layer1;
uniform sampler2D t_class1;
#endif
#if N_LAYERS > 2
uniform sampler3D t_layer2;
uniform sampler2D t_class2;
#endif
#if N_LAYERS > 3
uniform sampler3D t_layer3;
uniform sampler2D t_class3;
#endif
#if SKIP_EMPTY
uniform float u_brick;                   // brick edge in cells
uniform vec3 u_occupied_lo[N_LAYERS];    // the box around the layer's occupied bricks, grown
uniform vec3 u_occupied_hi[N_LAYERS];    //   by a sample (its own frame)
uniform sampler3D t_occupancy0;          // per brick of the layer: 1 if anything in it has opacity
  #if N_LAYERS > 1
uniform sampler3D t_occupancy1;
  #endif
  #if N_LAYERS > 2
uniform sampler3D t_occupancy2;
  #endif
  #if N_LAYERS > 3
uniform sampler3D t_occupancy3;
  #endif
#endif

#if COMPUTE_PIXELS
vec4 f_color;                 // stored by common/pixel_store.glsl's main()
#else
out vec4 f_color;
#endif

// A table row at value s, linear between entries (GLSL lerpTableRow with the layer's
// own mapping; NumPy twin: LookupTable.interpolate).
vec4 tableRow(sampler2D table, vec3 cls, float s, int row) {
    float u = clamp((s - cls.x) * cls.y, 0.0, cls.z - 1.0);
    int i0 = min(int(floor(u)), int(cls.z) - 2);
    float f = u - float(i0);
    vec4 a = texelFetch(table, ivec2(i0, row), 0);
    vec4 b = texelFetch(table, ivec2(i0 + 1, row), 0);
    return a * (1.0 - f) + b * f;
}

// The value of layer i at q (its own frame): the trilinear field of a scan, or the label
// of the nearest sample (index rounded, halves upward) of a label volume.
float layerValue(sampler3D volume, int i, bool labels, vec3 q) {
    vec3 x = q / u_layer_spacing[i];
    if (labels) {
        ivec3 index = clamp(ivec3(floor(x + 0.5)), ivec3(0), ivec3(u_layer_dims[i]) - 1);
        return texelFetch(volume, index, 0).r;
    }
#if TEXTURE_FILTER_EXACT
    return texture(volume, (x + 0.5) / u_layer_dims[i]).r;
#else
    return fetchTrilinear(volume, x).r;
#endif
}

// Colour and opacity of layer i's value s (straight colour, unit-distance opacity), and
// its transparency 1 - alpha (precise near 1).
vec4 layerClass(sampler2D table, int i, bool labels, float s, out float transparency) {
    vec3 cls = u_layer_class[i];
    if (labels) {
        int label = int(s + 0.5);
        if (label < 0 || label >= int(cls.z)) {
            transparency = 1.0;
            return vec4(0.0);
        }
        transparency = texelFetch(table, ivec2(label, 1), 0).r;
        return texelFetch(table, ivec2(label, 0), 0);
    }
    vec4 rgba = tableRow(table, cls, s, 0);
    transparency = rgba.a > 0.5 ? tableRow(table, cls, s, 1).r : 1.0 - rgba.a;
    return rgba;
}

// tau = -log(1 - alpha) / u (log1p below alpha 0.5, the stored transparency above);
// opaque where alpha reaches 1.
float extinction(vec4 rgba, float transparency, float inv_unit, out bool opaque) {
    opaque = rgba.a >= 1.0 || transparency <= 0.0;
    if (opaque || rgba.a <= 0.0) return 0.0;
    float log_t = rgba.a <= 0.5 ? log1pAccurate(-rgba.a) : log(transparency);
    return -log_t * inv_unit;
}

// Mixed: layer i's extinction and emission at the midpoint t, where it holds the point,
// added to the medium's (and, where it is opaque, its colour to the opaque ones').
void mixLayer(sampler3D volume, sampler2D table, int i, bool labels, vec3 o, vec3 d, float t, vec2 span,
              inout float tau, inout vec3 emission, inout vec3 opaque_color, inout float opaque_count) {
    if (!(span.x <= t && t <= span.y)) return;
    float transparency;
    vec4 rgba = layerClass(table, i, labels, layerValue(volume, i, labels, o + t * d), transparency);
    bool opaque;
    float tau_i = extinction(rgba, transparency, u_layer_inv_unit[i], opaque);
    tau += tau_i;
    emission += rgba.rgb * tau_i;
    if (opaque) {
        opaque_color += rgba.rgb;
        opaque_count += 1.0;
    }
}

#if SKIP_EMPTY
// Whether layer i's brick holding the ray's point at t is empty; if so t_exit is lowered
// to where the ray (o + t d, the layer's frame) leaves that brick, else recheck is set
// there (no skip can start before: a look-up saved, never a sample).
bool emptyBrick(sampler3D occupancy, int i, vec3 o, vec3 d, float t, inout float t_exit, inout float recheck) {
    vec3 size = u_brick * u_layer_spacing[i];
    ivec3 brick = clamp(ivec3(floor((o + t * d) / size)), ivec3(0), textureSize(occupancy, 0) - 1);
    vec3 lo = vec3(brick) * size;
    vec3 t_far = max((lo - o) / d, (lo + size - o) / d);
    float leave = min(min(t_far.x, t_far.y), t_far.z);
    if (texelFetch(occupancy, brick, 0).r >= 0.5) {
        recheck = leave;
        return false;
    }
    t_exit = min(t_exit, leave);
    return true;
}

// Layer i at t adds nothing from here to t_exit: it does not hold t, it has ended
// (done), or its brick there is empty (never where it has no empty brick: full).
#define SKIP_LAYER(occupancy, i, done, full) \
    if (empty && span[i].x <= t && t <= span[i].y && !(done)) { \
        if (full) { \
            empty = false; \
            recheck = span[i].y; \
        } else { \
            empty = emptyBrick(occupancy, i, o[i], d[i], t, t_exit, recheck); \
        } \
    }
#endif

// Added: layer i's own segment len long at the midpoint t composited into its own
// (colour, opacity) until it ends (composite), or its value into its extreme or its
// integral (mip, minip, average); all_done stays true while every layer has ended.
void addLayer(sampler3D volume, sampler2D table, int i, bool labels, vec3 o, vec3 d, float t, vec2 span,
              float len, inout vec4 acc, inout bool done, inout float best, inout float len_sum,
              inout bool all_done) {
    if (!(span.x <= t && t <= span.y) || done) {
        all_done = all_done && done;
        return;
    }
    float s = layerValue(volume, i, labels, o + t * d);
#if MODE_COMPOSITE
    float transparency;
    vec4 rgba = layerClass(table, i, labels, s, transparency);
    bool opaque;
    float tau = extinction(rgba, transparency, u_layer_inv_unit[i], opaque);
    float alpha = opaque ? 1.0 : -expm1Accurate(-len * tau);
    compositePremultiplied(acc.rgb, acc.a, vec4(rgba.rgb * alpha, alpha));
    done = acc.a >= 1.0;
  #if EARLY_RAY_TERMINATION
    done = done || 1.0 - acc.a < u_ert_transmittance;
  #endif
    all_done = all_done && done;
#elif MODE_MIP
    best = max(best, s);
    all_done = false;
#elif MODE_MINIP
    best = min(best, s);
    all_done = false;
#else
    best += s * len;
    len_sum += len;
    all_done = false;
#endif
}

// The final (premultiplied) class of a layer's extreme value, or of its mean (average:
// best is the integral over len_sum); transparent where the layer saw no sample.
vec4 finalClass(sampler2D table, int i, float best, float len_sum) {
#if MODE_AVERAGE
    if (len_sum <= 0.0) return vec4(0.0);
    float s = best / len_sum;
#else
    if (isinf(best)) return vec4(0.0);
    float s = best;
#endif
    float transparency;
    vec4 rgba = layerClass(table, i, false, s, transparency);
    return vec4(rgba.rgb * rgba.a, rgba.a);
}

void PIXEL_MAIN() {
    vec3 origin, dir;
    pixelRay(origin, dir);
    vec3 o[N_LAYERS];
    vec3 d[N_LAYERS];
    vec2 span[N_LAYERS];
    float t_lo = 3.0e38, t_hi = -3.0e38;
    for (int i = 0; i < N_LAYERS; ++i) {
        o[i] = u_to_layer[i] * origin + u_layer_offset[i];
        d[i] = u_to_layer[i] * dir;
        span[i] = intersectBox(o[i], d[i], vec3(0.0), u_layer_extent[i]);
        if (span[i].y > span[i].x) {
            t_lo = min(t_lo, span[i].x);
            t_hi = max(t_hi, span[i].y);
        }
    }
    vec2 range = clipRange(origin, dir, vec2(t_lo, t_hi));
    f_color = vec4(0.0);
#if GEOMETRY
    vec4 surface = texelFetch(t_surface, ivec2(FRAG_COORD.xy), 0);
    bool on_surface = surface.a < 1e38;
    range.y = min(range.y, surface.a);
    if (range.y <= range.x) {
        if (on_surface) f_color = vec4(surface.rgb, 1.0);
        return;
    }
#else
    if (range.y <= range.x) return;
#endif
    float t0 = range.x, t1 = range.y;
#if SKIP_EMPTY
    // Where the ray meets any layer's occupied box: a midpoint outside is in an empty
    // brick of every layer that holds it.
    float occupied_lo = 3.0e38, occupied_hi = -3.0e38;
    for (int i = 0; i < N_LAYERS; ++i) {
        vec2 occupied = intersectBox(o[i], d[i], u_occupied_lo[i], u_occupied_hi[i]);
        if (occupied.y > occupied.x) {
            occupied_lo = min(occupied_lo, occupied.x);
            occupied_hi = max(occupied_hi, occupied.y);
        }
    }
#endif

    // every layer's entry and exit, clamped to [t0, t1] (a layer the ray misses: t1), sorted
    float cut[N_CUTS];
    for (int i = 0; i < N_LAYERS; ++i) {
        bool hit = span[i].y > span[i].x;
        cut[2 * i] = hit ? clamp(span[i].x, t0, t1) : t1;
        cut[2 * i + 1] = hit ? clamp(span[i].y, t0, t1) : t1;
    }
    for (int i = 1; i < N_CUTS; ++i) {
        for (int j = i; j > 0; --j) {
            float lo = min(cut[j - 1], cut[j]);
            float hi = max(cut[j - 1], cut[j]);
            cut[j - 1] = lo;
            cut[j] = hi;
        }
    }

#if BLEND_ADD
    vec4 acc[N_LAYERS];
    bool done[N_LAYERS];
    float best[N_LAYERS];
    float len_sum[N_LAYERS];
    for (int i = 0; i < N_LAYERS; ++i) {
        acc[i] = vec4(0.0);
        done[i] = false;
#if MODE_MIP
        best[i] = -1.0 / 0.0;
#elif MODE_MINIP
        best[i] = 1.0 / 0.0;
#else
        best[i] = 0.0;     // average: the integral of the value over the layer's length
#endif
        len_sum[i] = 0.0;
    }
#else
    vec3 color = vec3(0.0);
    float alpha_acc = 0.0;
#endif
    bool ended = false;
    int budget = u_max_segments;
    for (int j = 0; j < N_CUTS - 1; ++j) {
        float a = cut[j], b = cut[j + 1];
        if (!(b > a)) continue;
        float middle = 0.5 * (a + b);
        bool held = false;
        for (int i = 0; i < N_LAYERS; ++i) {
            held = held || (span[i].y > span[i].x && span[i].x <= middle && middle <= span[i].y);
        }
        if (!held) continue;
        int n = int(ceil((b - a) / u_step));
        float h = (b - a) / float(n);
        int k_begin = 0, k_end = n;
#if SKIP_EMPTY
        // only the segments whose midpoint may be in [occupied_lo, occupied_hi] (one more
        // each side, for rounding); the others add nothing but count against the budget
        k_begin = int(clamp(floor((occupied_lo - a) / h - 0.5) - 1.0, 0.0, float(n)));
        k_end = max(k_begin, int(clamp(ceil((occupied_hi - a) / h - 0.5) + 2.0, 0.0, float(n))));
        budget -= k_begin;
        float recheck = -3.0e38;    // no look-up before: a layer holding the ray is occupied up to here
#endif
        for (int k = k_begin; k < k_end; ++k) {
            if (budget <= 0) break;
            --budget;
            float t = a + (float(k) + 0.5) * h;
#if BLEND_ADD
            bool all_done = true;
  #if SKIP_EMPTY
            float opacity_before = 0.0;
            for (int i = 0; i < N_LAYERS; ++i) opacity_before += acc[i].a;
  #endif
            addLayer(t_layer0, t_class0, 0, LAYER0_LABELS != 0, o[0], d[0], t, span[0], h, acc[0], done[0], best[0],
                     len_sum[0], all_done);
  #if N_LAYERS > 1
            addLayer(t_layer1, t_class1, 1, LAYER1_LABELS != 0, o[1], d[1], t, span[1], h, acc[1], done[1], best[1],
                     len_sum[1], all_done);
  #endif
  #if N_LAYERS > 2
            addLayer(t_layer2, t_class2, 2, LAYER2_LABELS != 0, o[2], d[2], t, span[2], h, acc[2], done[2], best[2],
                     len_sum[2], all_done);
  #endif
  #if N_LAYERS > 3
            addLayer(t_layer3, t_class3, 3, LAYER3_LABELS != 0, o[3], d[3], t, span[3], h, acc[3], done[3], best[3],
                     len_sum[3], all_done);
  #endif
            ended = all_done;
#else
            // one medium: extinctions and emissions add
            float tau = 0.0;
            vec3 emission = vec3(0.0);
            vec3 opaque_color = vec3(0.0);
            float opaque_count = 0.0;
            mixLayer(t_layer0, t_class0, 0, LAYER0_LABELS != 0, o[0], d[0], t, span[0], tau, emission, opaque_color,
                     opaque_count);
  #if N_LAYERS > 1
            mixLayer(t_layer1, t_class1, 1, LAYER1_LABELS != 0, o[1], d[1], t, span[1], tau, emission, opaque_color,
                     opaque_count);
  #endif
  #if N_LAYERS > 2
            mixLayer(t_layer2, t_class2, 2, LAYER2_LABELS != 0, o[2], d[2], t, span[2], tau, emission, opaque_color,
                     opaque_count);
  #endif
  #if N_LAYERS > 3
            mixLayer(t_layer3, t_class3, 3, LAYER3_LABELS != 0, o[3], d[3], t, span[3], tau, emission, opaque_color,
                     opaque_count);
  #endif
            vec4 piece = vec4(0.0);
            if (opaque_count > 0.0) {
                piece = vec4(opaque_color / opaque_count, 1.0);
            } else if (tau > 0.0) {
                float alpha = -expm1Accurate(-h * tau);
                piece = vec4(emission / tau * alpha, alpha);
            }
            compositePremultiplied(color, alpha_acc, piece);
            ended = alpha_acc >= 1.0;
  #if EARLY_RAY_TERMINATION
            ended = ended || 1.0 - alpha_acc < u_ert_transmittance;
  #endif
#endif
#if SKIP_EMPTY
            // Nothing composited: only now look at the bricks (occupied regions never pay
            // for it). Where every layer holding t is in an empty brick (or has ended), each
            // midpoint before the first of those bricks' exits adds exactly nothing: go on at
            // the segment before the first midpoint past it (rounding can only make the ray
            // look once more, never skip a sample; t is made from k, never accumulated).
  #if BLEND_ADD
            float opacity_after = 0.0;
            for (int i = 0; i < N_LAYERS; ++i) opacity_after += acc[i].a;
            bool blank = opacity_after == opacity_before;
  #else
            bool blank = opaque_count == 0.0 && tau == 0.0;
  #endif
            if (blank && !ended && t >= recheck) {
                bool empty = true;
                float t_exit = 3.0e38;
  #if BLEND_ADD
                SKIP_LAYER(t_occupancy0, 0, done[0], LAYER0_OCCUPIED != 0)
    #if N_LAYERS > 1
                SKIP_LAYER(t_occupancy1, 1, done[1], LAYER1_OCCUPIED != 0)
    #endif
    #if N_LAYERS > 2
                SKIP_LAYER(t_occupancy2, 2, done[2], LAYER2_OCCUPIED != 0)
    #endif
    #if N_LAYERS > 3
                SKIP_LAYER(t_occupancy3, 3, done[3], LAYER3_OCCUPIED != 0)
    #endif
  #else
                SKIP_LAYER(t_occupancy0, 0, false, LAYER0_OCCUPIED != 0)
    #if N_LAYERS > 1
                SKIP_LAYER(t_occupancy1, 1, false, LAYER1_OCCUPIED != 0)
    #endif
    #if N_LAYERS > 2
                SKIP_LAYER(t_occupancy2, 2, false, LAYER2_OCCUPIED != 0)
    #endif
    #if N_LAYERS > 3
                SKIP_LAYER(t_occupancy3, 3, false, LAYER3_OCCUPIED != 0)
    #endif
  #endif
                if (empty && t_exit > t) {
                    float past = min((t_exit - a) / h - 0.5, float(n));
                    int k_to = min(max(k, int(ceil(past)) - 2), k_end - 1);
                    budget -= k_to - k;     // as if each skipped segment had been taken
                    k = k_to;
                }
            }
#endif
            if (ended) break;
        }
#if SKIP_EMPTY
        budget -= n - k_end;
#endif
        if (ended) break;
    }

#if BLEND_ADD
  #if !MODE_COMPOSITE
    acc[0] = finalClass(t_class0, 0, best[0], len_sum[0]);
    #if N_LAYERS > 1
    acc[1] = finalClass(t_class1, 1, best[1], len_sum[1]);
    #endif
    #if N_LAYERS > 2
    acc[2] = finalClass(t_class2, 2, best[2], len_sum[2]);
    #endif
    #if N_LAYERS > 3
    acc[3] = finalClass(t_class3, 3, best[3], len_sum[3]);
    #endif
  #endif
    vec3 sum = vec3(0.0);
    float transmittance = 1.0;
    for (int i = 0; i < N_LAYERS; ++i) {
        sum += acc[i].rgb;
        transmittance *= 1.0 - acc[i].a;
    }
    f_color = vec4(sum, 1.0 - transmittance);
#else
    f_color = vec4(color, alpha_acc);
#endif
#if GEOMETRY
    if (on_surface) f_color = vec4(f_color.rgb + (1.0 - f_color.a) * surface.rgb, 1.0);
#endif
}

#include "common/pixel_store.glsl"
