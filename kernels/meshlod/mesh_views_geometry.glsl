// Geometry stage of the multi-view meshlets-gl draw (paramlod/meshlod/draw.py: MeshDraw.draw_views),
// the pipeline's last geometry stage, where each triangle is amplified into the views: invocation i
// of a draw takes view v = u_base + i (PL_VIEWS_PER_DRAW invocations; one draw per chunk of that
// many views), skips it when the cut culled the triangle's cluster for v (the pair's view mask) or
// when the triangle lies wholly outside one of v's clip planes, and otherwise projects it with v's
// matrices as mesh_vertex.glsl does for one view, into layer v of the layered targets.
layout(triangles, invocations = PL_VIEWS_PER_DRAW) in;
layout(triangle_strip, max_vertices = 3) out;

in vec3 vs_world[];
in vec3 vs_normal[];
flat in vec4 vs_material[];
flat in uint vs_object[];
flat in uint vs_cluster[];
flat in uint vs_level[];
flat in uvec2 vs_views[];

// mesh_fragment.glsl's inputs
centroid out vec3 ms_view;
centroid out vec3 ms_normal;
flat out vec4 ms_material;
flat out uint ms_object;
flat out uint ms_cluster;
flat out uint ms_level;
flat out uint ms_view_index;

uniform uint u_base;      // the first view of this draw
uniform uint u_n_views;   // the frame's views

void main() {
    uint v = u_base + uint(gl_InvocationID);
    uvec2 m = vs_views[0];
    if (v >= u_n_views || ((v < 32u ? m.x >> v : m.y >> (v - 32u)) & 1u) == 0u) return;
    mat4 V = pl_views[v].view;
    mat4 P = pl_views[v].proj;
    vec3 e[3];
    vec4 c[3];
    for (int i = 0; i < 3; ++i) {
        e[i] = (V * vec4(vs_world[i], 1.0)).xyz;
        c[i] = P * vec4(e[i], 1.0);
    }
    // every vertex outside one plane -w <= x, y, z <= w: no part of the triangle is in view v
    for (int k = 0; k < 3; ++k) {
        if (c[0][k] < -c[0].w && c[1][k] < -c[1].w && c[2][k] < -c[2].w) return;
        if (c[0][k] > c[0].w && c[1][k] > c[1].w && c[2][k] > c[2].w) return;
    }
    for (int i = 0; i < 3; ++i) {
        gl_Position = c[i];
        gl_Layer = int(v);
        ms_view = e[i];
        ms_normal = mat3(V) * vs_normal[i];
        ms_material = vs_material[0];
        ms_object = vs_object[0];
        ms_cluster = vs_cluster[0];
        ms_level = vs_level[0];
        ms_view_index = v;
        EmitVertex();
    }
    EndPrimitive();
}
