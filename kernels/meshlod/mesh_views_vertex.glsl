// Vertex stage of the multi-view meshlets-gl draw (paramlod/meshlod/draw.py: MeshDraw.draw_views):
// mesh_vertex.glsl's fetches, in world space; the geometry stage (mesh_views_geometry.glsl)
// projects each triangle into the views, so the instance's transform runs once for all of them.
in vec4 in_position;   // MeshArrays.vertices: object-space xyz, 1
in vec4 in_normal;     // MeshArrays.normals: object-space unit normal, 0
in uvec2 in_pick;      // (instance into MeshInstances, cluster into MeshArrays.clusters)
in uvec2 in_views;     // the pair's view mask from the cut: views 0-31, 32-63

out vec3 vs_world;             // world-space position
out vec3 vs_normal;            // world-space vertex normal (not unit)
flat out vec4 vs_material;     // rgb, specular
flat out uint vs_object;       // 1-based object id
flat out uint vs_cluster;      // global cluster index
flat out uint vs_level;        // its LOD level
flat out uvec2 vs_views;

void main() {
    uint inst = in_pick.x;
    uint I = inst * PL_INST_F;
    vs_world = pl_rows_point(I + PL_INST_MODEL, in_position.xyz);
    vs_normal = pl_rows_dir(I + PL_INST_NORMAL, in_normal.xyz);
    vs_material = pl_materials[inst];
    vs_object = pl_inst_u[inst * PL_INST_U + PL_INST_OBJECT];
    vs_cluster = in_pick.y;
    vs_level = pl_clusters[in_pick.y].level;
    vs_views = in_views;
}
