// Fragment stage of the meshlets-gl draw: the shared shading model (common/shading.cl, two-sided
// Blinn-Phong in view space, the tess renderer's body) of the interpolated vertex normal turned
// to face the viewer, into the attachments of paramlod.renderers.gl_targets (common/targets.glsl):
//   0 colour (linear RGB, alpha 1), 1 linear view depth, 2 world-space normal facing the viewer,
//   3 object id, and into targets drawn directly (noAA, u_image 1) 4 the 8-bit sRGB image.
// PL_COLOR_BY (MeshDraw.draw's color_by): 0 the material's colour; 1 a colour per cluster, 2 a
// colour per LOD level (common/debug_color.cl, which the host puts before this file for 1 and 2),
// shaded like a material of that colour.
// Multi-view draws (PL_VIEWS) read the matrices of the fragment's view from pl_views
// (mesh_common.glsl), where one view reads u_view.
// Hand-off (paramlod/scene/handoff.py): an object of weight w < 1 (pl_object_weight, indexed by
// object id: a hand-off mesh is one instance of its own object) keeps only the fragments whose
// dither is below w, the surfels drawing the others. pl_dither is kernels/common/hash.cl's, on the
// target's grid with rows counted from the top as the key buffers count them; numpy twin:
// paramlod.core.hashing.dither.
centroid in vec3 ms_view;
centroid in vec3 ms_normal;
flat in vec4 ms_material;
flat in uint ms_object;
flat in uint ms_cluster;
flat in uint ms_level;
#ifdef PL_VIEWS
flat in uint ms_view_index;   // the view (layer) the geometry stage drew the triangle into
#define PL_VIEW_MATRIX pl_views[ms_view_index].view
#else
#define PL_VIEW_MATRIX u_view
#endif

#include "common/targets.glsl"

uniform int u_image;    // 1: the targets are drawn directly (noAA) and take the image from here
uniform vec4 u_light;   // the light record: towards the light in view space (xyz), ambient share (w)
uniform int u_rows;     // the target's height in pixels (subsamples with SSAA), for rows from the top

layout(std430, binding = 4) readonly buffer PlObjectWeights { float pl_object_weight[]; };   // [4096]

#include "common/dialect.glsl"
#include "common/shading.cl"
#include "common/hash.cl"

void main() {
    float weight = pl_object_weight[ms_object & 0xFFFu];
    if (weight < 1.0) {
        uint x = uint(gl_FragCoord.x), y = uint(u_rows - 1 - int(gl_FragCoord.y));
        if (!(pl_dither(x, y) < weight)) discard;   // the surfels' pixel
    }
    vec3 ev = normalize(-ms_view);
    vec3 n = pl_facing_normal(ms_normal, ev);
#if PL_COLOR_BY == 1
    vec3 base = pl_cluster_color(ms_cluster);
#elif PL_COLOR_BY == 2
    vec3 base = pl_level_color(ms_level);
#else
    vec3 base = ms_material.xyz;
#endif
    vec3 rgb = pl_shade_rgb(n, ev, base, ms_material.w, u_light.xyz, u_light.w);
    rgb = clamp(rgb, 0.0, 1.0);
    out_color = vec4(rgb, 1.0);
    out_depth = -ms_view.z;
    out_normal = vec4(transpose(mat3(PL_VIEW_MATRIX)) * n, 0.0);
    out_object = ms_object;
    if (u_image != 0) out_image = srgb8_image(rgb);   // alpha 1: the host's composite is rgb itself
}
