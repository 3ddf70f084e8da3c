// Fragment stage: the shading model (common/shading.cl, the body the point renderer's shade()
// uses too: two-sided Blinn-Phong in view space) and the Frame's extra channels, into the colour
// attachments of common/targets.glsl:
//   0 colour (linear RGB, alpha 1: alpha 0 = nothing drawn), 1 linear view depth,
//   2 world-space normal facing the viewer, 3 object id, and into targets drawn directly (noAA,
//   u_image 1) 4 the 8-bit sRGB image.
// Multi-view geometry-stage passes (PL_VIEWS): the same, for the view of the layer drawn into.
// u_tier >= 0 (TessSettings.color_by "tier"): the patch is shaded with that hybrid tier's debug
// colour (common/debug_color.cl) instead of its material's.
centroid in vec3 te_view;
centroid in vec3 te_normal;
centroid in float te_bad;
flat in vec4 te_material;
flat in uint te_object;

#include "common/targets.glsl"

uniform int u_image;    // 1: the targets are drawn directly (noAA) and take the image from here
uniform vec4 u_light;   // the light record: towards the light in view space (xyz), ambient share (w)
uniform int u_tier;     // -1: the material's colour; else the tier the patches drawn belong to

#include "common/dialect.glsl"
#include "common/shading.cl"
#include "common/debug_color.cl"

void main() {
    if (te_bad > 0.0) discard;
    vec3 ev = normalize(-te_view);
    vec3 n = pl_facing_normal(te_normal, ev);
    vec3 base = u_tier < 0 ? te_material.xyz : pl_tier_color(uint(u_tier));
    vec3 rgb = pl_shade_rgb(n, ev, base, te_material.w, u_light.xyz, u_light.w);
    rgb = clamp(rgb, 0.0, 1.0);
    out_color = vec4(rgb, 1.0);
    out_depth = -te_view.z;
#ifdef PL_VIEWS
    out_normal = vec4(transpose(mat3(pl_views[gl_Layer].view)) * n, 0.0);   // the layer is the view
#else
    out_normal = vec4(transpose(mat3(u_view)) * n, 0.0);
#endif
    out_object = te_object;
    if (u_image != 0) out_image = srgb8_image(rgb);   // alpha 1: the host's composite is rgb itself
}
