// What the two mesh cut kernels share: kernels/meshlod/cut.cl (the DAG cut, twin
// paramlod/meshlod/cut_reference.py) and kernels/meshlod/skin_cull.cl (skinned meshlets, twin
// paramlod/meshlod/skin_cull_reference.py). Included after `#pragma OPENCL FP_CONTRACT OFF`;
// needs CC_PLANES (the cut camera record) and the 64-bit atomics of kernels/common/common.cl; the
// counters are CUT_* of the prelude (paramlod.core.layouts.CUT_COUNTER).
//
// Views: a kernel gets the first view's cut camera record by value (all a one-view cut reads) and
// the records of a frame's N views one after another in a buffer (N * CC_FLOATS floats,
// paramlod.meshlod.cut_reference.cut_cameras), read only for N > 1, a view at a time into private
// memory (cut_view) so the tests read every view's record as the one-view cut reads its own. With
// N > 1 each selected pair also gets a view mask (bit v: the views it is drawn into, `masks`,
// parallel to the selection) and per-view counters follow the eight of the contract:
// [CUT_COUNTERS + 2v] the pairs drawn into view v, [CUT_COUNTERS + 2v + 1] their
// triangles. With N == 1 neither is written.
#ifndef PL_MESHLOD_CUT_COMMON
#define PL_MESHLOD_CUT_COMMON

// The views of a launch: the one-view program (built with CUT_ONE_VIEW) has exactly one, known to
// the compiler, so none of the code for several views is even emitted and the kernel is the
// one-view cut (on PoCL the code for several views, never run, made it 1.3-1.5 times slower).
#ifdef CUT_ONE_VIEW
#define CUT_VIEWS(n) 1u
#else
#define CUT_VIEWS(n) (n)
#endif

// a cut camera record, passed by value with the launch (no buffer write per frame for one view)
typedef struct { float v[CC_FLOATS]; } CutCamera;

// View v's record of the buffer of all views' records.
inline CutCamera cut_view(__global const float* cams, uint v) {
    CutCamera c;
    for (int i = 0; i < CC_FLOATS; ++i) c.v[i] = cams[v * CC_FLOATS + i];
    return c;
}

// True when the sphere (world centre w, radius r) lies wholly outside one of the six planes of
// the cut camera record, in a fixed order of operations (twin: cut_reference.planes_outside).
inline bool planes_outside(float3 w, float r, const float* cc) {
    bool out = false;
    for (int k = 0; k < 6; ++k) {
        const float* n = cc + CC_PLANES + 4 * k;
        float dist = ((n[0] * w.x + n[1] * w.y) + n[2] * w.z) + n[3];
        out |= dist < -r;
    }
    return out;
}

// The lowest set bit's index of a non-zero mask (OpenCL 1.2 has clz, not ctz).
inline uint cut_lowest_view(ulong m) {
    return 63u - (uint)clz(m & (~m + 1ul));
}

// Zero a work-group's per-view counts (before its first barrier; n_views > 1 only).
inline void cut_views_zero(volatile __local uint* l_v, uint n_views, uint local_size) {
    for (uint i = get_local_id(0); i < 2u * n_views; i += local_size) l_v[i] = 0u;
}

// Count one selected pair of `count` triangles into the views of its mask.
inline void cut_views_count(volatile __local uint* l_v, ulong mask, uint count) {
    for (ulong m = mask; m; m &= m - 1ul) {
        uint v = cut_lowest_view(m);
        atomic_inc(&l_v[2u * v]);
        atomic_add(&l_v[2u * v + 1u], count);
    }
}

// The end of a cut work-group. l_n holds the group's counts (selected, their triangles, culled by
// the frustum, culled by the backface test), `tests` the tests it made, l_v its per-view counts
// (n_views > 1): one global atomic per counter (counters: the same four, then tests, then the
// per-view ones) reserves the group's range of the selection, then each selected work-item
// (slot != ~0) writes its pair there (and, n_views > 1, its view mask), only below `capacity`.
// Every work-item of the group calls it (barriers).
inline void cut_group_append(volatile __local uint* l_n, volatile __local ulong* l_base, uint tests, uint slot,
                             uint2 pair, __global uint2* selection, uint capacity, __global ulong* counters,
                             volatile __local uint* l_v, uint n_views, ulong mask, __global ulong* masks,
                             uint local_size) {
    barrier(CLK_LOCAL_MEM_FENCE);
    if (get_local_id(0) == 0) {
        *l_base = l_n[0] ? atom_add(&counters[CUT_SELECTED], (ulong)l_n[0]) : 0;
        if (l_n[1]) atom_add(&counters[CUT_TRIANGLES], (ulong)l_n[1]);
        if (l_n[2]) atom_add(&counters[CUT_CULLED_FRUSTUM], (ulong)l_n[2]);
        if (l_n[3]) atom_add(&counters[CUT_CULLED_BACKFACE], (ulong)l_n[3]);
        if (tests) atom_add(&counters[CUT_TESTS], (ulong)tests);
    }
    if (CUT_VIEWS(n_views) > 1u)
        for (uint i = get_local_id(0); i < 2u * n_views; i += local_size)
            if (l_v[i]) atom_add(&counters[CUT_COUNTERS + i], (ulong)l_v[i]);
    barrier(CLK_LOCAL_MEM_FENCE);
    if (slot != 0xFFFFFFFFu) {
        ulong k = *l_base + slot;
        if (k < (ulong)capacity) {
            selection[k] = pair;
            if (CUT_VIEWS(n_views) > 1u) masks[k] = mask;
        }
    }
}
#endif
