// Geometry stage of multi-view frames drawn views_per_pass > 1 at a time (TessRenderer.draw_views):
// the tessellated triangle, in world space, is amplified here, at the pipeline's last geometry
// stage, into the views: invocation i draws it into view u_view_base + i, layer of the same index
// of the layered targets. A draw covers PL_GS_INVOCATIONS views; more views take several draws,
// u_view_base stepping by that. Each view projects the triangle itself (the very operations of
// the single-view evaluation stage, so that with equal levels a view's image equals a
// single-view frame of its camera) and drops it when all three vertices lie beyond one clip
// plane: the clipper would drop it too, later. No counters here: an atomic per emitted triangle
// made a 2-view frame on the H200 100x slower (2057 ms against 20 ms).
layout(triangles, invocations = PL_GS_INVOCATIONS) in;
layout(triangle_strip, max_vertices = 3) out;

in vec3 tw_world[];
in vec3 tw_normal[];
in float tw_bad[];
flat in vec4 tw_material[];
flat in uint tw_object[];

// what tess_eval.glsl gives the fragment stage of a single-view frame
centroid out vec3 te_view;
centroid out vec3 te_normal;
centroid out float te_bad;
flat out vec4 te_material;
flat out uint te_object;

uniform int u_view_base;

void main() {
    int view = u_view_base + gl_InvocationID;
    if (view >= u_n_views) return;
    mat4 V = pl_views[view].view, Pr = pl_views[view].proj;
    vec3 e[3];
    vec4 c[3];
    for (int k = 0; k < 3; ++k) {
        e[k] = (V * vec4(tw_world[k], 1.0)).xyz;
        c[k] = Pr * vec4(e[k], 1.0);
    }
    // per clip plane (x, y, z against -w and w): the vertices beyond it
    int beyond = 63;
    for (int k = 0; k < 3; ++k) {
        vec4 q = c[k];
        beyond &= (q.x < -q.w ? 1 : 0) | (q.x > q.w ? 2 : 0) | (q.y < -q.w ? 4 : 0) | (q.y > q.w ? 8 : 0)
                | (q.z < -q.w ? 16 : 0) | (q.z > q.w ? 32 : 0);
    }
    if (beyond != 0) return;
    mat3 R = mat3(V);
    for (int k = 0; k < 3; ++k) {
        vec3 nv = R * tw_normal[k];
        float ln = length(nv);
        te_normal = (ln > 1e-30 && !isnan(ln) && !isinf(ln)) ? nv / ln : vec3(0.0);
        te_view = e[k];
        te_bad = tw_bad[k];
        te_material = tw_material[k];
        te_object = tw_object[k];
        gl_Layer = view;
        gl_Position = c[k];
        EmitVertex();
    }
    EndPrimitive();
}
