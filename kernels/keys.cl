// 64-bit visibility keys shared by every point producer (points, surfels) and the resolve.
//   colour key = float bits of the linear view depth << 32 | sRGB RGBA8 (R in the top byte)
//   aux key    = float bits of the linear view depth << 32 | octahedral normal 10+10 | object id 12
// Both buffers are cleared to all ones; atom_min keeps the nearest sample. docs/frame.md.
#pragma OPENCL EXTENSION cl_khr_int64_base_atomics : enable
#pragma OPENCL EXTENSION cl_khr_int64_extended_atomics : enable

inline uint srgb8(float x) {
    x = clamp(x, 0.0f, 1.0f);
    float s = x <= 0.0031308f ? 12.92f * x : 1.055f * pow(x, 1.0f / 2.4f) - 0.055f;
    return (uint)(s * 255.0f + 0.5f);
}

inline uint oct10(float3 n) {
    // octahedral map of a unit vector to two 10-bit unsigned values
    float s = fabs(n.x) + fabs(n.y) + fabs(n.z);
    float2 p = n.xy / s;
    if (n.z < 0.0f) {
        p = (float2)((1.0f - fabs(p.y)) * (p.x >= 0.0f ? 1.0f : -1.0f),
                     (1.0f - fabs(p.x)) * (p.y >= 0.0f ? 1.0f : -1.0f));
    }
    uint x = (uint)clamp(p.x * 511.5f + 511.5f + 0.5f, 0.0f, 1023.0f);
    uint y = (uint)clamp(p.y * 511.5f + 511.5f + 0.5f, 0.0f, 1023.0f);
    return (x << 10) | y;
}

// Blinn-Phong with two-sided lighting in view space; returns the sRGB RGBA8 word and the
// viewer-facing unit normal in view space. `ev` points towards the viewer (view_dir()).
inline uint shade(float3 n_view, float3 ev, float4 mat, __global const float* light, float3* n_out) {
    float ln = length(n_view);
    float3 n = (ln > 1e-30f && !isnan(ln)) ? n_view / ln : ev;   // degenerate (poles): face the eye
    if (dot(n, ev) < 0.0f) n = -n;
    float3 L = (float3)(light[0], light[1], light[2]);
    float ambient = light[3];
    float diff = fmax(dot(n, L), 0.0f);
    float spec = mat.w * pow(fmax(dot(n, normalize(L + ev)), 0.0f), 48.0f);
    float3 rgb = mat.xyz * (ambient + (1.0f - ambient) * diff) + (float3)(spec);
    *n_out = n;
    return (srgb8(rgb.x) << 24) | (srgb8(rgb.y) << 16) | (srgb8(rgb.z) << 8) | 255u;
}

inline ulong color_key(float depth, uint rgba) {
    return ((ulong)as_uint(depth) << 32) | (ulong)rgba;
}

inline ulong aux_key(float depth, float3 n_world, uint object_id) {
    return ((ulong)as_uint(depth) << 32) | ((ulong)oct10(n_world) << 12) | (ulong)(object_id & 0xFFFu);
}

// atom_min both keys, reading first so that hidden samples cost no atomic (early depth).
// Returns 1 when the colour atomic was issued.
inline uint write_point(__global ulong* color_buf, __global ulong* aux_buf, uint pix, ulong key, ulong aux) {
    uint issued = 0u;
    if (key < color_buf[pix]) { atom_min(&color_buf[pix], key); issued = 1u; }
    if (aux < aux_buf[pix]) { atom_min(&aux_buf[pix], aux); }
    return issued;
}
