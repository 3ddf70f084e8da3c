// Skinned meshlet cull: one work-item per (meshlet, instance) of one skinned mesh (global id 0 =
// meshlet, 1 = instance). Every meshlet of a skinned mesh is drawn at full detail (no DAG); the
// offline bounds (paramlod/meshlod/build/skin_bounds.py) put it in a class: 0 = frustum and backface
// tests, 1 = frustum test only, 2 = always drawn. The rules are in paramlod/meshlod/skin_cull_reference.py,
// the numpy twin of this file (same float32 operations in the same order, no contraction, exact sqrt
// and division, so both select the same pairs). Driven by paramlod.meshlod.skin_cull.SkinCull, after
// the skinning kernel (kernels/meshlod/skin.cl) has been given the same frame's skin matrices.
// Built after the prelude (INST_*) and kernels/common/common.cl (64-bit atomics).
//
// Output: like kernels/meshlod/cut.cl (the raster draws it unchanged): (instance, cluster) uint2 pairs
// appended to `selection` (written only below `capacity`), and the counters CUT_SELECTED,
// CUT_TRIANGLES, CUT_CULLED_FRUSTUM, CUT_CULLED_BACKFACE and CUT_TESTS (meshlet tests made),
// summed per work-group in local memory (one global atomic per group and counter). An instance whose
// hand-off weight is 0 selects nothing and makes no tests.
// Views (`cams`: n_views cut camera records, kernels/meshlod/cut_common.cl; `cam`: view 0's by
// value): a meshlet is dropped only when every view culls it (frustum, or backface for class 0;
// counted as frustum-culled when every view's frustum test culls it) and is drawn into the views
// that do not (its view mask).
#pragma OPENCL FP_CONTRACT OFF
#include "common/rows.cl"
#include "meshlod/cut_common.cl"

// sqrt of a Gershgorin bound on the largest eigenvalue of A^T A (A = rows 0..2, columns 0..2 of m):
// >= the largest singular value, equal to it when A's columns are orthogonal (T R S joints).
inline float sc_scale(__global const float* m) {
    float g[9];
    for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b)
            g[3 * a + b] = (m[a] * m[b] + m[4 + a] * m[4 + b]) + m[8 + a] * m[8 + b];
    float r0 = (fabs(g[0]) + fabs(g[1])) + fabs(g[2]);
    float r1 = (fabs(g[3]) + fabs(g[4])) + fabs(g[5]);
    float r2 = (fabs(g[6]) + fabs(g[7])) + fabs(g[8]);
    return sqrt(fmax(fmax(r0, r1), r2));
}

// True when every triangle of the meshlet faces away from the eye: tested in the principal joint's
// space (PBS), where the meshlet lies in the sphere (c, r s_r) and its normals within alpha of n.
inline bool sc_backfacing(float4 S, float sr, float4 cone, __global const float* inst,
                          __global const float* J, const float* cc) {
    __global const float* m = inst + INST_MODEL;
    __global const float* nm = inst + INST_NORMAL;
    float ew = cc[CC_EYE + 3];
    // the eye in mesh space (as the static cut brings it to object space)
    float u0 = cc[CC_EYE] - ew * m[3], u1 = cc[CC_EYE + 1] - ew * m[7], u2 = cc[CC_EYE + 2] - ew * m[11];
    float ex = (nm[0] * u0 + nm[4] * u1) + nm[8] * u2;
    float ey = (nm[1] * u0 + nm[5] * u1) + nm[9] * u2;
    float ez = (nm[2] * u0 + nm[6] * u1) + nm[10] * u2;
    // then into PBS by the joint's inverse (adjugate / determinant); a mirroring or singular joint: no test
    float x0 = ex - ew * J[3], x1 = ey - ew * J[7], x2 = ez - ew * J[11];
    float a00 = J[5] * J[10] - J[6] * J[9], a01 = J[2] * J[9] - J[1] * J[10], a02 = J[1] * J[6] - J[2] * J[5];
    float a10 = J[6] * J[8] - J[4] * J[10], a11 = J[0] * J[10] - J[2] * J[8], a12 = J[2] * J[4] - J[0] * J[6];
    float a20 = J[4] * J[9] - J[5] * J[8], a21 = J[1] * J[8] - J[0] * J[9], a22 = J[0] * J[5] - J[1] * J[4];
    float det = (J[0] * a00 + J[1] * a10) + J[2] * a20;
    if (!(det > 0.0f) || isinf(det)) return false;
    float qx = ((a00 * x0 + a01 * x1) + a02 * x2) / det;
    float qy = ((a10 * x0 + a11 * x1) + a12 * x2) / det;
    float qz = ((a20 * x0 + a21 * x1) + a22 * x2) / det;
    float dx = S.x * ew - qx, dy = S.y * ew - qy, dz = S.z * ew - qz;
    float len = sqrt((dx * dx + dy * dy) + dz * dz);
    float dt = (dx * cone.x + dy * cone.y) + dz * cone.z;
    float cx = cone.y * dz - cone.z * dy, cy = cone.z * dx - cone.x * dz, cz = cone.x * dy - cone.y * dx;
    float cr = sqrt((cx * cx + cy * cy) + cz * cz);
    float sa = sqrt(fmax(1.0f - cone.w * cone.w, 0.0f));
    float lhs = cone.w * dt - sa * cr;
    float rhs = (S.w * sr) * ew + SC_SLACK * len;
    return len > 0.0f && isfinite(len) && lhs >= rhs;
}

