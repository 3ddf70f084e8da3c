// Resolve of PL_SS x PL_SS subsamples into one pixel, shared by the local-framebuffer variant
// (points_lfb.cl, subsamples in __local memory) and the supersampled direct variant
// (downsample_keys below, subsamples in a key buffer PL_SS times the frame's size). Built after
// keys.cl. Integer only, so the numpy twin (paramlod.points_reference.resolve_blocks) matches bit
// for bit.

// Integer twins must not depend on whether the compiler fuses a*b+c.
#pragma OPENCL FP_CONTRACT OFF

#ifndef PL_SS
#define PL_SS 2         // subsamples per pixel side
#endif
#define SS_COUNT (PL_SS * PL_SS)
#ifndef PL_RATIO
#define PL_RATIO 2      // upsample_keys: a finer hybrid tier's subsamples per coarser key and side
#endif
#define CLEAR_KEY 0xFFFFFFFFFFFFFFFFul

// sRGB8 -> linear in fixed point through lin[256], and back through the 256 thresholds thr[]
// (thr[i] = linear value of code i - 1/2): the largest i with thr[i] <= x
// (tables: paramlod.points_reference.srgb_tables).
inline uint encode_srgb8(uint x, __global const uint* thr) {
    uint i = 0u;
    for (uint step = 128u; step > 0u; step >>= 1)
        if (thr[i + step] <= x) i += step;   // i + step <= 255 always
    return i;
}

// One pixel from its subsamples' colour keys k[] and aux keys a[]: the covered subsamples'
// colours averaged in linear light, alpha = coverage, depth = the nearest subsample's, aux key =
// the smallest (nearest sample's normal and object id). Returns the number of covered subsamples
// (0: *key and *aux are left cleared).
inline uint resolve_subsamples(const ulong* k, const ulong* a, __global const uint* lin,
                               __global const uint* thr, ulong* key, ulong* aux) {
    uint cnt = 0u, r = 0u, g = 0u, b = 0u;
    ulong kmin = CLEAR_KEY, amin = CLEAR_KEY;
    for (uint i = 0; i < SS_COUNT; ++i) {
        if (k[i] == CLEAR_KEY) continue;   // only covered subsamples count
        uint c = (uint)k[i];
        cnt++;
        r += lin[c >> 24]; g += lin[(c >> 16) & 255u]; b += lin[(c >> 8) & 255u];
        kmin = min(kmin, k[i]);
        amin = min(amin, a[i]);
    }
    *key = CLEAR_KEY; *aux = CLEAR_KEY;
    if (cnt == 0u) return 0u;
    uint rnd = cnt >> 1;   // round to nearest
    uint rgba = (encode_srgb8((r + rnd) / cnt, thr) << 24) | (encode_srgb8((g + rnd) / cnt, thr) << 16)
              | (encode_srgb8((b + rnd) / cnt, thr) << 8)
              | ((cnt * 255u + SS_COUNT / 2u) / SS_COUNT);   // alpha = coverage
    *key = (kmin & 0xFFFFFFFF00000000ul) | (ulong)rgba;
    *aux = amin;
    return cnt;
}

// Supersampled direct variant: one work-item per pixel of the W x H frame reads its PL_SS x PL_SS
// block of the (W * PL_SS) x (H * PL_SS) key buffers and writes the resolved keys (plain stores:
// the frame's key buffers hold nothing else).
__kernel void downsample_keys(__global const ulong* color_ss, __global const ulong* aux_ss, uint W, uint H,
                              __global const uint* lin, __global const uint* thr,
                              __global ulong* color, __global ulong* aux)
{
    uint i = get_global_id(0);
    if (i >= W * H) return;
    uint px = i % W, py = i / W, SW = W * PL_SS;
    ulong k[SS_COUNT], a[SS_COUNT];
    for (uint dy = 0; dy < PL_SS; ++dy) {
        for (uint dx = 0; dx < PL_SS; ++dx) {
            uint s = (py * PL_SS + dy) * SW + px * PL_SS + dx;
            k[dy * PL_SS + dx] = color_ss[s];
            a[dy * PL_SS + dx] = aux_ss[s];
        }
    }
    ulong key, ax;
    resolve_subsamples(k, a, lin, thr, &key, &ax);
    color[i] = key;
    aux[i] = ax;
}

// Hybrid tiers: one work-item per key of the finer buffer, (W * PL_RATIO) x (H * PL_RATIO), takes
// the key of the coarser buffer's pixel it lies in (colour and aux: every subsample starts as the
// coarse sample, which the finer tier's samples then depth-test against). Plain stores: the
// finer buffer holds nothing yet. Layers are rows of one tall image, as in downsample_keys.
__kernel void upsample_keys(__global const ulong* color, __global const ulong* aux, uint W, uint H,
                            __global ulong* color_fine, __global ulong* aux_fine)
{
    uint i = get_global_id(0), FW = W * PL_RATIO;
    if (i >= FW * H * PL_RATIO) return;
    uint src = (i / FW / PL_RATIO) * W + (i % FW) / PL_RATIO;
    color_fine[i] = color[src];
    aux_fine[i] = aux[src];
}
