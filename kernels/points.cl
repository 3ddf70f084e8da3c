// Point renderers (thesis sections 5.5.3 and 5.5.5): a render patch is sampled on a regular
// (u, v) grid whose size comes from its measured screen extents, each sample is shaded with its
// analytic normal and written as a 64-bit key (keys.cl). This file holds the helpers both point
// variants share and the direct variant; points_lfb.cl (local framebuffers) builds on it.

// Sample counts: factor = density * oversample / (1 - epsilon) samples per measured pixel
// (paramlod/points.py, PointSettings.factor; the numpy twin is paramlod.points.side_counts).
// Rounding up and adding one gives at least `factor` steps per pixel; never fewer than 2.
inline uint side_count(float m, float factor, uint max_side) {
    float n = ceil(m * factor) + 1.0f;
    if (!(n < (float)max_side)) return max_side;  // also catches inf and NaN extents
    return max((uint)n, 2u);
}

// The sampling grid of one patch: nu x nv samples spanning the range widened by `widen` per
// side (so neighbouring patches overlap and leave no seam), clamped to the function's domain.
// use_extent = 0 measures with s_u, s_v (7 x the longest LOD segment: even the densest part of
// the patch gets `factor` samples per pixel); 1 with e_u, e_v (the thesis's adaptive sampling:
// about `factor` samples per pixel on average, cheaper, may leave 1-pixel holes).
typedef struct {
    float u0, v0, su, sv;   // first sample and steps
    uint nu, nv;
} PointGrid;

inline PointGrid point_grid(RenderPatch rp, __global const float* I, float factor, uint use_extent,
                            float widen, uint max_side) {
    PointGrid g;
    g.nu = side_count(use_extent ? rp.ext.x : rp.ext.z, factor, max_side);
    g.nv = side_count(use_extent ? rp.ext.y : rp.ext.w, factor, max_side);
    float wu = (rp.range.y - rp.range.x) * widen, wv = (rp.range.w - rp.range.z) * widen;
    float u0 = fmax(rp.range.x - wu, I[INST_DOMAIN + 0]), u1 = fmin(rp.range.y + wu, I[INST_DOMAIN + 1]);
    float v0 = fmax(rp.range.z - wv, I[INST_DOMAIN + 2]), v1 = fmin(rp.range.w + wv, I[INST_DOMAIN + 3]);
    g.u0 = u0; g.v0 = v0;
    g.su = (u1 - u0) / (float)(g.nu - 1);
    g.sv = (v1 - v0) / (float)(g.nv - 1);
    return g;
}

#define SAMPLE_DRAWN 0
#define SAMPLE_NAN 1
#define SAMPLE_CLIPPED 2

// Position only (no partials, no shading, no clipping): where a sample lands, for cheap
// rejection. Its bits may differ from point_sample's (separately generated code), so callers
// reject only with some slack. Returns SAMPLE_NAN or SAMPLE_DRAWN; *depth is the view depth.
inline int point_position(uint func, __global const float* P, __global const float* I,
                          __global const float* cam, float u, float v, float* fx, float* fy, float* depth) {
    float3 pos = pl_position(func, u, v, P);
    if (is_bad3(pos)) return SAMPLE_NAN;
    float3 e = xform_point(cam + CAM_VIEW, xform_point(I + INST_MODEL, pos));
    float4 c = project(cam, e);
    *depth = -e.z;
    *fx = (c.x / c.w * 0.5f + 0.5f) * cam[CAM_W];
    *fy = (0.5f - c.y / c.w * 0.5f) * cam[CAM_H];
    return SAMPLE_DRAWN;
}

