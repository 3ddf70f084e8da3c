// The hybrid tiers' spot check (thesis section 5.5.7, Listing 5.2): before a patch is rendered at
// a tier that has a finer one, the LOD step looks for sub-pixel detail in the patch. 7 x 3 cells,
// each about one pixel of the tier's target (a pixel / tier divisor), are spread evenly over the
// patch in (u, v), cell (i, j) centred at (i + 1/2) / 7 of its u range and (j + 1/2) / 3 of its v
// range (the thesis lays them side by side over the patch's middle, which misses a glyph lobe
// elsewhere in a patch of many pixels); along an axis of at most 7 (3) tier pixels they tile it. The
// surface normal at each cell's 4 corners and at nine sub-sample offsets per cell (every pair of
// 1/2, 1/3, 1/5 of the cell) comes from the analytic partials. A sub-sample whose normal turns
// from the bilinear blend of its cell's corner normals by more than the spot angle is detail the
// cell's pixel cannot show; with at least `spot_min` such sub-samples (of 189) the patch goes to
// the next tier. Twin: spot_counts in paramlod/lod/reference.py.

#define SPOT_CORNERS 84      // 4 a cell: corner k of cell k / 4 (bit 0 of k: its far side in u, bit 1 in v)
// SPOT_SUBS (from the host): 21 cells x 9 offsets

// the sub-sample offsets within a cell, as a share of its side
inline float spot_offset(uint k) {
    return k == 0u ? 0.5f : k == 1u ? (1.0f / 3.0f) : 0.2f;
}

// The cell size in (u, v): a pixel of the tier's target along the patch's longest measured line
// (e: its length in frame pixels, scale: the tier's divisor), never more than the patch can hold.
inline float spot_cell(float d, float e, float scale, float cells) {
    return d / fmax(e * scale, cells);
}

// The unit world-space normal at (u, v), or 0 where f or its partials are not finite or
// degenerate (a pole): such a place says nothing about detail.
inline float3 spot_normal(uint func, __global const float* P, __global const float* I, float u, float v) {
    float3 p, fu, fv;
    pl_surface(func, u, v, P, &p, &fu, &fv);
    float3 n = cross(xform_dir(I + INST_MODEL, fu), xform_dir(I + INST_MODEL, fv));
    float len = length(n);
    if (!(len > 0.0f) || !isfinite(len) || is_bad3(p)) return (float3)(0.0f, 0.0f, 0.0f);
    return n / len;
}

// Corner k's (u, v) (SPOT_CORNERS); cell c's first corner is k = 4c. The strides are products
// (correctly rounded, as the twin's), not divisions.
inline float2 spot_corner(float4 range, float cu, float cv, uint k) {
    uint cell = k / 4u;
    float u = range.x + ((float)(cell % 7u) + 0.5f) * ((range.y - range.x) * (1.0f / 7.0f)) - 0.5f * cu;
    float v = range.z + ((float)(cell / 7u) + 0.5f) * ((range.w - range.z) * (1.0f / 3.0f)) - 0.5f * cv;
    return (float2)(u + (float)(k & 1u) * cu, v + (float)((k >> 1) & 1u) * cv);
}

// The normal at corner k (spot_corner), as the check keeps it in local memory.
inline float4 spot_corner_normal(uint func, __global const float* P, __global const float* I, float4 range,
                                 float cu, float cv, uint k) {
    float2 c = spot_corner(range, cu, cv, k);
    return (float4)(spot_normal(func, P, I, c.x, c.y), 0.0f);
}

// Whether sub-sample s (cell s / 9, offset pair s % 9) turns from its cell's blended corner normals
// by more than acos(spot_cos); corner normals n[SPOT_CORNERS] from spot_normal.
inline bool spot_turns(uint func, __global const float* P, __global const float* I, float4 range,
                       float cu, float cv, __local const float4* n, uint s, float spot_cos) {
    uint k = (s / 9u) * 4u, o = s % 9u;
    float a = spot_offset(o % 3u), b = spot_offset(o / 3u);
    float3 n00 = n[k].xyz, n10 = n[k + 1u].xyz, n01 = n[k + 2u].xyz, n11 = n[k + 3u].xyz;
    if (n00.x == 0.0f && n00.y == 0.0f && n00.z == 0.0f) return false;
    if (n10.x == 0.0f && n10.y == 0.0f && n10.z == 0.0f) return false;
    if (n01.x == 0.0f && n01.y == 0.0f && n01.z == 0.0f) return false;
    if (n11.x == 0.0f && n11.y == 0.0f && n11.z == 0.0f) return false;
    float2 c = spot_corner(range, cu, cv, k);
    float3 ns = spot_normal(func, P, I, c.x + a * cu, c.y + b * cv);
    if (ns.x == 0.0f && ns.y == 0.0f && ns.z == 0.0f) return false;
    float3 blend = ((1.0f - a) * (1.0f - b)) * n00 + (a * (1.0f - b)) * n10 + ((1.0f - a) * b) * n01 + (a * b) * n11;
    return dot(ns, blend) < spot_cos * length(blend);
}

// Silhouettes (hybrid tier 0 only): a patch over which the surface turns from facing the view to
// facing away, or which comes within SIL_GRAZE of edge-on (a silhouette on its border: a glyph's
// lobes split along their equator), has a silhouette edge, whose pixels need coverage
// anti-aliasing even where the surface has no sub-pixel detail; it goes to tier 1 (multisampling,
// or 4xSS for points). The normals are finite differences of the LOD step's 5 x 5 grid of world
// positions g[25] (w != 0: a bad sample), central inside the grid, one-sided on its edges; the
// facing is the cosine to the view at `cam` (view_dir: towards the eye, or the view axis when
// orthographic). SIL_GRAZE (from the host): cos 80 degrees.
inline bool grid_silhouette(__local const float4* g, __global const float* cam) {
    bool front = false, back = false, grazing = false;
    for (uint k = 0; k < 25u; ++k) {
        uint i = k % 5u, j = k / 5u;
        float4 u1 = g[j * 5u + min(i + 1u, 4u)], u0 = g[j * 5u + (i == 0u ? 0u : i - 1u)];
        float4 v1 = g[min(j + 1u, 4u) * 5u + i], v0 = g[(j == 0u ? 0u : j - 1u) * 5u + i];
        if (g[k].w != 0.0f || u1.w != 0.0f || u0.w != 0.0f || v1.w != 0.0f || v0.w != 0.0f) continue;
        float3 e = xform_point(cam + CAM_VIEW, g[k].xyz);
        float3 n = xform_dir(cam + CAM_VIEW, cross(u1.xyz - u0.xyz, v1.xyz - v0.xyz));
        float s = dot(n, view_dir(cam, e)) / length(n);
        front |= s > 0.0f;
        back |= s < 0.0f;
        grazing |= fabs(s) < SIL_GRAZE;
    }
    return (front && back) || grazing;
}
