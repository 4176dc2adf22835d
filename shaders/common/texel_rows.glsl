// Long per-element tables stored as 2-D textures TEXEL_ROW_WIDTH texels wide (GL's 1-D
// textures are too short for meshes); NumPy side: techniques.tetra.texture_rows.
#ifndef DVR_TEXEL_ROWS_GLSL
#define DVR_TEXEL_ROWS_GLSL

const int TEXEL_ROW_WIDTH = 4096;

ivec2 texelRow(int index) {
    return ivec2(index % TEXEL_ROW_WIDTH, index / TEXEL_ROW_WIDTH);
}

#endif
