// Point renderer, direct variant (thesis section 5.5.3): one work-group per render patch samples
// the patch on a regular (u, v) grid sized from its measured screen extents (s_u, s_v: the
// longest segment, so that the densest part of the patch gets `density` samples per pixel), shades each sample
// with its analytic normal and writes it into the shared 64-bit key buffers (keys.cl).

// Samples per side for an extent e (pixels): about `density` per pixel, at least 2.
inline uint side_count(float e, float density, uint max_side) {
    float n = ceil(e * density) + 1.0f;
    if (!(n < (float)max_side)) return max_side;  // also catches inf and NaN extents
    return max((uint)n, 2u);
}

__kernel void points_direct(__global const RenderPatch* patches, uint n_patches,
                            __global const float* inst_f, __global const uint* inst_u,
                            __global const float* params, __global const float4* materials,
                            __global const float* cam, __global const float* light,
                            float density, float widen, uint max_side,
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

    uint nu = side_count(rp.ext.z, density, max_side);
    uint nv = side_count(rp.ext.w, density, max_side);
    // widen the range a little so neighbouring patches overlap (no seams), within the domain
    float wu = (rp.range.y - rp.range.x) * widen, wv = (rp.range.w - rp.range.z) * widen;
    float u0 = fmax(rp.range.x - wu, I[INST_DOMAIN + 0]), u1 = fmin(rp.range.y + wu, I[INST_DOMAIN + 1]);
    float v0 = fmax(rp.range.z - wv, I[INST_DOMAIN + 2]), v1 = fmin(rp.range.w + wv, I[INST_DOMAIN + 3]);
    float su = (u1 - u0) / (float)(nu - 1), sv = (v1 - v0) / (float)(nv - 1);

    uint W = (uint)cam[CAM_W], H = (uint)cam[CAM_H];
    float near = cam[CAM_NEAR], far = cam[CAM_FAR];
    __global const float* V = cam + CAM_VIEW;

    ulong n_samples = 0, n_atomics = 0, n_nan = 0;
    uint total = nu * nv;
    for (uint j = get_local_id(0); j < total; j += get_local_size(0)) {
        uint iu = j % nu, iv = j / nu;
        float3 pos, fu, fv;
        pl_surface(func, u0 + su * (float)iu, v0 + sv * (float)iv, P, &pos, &fu, &fv);
        n_samples++;
#ifdef PL_RECORD
        rec_pix[rec_offset[pid] + j] = 0xFFFFFFFFu;
#endif
        if (is_bad3(pos)) { n_nan++; continue; }
        float3 e = xform_point(V, xform_point(I + INST_MODEL, pos));
        float depth = -e.z;
        if (!(depth >= near && depth <= far)) continue;
        float4 c = project(cam, e);
        float fx = (c.x / c.w * 0.5f + 0.5f) * (float)W;
        float fy = (0.5f - c.y / c.w * 0.5f) * (float)H;
        if (!(fx >= 0.0f && fy >= 0.0f && fx < (float)W && fy < (float)H)) continue;
        uint pix = (uint)fy * W + (uint)fx;

        float3 n_view = xform_dir(V, xform_dir(I + INST_NORMAL, cross(fu, fv)));
        float3 n;
        uint rgba = shade(n_view, e, mat, light, &n);
        // the AOV normal is in world space: view -> world is the transpose of the view rotation
        float3 n_world = (float3)(V[0] * n.x + V[4] * n.y + V[8] * n.z,
                                  V[1] * n.x + V[5] * n.y + V[9] * n.z,
                                  V[2] * n.x + V[6] * n.y + V[10] * n.z);
        ulong key = color_key(depth, rgba);
#ifdef PL_RECORD
        rec_pix[rec_offset[pid] + j] = pix;
        rec_key[rec_offset[pid] + j] = key;
#endif
        n_atomics += write_point(color_buf, aux_buf, pix, key, aux_key(depth, n_world, object_id));
    }
    atom_add(&counters[0], n_samples);
    atom_add(&counters[1], n_atomics);
    atom_add(&counters[2], n_nan);
    if (get_local_id(0) == 0 && (nu == max_side || nv == max_side)) atom_add(&counters[3], (ulong)1);
}
