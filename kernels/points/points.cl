// Point renderers (thesis sections 5.5.3 and 5.5.5): a render patch is sampled on a regular
// (u, v) grid whose size comes from its measured screen extents, each sample is shaded with its
// analytic normal and written as a 64-bit key (keys.cl). This file holds the helpers both point
// variants share and the direct variant; points_lfb.cl (local framebuffers) builds on it.

#include "common/debug_color.cl"

// THIN_LOOP_1/2/3/5, THIN_ALONG, COVER_REACH, COVER_OWN and POINTS_LOCAL come from the build
// (paramlod.renderers.sampling.points_cl_defines), where the numpy twins read them too
#ifndef POINTS_LOCAL
#error "build points.cl with paramlod.renderers.sampling.points_cl_defines()"
#endif

// The debug colouring of the direct variant (PointSettings.color_by): 1 a colour per render patch,
// keyed by its parameter range and instance (the render list's order varies between devices and
// frames, its patches do not), 2 a colour per LOD step the patch was made in, 3 a colour per
// hybrid tier. Twin:
// paramlod.renderers.sampling.patch_debug_colors.
inline float4 debug_material(float4 mat, RenderPatch rp, uint color_by) {
    if (color_by == 1u) {
        uint k = pl_hash32(as_uint(rp.range.x) ^ pl_hash32(as_uint(rp.range.z) ^ pl_hash32(rp.inst)));
        return (float4)(pl_cluster_color(k), mat.w);
    }
    if (color_by == 2u) return (float4)(pl_level_color(rp.flags & 15u), mat.w);
    if (color_by == 3u) return (float4)(pl_tier_color((rp.flags >> TIER_SHIFT) & 3u), mat.w);
    return mat;
}

// Sample counts: factor = density * oversample / (1 - epsilon) samples per measured pixel
// (paramlod/renderers/sampling.py, PointSettings.factor; the numpy twin is paramlod.renderers.sampling.side_counts).
// Rounding up and adding one gives at least `factor` steps per pixel; never fewer than 2.
inline uint side_count(float m, float factor, uint max_side) {
    float n = pl_ceilf(m * factor) + 1.0f;
    if (!(n < (float)max_side)) return max_side;  // also catches inf and NaN extents
    return (uint)n > 2u ? (uint)n : 2u;
}

// What a patch's sample counts are measured from (`measure`, paramlod/renderers/sampling.py
// MEASURES): 0 s_u, s_v (7 x the longest LOD segment: even the densest part of the patch gets
// `factor` samples per pixel); 1 e_u, e_v (the thesis's adaptive sampling: about `factor` samples
// per pixel on average, cheaper, may leave 1-pixel holes); 2 w_u, w_v (s_u, s_v raised to what the
// patch's four boundary lines need, kernels/lod/lod.cl, used with s_u, s_v by grid_axis: two patches
// sharing an edge both sample it densely enough, so the direct variant is watertight on patch
// boundaries).
inline float2 patch_measure(RenderPatch rp, uint measure) {
    if (measure == 1u) return rp.ext.xy;
    if (measure == 2u) return rp.w;
    return rp.ext.zw;
}

// Quad coverage (PL_QUADS, PointSettings.coverage "quad"; below, "Quad coverage")
#ifndef PL_QUADS
#define PL_QUADS 0
#endif

// One direction of a grid. Uniform (na = 0): n samples, n - 1 equal steps. Boundary strips
// (measure 2 where the boundary raised the measure, w > s): the outer seventh at each end, where the
// LOD lines could not see the speed the edge has, is stepped for w (na steps each), the five
// sevenths between for s (nm steps): n = 2 na + nm + 1. Raising only the strips costs about 2/7 of
// what raising the whole grid to w would.
// wrap (a uniform grid along an axis over which the function repeats, spanned whole; `wraps` from
// patch_wraps): its last sample is a copy of its first and is not drawn (n - wrap samples drawn;
// the steps stay those of n).
typedef struct {
    uint n, na, nm, wrap;
} GridAxis;

inline GridAxis grid_axis(float s, float w, uint boundary, uint wraps, float factor, uint max_side) {
    GridAxis a;
    a.na = 0u; a.nm = 0u;
    a.n = side_count(w, factor, max_side);
    a.wrap = wraps;
    if (!boundary || !(w > s) || a.n >= max_side) return a;
    float fa = w * factor;
    fa = fa * (1.0f / 7.0f);
    float fm = s * factor;
    fm = fm * (5.0f / 7.0f);
    float na = pl_fmaxf(pl_ceilf(fa), 1.0f), nm = pl_fmaxf(pl_ceilf(fm), 1.0f);
    float n = 2.0f * na + nm + 1.0f;
    if (!(n < (float)max_side) || n >= (float)a.n) return a;   // no cheaper than uniform: uniform
    a.na = (uint)na; a.nm = (uint)nm; a.n = (uint)n; a.wrap = 0u;
    return a;
}

// (u, v): whether the patch spans its instance's domain along an axis over which the function
// repeats (INST_WRAP_U / INST_WRAP_V, set from the function's `periodic`)
inline uint2 patch_wraps(RenderPatch rp, __global const float* I, uint flags) {
    uint wu = (flags & INST_WRAP_U) != 0u && rp.range.x == I[INST_DOMAIN + 0] && rp.range.y == I[INST_DOMAIN + 1];
    uint wv = (flags & INST_WRAP_V) != 0u && rp.range.z == I[INST_DOMAIN + 2] && rp.range.w == I[INST_DOMAIN + 3];
    return (uint2)(wu, wv);
}

// A patch's two grid directions, as point_grid samples them and patch_units counts them.
// Thin tubes (`curve` > 0: PointSettings.curve_factor, pixel coverage): a patch that wraps around
// an axis whose loop measures at most THIN_LOOP_5 target pixels (a tube under 1.7 pixels across)
// needs no hole-free surface grid around it: n lines evenly around a tube of radius r project at
// most g(n) r apart (g = 2, 2, 1.5, 1.12 for n = 1, 2, 3, 5), so one line around loops of up to
// THIN_LOOP_1 pixels, two on opposite sides up to THIN_LOOP_2, three up to THIN_LOOP_3 and five up
// to THIN_LOOP_5 keep neighbouring lines' pixels touching. A loop of 1 to THIN_LOOP_2 pixels (a
// tube under a pixel across) is also sampled along at THIN_ALONG x `curve`, under a pixel apart,
// so the pixels it lands in stay 8-connected as a rasterized line's; thinner tubes share pixels
// with their neighbours, and the denser samples decide which is in front; wider ones keep
// `factor` along (docs/points.md, "Thin tubes"). v is tested first.
// THIN_ALONG (samples per target pixel along a thin tube) is over one because the measure sums
// chords of the LOD stage's segments, which fall short of the fastest part of a curve (a ring seen
// near edge on: up to ~14 %); at one a pixel, 4 of 108 thin rings seen at 75-85 degrees came out
// with a 1-pixel gap, at 1.1 none
inline uint thin_lines(float loop) {   // grid lines around a thin tube, the wrapped copy included
    return loop <= THIN_LOOP_1 ? 2u : loop <= THIN_LOOP_2 ? 3u : loop <= THIN_LOOP_3 ? 4u : 6u;
}

