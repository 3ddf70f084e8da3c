// Fragment stage of the meshlets-gl draw: the shared shading model (common/shading.cl, two-sided
// Blinn-Phong in view space, the tess renderer's body) of the interpolated vertex normal turned
// to face the viewer, into the four attachments of paramlod.renderers.gl_targets:
//   0 colour RGBA16F (linear RGB, alpha 1), 1 linear view depth R32F,
//   2 world-space normal facing the viewer RGBA16F, 3 object id R32UI.
// PL_COLOR_BY (MeshDraw.draw's color_by): 0 the material's colour; 1 a colour per cluster, 2 a
// colour per LOD level (meshlod/debug_color.cl, which the host puts before this file for 1 and 2),
// shaded like a material of that colour.
centroid in vec3 ms_view;
centroid in vec3 ms_normal;
flat in vec4 ms_material;
flat in uint ms_object;
flat in uint ms_cluster;
flat in uint ms_level;

layout(location = 0) out vec4 out_color;
layout(location = 1) out float out_depth;
layout(location = 2) out vec4 out_normal;
layout(location = 3) out uint out_object;

uniform vec4 u_light;   // the light record: towards the light in view space (xyz), ambient share (w)

#include "common/dialect.glsl"
#include "common/shading.cl"

void main() {
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
    out_color = vec4(clamp(rgb, 0.0, 1.0), 1.0);
    out_depth = -ms_view.z;
    out_normal = vec4(transpose(mat3(u_view)) * n, 0.0);
    out_object = ms_object;
}
