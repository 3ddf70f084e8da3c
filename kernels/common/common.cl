// Shared helpers of paramlod's OpenCL kernels. paramlod.device.programs.build puts the prelude
// (paramlod.core.layouts.cl_prelude: the records' offsets and structs -- EvalPatch, RenderPatch,
// INST_*, CAM_*, MAT_*, LIGHT_*, LOD_* -- the shading constants and the sRGB table) before this
// file; the generated function code (pl_position, pl_surface; paramlod.function.codegen_cl) comes
// after it.
#pragma OPENCL EXTENSION cl_khr_int64_base_atomics : enable
#pragma OPENCL EXTENSION cl_khr_int64_extended_atomics : enable

#include "common/builtins.cl"

inline float3 xform_point(__global const float* m, float3 p) {
    return (float3)(m[0] * p.x + m[1] * p.y + m[2] * p.z + m[3],
                    m[4] * p.x + m[5] * p.y + m[6] * p.z + m[7],
                    m[8] * p.x + m[9] * p.y + m[10] * p.z + m[11]);
}

// 3x3 part of a matrix stored as rows of 4 floats.
inline float3 xform_dir(__global const float* m, float3 d) {
    return (float3)(m[0] * d.x + m[1] * d.y + m[2] * d.z,
                    m[4] * d.x + m[5] * d.y + m[6] * d.z,
                    m[8] * d.x + m[9] * d.y + m[10] * d.z);
}

// Homogeneous clip coordinates of a view-space point.
inline float4 project(__global const float* cam, float3 p) {
    __global const float* P = cam + CAM_PROJ;
    return (float4)(P[0] * p.x + P[1] * p.y + P[2] * p.z + P[3],
                    P[4] * p.x + P[5] * p.y + P[6] * p.z + P[7],
                    P[8] * p.x + P[9] * p.y + P[10] * p.z + P[11],
                    P[12] * p.x + P[13] * p.y + P[14] * p.z + P[15]);
}

// Frustum outcode: one bit per clip plane the point is outside of.
inline uint outcode(float4 c) {
    return (c.x < -c.w ? 1u : 0u) | (c.x > c.w ? 2u : 0u) | (c.y < -c.w ? 4u : 0u)
         | (c.y > c.w ? 8u : 0u) | (c.z < -c.w ? 16u : 0u) | (c.z > c.w ? 32u : 0u);
}

// Unit vector from a view-space point towards the viewer: (0, 0, 1) for an orthographic camera
// (its projection's last row is (0, 0, 0, 1)), towards the eye for a perspective one.
inline float3 view_dir(__global const float* cam, float3 e) {
    return cam[CAM_PROJ + 15] != 0.0f ? (float3)(0.0f, 0.0f, 1.0f) : pl_normalize3(-e);
}

inline bool is_bad3(float3 p) {
    return !(pl_finitef(p.x) && pl_finitef(p.y) && pl_finitef(p.z));
}

// The parameter range a renderer samples of a patch (u0, u1, v0, v1): widened by `widen` of its
// size per side and clamped to the instance's domain. One definition for the point renderer
// (points.cl point_grid) and for the bounds that must hold over what it samples (lod.cl
// cone_uv, occlusion.cl patch_bound); twins: the same arithmetic in float32 numpy.
// sampled_range_uv takes a share per axis (widen.x along u, widen.y along v: tess/grid.cl grid_range).
inline float4 sampled_range_uv(float4 range, __global const float* I, float2 widen) {
    float wu = (range.y - range.x) * widen.x, wv = (range.w - range.z) * widen.y;
    return (float4)(fmax(range.x - wu, I[INST_DOMAIN + 0]), fmin(range.y + wu, I[INST_DOMAIN + 1]),
                    fmax(range.z - wv, I[INST_DOMAIN + 2]), fmin(range.w + wv, I[INST_DOMAIN + 3]));
}

inline float4 sampled_range(float4 range, __global const float* I, float widen) {
    return sampled_range_uv(range, I, (float2)(widen, widen));
}