// How view cc treats meshlet k of class md.y < 2 (world centre w, radius r): 0 keeps it, 1 culls
// it by the frustum, 2 (class 0) by the backface test (the one-view tests, in their order).
inline uint sc_cull(float3 w, float r, float4 S, float sr, float4 cone, uint cls, __global const float* I,
                    __global const float* J, uint mode, const float* cc) {
    if ((mode & 1u) && planes_outside(w, r, cc)) return 1u;
    if ((mode & 2u) && cls == 0u && sc_backfacing(S, sr, cone, I, J, cc)) return 2u;
    return 0u;
}

__kernel __attribute__((reqd_work_group_size(SC_LOCAL, 1, 1)))
void skin_cull(__global const float4* spheres, __global const float4* cones, __global const uint4* meta,
               uint first_meshlet, uint n_meshlets, uint first_cluster, uint first_instance, uint first_joint,
               float sr, __global const float* inst_f, __global const float* scales,
               __global const float* weights, __global const float* skin, const CutCamera cam,
               __global const float* cams, uint n_views, uint mode, __global uint2* selection,
               __global ulong* masks, uint capacity, __global ulong* counters)
{
    __local uint l_n[4];   // selected, their triangles, frustum-culled, backface-culled (cut_group_append)
    __local uint l_v[2 * CUT_MAX_VIEWS];   // per view: selected, their triangles (n_views > 1)
    __local ulong l_base;
    uint inst = first_instance + (uint)get_global_id(1);
    // no early return: PoCL's work-group loops need every work-item to reach the barriers
    bool live = weights[inst] > 0.0f;
    const float* cc = cam.v;
    uint lid = get_local_id(0);
    if (lid == 0) { l_n[0] = 0u; l_n[1] = 0u; l_n[2] = 0u; l_n[3] = 0u; }
    if (CUT_VIEWS(n_views) > 1u) cut_views_zero(l_v, n_views, SC_LOCAL);
    barrier(CLK_LOCAL_MEM_FENCE);

    uint c = get_global_id(0);
    uint slot = 0xFFFFFFFFu;
    ulong mask = 0ul;
    if (c < n_meshlets && live) {
        uint k = first_meshlet + c;
        float4 S = spheres[k];
        uint4 md = meta[k];   // principal joint, class, triangles
        __global const float* I = inst_f + (size_t)inst * INST_F;
        __global const float* J = skin + (size_t)(first_joint + md.x) * 16;
        mask = CUT_VIEWS(n_views) == 64u ? ~0ul : (1ul << CUT_VIEWS(n_views)) - 1ul;   // class 2: every view, no test
        bool all_outside = false;
        if (md.y < 2u) {
            float3 w = rows_point(I + INST_MODEL, rows_point(J, S.xyz));
            float r = ((S.w * sr) * sc_scale(J)) * scales[inst];
            float4 cone = cones[k];
            if (CUT_VIEWS(n_views) == 1u) {
                uint why = sc_cull(w, r, S, sr, cone, md.y, I, J, mode, cc);
                mask = why ? 0ul : 1ul;
                all_outside = why == 1u;
            } else {
                all_outside = true;
                for (uint v = 0; v < CUT_VIEWS(n_views); ++v) {
                    CutCamera cv = cut_view(cams, v);
                    uint why = sc_cull(w, r, S, sr, cone, md.y, I, J, mode, cv.v);
                    if (why) mask &= ~(1ul << v);
                    all_outside = all_outside && why == 1u;
                }
            }
        }
        if (mask) {
            slot = atomic_inc(&l_n[0]);
            atomic_add(&l_n[1], md.z);
            if (CUT_VIEWS(n_views) > 1u) cut_views_count(l_v, mask, md.z);
        } else {
            atomic_inc(&l_n[all_outside ? 2 : 3]);
        }
    }
    uint start = (uint)get_group_id(0) * SC_LOCAL;
    uint tests = start < n_meshlets && live ? min((uint)SC_LOCAL, n_meshlets - start) : 0u;
    cut_group_append(l_n, &l_base, tests, slot, (uint2)(inst, first_cluster + c), selection, capacity, counters,
                     l_v, n_views, mask, masks, SC_LOCAL);
}
