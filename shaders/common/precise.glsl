// PRECISE: GLSL's `precise` where the context has it (GL_ARB_gpu_shader5), so that the
// compiler neither fuses nor reorders the arithmetic of a variable so declared. GPU
// compilers fuse a * b + c into one FMA where they please, which turns an exact zero (a
// ray in a face's plane: n . dir with n_y = -n_x and dir_x = dir_y) into the rounding
// error of a product, and ties that the tetra shaders decide exactly into noise;
// llvmpipe's images move with it too, by float rounding (ray casting: up to 2e-5).
// Include before any declaration (it may hold an #extension).
#ifndef DVR_PRECISE_GLSL
#define DVR_PRECISE_GLSL
#ifdef GL_ARB_gpu_shader5
#extension GL_ARB_gpu_shader5 : enable
#define PRECISE precise
#else
#define PRECISE
#endif
#endif
