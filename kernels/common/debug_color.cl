// Debug colours of the mesh renderers and the direct points (color_by 1: a colour per cluster or patch, 2: a colour per LOD
// level, 3: a colour per hybrid tier), linear RGB, shaded like a material colour. Written in the snippet dialect
// (kernels/README.md; vec3, VEC3, FRACT, ABS, FLOAT come from common/dialect.cl or
// common/dialect.glsl, which the includer includes first), so the same text compiles as OpenCL C
// (included by kernels/meshlod/raster.cl) and as GLSL 4.50 (the OpenGL draw of the cut).
// numpy twin: paramlod/core/debug_colors.py (cluster_color, level_color), bit for bit on
// OpenCL: every operation is a plain IEEE one (no mix, no library hue functions), in this order.
#ifndef PL_DEBUG_COLOR
#define PL_DEBUG_COLOR

#include "common/hash.cl"

#ifdef __OPENCL_VERSION__
#define PL_DEBUG_FN inline
#else
#define PL_DEBUG_FN
#endif

// A bright colour per global cluster index: hue, saturation and value from three bytes of the
// hash (value >= 0.55 so that shading keeps the colour readable).
PL_DEBUG_FN vec3 pl_cluster_color(uint cluster) {
    uint h = pl_hash32(cluster);
    float hue = FLOAT(h & 255u) / 256.0f;
    float sat = 0.55f + 0.45f * (FLOAT((h >> 8) & 255u) / 255.0f);
    float val = 0.55f + 0.45f * (FLOAT((h >> 16) & 255u) / 255.0f);
    vec3 k = VEC3(hue, hue + 0.6666667f, hue + 0.33333334f);
    vec3 rgb = clamp(ABS(FRACT(k) * 6.0f - 3.0f) - 1.0f, 0.0f, 1.0f);
    // grey towards the hue by the saturation, then scaled by the value
    return (1.0f + (rgb - 1.0f) * sat) * val;
}

// Eight clearly distinct colours, level 0 (the original triangles) first; levels past 7 repeat.
PL_DEBUG_FN vec3 pl_level_color(uint level) {
    uint k = level % 8u;
    if (k == 0u) return VEC3(0.85f, 0.85f, 0.85f);   // light grey
    if (k == 1u) return VEC3(0.90f, 0.12f, 0.10f);   // red
    if (k == 2u) return VEC3(0.10f, 0.70f, 0.15f);   // green
    if (k == 3u) return VEC3(0.12f, 0.30f, 0.95f);   // blue
    if (k == 4u) return VEC3(0.95f, 0.80f, 0.05f);   // yellow
    if (k == 5u) return VEC3(0.80f, 0.15f, 0.85f);   // magenta
    if (k == 6u) return VEC3(0.05f, 0.80f, 0.85f);   // cyan
    return VEC3(0.95f, 0.45f, 0.05f);                  // orange
}

// The hybrid anti-aliasing tiers (thesis Figure 5.9): 0 blue, 1 green, 2 red.
PL_DEBUG_FN vec3 pl_tier_color(uint tier) {
    if (tier == 0u) return VEC3(0.12f, 0.30f, 0.95f);
    if (tier == 1u) return VEC3(0.10f, 0.70f, 0.15f);
    return VEC3(0.90f, 0.12f, 0.10f);
}
#endif
