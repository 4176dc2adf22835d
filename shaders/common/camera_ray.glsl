// The ray through the centre of this fragment's pixel (NumPy twin: scene.Camera.rays),
// with positions relative to the volume box's lower corner.
//
// pixelCoord: this fragment's pixel centre in the whole image (GL window coordinates);
// with tiles, FRAG_COORD (gl_FragCoord) is relative to the tile.
#ifndef DVR_CAMERA_RAY_GLSL
#define DVR_CAMERA_RAY_GLSL
#include "common/pixel_stage.glsl"

#ifndef ORTHO
#define ORTHO 0
#endif
#ifndef PRECISE
#define PRECISE   // common/precise.glsl, where a shader includes it first
#endif

uniform vec2 u_viewport;      // image width, height in pixels (the whole image)
uniform vec2 u_tile_origin;   // where this render's target sits in the image (GL window
                              // coordinates, pixels): (0, 0) unless rendered in tiles
uniform vec3 u_eye;           // eye, relative to the box's lower corner
uniform vec3 u_right;         // camera basis (world)
uniform vec3 u_up;
uniform vec3 u_forward;
uniform vec2 u_screen;        // half extent of the view: at unit distance, or world (ortho)

// Perspective rays start at the eye; orthographic ones on the plane through the eye
// normal to the view. `dir` is a unit vector.
vec2 pixelCoord() {
    return FRAG_COORD.xy + u_tile_origin;
}

void pixelRay(out vec3 origin, out vec3 dir) {
    // (2 c - n) / n: the numerator is exact (pixel centres are half-integers), so the
    // middle row or column of an odd-sized image gets ndc exactly 0, as the NumPy twin's;
    // c * (2 / n) - 1 left it 1e-7 off, and a ray meant to lie in a face plane missed it
    PRECISE vec2 ndc = (2.0 * (FRAG_COORD.xy + u_tile_origin) - u_viewport) / u_viewport;
    PRECISE vec3 offset = (ndc.x * u_screen.x) * u_right + (ndc.y * u_screen.y) * u_up;
#if ORTHO
    PRECISE vec3 start = u_eye + offset;
    origin = start;
    dir = u_forward;
#else
    PRECISE vec3 unit = normalize(u_forward + offset);
    origin = u_eye;
    dir = unit;
#endif
}

#endif
