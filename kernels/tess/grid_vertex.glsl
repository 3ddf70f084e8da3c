// Vertex stage of the grid tessellator (TessSettings.tessellator "grid", kernels/tess/grid.cl):
// each vertex comes evaluated from OpenCL (a GridVertex: world position and normal, instance);
// it hands tess_fragment.glsl what the evaluation stage (tess_eval.glsl) would.
in vec4 in_pos;      // world position; w: 1 where f is NaN/inf
in vec3 in_normal;   // world normal, not normalized
in uint in_inst;

centroid out vec3 te_view;
centroid out vec3 te_normal;
centroid out float te_bad;
flat out vec4 te_material;
flat out uint te_object;

void main() {
    vec3 e = (u_view * vec4(in_pos.xyz, 1.0)).xyz;
    vec3 nv = mat3(u_view) * in_normal;
    float ln = length(nv);
    te_normal = (ln > 1e-30 && !isnan(ln) && !isinf(ln)) ? nv / ln : vec3(0.0);
    te_view = e;
    te_bad = in_pos.w;
    te_material = pl_materials[in_inst];
    te_object = pl_inst_u[in_inst * PL_INST_U + PL_INST_OBJECT];
    gl_Position = u_proj * vec4(e, 1.0);
}
