// A 3x4 row-major affine (12 floats: the instance and camera records' rows) applied to a point and
// a direction, in one fixed order of operations: included after `#pragma OPENCL FP_CONTRACT OFF`
// by the kernels whose numpy twins must match bit for bit (meshlod/cut.cl, meshlod/raster.cl,
// surfels/surfels_splat.cl). GLSL's copy for the tess and mesh draws: common/rows.glsl.
#ifndef PL_ROWS
#define PL_ROWS
inline float3 rows_point(__global const float* m, float3 p) {
    return (float3)(((m[0] * p.x + m[1] * p.y) + m[2] * p.z) + m[3],
                    ((m[4] * p.x + m[5] * p.y) + m[6] * p.z) + m[7],
                    ((m[8] * p.x + m[9] * p.y) + m[10] * p.z) + m[11]);
}

inline float3 rows_dir(__global const float* m, float3 d) {
    return (float3)((m[0] * d.x + m[1] * d.y) + m[2] * d.z,
                    (m[4] * d.x + m[5] * d.y) + m[6] * d.z,
                    (m[8] * d.x + m[9] * d.y) + m[10] * d.z);
}
#endif
