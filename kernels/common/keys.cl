// 64-bit visibility keys shared by every point producer (points, surfels, the mesh raster) and the
// resolve, and the hand-off dither of surfels and meshes (pl_dither, at the end).
//   colour key = float bits of the linear view depth << 32 | sRGB RGBA8 (R in the top byte)
//   aux key    = float bits of the linear view depth << 32 | octahedral normal 10+10 | object id 12
// Both buffers are cleared to all ones; atom_min keeps the nearest sample. docs/frame.md.
#pragma OPENCL EXTENSION cl_khr_int64_base_atomics : enable
#pragma OPENCL EXTENSION cl_khr_int64_extended_atomics : enable

#include "common/dialect.cl"
#include "common/shading.cl"
#include "common/hash.cl"

// Linear [0, 1] to the sRGB 8-bit code that rounding the exact sRGB curve would give: the count
// of the prelude's SRGB8_THRESHOLDS[1..255] at or below x (paramlod.core.color.srgb8_thresholds);
// below 0 and NaN give 0, above 1 255. Two forms of one result:
// - CPUs: x's bucket of [0, 1] (x * SRGB8_BUCKETS is exact) holds at most one threshold, so the
//   code is the bucket's first code (srgb8_bucket_codes) or one more: a load and a comparison
//   where the search takes eight dependent steps (the 640x640 torus's render 37 -> 31 ms, PoCL).
// - GPUs: a binary search. Its first loads are the same for neighbouring samples; the bucket's
//   are not, and a GPU's constant cache serves different addresses one after another (an H100's
//   HARDI field rendered 0.39 -> 0.58 ms with the buckets).
inline uint srgb8(float x) {
#if PL_GPU
    uint k = 0;
    for (uint step = 128; step > 0; step >>= 1)
        if (SRGB8_THRESHOLDS[k + step] <= x) k += step;
    return k;
#else
    uint bucket = x > 0.0f ? (uint)pl_fminf(x * (float)SRGB8_BUCKETS, (float)(SRGB8_BUCKETS - 1)) : 0u;
    uint k = SRGB8_BUCKET_CODES[bucket];
    return k < 255u ? k + (uint)(SRGB8_THRESHOLDS[k + 1u] <= x) : k;
#endif
}

inline uint oct10(float3 n) {
    // octahedral map of a unit vector to two 10-bit unsigned values
    float s = pl_fabsf(n.x) + pl_fabsf(n.y) + pl_fabsf(n.z);
    float2 p = n.xy / s;
    if (n.z < 0.0f) {
        p = (float2)((1.0f - pl_fabsf(p.y)) * (p.x >= 0.0f ? 1.0f : -1.0f),
                     (1.0f - pl_fabsf(p.x)) * (p.y >= 0.0f ? 1.0f : -1.0f));
    }
    // clamp(v, 0, 1023) as the standard defines it, fmin(fmax(v, 0), 1023)
    uint x = (uint)pl_fminf(pl_fmaxf(p.x * 511.5f + 511.5f + 0.5f, 0.0f), 1023.0f);
    uint y = (uint)pl_fminf(pl_fmaxf(p.y * 511.5f + 511.5f + 0.5f, 0.0f), 1023.0f);
    return (x << 10) | y;
}

// The shading model (common/shading.cl) for a view-space normal n_view (any length) and the
// material (linear RGB, specular weight); returns the sRGB RGBA8 word and the viewer-facing unit
// normal in view space. `ev` points towards the viewer (view_dir()); `light` is the light record.
inline uint shade(float3 n_view, float3 ev, float4 mat, __global const float* light, float3* n_out) {
    float3 n = pl_facing_normal(n_view, ev);
    float3 L = (float3)(light[LIGHT_TOWARDS], light[LIGHT_TOWARDS + 1], light[LIGHT_TOWARDS + 2]);
    float3 rgb = pl_shade_rgb(n, ev, mat.xyz, mat.w, L, light[LIGHT_AMBIENT]);
    *n_out = n;
    return (srgb8(rgb.x) << 24) | (srgb8(rgb.y) << 16) | (srgb8(rgb.z) << 8) | 255u;
}

inline ulong color_key(float depth, uint rgba) {
    return ((ulong)as_uint(depth) << 32) | (ulong)rgba;
}

inline ulong aux_key(float depth, float3 n_world, uint object_id) {
    return ((ulong)as_uint(depth) << 32) | ((ulong)oct10(n_world) << 12) | (ulong)(object_id & 0xFFFu);
}

// Early depth before shading: true when the colour key at `pix` already holds a strictly nearer
// depth. Then a sample at `depth` loses both atom_mins whatever its shade (the sample that wrote
// that depth writes an aux key of the same depth, so the aux key's depth ends no larger), and
// skipping it leaves the frame's keys bit for bit.
inline bool key_hidden(__global const ulong* color_buf, uint pix, float depth) {
    return (uint)(color_buf[pix] >> 32) < as_uint(depth);
}

// atom_min both keys, reading first so that hidden samples cost no atomic (early depth).
// Returns 1 when the colour atomic was issued.
inline uint write_point(__global ulong* color_buf, __global ulong* aux_buf, uint pix, ulong key, ulong aux) {
    uint issued = 0u;
    if (key < color_buf[pix]) { atom_min(&color_buf[pix], key); issued = 1u; }
    if (aux < aux_buf[pix]) { atom_min(&aux_buf[pix], aux); }
    return issued;
}
