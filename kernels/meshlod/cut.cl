// Mesh LOD cut: one work-item per (instance, cluster) of a batch (the instances of one mesh over
// that mesh's clusters: global id 0 = cluster, 1 = instance). A cluster is drawn for an instance
// iff its group's projected error does not exceed the threshold and its parent group's does; drawn
// clusters then meet the frustum test and, for instances flagged SIMILAR and ONE_SIDED (CUT_CONES:
// the cone holds under the model, and the material hides back faces), the backface cone. The rule and
// the cut camera record (CC_* offsets, passed as -D defines) are described in
// paramlod/meshlod/cut_reference.py, the numpy twin of this file: the float32 operations here are
// in the twin's order (no contraction, exact division and sqrt), so both select the same pairs.
// Driven by paramlod.meshlod.cut.ClusterCut. Built after the prelude (Cluster, INST_*) and
// kernels/common/common.cl (64-bit atomics).
//
// Output: (instance, cluster) uint2 pairs appended to `selection` (written only below
// `capacity`; with several views their masks to `masks`), and the CUT_COUNTERS ulong counters:
// CUT_SELECTED (may exceed capacity), CUT_TRIANGLES, CUT_CULLED_FRUSTUM, CUT_CULLED_BACKFACE,
// CUT_TESTS (then, with several views, two per view).
// Each work-group sums its counts in local memory and reserves its range of the selection with
// one global atomic, so the counters see one atomic per group and counter, not per cluster.
// An instance whose hand-off weight (`weights`, paramlod/scene/handoff.py) is 0 selects nothing and
// makes no tests: its surfels draw every pixel (a group holds one instance).
//
// Views (`cams`: n_views cut camera records, kernels/meshlod/cut_common.cl; `cam`: view 0's, by
// value): the projected error of a group is its largest over the views whose frustum its LOD
// sphere meets (the smallest over all views when none does), so a child's parent test and its
// parent group's own test still read the same values and the cut stays a cut, refined as far as
// the view that needs most asks; a selected cluster is dropped only when every view culls it
// (frustum or backface cone), and otherwise drawn into the views that do not (its view mask).
// n_views == 1 is the one-view rule.
#pragma OPENCL FP_CONTRACT OFF
#include "common/rows.cl"
#include "meshlod/cut_common.cl"

// The projected error in pixels of error e around the sphere of world centre w and object-space
// radius r (0 for e == 0) in the view of cut camera record cc, for an instance of largest scale s.
inline float cut_proj_at(float e, float3 w, float r, float s, const float* cc) {
    if (e == 0.0f) return 0.0f;
    float depth = ((cc[CC_DEPTH] * w.x + cc[CC_DEPTH + 1] * w.y) + cc[CC_DEPTH + 2] * w.z) + cc[CC_DEPTH + 3];
    float dn = fmax(depth - r * s, cc[CC_NEAR]);
    float wd = cc[CC_WA] * dn + cc[CC_WB];
    return ((e * s) * cc[CC_K]) / wd;
}

// The projected error of error e around object-space sphere S.
inline float cut_proj(float e, float4 S, __global const float* m, float s, const float* cc) {
    return e == 0.0f ? 0.0f : cut_proj_at(e, rows_point(m, S.xyz), S.w, s, cc);
}

// True when the bounding sphere (world centre, radius r * s) lies wholly outside one clip plane.
inline bool cut_outside(float4 S, __global const float* m, float s, const float* cc) {
    return planes_outside(rows_point(m, S.xyz), S.w * s, cc);
}

