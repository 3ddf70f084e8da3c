// 64-bit visibility keys shared by every point producer (points, surfels) and the resolve.
//   colour key = float bits of the linear view depth << 32 | sRGB RGBA8 (R in the top byte)
//   aux key    = float bits of the linear view depth << 32 | octahedral normal 10+10 | object id 12
// Both buffers are cleared to all ones; atom_min keeps the nearest sample. docs/frame.md.
#pragma OPENCL EXTENSION cl_khr_int64_base_atomics : enable
#pragma OPENCL EXTENSION cl_khr_int64_extended_atomics : enable

// Linear-light value at which each sRGB 8-bit code begins (code k for k/255 - 1/510 in sRGB),
// so that encoding is a binary search instead of pow(x, 1/2.4): pow dominated the point
// renderer's per-sample cost on CPUs. Entry 0 is below every input.
__constant float SRGB8_THRESHOLDS[256] = {
    -1.0f, 0.0001517635f, 0.0004552905f, 0.0007588175f, 0.0010623444f, 0.0013658714f, 0.0016693984f, 0.0019729254f,
    0.0022764525f, 0.0025799794f, 0.0028835062f, 0.0031883009f, 0.0035092593f, 0.003848315f, 0.004205748f, 0.004581833f,
    0.0049768374f, 0.005391024f, 0.0058246506f, 0.0062779696f, 0.0067512277f, 0.0072446684f, 0.0077585303f, 0.0082930485f,
    0.008848453f, 0.0094249705f, 0.010022826f, 0.010642237f, 0.011283421f, 0.0119465925f, 0.01263196f, 0.013339732f,
    0.014070112f, 0.014823303f, 0.015599503f, 0.01639891f, 0.017221715f, 0.018068114f, 0.018938294f, 0.019832443f,
    0.020750744f, 0.021693382f, 0.022660539f, 0.02365239f, 0.024669115f, 0.025710888f, 0.026777882f, 0.02787027f,
    0.02898822f, 0.030131903f, 0.03130148f, 0.032497123f, 0.03371899f, 0.034967244f, 0.036242045f, 0.037543554f,
    0.038871925f, 0.04022732f, 0.041609887f, 0.043019786f, 0.044457164f, 0.04592217f, 0.047414962f, 0.048935685f,
    0.050484486f, 0.052061506f, 0.053666897f, 0.055300802f, 0.05696336f, 0.058654718f, 0.060375012f, 0.062124383f,
    0.063902974f, 0.06571092f, 0.06754835f, 0.06941541f, 0.071312234f, 0.073238954f, 0.07519571f, 0.07718261f,
    0.07919982f, 0.08124744f, 0.083325624f, 0.08543449f, 0.087574154f, 0.08974477f, 0.09194644f, 0.0941793f,
    0.096443474f, 0.098739095f, 0.10106627f, 0.10342513f, 0.105815805f, 0.1082384f, 0.110693045f, 0.11317986f,
    0.11569897f, 0.11825048f, 0.12083452f, 0.1234512f, 0.12610064f, 0.12878296f, 0.13149826f, 0.13424668f,
    0.1370283f, 0.13984327f, 0.14269169f, 0.14557366f, 0.14848931f, 0.15143873f, 0.15442206f, 0.15743938f,
    0.16049083f, 0.1635765f, 0.16669649f, 0.16985093f, 0.17303991f, 0.17626357f, 0.17952198f, 0.18281525f,
    0.1861435f, 0.18950683f, 0.19290535f, 0.19633915f, 0.19980834f, 0.20331304f, 0.20685335f, 0.21042934f,
    0.21404114f, 0.21768884f, 0.22137256f, 0.2250924f, 0.22884843f, 0.23264076f, 0.2364695f, 0.24033478f,
    0.24423663f, 0.2481752f, 0.25215057f, 0.25616285f, 0.26021212f, 0.26429847f, 0.26842204f, 0.2725829f,
    0.2767811f, 0.2810168f, 0.2852901f, 0.28960103f, 0.29394972f, 0.2983363f, 0.3027608f, 0.30722335f,
    0.31172404f, 0.31626296f, 0.32084018f, 0.32545584f, 0.33010998f, 0.33480275f, 0.33953416f, 0.34430438f,
    0.34911346f, 0.3539615f, 0.35884857f, 0.36377478f, 0.36874023f, 0.37374496f, 0.37878913f, 0.38387278f,
    0.388996f, 0.3941589f, 0.39936152f, 0.40460402f, 0.40988642f, 0.41520882f, 0.42057136f, 0.42597404f,
    0.43141702f, 0.43690035f, 0.44242412f, 0.44798842f, 0.4535933f, 0.45923892f, 0.4649253f, 0.47065252f,
    0.4764207f, 0.48222992f, 0.48808023f, 0.49397177f, 0.49990454f, 0.5058787f, 0.5118943f, 0.5179514f,
    0.5240501f, 0.5301905f, 0.5363727f, 0.54259676f, 0.5488627f, 0.55517066f, 0.5615207f, 0.5679129f,
    0.5743473f, 0.58082414f, 0.58734334f, 0.593905f, 0.6005092f, 0.6071561f, 0.6138457f, 0.6205781f,
    0.62735337f, 0.6341716f, 0.6410329f, 0.64793724f, 0.6548848f, 0.66187567f, 0.6689098f, 0.67598736f,
    0.68310845f, 0.6902731f, 0.69748133f, 0.7047334f, 0.71202916f, 0.7193688f, 0.72675246f, 0.73418003f,
    0.7416518f, 0.7491677f, 0.7567278f, 0.7643323f, 0.7719811f, 0.7796744f, 0.7874123f, 0.79519475f,
    0.8030219f, 0.81089383f, 0.8188105f, 0.8267722f, 0.8347788f, 0.8428305f, 0.8509273f, 0.8590692f,
    0.8672565f, 0.87548906f, 0.88376707f, 0.89209056f, 0.9004596f, 0.9088742f, 0.91733456f, 0.9258406f,
    0.9343926f, 0.94299036f, 0.95163417f, 0.96032405f, 0.96906f, 0.97784215f, 0.98667055f, 0.99554527f,
};

// Linear [0, 1] to the sRGB 8-bit code that rounding the exact sRGB curve would give.
inline uint srgb8(float x) {
    uint k = 0;
    for (uint step = 128; step > 0; step >>= 1)
        if (SRGB8_THRESHOLDS[k + step] <= x) k += step;
    return k;
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
    float c = fmax(dot(n, normalize(L + ev)), 0.0f);
    float c4 = (c * c) * (c * c), c16 = (c4 * c4) * (c4 * c4);
    float spec = mat.w * c16 * c16 * c16;   // c^48 by squaring (pow is slow on CPUs)
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
