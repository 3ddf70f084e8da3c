// Linear blend skinning of a skinned mesh's bind pose into the posed vertex and normal buffers
// that the mesh cut, the OpenCL raster and the OpenGL draw read (paramlod.meshlod.buffers
// DeviceMeshes.vertices / .normals). One work-item per vertex of one skinned mesh slot.
// Driven by paramlod.meshlod.skin.Skinning (one launch per skinned object, each frame, before the
// cut); its numpy twin is paramlod.meshlod.skin_reference, which does the same float32 operations
// in the same order (no contraction, correctly rounded sqrt and division), so both agree bit for bit.
// Built after the prelude (paramlod.core.layouts) alone.
//
// Per vertex: B = ((w0 M[j0] + w1 M[j1]) + w2 M[j2]) + w3 M[j3], the blended 3x4 of the frame's
// skin matrices (row-major 4x4 records, `skin`, of which rows 0..2 are read), then
//   position = B (x, y, z, 1)
//   normal   = normalize(sign(det A) cof(A) n), A = B's 3x3, cof(A) = det(A) A^-T
// The cofactor matrix is the inverse transpose up to a positive factor, so normals stay correct
// under the blended matrix's non-uniform scale and shear without a division by det.
#pragma OPENCL FP_CONTRACT OFF

__kernel void skin_vertices(__global const float4* bind_v, __global const float4* bind_n,
                            __global const uint4* joints, __global const float4* weights,
                            uint src_first, uint n_vertices, __global const float* skin,
                            __global float4* out_v, __global float4* out_n, uint dst_first)
{
    uint i = (uint)get_global_id(0);
    if (i >= n_vertices) return;
    uint s = src_first + i;
    uint4 j = joints[s];
    float4 w = weights[s];
    __global const float* m0 = skin + (size_t)j.x * 16;
    __global const float* m1 = skin + (size_t)j.y * 16;
    __global const float* m2 = skin + (size_t)j.z * 16;
    __global const float* m3 = skin + (size_t)j.w * 16;
    float b[12];
    for (int k = 0; k < 12; ++k)
        b[k] = ((w.x * m0[k] + w.y * m1[k]) + w.z * m2[k]) + w.w * m3[k];
    float4 p = bind_v[s];
    float4 n = bind_n[s];
    float px = ((b[0] * p.x + b[1] * p.y) + b[2] * p.z) + b[3];
    float py = ((b[4] * p.x + b[5] * p.y) + b[6] * p.z) + b[7];
    float pz = ((b[8] * p.x + b[9] * p.y) + b[10] * p.z) + b[11];
    // cofactors of A = (a b c; d e f; g h i) = (b0 b1 b2; b4 b5 b6; b8 b9 b10)
    float c00 = b[5] * b[10] - b[6] * b[9], c01 = b[6] * b[8] - b[4] * b[10], c02 = b[4] * b[9] - b[5] * b[8];
    float c10 = b[2] * b[9] - b[1] * b[10], c11 = b[0] * b[10] - b[2] * b[8], c12 = b[1] * b[8] - b[0] * b[9];
    float c20 = b[1] * b[6] - b[2] * b[5], c21 = b[2] * b[4] - b[0] * b[6], c22 = b[0] * b[5] - b[1] * b[4];
    float det = (b[0] * c00 + b[1] * c01) + b[2] * c02;
    float sg = det < 0.0f ? -1.0f : 1.0f;
    float nx = sg * ((c00 * n.x + c01 * n.y) + c02 * n.z);
    float ny = sg * ((c10 * n.x + c11 * n.y) + c12 * n.z);
    float nz = sg * ((c20 * n.x + c21 * n.y) + c22 * n.z);
    float len = sqrt((nx * nx + ny * ny) + nz * nz);
    float4 no = len > 0.0f ? (float4)(nx / len, ny / len, nz / len, 0.0f) : (float4)(0.0f, 0.0f, 1.0f, 0.0f);
    uint d = dst_first + i;
    out_v[d] = (float4)(px, py, pz, 1.0f);
    out_n[d] = no;
}
