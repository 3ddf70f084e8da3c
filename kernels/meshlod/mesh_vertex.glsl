// Vertex stage of the meshlets-gl draw: one indirect draw command per selected cluster, over the
// scene's global triangle index buffer (firstIndex = 3 * the cluster's first triangle). The
// command's baseInstance is its own index k, so the instanced attribute in_pick (divisor 1, the
// selection buffer itself) reads selection[k] = (instance, cluster): baseInstance offsets
// instanced attributes in core GL >= 4.2, no extension needed (gl_BaseInstance and gl_DrawID would
// need ARB_shader_draw_parameters). The instance's model and normal matrices, material and object
// id, and the cluster's level, are then fetched from the storage buffers.
in vec4 in_position;   // MeshArrays.vertices: object-space xyz, 1
in vec4 in_normal;     // MeshArrays.normals: object-space unit normal, 0
in uvec2 in_pick;      // (instance into MeshInstances, cluster into MeshArrays.clusters)

// centroid: with multisampling a partly covered pixel interpolates inside the triangle, so edge
// pixels' depth, normal and shading are never extrapolated beyond it
centroid out vec3 ms_view;     // view-space position
centroid out vec3 ms_normal;   // view-space vertex normal, interpolated (not unit, not yet facing)
flat out vec4 ms_material;     // rgb, specular
flat out uint ms_object;       // 1-based object id
flat out uint ms_cluster;      // global cluster index (debug colour per cluster)
flat out uint ms_level;        // its LOD level (debug colour per level)

void main() {
    uint inst = in_pick.x;
    uint I = inst * PL_INST_F;
    vec3 e = (u_view * vec4(pl_rows_point(I + PL_INST_MODEL, in_position.xyz), 1.0)).xyz;
    ms_normal = mat3(u_view) * pl_rows_dir(I + PL_INST_NORMAL, in_normal.xyz);
    ms_view = e;
    ms_material = pl_materials[inst];
    ms_object = pl_inst_u[inst * PL_INST_U + PL_INST_OBJECT];
    ms_cluster = in_pick.y;
    ms_level = pl_clusters[in_pick.y].level;
    gl_Position = u_proj * vec4(e, 1.0);
}