inline void patch_axes(RenderPatch rp, __global const float* I, uint flags, float factor, float curve,
                       uint measure, uint max_side, GridAxis* gu, GridAxis* gv) {
    float2 m = patch_measure(rp, measure);
    uint2 wraps = patch_wraps(rp, I, flags);
    float2 loop = m * curve;   // target pixels around
    uint thin_v = curve > 0.0f && wraps.y && loop.y <= THIN_LOOP_5;
    uint thin_u = curve > 0.0f && !thin_v && wraps.x && loop.x <= THIN_LOOP_5;
    float along = pl_fminf(factor, THIN_ALONG * curve);
    float fu = thin_v && loop.y >= 1.0f && loop.y <= THIN_LOOP_2 ? along : factor;
    float fv = thin_u && loop.x >= 1.0f && loop.x <= THIN_LOOP_2 ? along : factor;
    *gu = grid_axis(rp.ext.z, m.x, measure == 2u, wraps.x, fu, max_side);
    *gv = grid_axis(rp.ext.w, m.y, measure == 2u, wraps.y, fv, max_side);
    // thin_lines' lines around (for loops up to THIN_LOOP_1 one: a second on the far side, at most
    // a pixel away, doubled the fibre curtain's samples and left its pixels and FLIP as they were)
    if (thin_u) { gu->n = min(gu->n, thin_lines(loop.x)); gu->na = 0u; gu->nm = 0u; gu->wrap = 1u; }
    if (thin_v) { gv->n = min(gv->n, thin_lines(loop.y)); gv->na = 0u; gv->nm = 0u; gv->wrap = 1u; }
#if PL_QUADS
    // quads around a tube need 3 lines around (4 grid lines with the wrapped copy): between 2 they
    // are a flat ribbon that vanishes edge on, and one line and its copy make quads without area
    if (gu->wrap) gu->n = max(gu->n, min(4u, max_side));
    if (gv->wrap) gv->n = max(gv->n, min(4u, max_side));
#endif
}

// The sampling grid of one patch: nu x nv samples spanning the range widened by `widen` per
// side (so neighbouring patches overlap and leave no seam), clamped to the function's domain,
// less the repeated last line of a wrapping axis (grid_axis).
typedef struct {
    float u0, v0, su, sv;   // first sample and (middle) steps
    uint nu, nv;            // samples drawn per direction
    uint nu_grid, nv_grid;  // samples per direction, a wrapping axis's repeated last line included
    float u1, v1, au, av;   // last sample, strip steps (boundary strips only)
    uint nau, nav;          // strip steps per end; 0: uniform
    uint capped;            // a direction has max_side samples
} PointGrid;

inline PointGrid point_grid(RenderPatch rp, __global const float* I, uint flags, float factor, float curve,
                            uint measure, float widen, uint max_side) {
    PointGrid g;
    GridAxis gu, gv;
    patch_axes(rp, I, flags, factor, curve, measure, max_side, &gu, &gv);
    g.nu = gu.n - gu.wrap; g.nv = gv.n - gv.wrap; g.nau = gu.na; g.nav = gv.na;
    g.nu_grid = gu.n; g.nv_grid = gv.n;
    g.capped = gu.n == max_side || gv.n == max_side;
    float4 r = sampled_range(rp.range, I, widen);
    float u0 = r.x, u1 = r.y, v0 = r.z, v1 = r.w;
    g.u0 = u0; g.v0 = v0; g.u1 = u1; g.v1 = v1;
    if (gu.na) {
        float l = (u1 - u0) * (1.0f / 7.0f);
        g.au = l / (float)gu.na;
        g.su = ((u1 - u0) - 2.0f * l) / (float)gu.nm;
    } else {
        g.au = 0.0f;
        g.su = (u1 - u0) / (float)(gu.n - 1);
    }
    if (gv.na) {
        float l = (v1 - v0) * (1.0f / 7.0f);
        g.av = l / (float)gv.na;
        g.sv = ((v1 - v0) - 2.0f * l) / (float)gv.nm;
    } else {
        g.av = 0.0f;
        g.sv = (v1 - v0) / (float)(gv.n - 1);
    }
    return g;
}

// Sample i of one grid direction (first x0, last x1, n samples, na strip steps of a, middle steps of m).
inline float grid_at(float x0, float x1, uint n, uint na, float a, float m, uint i) {
    if (na == 0u) return x0 + m * (float)i;                        // uniform, as ever
    if (i <= na) return x0 + a * (float)i;                         // first strip
    if (i + na >= n - 1u) return x1 - a * (float)(n - 1u - i);     // last strip, from the end
    return (x0 + a * (float)na) + m * (float)(i - na);             // middle
}

// Index i of g's nu x nv grid along u, or along v for PL_SPLIT_V: with a run's split, the run's
// grid line (patch_runs, quad_runs); with the other axis, a sample down that line (line_lanes).
inline float line_at(PointGrid g, uint split, uint nu, uint nv, uint i) {
    return split == PL_SPLIT_V ? grid_at(g.v0, g.v1, nv, g.nav, g.av, g.sv, i) : grid_at(g.u0, g.u1, nu, g.nau, g.au, g.su, i);
}

#define SAMPLE_DRAWN 0
#define SAMPLE_NAN 1
#define SAMPLE_CLIPPED 2

// Position only (no partials, no shading, no clipping): where a sample lands, for cheap
// rejection. Its bits may differ from point_sample's (separately generated code), so callers
// reject only with some slack. Returns SAMPLE_NAN or SAMPLE_DRAWN; *depth is the view depth.
inline int point_position(uint func, __global const float* P, __global const float* I,
                          __global const float* cam, float u, float v, float* fx, float* fy, float* depth) {
    float3 pos = pl_position(func, u, v, P);
    if (is_bad3(pos)) return SAMPLE_NAN;
    float3 e = xform_point(cam + CAM_VIEW, xform_point(I + INST_MODEL, pos));
    float4 c = project(cam, e);
    *depth = -e.z;
    *fx = (c.x / c.w * 0.5f + 0.5f) * cam[CAM_W];
    *fy = (0.5f - c.y / c.w * 0.5f) * cam[CAM_H];
    return SAMPLE_DRAWN;
}

// Where one evaluated sample (``world``, after the instance transform) lands in one view:
// SAMPLE_CLIPPED outside its depth range or image, else SAMPLE_DRAWN with its view-space
// position, view depth and screen position in pixels (inside the image).
typedef struct {
    float3 e;
    float4 c;   // clip coordinates
    float depth, x, y;
} Placed;

inline int point_place(float3 world, __global const float* cam, Placed* p) {
    float3 e = xform_point(cam + CAM_VIEW, world);
    float depth = -e.z;
    if (!(depth >= cam[CAM_NEAR] && depth <= cam[CAM_FAR])) return SAMPLE_CLIPPED;
    float W = cam[CAM_W], H = cam[CAM_H];
    float4 c = project(cam, e);
    float x = (c.x / c.w * 0.5f + 0.5f) * W;
    float y = (0.5f - c.y / c.w * 0.5f) * H;
    if (!(x >= 0.0f && y >= 0.0f && x < W && y < H)) return SAMPLE_CLIPPED;
    p->e = e; p->c = c; p->depth = depth; p->x = x; p->y = y;
    return SAMPLE_DRAWN;
}

// The keys of a placed sample: ``n_obj`` its (unnormalised) normal after the instance transform,
// shaded; *key its colour key and *aux its attribute key.
inline void point_keys(Placed p, float3 n_obj, __global const float* cam, float4 mat,
                       __global const float* light, uint object_id, ulong* key, ulong* aux) {
    __global const float* V = cam + CAM_VIEW;
    float3 n_view = xform_dir(V, n_obj);
    float3 n;
    uint rgba = shade(n_view, view_dir(cam, p.e), mat, light, &n);
    // the AOV normal is in world space: view -> world is the transpose of the view rotation
    float3 n_world = (float3)(V[0] * n.x + V[4] * n.y + V[8] * n.z,
                              V[1] * n.x + V[5] * n.y + V[9] * n.z,
                              V[2] * n.x + V[6] * n.y + V[10] * n.z);
    *key = color_key(p.depth, rgba);
    *aux = aux_key(p.depth, n_world, object_id);
}