// Evaluate, transform, clip and shade one sample. On SAMPLE_DRAWN, (*fx, *fy) is its screen
// position in pixels (inside the image), *key its colour key and *aux its attribute key.
inline int point_sample(uint func, __global const float* P, __global const float* I,
                        __global const float* cam, float4 mat, __global const float* light,
                        uint object_id, float u, float v, float* fx, float* fy, ulong* key, ulong* aux) {
    float3 pos, fu, fv;
    pl_surface(func, u, v, P, &pos, &fu, &fv);
    if (is_bad3(pos)) return SAMPLE_NAN;
    __global const float* V = cam + CAM_VIEW;
    float3 e = xform_point(V, xform_point(I + INST_MODEL, pos));
    float depth = -e.z;
    if (!(depth >= cam[CAM_NEAR] && depth <= cam[CAM_FAR])) return SAMPLE_CLIPPED;
    float W = cam[CAM_W], H = cam[CAM_H];
    float4 c = project(cam, e);
    float x = (c.x / c.w * 0.5f + 0.5f) * W;
    float y = (0.5f - c.y / c.w * 0.5f) * H;
    if (!(x >= 0.0f && y >= 0.0f && x < W && y < H)) return SAMPLE_CLIPPED;
    float3 n_view = xform_dir(V, xform_dir(I + INST_NORMAL, cross(fu, fv)));
    float3 n;
    uint rgba = shade(n_view, view_dir(cam, e), mat, light, &n);
    // the AOV normal is in world space: view -> world is the transpose of the view rotation
    float3 n_world = (float3)(V[0] * n.x + V[4] * n.y + V[8] * n.z,
                              V[1] * n.x + V[5] * n.y + V[9] * n.z,
                              V[2] * n.x + V[6] * n.y + V[10] * n.z);
    *fx = x; *fy = y;
    *key = color_key(depth, rgba);
    *aux = aux_key(depth, n_world, object_id);
    return SAMPLE_DRAWN;
}

// Direct variant: one work-group per render patch, samples written straight into the shared
// key buffers with early depth (write_point reads before it issues an atom_min).
__kernel void points_direct(__global const RenderPatch* patches, uint n_patches,
                            __global const float* inst_f, __global const uint* inst_u,
                            __global const float* params, __global const float4* materials,
                            __global const float* cam, __global const float* light,
                            float factor, uint use_extent, float widen, uint max_side,
                            __global ulong* color_buf, __global ulong* aux_buf,
                            __global ulong* counters   // samples, atomics, NaN samples, capped patches
#ifdef PL_RECORD
                            // test hook: every sample's pixel (or ~0 if dropped) and colour key
                            , __global const uint* rec_offset, __global uint* rec_pix, __global ulong* rec_key
#endif
                            )
{
    uint pid = get_group_id(0);
    if (pid >= n_patches) return;
    RenderPatch rp = patches[pid];
    uint inst = rp.inst;
    __global const float* I = inst_f + inst * INST_F;
    uint func = inst_u[inst * INST_U + 0];
    __global const float* P = params + inst_u[inst * INST_U + 1];
    uint object_id = inst_u[inst * INST_U + 2];
    float4 mat = materials[inst];
    PointGrid g = point_grid(rp, I, factor, use_extent, widen, max_side);
    uint W = (uint)cam[CAM_W];

    ulong n_samples = 0, n_atomics = 0, n_nan = 0;
    uint total = g.nu * g.nv;
    for (uint j = get_local_id(0); j < total; j += get_local_size(0)) {
        uint iu = j % g.nu, iv = j / g.nu;
        float fx, fy;
        ulong key, aux;
        int r = point_sample(func, P, I, cam, mat, light, object_id,
                             g.u0 + g.su * (float)iu, g.v0 + g.sv * (float)iv, &fx, &fy, &key, &aux);
        n_samples++;
#ifdef PL_RECORD
        rec_pix[rec_offset[pid] + j] = 0xFFFFFFFFu;
#endif
        if (r == SAMPLE_NAN) n_nan++;
        if (r != SAMPLE_DRAWN) continue;
        uint pix = (uint)fy * W + (uint)fx;
#ifdef PL_RECORD
        rec_pix[rec_offset[pid] + j] = pix;
        rec_key[rec_offset[pid] + j] = key;
#endif
        n_atomics += write_point(color_buf, aux_buf, pix, key, aux);
    }
    atom_add(&counters[0], n_samples);
    atom_add(&counters[1], n_atomics);
    atom_add(&counters[2], n_nan);
    if (get_local_id(0) == 0 && (g.nu == max_side || g.nv == max_side)) atom_add(&counters[3], (ulong)1);
}
