// Shared definitions for paramlod's OpenCL kernels. The generated function code (pl_position,
// pl_surface) is inserted after this file; see paramlod/codegen.py.
#pragma OPENCL EXTENSION cl_khr_int64_base_atomics : enable
#pragma OPENCL EXTENSION cl_khr_int64_extended_atomics : enable

// Patch waiting for evaluation in an LOD step (32 bytes, numpy: paramlod.patches.EVAL_DTYPE).
typedef struct {
    float4 range;   // u0, u1, v0, v1
    uint inst;
    uint pad0, pad1, pad2;
} EvalPatch;

// Patch scheduled for rendering (64 bytes, numpy: paramlod.patches.RENDER_DTYPE).
typedef struct {
    float4 range;   // u0, u1, v0, v1
    float4 bbox;    // screen x0, y0, x1, y1 in pixels (of the samples in front of the camera)
    // e_u, e_v: the thesis's measured extents (longest of the 4 polylines per direction);
    // s_u, s_v: 7 x the longest single segment, an upper estimate for even sampling
    float4 ext;
    uint inst;
    uint flags;     // bits 0-3: LOD step; bit 4: forced at the last step
    uint pad0, pad1;
} RenderPatch;

#define FLAG_FORCED 16u

// Instance record offsets (paramlod/scene.py): model matrix rows, normal matrix rows, domain.
#define INST_F 32
#define INST_U 4
#define INST_MODEL 0
#define INST_NORMAL 16
#define INST_DOMAIN 28

// Camera record (paramlod/render.py): view rows, projection rows, width, height, near, far.
#define CAM_VIEW 0
#define CAM_PROJ 16
#define CAM_W 32
#define CAM_H 33
#define CAM_NEAR 34
#define CAM_FAR 35

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
    return cam[CAM_PROJ + 15] != 0.0f ? (float3)(0.0f, 0.0f, 1.0f) : normalize(-e);
}

inline bool is_bad3(float3 p) {
    return isnan(p.x) || isnan(p.y) || isnan(p.z) || isinf(p.x) || isinf(p.y) || isinf(p.z);
}