// Transform, clip and shade one evaluated sample for one view (point_place, then point_keys):
// on SAMPLE_DRAWN, (*fx, *fy) is its screen position in pixels, *key and *aux its keys.
inline int point_view(float3 world, float3 n_obj, __global const float* cam, float4 mat,
                      __global const float* light, uint object_id, float* fx, float* fy, ulong* key, ulong* aux) {
    Placed p;
    if (point_place(world, cam, &p) != SAMPLE_DRAWN) return SAMPLE_CLIPPED;
    point_keys(p, n_obj, cam, mat, light, object_id, key, aux);
    *fx = p.x; *fy = p.y;
    return SAMPLE_DRAWN;
}

// Evaluate one sample: SAMPLE_NAN, or SAMPLE_DRAWN with its world position and normal direction.
// split: 0, or the function's split with C its carried values (pl_surface_axis at the sample's u
// or v; patch_runs).
inline int point_eval(uint func, __global const float* P, __global const float* I, uint split, const float* C,
                      float u, float v, float3* world, float3* n_obj) {
    float3 pos, fu, fv;
    if (split) pl_surface_rest(func, u, v, P, C, &pos, &fu, &fv);
    else pl_surface(func, u, v, P, &pos, &fu, &fv);
    if (is_bad3(pos)) return SAMPLE_NAN;
    *world = xform_point(I + INST_MODEL, pos);
    *n_obj = xform_dir(I + INST_NORMAL, cross(fu, fv));
    return SAMPLE_DRAWN;
}

// point_eval, also giving the partials df/du, df/dv after the instance transform (world space).
inline int point_eval_partials(uint func, __global const float* P, __global const float* I, uint split,
                               const float* C, float u, float v, float3* world, float3* n_obj, float3* tu,
                               float3* tv) {
    float3 pos, fu, fv;
    if (split) pl_surface_rest(func, u, v, P, C, &pos, &fu, &fv);
    else pl_surface(func, u, v, P, &pos, &fu, &fv);
    if (is_bad3(pos)) return SAMPLE_NAN;
    *world = xform_point(I + INST_MODEL, pos);
    *n_obj = xform_dir(I + INST_NORMAL, cross(fu, fv));
    *tu = xform_dir(I + INST_MODEL, fu);
    *tv = xform_dir(I + INST_MODEL, fv);
    return SAMPLE_DRAWN;
}

// Pixel-centre coverage (PointSettings.coverage "centre"; cover_cells' twin:
// paramlod.renderers.sampling.cover_cells). A sample stands for its cell of the patch's grid: the
// parameters from half-way to the previous sample to half-way to the next along u and v,
// widened by COVER_MARGIN for the surface's curvature, mapped to the screen by the linearised
// projection at the sample (its screen Jacobian from the partials). It covers the pixels whose
// centres its cell holds, as a triangle covers the pixels whose centres it holds; neighbouring
// cells tile the patch, so the points' silhouette is the surface's, not the surface grown by up
// to a pixel as when a sample covers the pixel it lands in.
#define COVER_MARGIN 1.3f    // cells overlap by 15 % of a step on each side
// COVER_REACH: pixels from the sample's own that a cell may reach; COVER_OWN (cover_cells): the
// cell is degenerate, the own pixel

// the screen-space image (pixels) of the world-space direction d at the placed sample p
inline float2 screen_dir(__global const float* cam, Placed p, float3 d) {
#pragma OPENCL FP_CONTRACT OFF
    float3 de = xform_dir(cam + CAM_VIEW, d);
    __global const float* M = cam + CAM_PROJ;
    float dcx = M[0] * de.x + M[1] * de.y + M[2] * de.z, dcy = M[4] * de.x + M[5] * de.y + M[6] * de.z;
    float dcw = M[12] * de.x + M[13] * de.y + M[14] * de.z;
    float iw = 1.0f / p.c.w;
    return (float2)(0.5f * cam[CAM_W] * ((dcx - p.c.x * iw * dcw) * iw),
                    -0.5f * cam[CAM_H] * ((dcy - p.c.y * iw * dcw) * iw));
}

inline int ceil_small(float t) { int i = (int)t; return (float)i < t ? i + 1 : i; }
inline int floor_small(float t) { int i = (int)t; return (float)i > t ? i - 1 : i; }

// The pixel centres the cell [-lo.x, hi.x] x [-lo.y, hi.y] (parameter offsets along u, v) of the
// sample placed at p holds, for screen Jacobian columns ju, jv: bit (dy + 2) * 5 + (dx + 2) for the
// pixel (dx, dy) from the sample's own, up to COVER_REACH pixels away; COVER_OWN when the cell is
// degenerate (its Jacobian singular: a silhouette seen edge-on, a pole; or not finite), where the
// sample covers its own pixel as before. Pixels outside the image (W x H) are never set.
inline uint cover_cells(Placed p, float2 ju, float2 jv, float2 lo, float2 hi, uint W, uint H) {
#pragma OPENCL FP_CONTRACT OFF   // as its twin evaluates it
    float det = ju.x * jv.y - ju.y * jv.x;
    if (!(det * det > 1e-12f * (ju.x * ju.x + ju.y * ju.y) * (jv.x * jv.x + jv.y * jv.y))) return COVER_OWN;
    // the cell's screen bounding box, relative to the sample
    float ax0 = ju.x * -lo.x, ax1 = ju.x * hi.x, bx0 = jv.x * -lo.y, bx1 = jv.x * hi.y;
    float ay0 = ju.y * -lo.x, ay1 = ju.y * hi.x, by0 = jv.y * -lo.y, by1 = jv.y * hi.y;
    float xmin = (ax0 < ax1 ? ax0 : ax1) + (bx0 < bx1 ? bx0 : bx1);
    float xmax = (ax0 < ax1 ? ax1 : ax0) + (bx0 < bx1 ? bx1 : bx0);
    float ymin = (ay0 < ay1 ? ay0 : ay1) + (by0 < by1 ? by0 : by1);
    float ymax = (ay0 < ay1 ? ay1 : ay0) + (by0 < by1 ? by1 : by0);
    int px = (int)p.x, py = (int)p.y;
    float fx = p.x - (float)px - 0.5f, fy = p.y - (float)py - 0.5f;   // the sample from its pixel's centre
    float ex0 = fx + xmin, ex1 = fx + xmax, ey0 = fy + ymin, ey1 = fy + ymax;   // the box from that centre
    const float reach = (float)(COVER_REACH + 1);
    if (!(ex0 <= ex1 && ey0 <= ey1)) return COVER_OWN;   // NaN
    // a larger cell (an undersampled patch) covers the centres inside it up to COVER_REACH pixels
    // away: taking only its own pixel left holes beside it (Johi's heart)
    int x0 = ceil_small(ex0 > -reach ? ex0 : -reach), x1 = floor_small(ex1 < reach ? ex1 : reach);
    int y0 = ceil_small(ey0 > -reach ? ey0 : -reach), y1 = floor_small(ey1 < reach ? ey1 : reach);
    x0 = x0 > -COVER_REACH ? x0 : -COVER_REACH; x1 = x1 < COVER_REACH ? x1 : COVER_REACH;
    y0 = y0 > -COVER_REACH ? y0 : -COVER_REACH; y1 = y1 < COVER_REACH ? y1 : COVER_REACH;
    float idet = 1.0f / det;
    uint bits = 0u;
    for (int dy = y0; dy <= y1; ++dy) {
        for (int dx = x0; dx <= x1; ++dx) {
            float qx = (float)dx - fx, qy = (float)dy - fy;   // the centre from the sample
            float a = (qx * jv.y - qy * jv.x) * idet, b = (ju.x * qy - ju.y * qx) * idet;
            bool inside = a >= -lo.x && a <= hi.x && b >= -lo.y && b <= hi.y
                          && px + dx >= 0 && px + dx < (int)W && py + dy >= 0 && py + dy < (int)H;
            if (inside) bits |= 1u << ((dy + COVER_REACH) * (2 * COVER_REACH + 1) + dx + COVER_REACH);
        }
    }
    return bits;
}

