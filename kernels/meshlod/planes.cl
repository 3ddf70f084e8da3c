// The six-plane sphere test of the mesh cut camera record (CC_PLANES, paramlod/meshlod/cut_reference.py)
// on a world-space centre and radius, in the fixed order of operations of kernels/meshlod/cut.cl's
// cut_outside (same floats, same order), so the numpy twins share one formula. Included after
// `#pragma OPENCL FP_CONTRACT OFF` by kernels/meshlod/skin_cull.cl (twin:
// paramlod/meshlod/skin_cull_reference.py); needs CC_PLANES defined.
#ifndef PL_MESHLOD_PLANES
#define PL_MESHLOD_PLANES
inline bool planes_outside(float3 w, float r, const float* cc) {
    bool out = false;
    for (int k = 0; k < 6; ++k) {
        const float* n = cc + CC_PLANES + 4 * k;
        float dist = ((n[0] * w.x + n[1] * w.y) + n[2] * w.z) + n[3];
        out |= dist < -r;
    }
    return out;
}
#endif
