// Tessellation evaluation stage: each generated vertex is f(u, v) of the patch's function at the
// interpolated parameters, with its analytic normal (df/du x df/dv).
// PL_SPACING is equal_spacing or fractional_odd_spacing (TessSettings.spacing).
layout(quads, PL_SPACING, ccw) in;

patch in vec4 tc_range;
patch in vec4 tc_core;
patch in uint tc_inst;

#ifdef PL_VIEWS
// multi-view: world space, which the geometry stage (tess_geometry.glsl) takes into each view
out vec3 tw_world;           // world-space position
out vec3 tw_normal;          // world-space normal (not normalized)
out float tw_bad;            // as te_bad
flat out vec4 tw_material;
flat out uint tw_object;
#else
// centroid: with multisampling a partly covered pixel interpolates inside the triangle, so the
// depth, normal and shading of edge pixels are never extrapolated beyond the surface
centroid out vec3 te_view;            // view-space position
centroid out vec3 te_normal;          // view-space unit normal (not yet facing the viewer)
centroid out float te_bad;            // 1 at a vertex where f is NaN/inf: the fragment stage drops its triangles
flat out vec4 te_material;   // rgb, specular
flat out uint te_object;     // 1-based object id
#endif

void main() {
    uint inst = tc_inst;
    uint func = pl_inst_u[inst * PL_INST_U + PL_INST_FUNC];
    uint P = pl_inst_u[inst * PL_INST_U + PL_INST_PARAMS];
    float u = pl_lerp(tc_range.x, tc_range.y, gl_TessCoord.x);
    float v = pl_lerp(tc_range.z, tc_range.w, gl_TessCoord.y);
    // f and its partials; where the parametrization degenerates (a pole, a collapsed edge) the
    // normal is taken a little way towards the patch centre instead (one call site of pl_surface,
    // so that the function's code is inlined once)
    vec3 pos, fu, fv, n;
    float uc = 0.5 * (tc_core.x + tc_core.y), vc = 0.5 * (tc_core.z + tc_core.w);
    for (int k = 0; k < 2; ++k) {
        float t = k == 0 ? 0.0 : 1e-3;
        vec3 p1, du1, dv1;
        pl_surface(func, u + (uc - u) * t, v + (vc - v) * t, P, p1, du1, dv1);
        if (k == 0) pos = p1;
        n = cross(du1, dv1);
        if (dot(n, n) > 1e-12 * dot(du1, du1) * dot(dv1, dv1) || pl_bad3(pos)) break;
    }
    float bad = 0.0;
    if (pl_bad3(pos)) {
        atomicAdd(pl_nan_vertices, 1u);
        bad = 1.0;
        pos = vec3(0.0);
        n = vec3(0.0, 0.0, 1.0);
    }
    uint I = inst * PL_INST_F;
    vec3 world = pl_rows_point(I + PL_INST_MODEL, pos);
#ifdef PL_VIEWS
    tw_world = world;
    tw_normal = pl_rows_dir(I + PL_INST_NORMAL, n);
    tw_bad = bad;
    tw_material = pl_materials[inst];
    tw_object = pl_inst_u[inst * PL_INST_U + PL_INST_OBJECT];
    gl_Position = vec4(world, 1.0);   // unused: each view's position is the geometry stage's
#else
    vec3 e = (u_view * vec4(world, 1.0)).xyz;
    vec3 nv = mat3(u_view) * pl_rows_dir(I + PL_INST_NORMAL, n);
    float ln = length(nv);
    te_normal = (ln > 1e-30 && !isnan(ln) && !isinf(ln)) ? nv / ln : vec3(0.0);
    te_view = e;
    te_bad = bad;
    te_material = pl_materials[inst];
    te_object = pl_inst_u[inst * PL_INST_U + PL_INST_OBJECT];
    gl_Position = u_proj * vec4(e, 1.0);
#endif
}