// Half the parameter gaps from sample i (at x) of a grid direction to the previous and the next,
// times COVER_MARGIN; a grid end takes the gap on its inner side for both.
inline float2 cell_half(float x, float x0, float x1, uint n, uint na, float a, float m, uint i) {
    float prev = i > 0u ? x - grid_at(x0, x1, n, na, a, m, i - 1u) : grid_at(x0, x1, n, na, a, m, 1u) - x;
    float next = i + 1u < n ? grid_at(x0, x1, n, na, a, m, i + 1u) - x : prev;
    if (i == 0u) prev = next;
    return (float2)(prev, next) * (0.5f * COVER_MARGIN);
}

// Quad coverage (PointSettings.coverage "quad"; cover_triangle's twin:
// paramlod.renderers.sampling.cover_triangle). Neighbouring samples of a patch's grid are the corners of quads, each drawn as
// two triangles that cover the pixels whose centres they hold, as a rasterizer covers a mesh of
// the sample grid: a silhouette is its polygon's, where a sample's linearised cell (cover_cells)
// reaches past it wherever the surface turns sharply (the tips of thin glyph lobes). A quad is
// exact however far apart its corners are, so its grid may be coarser (docs/points.md).
typedef struct {
    float x, y, depth;   // screen position (pixels, not clipped to the image) and view depth
    float3 e, n;         // view-space position and normal direction after the instance transform
    uint state;          // SAMPLE_DRAWN, or SAMPLE_NAN, or SAMPLE_CLIPPED outside the depth range
} QuadVertex;

// A corner evaluated and placed, not shaded: only the pixels that pass early depth are. A quad
// with a corner NaN or outside the depth range is not drawn (as a sample there is not).
inline QuadVertex quad_vertex(uint func, __global const float* P, __global const float* I, uint split, const float* C,
                              float u, float v, __global const float* cam) {
    QuadVertex q;
    q.state = SAMPLE_NAN; q.x = q.y = q.depth = 0.0f; q.e = q.n = (float3)(0.0f);
    float3 world;
    if (point_eval(func, P, I, split, C, u, v, &world, &q.n) == SAMPLE_NAN) return q;
    q.state = SAMPLE_CLIPPED;
    q.e = xform_point(cam + CAM_VIEW, world);
    q.depth = -q.e.z;
    if (!(q.depth >= cam[CAM_NEAR] && q.depth <= cam[CAM_FAR])) return q;
    float4 c = project(cam, q.e);
    q.x = (c.x / c.w * 0.5f + 0.5f) * cam[CAM_W];
    q.y = (0.5f - c.y / c.w * 0.5f) * cam[CAM_H];
    if (isfinite(q.x) && isfinite(q.y)) q.state = SAMPLE_DRAWN;
    return q;
}

#ifdef PL_VECTOR
// point_eval_partials on PL_VW samples of one grid line at once (pl_vsurface_rest, the generated
// code on vector lanes: paramlod.function.codegen_vector; the line's carried values C are
// shared): world position, normal direction and partials after the instance transform, and which
// lanes are NaN or infinite, as vectors. The same arithmetic as the scalar forms, lane for lane.
typedef struct { plv wx, wy, wz, nx, ny, nz, ux, uy, uz, vx, vy, vz; plvi bad; } SurfaceLanes;

inline SurfaceLanes surface_lanes(uint func, __global const float* P, __global const float* I, const float* C,
                                  plv u, plv v) {
#pragma OPENCL FP_CONTRACT OFF
    plv o[9];
    pl_vsurface_rest(func, u, v, P, C, o);
    SurfaceLanes s;
    s.bad = isnan(o[0]) | isnan(o[1]) | isnan(o[2]) | isinf(o[0]) | isinf(o[1]) | isinf(o[2]);
    __global const float* M = I + INST_MODEL;
    s.wx = M[0] * o[0] + M[1] * o[1] + M[2] * o[2] + M[3];
    s.wy = M[4] * o[0] + M[5] * o[1] + M[6] * o[2] + M[7];
    s.wz = M[8] * o[0] + M[9] * o[1] + M[10] * o[2] + M[11];
    plv cx = o[4] * o[8] - o[5] * o[7], cy = o[5] * o[6] - o[3] * o[8], cz = o[3] * o[7] - o[4] * o[6];
    __global const float* N = I + INST_NORMAL;
    s.nx = N[0] * cx + N[1] * cy + N[2] * cz; s.ny = N[4] * cx + N[5] * cy + N[6] * cz;
    s.nz = N[8] * cx + N[9] * cy + N[10] * cz;
    s.ux = M[0] * o[3] + M[1] * o[4] + M[2] * o[5]; s.uy = M[4] * o[3] + M[5] * o[4] + M[6] * o[5];
    s.uz = M[8] * o[3] + M[9] * o[4] + M[10] * o[5];
    s.vx = M[0] * o[6] + M[1] * o[7] + M[2] * o[8]; s.vy = M[4] * o[6] + M[5] * o[7] + M[6] * o[8];
    s.vz = M[8] * o[6] + M[9] * o[7] + M[10] * o[8];
    return s;
}

// (u, v) of PL_VW samples down one grid line of g (a run: patch_runs, quad_runs): the line at
// parameter `a` across the split's axis (u, or v for a split along v), samples ib .. ib + PL_VW - 1
// of the nu x nv grid along it, lanes past `last` repeating sample `last`; as grid_at gives them.
inline void line_lanes(PointGrid g, uint split, uint nu, uint nv, float a, uint ib, uint last, plv* u, plv* v) {
    uint along = split == PL_SPLIT_V ? PL_SPLIT_U : PL_SPLIT_V;   // the line's own parameter
    float b[PL_VW];
    for (uint l = 0u; l < PL_VW; ++l) b[l] = line_at(g, along, nu, nv, min(ib + l, last));
    plv bv = pl_vload(0, b);
    *u = split == PL_SPLIT_V ? bv : (plv)a;
    *v = split == PL_SPLIT_V ? (plv)a : bv;
}

// Lane l of surface_lanes as point_eval_partials gives it.
inline int lane_eval(const SurfaceLanes* s, uint l, float3* world, float3* n_obj, float3* tu, float3* tv) {
    if (s->bad[l]) return SAMPLE_NAN;
    *world = (float3)(s->wx[l], s->wy[l], s->wz[l]);
    *n_obj = (float3)(s->nx[l], s->ny[l], s->nz[l]);
    *tu = (float3)(s->ux[l], s->uy[l], s->uz[l]);
    *tv = (float3)(s->vx[l], s->vy[l], s->vz[l]);
    return SAMPLE_DRAWN;
}

// quad_vertex on PL_VW corners of one grid line at once (surface_lanes); the first n lanes are
// stored in out[0..n).
inline void quad_vertices(uint func, __global const float* P, __global const float* I, const float* C,
                          plv u, plv v, __global const float* cam, uint n, QuadVertex* out) {
    SurfaceLanes s = surface_lanes(func, P, I, C, u, v);
    plv wx = s.wx, wy = s.wy, wz = s.wz, nx = s.nx, ny = s.ny, nz = s.nz;
    plvi bad = s.bad;
    __global const float* V = cam + CAM_VIEW;
    plv ex = V[0] * wx + V[1] * wy + V[2] * wz + V[3], ey = V[4] * wx + V[5] * wy + V[6] * wz + V[7];
    plv ez = V[8] * wx + V[9] * wy + V[10] * wz + V[11];
    plv depth = -ez;
    __global const float* Q = cam + CAM_PROJ;
    plv clx = Q[0] * ex + Q[1] * ey + Q[2] * ez + Q[3], cly = Q[4] * ex + Q[5] * ey + Q[6] * ez + Q[7];
    plv clw = Q[12] * ex + Q[13] * ey + Q[14] * ez + Q[15];
    plv x = (clx / clw * 0.5f + 0.5f) * cam[CAM_W], y = (0.5f - cly / clw * 0.5f) * cam[CAM_H];
    plvi drawn = depth >= cam[CAM_NEAR] && depth <= cam[CAM_FAR] && isfinite(x) && isfinite(y);
    for (uint l = 0u; l < n; ++l) {
        QuadVertex q;
        q.x = x[l]; q.y = y[l]; q.depth = depth[l];
        q.e = (float3)(ex[l], ey[l], ez[l]);
        q.n = (float3)(nx[l], ny[l], nz[l]);
        q.state = bad[l] ? SAMPLE_NAN : drawn[l] ? SAMPLE_DRAWN : SAMPLE_CLIPPED;
        out[l] = q;
    }
}
#endif

