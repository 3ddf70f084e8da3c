// One integer hash for every kernel and shader that needs noise: the debug colour per cluster
// (common/debug_color.cl) and the screen-door dither of the surfel -> mesh hand-off (pl_dither:
// the surfel splat skips pixels whose dither is below the object's mesh weight, the mesh raster and
// the GL draw those at or above it, so at any weight each pixel comes from exactly one of them;
// docs/surfels.md). Written in the snippet dialect (the includer includes common/dialect.cl or
// .glsl first), so it compiles as OpenCL C and as GLSL. numpy twin: paramlod/core/hashing.py.
#ifndef PL_HASH
#define PL_HASH

#ifdef __OPENCL_VERSION__
#define PL_HASH_FN inline
#else
#define PL_HASH_FN
#endif

// xor-shift-multiply, two rounds: neighbouring inputs get unrelated outputs
PL_HASH_FN uint pl_hash32(uint x) {
    x = x ^ (x >> 16);
    x = x * 0x7feb352du;
    x = x ^ (x >> 15);
    x = x * 0x846ca68bu;
    x = x ^ (x >> 16);
    return x;
}

// [0, 1) per pixel or subsample (column x, row y from the top): the top 24 bits of
// hash(hash(y) + x), exact in float32
PL_HASH_FN float pl_dither(uint x, uint y) {
    return FLOAT(pl_hash32(pl_hash32(y) + x) >> 8u) * (1.0f / 16777216.0f);
}
#endif
