// What the two mesh cut kernels share: kernels/meshlod/cut.cl (the DAG cut, twin
// paramlod/meshlod/cut_reference.py) and kernels/meshlod/skin_cull.cl (skinned meshlets, twin
// paramlod/meshlod/skin_cull_reference.py). Included after `#pragma OPENCL FP_CONTRACT OFF`;
// needs CC_PLANES (the cut camera record) and the 64-bit atomics of kernels/common/common.cl.
#ifndef PL_MESHLOD_CUT_COMMON
#define PL_MESHLOD_CUT_COMMON

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

// The end of a cut work-group. l_n holds the group's counts (selected, their triangles, culled by
// the frustum, culled by the backface test), `tests` the tests it made: one global atomic per
// counter (counters: the same four, then tests) reserves the group's range of the selection, then
// each selected work-item (slot != ~0) writes its pair there, only below `capacity`. Every
// work-item of the group calls it (barriers).
inline void cut_group_append(volatile __local uint* l_n, volatile __local ulong* l_base, uint tests, uint slot,
                             uint2 pair, __global uint2* selection, uint capacity, __global ulong* counters) {
    barrier(CLK_LOCAL_MEM_FENCE);
    if (get_local_id(0) == 0) {
        *l_base = l_n[0] ? atom_add(&counters[0], (ulong)l_n[0]) : 0;
        for (int i = 1; i < 4; ++i)
            if (l_n[i]) atom_add(&counters[i], (ulong)l_n[i]);
        if (tests) atom_add(&counters[4], (ulong)tests);
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    if (slot != 0xFFFFFFFFu) {
        ulong k = *l_base + slot;
        if (k < (ulong)capacity) selection[k] = pair;
    }
}
#endif