// twice the signed area of (a, b, q): > 0 when q is left of a -> b
inline float edge_fn(float ax, float ay, float bx, float by, float qx, float qy) {
#pragma OPENCL FP_CONTRACT OFF   // as its twin evaluates it
    return (bx - ax) * (qy - ay) - (by - ay) * (qx - ax);
}

// Writes the pixels whose centres the triangle (a, b, c) holds (edges included, either winding;
// none when it has no area) inside the W x H image: depth interpolated at the centre, shaded
// with the normal of the corner nearest to it. Returns the colour atomics issued.
inline uint cover_triangle(QuadVertex a, QuadVertex b, QuadVertex c, __global const float* cam, float4 mat,
                           __global const float* light, uint object_id,
                           __global ulong* color_buf, __global ulong* aux_buf) {
#pragma OPENCL FP_CONTRACT OFF
    float area = edge_fn(a.x, a.y, b.x, b.y, c.x, c.y);
    if (!(area != 0.0f)) return 0u;
    uint W = (uint)cam[CAM_W], H = (uint)cam[CAM_H];
    float x0 = pl_fmaxf(pl_ceilf(pl_fminf(pl_fminf(a.x, b.x), c.x) - 0.5f), 0.0f);
    float x1 = pl_fminf(pl_floorf(pl_fmaxf(pl_fmaxf(a.x, b.x), c.x) - 0.5f), (float)W - 1.0f);
    float y0 = pl_fmaxf(pl_ceilf(pl_fminf(pl_fminf(a.y, b.y), c.y) - 0.5f), 0.0f);
    float y1 = pl_fminf(pl_floorf(pl_fmaxf(pl_fmaxf(a.y, b.y), c.y) - 0.5f), (float)H - 1.0f);
    uint issued = 0u;
    float inv = 1.0f / area;
    for (float py = y0; py <= y1; py += 1.0f) {
        for (float px = x0; px <= x1; px += 1.0f) {
            float qx = px + 0.5f, qy = py + 0.5f;
            float wa = edge_fn(b.x, b.y, c.x, c.y, qx, qy);   // a's weight (times area)
            float wb = edge_fn(c.x, c.y, a.x, a.y, qx, qy);
            float wc = edge_fn(a.x, a.y, b.x, b.y, qx, qy);
            if (!((wa >= 0.0f && wb >= 0.0f && wc >= 0.0f) || (wa <= 0.0f && wb <= 0.0f && wc <= 0.0f))) continue;
            float la = wa * inv, lb = wb * inv, lc = wc * inv;
            Placed p;
            p.depth = la * a.depth + lb * b.depth + lc * c.depth;
            uint pix = (uint)py * W + (uint)px;
            if (key_hidden(color_buf, pix, p.depth)) continue;
            QuadVertex n = la >= lb && la >= lc ? a : lb >= lc ? b : c;
            p.e = n.e;
            ulong key, aux;
            point_keys(p, n.n, cam, mat, light, object_id, &key, &aux);
            issued += write_point(color_buf, aux_buf, pix, key, aux);
        }
    }
    return issued;
}

// Evaluate, transform, clip and shade one sample for one view (point_eval, then point_view).
inline int point_sample(uint func, __global const float* P, __global const float* I,
                        __global const float* cam, float4 mat, __global const float* light,
                        uint object_id, float u, float v, float* fx, float* fy, ulong* key, ulong* aux) {
    float3 world, n_obj;
    if (point_eval(func, P, I, 0u, 0, u, v, &world, &n_obj) == SAMPLE_NAN) return SAMPLE_NAN;
    return point_view(world, n_obj, cam, mat, light, object_id, fx, fy, key, aux);
}

