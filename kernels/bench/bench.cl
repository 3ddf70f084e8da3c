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
