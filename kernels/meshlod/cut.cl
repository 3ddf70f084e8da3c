// Mesh LOD cut: one work-item per (instance, cluster) of a batch (the instances of one mesh over
// that mesh's clusters: global id 0 = cluster, 1 = instance). A cluster is drawn for an instance
// iff its group's projected error is <= the threshold and its parent group's is > it; drawn
// clusters then meet the frustum test and, for SIMILAR instances, the backface cone. The rule and
// the cut camera record (CC_* offsets, passed as -D defines) are described in
// paramlod/meshlod/cut_reference.py, the numpy twin of this file: the float32 operations here are
// in the twin's order (no contraction, exact division and sqrt), so both select the same pairs.
// Driven by paramlod.meshlod.cut.ClusterCut. Built after the prelude (Cluster, INST_*) and
// kernels/common/common.cl (64-bit atomics).
//
// Output: (instance, cluster) uint2 pairs appended to `selection` (written only below
// `capacity`), and 8 ulong counters: [0] selected (may exceed capacity), [1] their triangles,
// [2] culled by the frustum, [3] culled by the backface cone, [4] cluster tests made.
// Each work-group sums its counts in local memory and reserves its range of the selection with
// one global atomic, so the counters see one atomic per group and counter, not per cluster.
// An instance whose hand-off weight (`weights`, paramlod/scene/handoff.py) is 0 selects nothing and
// makes no tests: its surfels draw every pixel (a group holds one instance).
#pragma OPENCL FP_CONTRACT OFF
#include "common/rows.cl"
#include "meshlod/cut_common.cl"

// the cut camera record, passed by value with the launch (no buffer write per frame)
typedef struct { float v[CC_FLOATS]; } CutCamera;

// The projected error in pixels of error e around object-space sphere S (0 for e == 0).
inline float cut_proj(float e, float4 S, __global const float* m, float s, const float* cc) {
    if (e == 0.0f) return 0.0f;
    float3 w = rows_point(m, S.xyz);
    float depth = ((cc[CC_DEPTH] * w.x + cc[CC_DEPTH + 1] * w.y) + cc[CC_DEPTH + 2] * w.z) + cc[CC_DEPTH + 3];
    float dn = fmax(depth - S.w * s, cc[CC_NEAR]);
    float wd = cc[CC_WA] * dn + cc[CC_WB];
    return ((e * s) * cc[CC_K]) / wd;
}

// True when the bounding sphere (world centre, radius r * s) lies wholly outside one clip plane.
inline bool cut_outside(float4 S, __global const float* m, float s, const float* cc) {
    return planes_outside(rows_point(m, S.xyz), S.w * s, cc);
}

// meshoptimizer's cone rule in object space: the eye is brought there by M^-1 = (N^T, -N^T t).
inline bool cut_backfacing(float4 apex, float4 cone, __global const float* inst, const float* cc) {
    __global const float* m = inst + INST_MODEL;
    __global const float* nm = inst + INST_NORMAL;
    float ew = cc[CC_EYE + 3];
    float u0 = cc[CC_EYE] - ew * m[3], u1 = cc[CC_EYE + 1] - ew * m[7], u2 = cc[CC_EYE + 2] - ew * m[11];
    float ex = (nm[0] * u0 + nm[4] * u1) + nm[8] * u2;
    float ey = (nm[1] * u0 + nm[5] * u1) + nm[9] * u2;
    float ez = (nm[2] * u0 + nm[6] * u1) + nm[10] * u2;
    float dx = apex.x * ew - ex, dy = apex.y * ew - ey, dz = apex.z * ew - ez;
    float len = sqrt((dx * dx + dy * dy) + dz * dz);
    float dt = (dx * cone.x + dy * cone.y) + dz * cone.z;
    return cone.w < 1.0f && len > 0.0f && dt >= cone.w * len;
}

__kernel __attribute__((reqd_work_group_size(CUT_LOCAL, 1, 1)))
void cluster_cut(__global const Cluster* clusters, uint first_cluster, uint n_clusters, uint first_instance,
                 __global const float* inst_f, __global const uint* inst_u, __global const float* scales,
                 __global const float* weights, const CutCamera cam, uint mode,
                 __global uint2* selection, uint capacity, __global ulong* counters)
{
    __local uint l_n[4];   // selected, their triangles, frustum-culled, backface-culled (cut_group_append)
    __local ulong l_base;
    uint inst = first_instance + (uint)get_global_id(1);
    // no early return: PoCL's work-group loops need every work-item to reach the barriers
    bool live = weights[inst] > 0.0f;
    const float* cc = cam.v;
    uint lid = get_local_id(0);
    if (lid == 0) { l_n[0] = 0u; l_n[1] = 0u; l_n[2] = 0u; l_n[3] = 0u; }
    barrier(CLK_LOCAL_MEM_FENCE);

    uint c = get_global_id(0);
    uint slot = 0xFFFFFFFFu;
    if (c < n_clusters && live) {
        __global const Cluster* cl = clusters + first_cluster + c;
        __global const float* I = inst_f + (size_t)inst * INST_F;
        __global const float* m = I + INST_MODEL;
        float s = scales[inst];
        float T = cc[CC_T];
        bool draw = cut_proj(cl->error, cl->lod_sphere, m, s, cc) <= T;
        if (draw && !isinf(cl->parent_error))
            draw = cut_proj(cl->parent_error, cl->parent_sphere, m, s, cc) > T;
        if (draw) {
            if ((mode & 1u) && cut_outside(cl->sphere, m, s, cc)) {
                atomic_inc(&l_n[2]);
            } else if ((mode & 2u) && (inst_u[(size_t)inst * INST_U + INST_FLAGS] & CUT_SIMILAR)
                       && cut_backfacing(cl->cone_apex, cl->cone, I, cc)) {
                atomic_inc(&l_n[3]);
            } else {
                slot = atomic_inc(&l_n[0]);
                atomic_add(&l_n[1], cl->count);
            }
        }
    }
    uint start = (uint)get_group_id(0) * CUT_LOCAL;
    uint tests = start < n_clusters && live ? min((uint)CUT_LOCAL, n_clusters - start) : 0u;
    cut_group_append(l_n, &l_base, tests, slot, (uint2)(inst, first_cluster + c), selection, capacity, counters);
}
