#ifndef PL_BUILTINS
#define PL_BUILTINS
// Built-ins of hot code, inline on CPUs. PoCL calls its library's ceil, floor, fmin, fmax, sqrt,
// fabs, isfinite, dot, length and normalize out of line, a call each: a seventh of an order-12 glyph field's quad
// frame and a tenth of the torus's points frame (perf, 2-core EPYC). Clang's builtins are the same
// IEEE operations (fmin, fmax: minNum, maxNum; sqrt correctly rounded); dot, length and normalize
// are written as PoCL computes them (paramlod/meshlod/raster_reference.py, measured), so the
// results are the same bits.
#if PL_GPU
#define pl_ceilf ceil
#define pl_floorf floor
#define pl_fminf fmin
#define pl_fmaxf fmax
#define pl_sqrtf sqrt
#define pl_fabsf fabs
#define pl_finitef isfinite
#else
#define pl_ceilf __builtin_ceilf
#define pl_floorf __builtin_floorf
#define pl_fminf __builtin_fminf
#define pl_fmaxf __builtin_fmaxf
#define pl_sqrtf __builtin_sqrtf
#define pl_fabsf __builtin_fabsf
#define pl_finitef(x) (pl_fabsf(x) < INFINITY)   // false for NaN and the infinities
#endif
// A program whose keys must equal its twin's on every device (-D PL_EXACT_VECTORS: the mesh raster)
// takes these too on a GPU: NVIDIA's dot and normalize round differently (on an H100, one pixel's
// shade in 41,472 came out an sRGB code apart)
#if PL_GPU && !defined(PL_EXACT_VECTORS)
#define pl_dot3 dot
#define pl_length2 length
#define pl_length3 length
#define pl_normalize3 normalize
#else
inline float pl_length2(float2 a) {
#pragma OPENCL FP_CONTRACT OFF
    return pl_sqrtf(a.x * a.x + a.y * a.y);
}
inline float pl_dot3(float3 a, float3 b) {
#pragma OPENCL FP_CONTRACT OFF
    return (a.x * b.x + a.y * b.y) + a.z * b.z;
}
inline float pl_length3(float3 a) {
    return pl_sqrtf(pl_dot3(a, a));
}
inline float3 pl_normalize3(float3 a) {
#pragma OPENCL FP_CONTRACT OFF
    return a * (1.0f / pl_sqrtf(pl_dot3(a, a)));
}
#endif
#endif
