// Shared by the meshlets-gl draw's shader stages (paramlod/meshlod/draw.py: MeshDraw), which
// prepend "#version 450 core", the PL_* defines and the prelude (paramlod.core.layouts.glsl_prelude:
// the records' PL_INST_*, PL_MAT_* offsets and the Cluster struct).

// The scene's mesh instances and clusters (paramlod.meshlod.buffers: MeshInstances, MeshArrays),
// read-only shader storage buffers.
layout(std430, binding = 0) readonly buffer PlInstF { float pl_inst_f[]; };      // [n][PL_INST_F]
layout(std430, binding = 1) readonly buffer PlInstU { uint pl_inst_u[]; };       // [n][PL_INST_U]
layout(std430, binding = 2) readonly buffer PlMaterials { vec4 pl_materials[]; }; // rgb, specular
layout(std430, binding = 3) readonly buffer PlClusters { Cluster pl_clusters[]; };

uniform mat4 u_view;        // world -> view
uniform mat4 u_proj;        // view -> clip

// rows of 4 floats from pl_inst_f[base]: the 3x4 affine part applied to a point / a direction
// (the order of the tess renderer's, so a mesh and a parametric object of one transform agree)
vec3 pl_rows_point(uint base, vec3 p) {
    return vec3(pl_inst_f[base + 0u] * p.x + pl_inst_f[base + 1u] * p.y + pl_inst_f[base + 2u] * p.z + pl_inst_f[base + 3u],
                pl_inst_f[base + 4u] * p.x + pl_inst_f[base + 5u] * p.y + pl_inst_f[base + 6u] * p.z + pl_inst_f[base + 7u],
                pl_inst_f[base + 8u] * p.x + pl_inst_f[base + 9u] * p.y + pl_inst_f[base + 10u] * p.z + pl_inst_f[base + 11u]);
}

vec3 pl_rows_dir(uint base, vec3 d) {
    return vec3(pl_inst_f[base + 0u] * d.x + pl_inst_f[base + 1u] * d.y + pl_inst_f[base + 2u] * d.z,
                pl_inst_f[base + 4u] * d.x + pl_inst_f[base + 5u] * d.y + pl_inst_f[base + 6u] * d.z,
                pl_inst_f[base + 8u] * d.x + pl_inst_f[base + 9u] * d.y + pl_inst_f[base + 10u] * d.z);
}
