// Ceiling microbenchmark: random 64-bit atom_min into a screen-sized buffer, the operation the
// point renderers are built on. Each work-item issues `per_item` atomics at hashed pixels.
#pragma OPENCL EXTENSION cl_khr_int64_extended_atomics : enable

inline uint hash32(uint x) {
    x ^= x >> 16; x *= 0x7feb352du; x ^= x >> 15; x *= 0x846ca68bu; x ^= x >> 16;
    return x;
}

__kernel void random_atom_min(__global ulong* buf, uint n_pixels, uint per_item, uint seed) {
    uint gid = get_global_id(0);
    for (uint k = 0; k < per_item; ++k) {
        uint h = hash32(gid * per_item + k + seed);
        atom_min(&buf[h % n_pixels], ((ulong)hash32(h) << 32) | (ulong)gid);
    }
}

// FP32 ceiling: 64 independent fma chains per work-item (16 float4 vectors) of `steps` fmas each,
// 2 FLOPs per fma: explicit vectors because PoCL does not vectorise a loop that carries a chain
// across its iterations (scalar chains ran at 1/15 of this on a 2-core Xeon), and enough
// independent work to hide the fma latency on GPUs. float4, not float16: PoCL on a CPU without
// AVX-512 built a float16 version without its kernels (INVALID_KERNEL_NAME, AMD EPYC). The seeds
// come from the id and `a`, `b` are arguments, so nothing folds at compile time; the sum is
// written so that nothing is dropped.
// Twin: fma_ceiling_reference in paramlod/app/bench/functions.py, which drives it.
#define FMA_VECTORS 16
__kernel void fma_ceiling(uint steps, float a, float b, __global float* out)
{
    uint gid = get_global_id(0);
    float4 x[FMA_VECTORS];
    #pragma unroll
    for (uint j = 0; j < FMA_VECTORS; ++j)
        x[j] = (float)(gid & 255u) * 1e-3f + ((float4)(0, 1, 2, 3) + (float)(4u * (j % 4u))) * 1e-4f
               + (float)(j / 4u) * 1e-5f;
    for (uint k = 0; k < steps; ++k) {
        #pragma unroll
        for (uint j = 0; j < FMA_VECTORS; ++j) x[j] = fma(x[j], a, b);
    }
    float4 s = (float4)(0.0f);
    #pragma unroll
    for (uint j = 0; j < FMA_VECTORS; ++j) s += x[j];
    out[gid] = (s.x + s.y) + (s.z + s.w);
}
