// Point sprites for spheres (particles, splat kernels): the side in pixels of the square
// sprite that holds a sphere's outline.
#ifndef DVR_SPRITE_GLSL
#define DVR_SPRITE_GLSL

#ifndef ORTHO
#define ORTHO 0
#endif

// centre relative to the data's lower corner, like eye; pixels_per_unit: pixels per world
// unit at unit depth (orthographic: at any depth).
float spriteSize(vec3 centre, float radius, vec3 eye, vec3 forward, float pixels_per_unit) {
#if ORTHO
    float reach = radius;
#else
    // The outline reaches tan(theta + a) - tan(theta) = sin a / (cos(theta + a) cos theta)
    // from the centre's image at unit depth (theta off the axis, a the sphere's angular
    // radius): its far side, the widest. Near 90 degrees the sprite is capped (and GL's
    // own point size limit applies).
    vec3 to = centre - eye;
    float dist = length(to);
    float cos_t = dot(to, forward) / dist;
    float sin_t = sqrt(max(1.0 - cos_t * cos_t, 0.0));
    float sin_a = min(radius / dist, 1.0);
    float cos_a = sqrt(1.0 - sin_a * sin_a);
    float reach = sin_a / max((cos_t * cos_a - sin_t * sin_a) * cos_t, 1e-3);
#endif
    // pixel centres inside the outline lie within reach * ppu of the centre's image, so
    // inside the sprite's square; the margin covers float rounding only
    return 2.0 * reach * pixels_per_unit * 1.001 + 0.01;
}

#endif