// True when the projected error of (e, S) over the views exceeds T: in a view whose frustum S
// meets, or, when S is outside every view, in all of them (cut_reference.exceeds). `cam`: view 0.
inline bool cut_exceeds(float e, float4 S, __global const float* m, float s, const float* cam,
                        __global const float* cams, uint n_views, float T) {
    if (CUT_VIEWS(n_views) == 1u) return cut_proj(e, S, m, s, cam) > T;
    if (e == 0.0f) return false;   // 0 in every view, and T >= 0
    float3 w = rows_point(m, S.xyz);   // the same in every view
    bool seen = false, all = true;
    for (uint v = 0; v < CUT_VIEWS(n_views); ++v) {
        CutCamera cv = cut_view(cams, v);
        bool above = cut_proj_at(e, w, S.w, s, cv.v) > T;
        if (!planes_outside(w, S.w * s, cv.v)) {
            if (above) return true;
            seen = true;
        }
        all = all && above;
    }
    return !seen && all;
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

// How view cc treats a cluster the LOD chose: 0 keeps it, 1 culls it by the frustum, 2 by the
// backface cone (the one-view tests, in their order).
inline uint cut_cull(__global const Cluster* cl, __global const float* I, float s, bool cones, uint mode,
                     const float* cc) {
    if ((mode & 1u) && cut_outside(cl->sphere, I + INST_MODEL, s, cc)) return 1u;
    if ((mode & 2u) && cones && cut_backfacing(cl->cone_apex, cl->cone, I, cc)) return 2u;
    return 0u;
}

__kernel __attribute__((reqd_work_group_size(CUT_LOCAL, 1, 1)))
void cluster_cut(__global const Cluster* clusters, uint first_cluster, uint n_clusters, uint first_instance,
                 __global const float* inst_f, __global const uint* inst_u, __global const float* scales,
                 __global const float* weights, const CutCamera cam, __global const float* cams, uint n_views,
                 uint mode, __global uint2* selection, __global ulong* masks, uint capacity, __global ulong* counters)
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
    if (CUT_VIEWS(n_views) > 1u) cut_views_zero(l_v, n_views, CUT_LOCAL);
    barrier(CLK_LOCAL_MEM_FENCE);

    uint c = get_global_id(0);
    uint slot = 0xFFFFFFFFu;
    ulong mask = 0ul;
    if (c < n_clusters && live) {
        __global const Cluster* cl = clusters + first_cluster + c;
        __global const float* I = inst_f + (size_t)inst * INST_F;
        __global const float* m = I + INST_MODEL;
        float s = scales[inst];
        float T = cc[CC_T];
        bool draw = !cut_exceeds(cl->error, cl->lod_sphere, m, s, cc, cams, n_views, T);
        if (draw && !isinf(cl->parent_error))
            draw = cut_exceeds(cl->parent_error, cl->parent_sphere, m, s, cc, cams, n_views, T);
        if (draw) {
            bool cones = (inst_u[(size_t)inst * INST_U + INST_FLAGS] & CUT_CONES) == CUT_CONES;
            bool all_outside;
            if (CUT_VIEWS(n_views) == 1u) {
                uint why = cut_cull(cl, I, s, cones, mode, cc);
                mask = why ? 0ul : 1ul;
                all_outside = why == 1u;
            } else {
                all_outside = true;
                for (uint v = 0; v < CUT_VIEWS(n_views); ++v) {
                    CutCamera cv = cut_view(cams, v);
                    uint why = cut_cull(cl, I, s, cones, mode, cv.v);
                    if (!why) mask |= 1ul << v;
                    all_outside = all_outside && why == 1u;
                }
            }
            if (mask) {
                slot = atomic_inc(&l_n[0]);
                atomic_add(&l_n[1], cl->count);
                if (CUT_VIEWS(n_views) > 1u) cut_views_count(l_v, mask, cl->count);
            } else {
                atomic_inc(&l_n[all_outside ? 2 : 3]);
            }
        }
    }
    uint start = (uint)get_group_id(0) * CUT_LOCAL;
    uint tests = start < n_clusters && live ? min((uint)CUT_LOCAL, n_clusters - start) : 0u;
    cut_group_append(l_n, &l_base, tests, slot, (uint2)(inst, first_cluster + c), selection, capacity, counters,
                     l_v, n_views, mask, masks, CUT_LOCAL);
}
