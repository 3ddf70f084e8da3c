// Multi-view frames drawn by the geometry stage (TessRenderer.draw_views, views_per_pass > 1): the
// views' cameras, read by the control stage (adaptive levels: the largest any view needs), the
// geometry stage (one invocation per view) and the fragment stage (world normals). The renderer
// writes PL_MAX_VIEWS records and the count.
struct PlView {
    mat4 view;    // world -> view
    mat4 proj;    // view -> clip
    vec4 near;    // x: the near plane's view depth
};
layout(std140, binding = 0) uniform PlViews { PlView pl_views[PL_MAX_VIEWS]; };
uniform int u_n_views;

