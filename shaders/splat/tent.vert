// Sheet-buffer splatting, the splat pass (see techniques/splat.py): the splatted samples
// come in runs along one axis (u_axis), and each run whose tents reach sheet u_slice
// becomes one quad on that sheet, placed by gl_VertexID (no attributes): vertices
// 4q .. 4q + 3 are quad q's corners, an index buffer makes its two triangles. The quad is
// the bounding rectangle, along u_u (the runs' direction on the sheet) and u_v, of the
// sheet's cut through the run's supports, grown by a sixteenth of a pixel
// (techniques.splat.QUAD_MARGIN). The cut through one support at offset delta is read
// from a table at the support box's 8 corner depths, linear in between; sweeping it along
// the run moves it by x (e_axis . u_u, e_axis . u_v) at offset delta0 - x forward[axis],
// so its bounds' extremes lie at the run's ends or where the offset meets a table depth
// (NumPy twin: techniques.splat.run_quads). Runs that do not reach the sheet draw nothing.
#version 330 core

#include "common/texel_rows.glsl"
#include "common/slabs.glsl"

#ifndef ORTHO
#define ORTHO 0
#endif

uniform isampler2D t_order;       // the view's runs, sheet by sheet (TEXEL_ROW_WIDTH per row)
uniform isampler2D t_runs;        // per run: its first sample's indices (x, y, z) and first row in
                                  // the per-sample tables; one row more holds the total
uniform int u_first;              // sheet u_slice's first slot in t_order
uniform int u_slice;              // the sheet (0 the farthest)
uniform int u_axis;               // the runs' axis (0 = x)
uniform vec3 u_spacing;
uniform vec3 u_eye;               // relative to the lower corner
uniform vec3 u_forward;
uniform vec3 u_u;                 // the quad's axes on the sheet
uniform vec3 u_v;
uniform float u_section_depth[8]; // the support box's corner depths about its centre, ascending
uniform vec4 u_section_rect[8];   // the cut's (u min, u max, v min, v max) at those depths
uniform float u_margin;           // the quads' growth in world units at unit depth (ortho: anywhere)
uniform mat4 u_view_proj;

flat out vec3 v_first;            // the run's first sample, relative to the lower corner
flat out int v_row;               // its row in the per-sample tables
flat out int v_count;             // the run's length

// The cut's rectangle at offset delta (clamped into the support's depth range).
vec4 sectionRect(float delta) {
    delta = clamp(delta, u_section_depth[0], u_section_depth[7]);
    int j = 0;
    while (j < 6 && delta > u_section_depth[j + 1]) ++j;
    float span = u_section_depth[j + 1] - u_section_depth[j];
    float f = span > 0.0 ? clamp((delta - u_section_depth[j]) / span, 0.0, 1.0) : 0.0;
    return mix(u_section_rect[j], u_section_rect[j + 1], f);
}

void grow(inout vec4 bounds, vec4 rect, vec2 shift) {
    bounds = vec4(min(bounds.x, rect.x + shift.x), max(bounds.y, rect.y + shift.x),
                  min(bounds.z, rect.z + shift.y), max(bounds.w, rect.w + shift.y));
}

void main() {
    int id = texelFetch(t_order, texelRow(u_first + gl_VertexID / 4), 0).r;
    ivec4 run = texelFetch(t_runs, texelRow(id), 0);
    int count = texelFetch(t_runs, texelRow(id + 1), 0).w - run.w;
    vec3 first = vec3(run.xyz) * u_spacing;
    v_first = first;
    v_row = run.w;
    v_count = count;
    gl_Position = vec4(2.0, 2.0, 2.0, 1.0);                    // outside the view: clipped

    float depth = u_far_depth - float(u_slice) * u_step;        // as sliceT's
    float delta0 = depth - dot(first - u_eye, u_forward);      // the sheet ahead of the first centre
    float fa = u_forward[u_axis];
    vec2 g = vec2(u_u[u_axis], u_v[u_axis]);     // the runs' direction on the sheet
    // the run's centres x e_axis, x in [0, extent], whose supports the sheet cuts
    float lo = 0.0;
    float hi = float(count - 1) * u_spacing[u_axis];
    float d0 = u_section_depth[0];
    float d7 = u_section_depth[7];
    if (fa != 0.0) {
        float a = (delta0 - d7) / fa;
        float b = (delta0 - d0) / fa;
        lo = max(lo, min(a, b));
        hi = min(hi, max(a, b));
    } else if (delta0 < d0 || delta0 > d7) {
        return;
    }
    if (lo > hi) return;
    vec4 bounds = vec4(1e30, -1e30, 1e30, -1e30);
    grow(bounds, sectionRect(delta0 - lo * fa), lo * g);
    grow(bounds, sectionRect(delta0 - hi * fa), hi * g);
    if (fa != 0.0) {
        for (int j = 0; j < 8; ++j) {
            float x = (delta0 - u_section_depth[j]) / fa;
            if (x > lo && x < hi) grow(bounds, u_section_rect[j], x * g);
        }
    }
#if ORTHO
    float margin = u_margin;
#else
    float margin = u_margin * depth;
#endif
    int corner = gl_VertexID % 4;
    float u = (corner & 1) == 1 ? bounds.y + margin : bounds.x - margin;
    float v = (corner & 2) == 2 ? bounds.w + margin : bounds.z - margin;
    vec3 p = first + delta0 * u_forward + u * u_u + v * u_v;
    gl_Position = u_view_proj * vec4(p, 1.0);
}