// Sums four per-work-item counters over the work-group in local memory, then one atom_add each:
// global atomics from every work-item on the same four addresses would serialise.
inline void add_counters(__global ulong* counters, ulong4 mine, __local ulong4* red) {
    uint l = get_local_id(0);
    red[l] = mine;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (uint s = POINTS_LOCAL / 2; s > 0; s >>= 1) {
        if (l < s) red[l] += red[l + s];
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (l == 0) {
        ulong4 t = red[0];
        if (t.x) atom_add(&counters[PTS_SAMPLES], t.x);
        if (t.y) atom_add(&counters[PTS_ATOMICS], t.y);
        if (t.z) atom_add(&counters[PTS_NAN_SAMPLES], t.z);
        if (t.w) atom_add(&counters[PTS_CAPPED_PATCHES], t.w);
    }
}

// Direct variant, in two kernels. The work of all patches is cut into units, a patch's units
// numbered consecutively: points_schedule lists the patches with the number of their first unit,
// then every work-group of points_direct takes an equal, contiguous range of units. Patches differ
// in size by 100x (an order-12 glyph at 1440 x 1440: 600 patches, 2 to 37,000 samples each); even
// shares are up to 18% faster than a fixed number of work-groups per patch (docs/points.md).
// Packed (PL_PACK 1): a unit is a run of samples (patch_runs), and each work-item takes every
// POINTS_LOCAL-th unit of its group's range, across patches. The fibre curtain's patches have
// about 30 samples; a pass of the work-group each left most work-items idle. Otherwise (and for
// quads) a unit is a chunk of POINTS_LOCAL runs (quads: blocks and runs, quad_runs), a pass of the
// work-group per patch. CPUs always pack; GPUs only after a frame of small patches: packed, the
// lanes of a warp set up their patches apart, and an H200 drew scenes of larger patches 1.04-1.18x
// slower (paramlod/renderers/points.py packs; docs/points.md, "Packed work").
// The patch count is read on the device (count[count_at], e.g. the LOD stage's render total,
// capped at the list's capacity), so the host enqueues the LOD stage and these kernels without
// waiting in between.

// counters: PTS_* of the prelude (paramlod.core.layouts.POINTS_COUNTER). counters[PTS_SCHED] =
// patches listed << CHUNK_BITS | units listed so far (zeroed with the renderer's counters before
// points_schedule); counters[PTS_UNITS]: the most units a list of the frame had
// (paramlod/renderers/points.py refuses a frame past MAX_UNITS: order[] numbers units in 32 bits)
#define CHUNK_BITS 40
#ifndef PL_PACK
#define PL_PACK 1
#endif
#if PL_PACK && !PL_QUADS
#define PL_PACKED 1u
#else
#define PL_PACKED 0u
#endif
#define CHUNK_MASK ((1ul << CHUNK_BITS) - 1ul)

// A patch's samples in runs, one run a work-item (the surface split of paramlod.function.codegen_cl):
// with a split along u, a work-item evaluates the steps that read only u once for its grid column
// (pl_surface_axis) and then up to PL_RUN samples down it; along v, the same for a grid row;
// without a split, runs down the columns too. Lines: the na grid lines along the split's axis;
// each is cut into `runs` runs of at most `len` of its nb samples. PL_RUN 1 (GPUs): one sample a
// work-item in row order, evaluated whole (pl_surface): runs were slower on the H200 where
// placing and testing the samples, not evaluating them, bounds the frame (docs/points.md).
typedef struct { uint split, na, nb, runs, len; } Runs;
#ifndef PL_RUN   // set by the host per device (paramlod/function/programs.py sample_run)
#define PL_RUN 8u
#endif

inline Runs patch_runs(uint split, uint nu, uint nv) {
    Runs r;
    r.split = PL_RUN > 1u ? split : 0u;
    r.na = r.split == PL_SPLIT_V ? nv : nu;
    r.nb = r.split == PL_SPLIT_V ? nu : nv;
    r.runs = PL_RUN == 1u ? r.nb : (r.nb + PL_RUN - 1u) / PL_RUN;
    r.len = PL_RUN == 1u ? 1u : (r.nb + r.runs - 1u) / r.runs;
    return r;
}

// Quad coverage (PL_QUADS): a work-item draws the quads of a block of up to PL_QUAD_LINES strips
// between neighbouring grid lines (lines as patch_runs orders them), for a run of up to
// PL_QUAD_STEPS (PL_QUAD_STEPS_SPLIT) steps down them, keeping the last column of corners: each
// corner is evaluated once per block and run, not four times. All nu_grid x nv_grid samples are
// corners (a wrapping axis's repeated line closes the seam). GPUs (PL_RUN 1): one quad a
// work-item, its four corners evaluated.
#define PL_QUAD_LINES (PL_RUN > 1u ? 4u : 1u)
// CPUs: runs of 15 steps (16 corners down a line, two vectors), or 31 (four) down the lines of a
// function's surface split, whose steps of one parameter a work-item evaluates once per line and
// run: the order-12 glyph field's quad render 40-43 -> 34-35 ms (2-core EPYC); without a split the
// longer runs were no faster (the torus 22-24 -> 23-26 ms)
#define PL_QUAD_STEPS (PL_RUN > 1u ? PL_RUN - 1u : 1u)
#define PL_QUAD_STEPS_SPLIT (PL_RUN > 1u ? 2u * PL_RUN - 1u : 1u)
typedef struct { uint split, na, nb, blocks, runs, len; } QuadRuns;

inline QuadRuns quad_runs(uint split, uint nu, uint nv) {
    QuadRuns r;
    r.split = PL_RUN > 1u ? split : 0u;
    r.na = r.split == PL_SPLIT_V ? nv : nu;
    r.nb = r.split == PL_SPLIT_V ? nu : nv;
    r.blocks = (r.na - 1u + PL_QUAD_LINES - 1u) / PL_QUAD_LINES;   // side counts are >= 2
    uint steps = r.split ? PL_QUAD_STEPS_SPLIT : PL_QUAD_STEPS;
    r.runs = (r.nb - 1u + steps - 1u) / steps;
    r.len = (r.nb - 1u + r.runs - 1u) / r.runs;
    return r;
}

// Whether the quad of four corners may cover a pixel: every corner drawn (none NaN or clipped),
// and on CPUs a pixel centre inside their bounding box, which holds both triangles' (most quads
// of a grid of about a pixel a step hold none or one: cover_triangle's setup is then skipped;
// 2-core EPYC, order-8 glyph field: render 50 -> 46 ms. The H100 drew 10 % slower with it.)
inline bool quad_may_cover(QuadVertex a, QuadVertex b, QuadVertex c, QuadVertex d) {
    if (a.state || b.state || c.state || d.state) return false;
    if (PL_RUN == 1u) return true;
    float x0 = pl_fminf(pl_fminf(a.x, b.x), pl_fminf(c.x, d.x)), x1 = pl_fmaxf(pl_fmaxf(a.x, b.x), pl_fmaxf(c.x, d.x));
    float y0 = pl_fminf(pl_fminf(a.y, b.y), pl_fminf(c.y, d.y)), y1 = pl_fmaxf(pl_fmaxf(a.y, b.y), pl_fmaxf(c.y, d.y));
    return pl_ceilf(x0 - 0.5f) <= pl_floorf(x1 - 0.5f) && pl_ceilf(y0 - 0.5f) <= pl_floorf(y1 - 0.5f);
}

// quad_may_cover, then the quad's two triangles (q00, q10, q11) and (q00, q11, q01), one after the
// other; the colour atomics issued.
inline uint cover_quad(QuadVertex q00, QuadVertex q10, QuadVertex q01, QuadVertex q11, __global const float* cam,
                       float4 mat, __global const float* light, uint object_id, __global ulong* color_buf,
                       __global ulong* aux_buf) {
    if (!quad_may_cover(q00, q10, q01, q11)) return 0u;
    uint issued = cover_triangle(q00, q10, q11, cam, mat, light, object_id, color_buf, aux_buf);
    return issued + cover_triangle(q00, q11, q01, cam, mat, light, object_id, color_buf, aux_buf);
}

inline uint patch_units(RenderPatch rp, __global const float* I, uint flags, uint split, float factor,
                        float curve, uint measure, uint max_side) {
    GridAxis gu, gv;
    patch_axes(rp, I, flags, factor, curve, measure, max_side, &gu, &gv);
#if PL_QUADS
    QuadRuns q = quad_runs(split, gu.n, gv.n);
    return (q.blocks * q.runs + POINTS_LOCAL - 1u) / POINTS_LOCAL;
#else
    Runs r = patch_runs(split, gu.n - gu.wrap, gv.n - gv.wrap);
    return PL_PACKED ? r.na * r.runs : (r.na * r.runs + POINTS_LOCAL - 1u) / POINTS_LOCAL;
#endif
}

// The last place in order[lo, hi) whose first unit is <= c (order[lo]'s is)
inline uint place_of(__global const ulong* order, uint lo, uint hi, uint c) {
    while (hi - lo > 1u) {
        uint mid = (lo + hi) / 2u;
        if ((uint)(order[mid] >> 32) <= c) lo = mid; else hi = mid;
    }
    return lo;
}

// One work-item per patch: one 64-bit atomic gives the patch both its place in the schedule and
// its first unit, so first units increase with the place (points_direct searches them).
// order[place] = first unit << 32 | patch index. `tier`: only the patches of that hybrid tier
// are listed (ALL_TIERS: every patch). GPUs (PL_GROUP_SCHEDULE): the work-group sums its patches'
// (1 << CHUNK_BITS | units) in local memory and takes their places and units with one atomic,
// each patch its prefix of the sum: the same order within the group, and one atomic on the
// counter where every patch took one (an H100 scheduled the fibre curtain's 346k patches in
// 0.26 ms, most of it that counter's atomics in turn).
#define ALL_TIERS 0xFFFFFFFFu
inline ulong schedule_units(__global const RenderPatch* patches, uint pid, __global const float* inst_f,
                            __global const uint* inst_u, float factor, float curve, uint measure,
                            uint max_side, uint tier) {
    RenderPatch rp = patches[pid];
    if (tier != ALL_TIERS && ((rp.flags >> TIER_SHIFT) & 3u) != tier) return 0ul;   // not listed
    __global const uint* U = inst_u + rp.inst * INST_U;
    ulong k = patch_units(rp, inst_f + rp.inst * INST_F, U[INST_FLAGS], pl_split(U[INST_FUNC]), factor, curve,
                          measure, max_side);
    return (1ul << CHUNK_BITS) | k;
}

__kernel __attribute__((reqd_work_group_size(POINTS_LOCAL, 1, 1)))
void points_schedule(__global const RenderPatch* patches, __global const uint* count,
                     uint count_at, uint capacity, __global const float* inst_f,
                     __global const uint* inst_u, float factor, float curve,
                     uint measure, uint max_side, uint tier, __global ulong* order,
                     __global ulong* counters)
{
    uint n_patches = min(count[count_at], capacity);
#ifdef PL_GROUP_SCHEDULE
    __local ulong sum[POINTS_LOCAL];
    __local ulong group_first;
    uint l = get_local_id(0);
    // the whole group runs every pass (its barriers), each work-item one patch or none
    for (uint p0 = get_group_id(0) * POINTS_LOCAL; p0 < n_patches; p0 += get_global_size(0)) {
        uint pid = p0 + l;
        ulong mine = pid < n_patches ? schedule_units(patches, pid, inst_f, inst_u, factor, curve, measure,
                                                      max_side, tier) : 0ul;
        sum[l] = mine;
        barrier(CLK_LOCAL_MEM_FENCE);
        for (uint s = 1u; s < POINTS_LOCAL; s <<= 1) {   // inclusive prefix sums (Hillis-Steele)
            ulong add = l >= s ? sum[l - s] : 0ul;
            barrier(CLK_LOCAL_MEM_FENCE);
            sum[l] += add;
            barrier(CLK_LOCAL_MEM_FENCE);
        }
        if (l == POINTS_LOCAL - 1u) group_first = sum[l] ? atom_add(&counters[PTS_SCHED], sum[l]) : 0ul;
        barrier(CLK_LOCAL_MEM_FENCE);
        ulong old = group_first + sum[l] - mine;
        if (mine) order[old >> CHUNK_BITS] = (old & CHUNK_MASK) << 32 | (ulong)pid;
        barrier(CLK_LOCAL_MEM_FENCE);   // sum and group_first are written again in the next pass
    }
#else   // CPU devices: a barrier here makes PoCL's compiled work-group loops much slower
    for (uint pid = get_global_id(0); pid < n_patches; pid += get_global_size(0)) {
        ulong mine = schedule_units(patches, pid, inst_f, inst_u, factor, curve, measure, max_side, tier);
        if (!mine) continue;
        ulong old = atom_add(&counters[PTS_SCHED], mine);
        order[old >> CHUNK_BITS] = (old & CHUNK_MASK) << 32 | (ulong)pid;
    }
#endif
}

// Samples written straight into the shared key buffers with early depth twice: a sample is
// shaded only if key_hidden finds nothing nearer in its pixel, and write_point reads again
// before it issues an atom_min.
// Compiled per kind of frame (paramlod/renderers/points.py, DirectPointRenderer.program_for):
// PL_CENTRE 1 for PointSettings.coverage "centre", each sample covering the pixels whose centres
// its cell holds (cover_cells) instead of the pixel it lands in; PL_VIEWS 1 for frames of several
// views. Code a frame never runs still costs the GPU: with both in the kernel and chosen by
// arguments, the H100 drew the fibre curtain's samples 2.5x slower (docs/points.md).
#ifndef PL_CENTRE
#define PL_CENTRE 0
#endif
#ifndef PL_VIEWS
#define PL_VIEWS 0
#endif
__kernel __attribute__((reqd_work_group_size(POINTS_LOCAL, 1, 1)))
void points_direct(__global const RenderPatch* patches, __global const ulong* order,
                   __global const float* inst_f, __global const uint* inst_u,
                   __global const float* params, __global const float4* materials,
                   __global const float* cam, __global const ulong* view_masks,
                   __global const float* light,
                   float factor, float curve, uint measure, float widen, uint max_side, uint color_by,
                   __global ulong* color_buf, __global ulong* aux_buf,
                   __global ulong* counters   // samples, atomics, NaN samples, capped patches, schedule
#ifdef PL_RECORD
                   // test hook: every sample's pixel (or ~0 if dropped) and colour key
                   , __global const uint* rec_offset, __global uint* rec_pix, __global ulong* rec_key
#endif
                   )
{
    uint n_patches = (uint)(counters[PTS_SCHED] >> CHUNK_BITS);   // the patches listed
    ulong total = counters[PTS_SCHED] & CHUNK_MASK;
    if (get_global_id(0) == 0) atom_max(&counters[PTS_UNITS], total);
    if (total > 0xFFFFFFFFul - POINTS_LOCAL) return;   // refused by the host, drawn by nothing
    ulong groups = get_num_groups(0), group = get_group_id(0);
    uint c = (uint)(group * total / groups), c_end = (uint)((group + 1) * total / groups);
    ulong n_samples = 0, n_atomics = 0, n_nan = 0, n_capped = 0;
#if PL_PACKED
    c += get_local_id(0);   // this work-item's first unit; then every POINTS_LOCAL-th
#endif
    if (c < c_end) {
        uint place = place_of(order, 0u, n_patches, c);   // place 0 starts at unit 0
        uint W = (uint)cam[CAM_W], H = (uint)cam[CAM_H], layer_pixels = W * H;
        while (c < c_end) {   // the patch at `place`: its units in [c, c_end)
            ulong entry = order[place];
            uint first = (uint)(entry >> 32), pid = (uint)entry;
            uint next = place + 1u < n_patches ? (uint)(order[place + 1u] >> 32) : (uint)total;
            RenderPatch rp = patches[pid];
            uint inst = rp.inst;
            __global const float* I = inst_f + inst * INST_F;
            uint func = inst_u[inst * INST_U + INST_FUNC];
            __global const float* P = params + inst_u[inst * INST_U + INST_PARAMS];
            uint object_id = inst_u[inst * INST_U + INST_OBJECT];
            float4 mat = debug_material(materials[inst], rp, color_by);
            PointGrid g = point_grid(rp, I, inst_u[inst * INST_U + INST_FLAGS], factor, curve, measure, widen, max_side);
#if PL_VIEWS   // the views that see the patch (the LOD stage's render_views): the others are skipped
            ulong seen = view_masks[pid];
#endif
#if PL_PACKED   // the work-item of the patch's first unit counts it
            if (c == first && g.capped) n_capped++;
#else
            if (c == first && get_local_id(0) == 0 && g.capped) n_capped++;
#endif
#if PL_QUADS
            QuadRuns qr = quad_runs(pl_split(func), g.nu_grid, g.nv_grid);
            for (; c < min(next, c_end); ++c) {
                uint unit = (c - first) * POINTS_LOCAL + get_local_id(0);   // the patch's block and run
                if (unit >= qr.blocks * qr.runs) continue;
                uint a0 = unit % qr.blocks * PL_QUAD_LINES, lines = min(PL_QUAD_LINES, qr.na - 1u - a0) + 1u;
                uint b0 = unit / qr.blocks * qr.len, b1 = min(b0 + qr.len, qr.nb - 1u);
#if PL_RUN > 1
                float a_line[PL_QUAD_LINES + 1u], C[PL_QUAD_LINES + 1u][PL_SPLIT_FLOATS];
                for (uint k = 0u; k < lines; ++k) {
                    a_line[k] = line_at(g, qr.split, g.nu_grid, g.nv_grid, a0 + k);
                    if (qr.split) pl_surface_axis(func, a_line[k], P, C[k]);
                }
#endif
                // each view that sees the patch draws the block's quads into its layer; a corner is
                // placed in one view, so the corners are evaluated again for every further view
#if PL_VIEWS
                for (ulong left = seen; left != 0ul; left &= left - 1ul) {
                    uint view = 63u - (uint)clz(left & (~left + 1ul));   // the lowest view left
#else
                {
                    uint view = 0u;
#endif
                    __global const float* cv = cam + view * CAM_FLOATS;
                    __global ulong* color_view = color_buf + view * layer_pixels;
                    __global ulong* aux_view = aux_buf + view * layer_pixels;
#ifdef PL_VECTOR   // CPUs: each line's corners evaluated PL_VW at a time, then the quads drawn
                    QuadVertex qv[PL_QUAD_LINES + 1u][PL_QUAD_STEPS_SPLIT + 1u];
                    uint nb = b1 - b0 + 1u;   // corners down each line
                    for (uint k = 0u; k < lines; ++k) {
                        for (uint j0 = 0u; j0 < nb; j0 += PL_VW) {
                            plv u, v;
                            line_lanes(g, qr.split, g.nu_grid, g.nv_grid, a_line[k], b0 + j0, b1, &u, &v);
                            quad_vertices(func, P, I, C[k], u, v, cv, min((uint)PL_VW, nb - j0), &qv[k][j0]);
                        }
                        for (uint j = 0u; j < nb; ++j) n_nan += qv[k][j].state == SAMPLE_NAN;
                    }
                    n_samples += lines * nb;
                    for (uint j = 1u; j < nb; ++j)
                        for (uint k = 0u; k + 1u < lines; ++k)
                            n_atomics += cover_quad(qv[k][j - 1u], qv[k + 1u][j - 1u], qv[k][j], qv[k + 1u][j], cv, mat, light,
                                                    object_id, color_view, aux_view);
#else
                    QuadVertex prev[PL_QUAD_LINES + 1u], cur[PL_QUAD_LINES + 1u];
                    for (uint ib = b0; ib <= b1; ++ib) {
                        for (uint k = 0u; k < lines; ++k) {
                            uint iu = qr.split == PL_SPLIT_V ? ib : a0 + k, iv = qr.split == PL_SPLIT_V ? a0 + k : ib;
                            float us = grid_at(g.u0, g.u1, g.nu_grid, g.nau, g.au, g.su, iu);
                            float vs = grid_at(g.v0, g.v1, g.nv_grid, g.nav, g.av, g.sv, iv);
#if PL_RUN > 1
                            cur[k] = quad_vertex(func, P, I, qr.split, C[k], us, vs, cv);
#else
                            cur[k] = quad_vertex(func, P, I, 0u, 0, us, vs, cv);
#endif
                            n_samples++;
                            if (cur[k].state == SAMPLE_NAN) n_nan++;
                        }
                        for (uint k = 0u; ib > b0 && k + 1u < lines; ++k)
                            n_atomics += cover_quad(prev[k], prev[k + 1u], cur[k], cur[k + 1u], cv, mat, light, object_id,
                                                    color_view, aux_view);
                        for (uint k = 0u; k < lines; ++k) prev[k] = cur[k];
                    }
#endif
                }   // the views
            }
#else
            Runs runs = patch_runs(pl_split(func), g.nu, g.nv);
            for (; c < min(next, c_end); c += PL_PACKED ? POINTS_LOCAL : 1u) {
                // the patch's run
                uint unit = PL_PACKED ? c - first : (c - first) * POINTS_LOCAL + get_local_id(0);
                if (unit >= runs.na * runs.runs) continue;   // chunks: the patch's last is partly empty
                uint ia = unit % runs.na, ib0 = unit / runs.na * runs.len;
#if PL_RUN > 1
                uint ib1 = min(ib0 + runs.len, runs.nb);
                float a_line = line_at(g, runs.split, g.nu, g.nv, ia), C[PL_SPLIT_FLOATS];
                if (runs.split) pl_surface_axis(func, a_line, P, C);
#ifdef PL_VECTOR   // CPUs: the run's samples evaluated PL_VW at a time (surface_lanes)
                SurfaceLanes lanes;
#endif
                for (uint ib = ib0; ib < ib1; ++ib) {
#else   // GPUs: one sample, no private array and no loop (with them the H200's frames were 5-15 % slower)
                const float* C = 0;
                {
                    uint ib = ib0;
#endif
                    uint iu = runs.split == PL_SPLIT_V ? ib : ia, iv = runs.split == PL_SPLIT_V ? ia : ib;
                    uint j = iv * g.nu + iu;
                    float3 world, n_obj, tu, tv;
                    float us = grid_at(g.u0, g.u1, g.nu, g.nau, g.au, g.su, iu);
                    float vs = grid_at(g.v0, g.v1, g.nv, g.nav, g.av, g.sv, iv);
#ifdef PL_VECTOR
                    uint lane = (ib - ib0) % PL_VW;
                    if (lane == 0u) {
                        plv u, v;
                        line_lanes(g, runs.split, g.nu, g.nv, a_line, ib, ib1 - 1u, &u, &v);
                        lanes = surface_lanes(func, P, I, C, u, v);
                    }
                    int r = lane_eval(&lanes, lane, &world, &n_obj, &tu, &tv);
#else
                    int r = PL_CENTRE ? point_eval_partials(func, P, I, runs.split, C, us, vs, &world, &n_obj, &tu, &tv)
                                   : point_eval(func, P, I, runs.split, C, us, vs, &world, &n_obj);
#endif
                    n_samples++;
#ifdef PL_RECORD
                    rec_pix[rec_offset[pid] + j] = 0xFFFFFFFFu;
#endif
                    if (r == SAMPLE_NAN) { n_nan++; continue; }
                    // one evaluation, shaded and written into every view that sees the patch and
                    // whose frustum holds the sample
#if PL_VIEWS
                    for (ulong left = seen; left != 0ul; left &= left - 1ul) {
                        uint view = 63u - (uint)clz(left & (~left + 1ul));   // the lowest view left
#else   // view 0 alone (a loop of one, so that `continue` ends the view as above)
                    for (uint view = 0u; view < 1u; ++view) {
#endif
                        __global const float* cv = cam + view * CAM_FLOATS;
                        Placed p;
                        if (point_place(world, cv, &p) != SAMPLE_DRAWN) continue;
                        uint pix = view * layer_pixels + (uint)p.y * W + (uint)p.x;
                        // the pixels it covers: its own, or (centre) those whose centres its cell holds
                        uint cover = COVER_OWN;
                        if (PL_CENTRE) {
                            float2 hu = cell_half(us, g.u0, g.u1, g.nu, g.nau, g.au, g.su, iu);
                            float2 hv = cell_half(vs, g.v0, g.v1, g.nv, g.nav, g.av, g.sv, iv);
                            cover = cover_cells(p, screen_dir(cv, p, tu), screen_dir(cv, p, tv), (float2)(hu.x, hv.x),
                                                (float2)(hu.y, hv.y), W, H);
                        }
                        bool shaded = false;
                        ulong key, aux;
#ifdef PL_RECORD   // the hook records every sample's own pixel and key
                        point_keys(p, n_obj, cv, mat, light, object_id, &key, &aux);
                        shaded = true;
                        if (view == 0u) { rec_pix[rec_offset[pid] + j] = pix; rec_key[rec_offset[pid] + j] = key; }
#endif
                        for (uint left = cover == COVER_OWN ? 1u : cover; left != 0u; left &= left - 1u) {
                            uint q = pix;
                            if (cover != COVER_OWN) {
                                int k = 31 - (int)clz(left & (~left + 1u));   // the lowest bit left
                                int side = 2 * COVER_REACH + 1;
                                int dx = k % side - COVER_REACH, dy = k / side - COVER_REACH;
                                q = (uint)((int)pix + dy * (int)W + dx);
                            }
#ifndef PL_RECORD
                            if (key_hidden(color_buf, q, p.depth)) continue;
#endif
                            if (!shaded) { point_keys(p, n_obj, cv, mat, light, object_id, &key, &aux); shaded = true; }
                            n_atomics += write_point(color_buf, aux_buf, q, key, aux);
                        }
                    }
                }
            }
#endif
            // packed: the patch holding c, at most POINTS_LOCAL places on (each patch has a unit)
            place = PL_PACKED ? place_of(order, place, min(place + POINTS_LOCAL + 1u, n_patches), c) : place + 1u;
        }
    }
#ifdef PL_GROUP_COUNTERS
    __local ulong4 red[POINTS_LOCAL];
    add_counters(counters, (ulong4)(n_samples, n_atomics, n_nan, n_capped), red);
#else   // CPU devices: a barrier here makes PoCL's compiled work-group loops much slower
    if (n_samples) atom_add(&counters[PTS_SAMPLES], n_samples);
    if (n_atomics) atom_add(&counters[PTS_ATOMICS], n_atomics);
    if (n_nan) atom_add(&counters[PTS_NAN_SAMPLES], n_nan);
    if (n_capped) atom_add(&counters[PTS_CAPPED_PATCHES], n_capped);
#endif
}
