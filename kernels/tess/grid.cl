// The grid tessellator (TessSettings.tessellator "grid", paramlod/renderers/tess_grid.py): the
// render patches tessellated in OpenCL into an indexed triangle list, which GL then draws with a
// plain vertex stage (tess/grid_vertex.glsl). Where the device tessellates slowly (Mesa's
// llvmpipe runs the tessellation stages on one thread) this moves the function's evaluation to
// the OpenCL device and leaves GL only triangles to rasterize.
//
// The levels are the control stage's (tess_control.glsl): each outer edge from its screen
// polyline through 8 samples, the inner levels from the measured extents, both by the adaptive
// rule, or the fixed levels; each rounded up to a whole number of equal segments, as GL's
// equal_spacing does. The topology: an inner grid of a x b segments (at least 2 each), of which
// the (a - 1) x (b - 1) inner vertices are kept, and a ring that zips each outer edge's vertices
// to the inner grid's nearest row or column, so an edge shared by two patches that agree on its
// level gets the same vertices on both sides. Twin: paramlod.renderers.tess_grid_reference.
//
// A patch's levels record (int8): n0..n3, the outer edges' segments (0: u = u0, 1: v = v0,
// 2: u = u1, 3: v = v1, the control stage's order), a and b, the inner segments along u and v,
// then its vertex and triangle counts. Its vertices: the inner ones row by row (v outer, u inner),
// then the boundary counter-clockwise from (u0, v0): edge 1, edge 2, edge 3, edge 0, each from
// its first corner up to (not including) the next. Its triangles: the inner grid's quads row by
// row (two each), then the ring along edges 1, 2, 3, 0; all counter-clockwise in (u, v).
#include "common/rows.cl"

#define GRID_EDGE_SAMPLES 8

// tess_control.glsl's pl_adaptive
inline float grid_level(float e, float L, float t, float2 lclamp) {
    float l = e * L / fmin(t, L);
    return clamp(isnan(l) ? lclamp.x : l, lclamp.x, lclamp.y);
}

inline int grid_segments(float level) {
    return (int)ceil(level);
}

// a + (b - a) t, exact at both ends (tess_common.glsl's pl_lerp)
inline float grid_lerp(float a, float b, float t) {
    return t >= 1.0f ? b : a + (b - a) * t;
}

// a parameter line's polyline through GRID_EDGE_SAMPLES samples on the screen: x its length, y the largest
// second difference of its samples (|s[i-1] - 2 s[i] + s[i+1]|, how far it bends); INFINITY where
// a segment reaches behind the near plane (the finest level), NaN samples add nothing
inline float2 grid_line_measure(uint func, __global const float* P, __global const float* I,
                                __global const float* cam, float4 line) {
    float a = line.x, b = line.y, c = line.z, d = line.w;   // u from a to b, v from c to d
    float len = 0.0f, bend = 0.0f;
    float2 prev = (float2)(0.0f, 0.0f), prev2 = prev;
    int prev_state = 2, prev2_state = 2;
    for (int i = 0; i < GRID_EDGE_SAMPLES; ++i) {
        float f = (float)i / (float)(GRID_EDGE_SAMPLES - 1);
        float3 p = pl_position(func, grid_lerp(a, b, f), grid_lerp(c, d, f), P);
        int state = 2;   // 0 in front of the near plane, 1 behind it, 2 NaN/inf
        float2 s = (float2)(0.0f, 0.0f);
        if (!is_bad3(p)) {
            float4 q = project(cam, xform_point(cam + CAM_VIEW, rows_point(I + INST_MODEL, p)));
            state = q.w >= cam[CAM_NEAR] ? 0 : 1;
            s = (float2)((q.x / q.w * 0.5f + 0.5f) * cam[CAM_W], (0.5f - q.y / q.w * 0.5f) * cam[CAM_H]);
        }
        if (i > 0) {
            if (state == 1 || prev_state == 1) len = bend = INFINITY;
            else if (state == 0 && prev_state == 0) len += length(s - prev);
        }
        if (i > 1 && state == 0 && prev_state == 0 && prev2_state == 0) bend = fmax(bend, length(prev2 - 2.0f * prev + s));
        prev2 = prev;
        prev2_state = prev_state;
        prev = s;
        prev_state = state;
    }
    return (float2)(len, bend);
}

// segments of a curve whose samples 1/(GRID_EDGE_SAMPLES - 1) apart bend by `bend` pixels, so that
// its chords stray at most `chord` pixels from it: a chord of step h strays about h^2 |c''| / 8
inline float grid_chord_level(float bend, float chord, float2 lclamp) {
    float l = (float)(GRID_EDGE_SAMPLES - 1) * sqrt(bend / (8.0f * chord));
    return clamp(isnan(l) ? lclamp.x : l, lclamp.x, lclamp.y);
}

// The parameter range a patch's vertices span: sampled_range, and where overlap_px > 0 (a hybrid
// tier carried into a finer one) at least that many output pixels of its measured extents per
// side, at most 0.25 of its size (tess_control.glsl).
inline float4 grid_range(RenderPatch rp, __global const float* I, float overlap, float overlap_px) {
    if (overlap_px <= 0.0f) return sampled_range(rp.range, I, overlap);
    float2 e = rp.ext.xy;
    return sampled_range_uv(rp.range, I, (float2)(fmax(overlap, e.x > 0.0f ? fmin(overlap_px / e.x, 0.25f) : 0.0f),
                                                  fmax(overlap, e.y > 0.0f ? fmin(overlap_px / e.y, 0.25f) : 0.0f)));
}

// One work-item per render patch: its levels record. kind 0 (fixed): rule.xy the (inner, outer)
// levels; 1 (adaptive): rule (L inner, L outer, t_u, t_v), the inner levels from e_u, e_v (or
// from s_u, s_v where larger, with inner_segment); 2 (chord): rule.x the chord error in pixels,
// each inner level the larger of the two edges across it. lclamp: (l_min, l_max).
__kernel void grid_levels(__global const RenderPatch* patches, uint count,
                          __global const float* inst_f, __global const uint* inst_u, __global const float* params,
                          __global const float* cam, float4 rule, float2 lclamp, uint kind, uint inner_segment,
                          __global int8* levels) {
    uint p = get_global_id(0);
    if (p >= count) return;
    RenderPatch rp = patches[p];
    int n[4];
    int a, b;
    if (kind) {
        __global const float* I = inst_f + rp.inst * INST_F;
        __global const uint* U = inst_u + rp.inst * INST_U;
        __global const float* P = params + U[INST_PARAMS];
        for (int e = 0; e < 4; ++e) {
            float4 r = rp.range;   // the edge's u from, u to, v from, v to
            float2 m = grid_line_measure(U[INST_FUNC], P, I, cam,
                                         (float4)(e == 2 ? r.y : r.x, e == 0 ? r.x : r.y, e == 3 ? r.w : r.z, e == 1 ? r.z : r.w));
            n[e] = grid_segments(kind == 1u ? grid_level(m.x, rule.y, (e & 1) ? rule.z : rule.w, lclamp)
                                            : grid_chord_level(m.y, rule.x, lclamp));
        }
        if (kind == 1u) {
            float2 e = inner_segment ? fmax(rp.ext.xy, rp.ext.zw) : rp.ext.xy;
            a = grid_segments(grid_level(e.x, rule.x, rule.z, lclamp));
            b = grid_segments(grid_level(e.y, rule.x, rule.w, lclamp));
        } else {   // the lines between the edges, 1/7 of the patch apart: the bend inside
            float bend_u = 0.0f, bend_v = 0.0f;
            for (int k = 1; k < GRID_EDGE_SAMPLES - 1; ++k) {
                float f = (float)k / (float)(GRID_EDGE_SAMPLES - 1);
                float u = grid_lerp(rp.range.x, rp.range.y, f), v = grid_lerp(rp.range.z, rp.range.w, f);
                bend_u = fmax(bend_u, grid_line_measure(U[INST_FUNC], P, I, cam, (float4)(rp.range.x, rp.range.y, v, v)).y);
                bend_v = fmax(bend_v, grid_line_measure(U[INST_FUNC], P, I, cam, (float4)(u, u, rp.range.z, rp.range.w)).y);
            }
            a = max(max(n[1], n[3]), grid_segments(grid_chord_level(bend_u, rule.x, lclamp)));
            b = max(max(n[0], n[2]), grid_segments(grid_chord_level(bend_v, rule.x, lclamp)));
        }
    } else {
        for (int e = 0; e < 4; ++e) n[e] = grid_segments(rule.y);
        a = b = grid_segments(rule.x);
    }
    a = max(a, 2);
    b = max(b, 2);
    int verts = (a - 1) * (b - 1) + n[0] + n[1] + n[2] + n[3];
    int tris = 2 * (a - 2) * (b - 2) + n[0] + n[1] + n[2] + n[3] + 2 * (a - 2) + 2 * (b - 2);
    levels[p] = (int8)(n[0], n[1], n[2], n[3], a, b, verts, tris);
}

// (t_u, t_v) in [0, 1]^2 of local vertex l of a patch with levels L
inline float2 grid_vertex_t(int8 L, int l) {
    int a = L.s4, b = L.s5;
    int inner = (a - 1) * (b - 1);
    if (l < inner) return (float2)((float)(l % (a - 1) + 1) / (float)a, (float)(l / (a - 1) + 1) / (float)b);
    int k = l - inner;
    if (k < L.s1) return (float2)((float)k / (float)L.s1, 0.0f);
    k -= L.s1;
    if (k < L.s2) return (float2)(1.0f, (float)k / (float)L.s2);
    k -= L.s2;
    if (k < L.s3) return (float2)((float)(L.s3 - k) / (float)L.s3, 1.0f);
    k -= L.s3;
    return (float2)(0.0f, (float)(L.s0 - k) / (float)L.s0);
}

// The local vertex a patch's visit l reaches: the boundary as numbered; the inner grid row by row
// (the numbering), or column by column where `columns` (a function whose split reads u: a column
// keeps u, so its steps of u are evaluated once for the run).
inline int grid_visit(int8 L, int l, bool columns) {
    int rows = L.s5 - 1, inner = (L.s4 - 1) * rows;
    return columns && l < inner ? (l % rows) * (L.s4 - 1) + l / rows : l;
}

#ifndef PL_RUN   // set by the host per device (paramlod/function/programs.py sample_run)
#define PL_RUN 1u
#endif

// PL_RUN vertex visits a work-item, of the patches [0, count), whose first vertices are
// vert_start (count + 1 entries, the last the total): position and normal as the evaluation stage
// makes them (tess_eval.glsl), where a degenerate parametrization takes the normal a little way
// towards the patch centre. nan_count: the NaN/inf vertices. With PL_RUN > 1 (CPU devices) a
// function with a surface split (pl_split) evaluates the steps of its split parameter once for
// the visits of a run that share it (consecutive visits of one grid row or column), bit for bit
// what pl_surface gives (function/codegen_cl.py, "the surface split").
__kernel void grid_vertices(__global const RenderPatch* patches, uint count, __global const int8* levels,
                            __global const uint* vert_start,
                            __global const float* inst_f, __global const uint* inst_u, __global const float* params,
                            float overlap, float overlap_px, __global GridVertex* out,
                            volatile __global uint* nan_count) {
#if PL_RUN > 1
    float C[PL_SPLIT_FLOATS];
    uint carried_patch = 0xffffffffu;   // C holds the split's steps at carried_at for this patch
    float carried_at = 0.0f;
#endif
    uint lo = 0;   // the patch p with vert_start[p] <= g < vert_start[p + 1]
    for (uint r = 0; r < PL_RUN; ++r) {
        uint g = get_global_id(0) * PL_RUN + r;
        if (g >= vert_start[count]) return;
        if (r == 0u || g >= vert_start[lo + 1u]) {   // searched again only where a run enters the next patch
            uint hi = count;
            while (hi - lo > 1u) {
                uint mid = (lo + hi) >> 1;
                if (vert_start[mid] <= g) lo = mid; else hi = mid;
            }
        }
        RenderPatch rp = patches[lo];
        __global const float* I = inst_f + rp.inst * INST_F;
        __global const uint* U = inst_u + rp.inst * INST_U;
        __global const float* P = params + U[INST_PARAMS];
        uint func = U[INST_FUNC];
        uint split = PL_RUN > 1u ? pl_split(func) : 0u;
        int8 L = levels[lo];
        int l = grid_visit(L, (int)(g - vert_start[lo]), split == PL_SPLIT_U);
        float2 t = grid_vertex_t(L, l);
        float4 range = grid_range(rp, I, overlap, overlap_px);
        float u = grid_lerp(range.x, range.y, t.x), v = grid_lerp(range.z, range.w, t.y);
        float uc = 0.5f * (rp.range.x + rp.range.y), vc = 0.5f * (rp.range.z + rp.range.w);
        float3 pos, n;
        for (int k = 0; k < 2; ++k) {
            float f = k == 0 ? 0.0f : 1e-3f;
            float3 p1, du1, dv1;
#if PL_RUN > 1
            if (split && k == 0) {
                float at = split == PL_SPLIT_U ? u : v;
                if (lo != carried_patch || at != carried_at) {
                    pl_surface_axis(func, at, P, C);
                    carried_patch = lo;
                    carried_at = at;
                }
                pl_surface_rest(func, u, v, P, C, &p1, &du1, &dv1);
            } else
#endif
            pl_surface(func, u + (uc - u) * f, v + (vc - v) * f, P, &p1, &du1, &dv1);
            if (k == 0) pos = p1;
            n = cross(du1, dv1);
            if (dot(n, n) > 1e-12f * dot(du1, du1) * dot(dv1, dv1) || is_bad3(pos)) break;
        }
        GridVertex o;
        o.pos = (float4)(0.0f, 0.0f, 0.0f, 1.0f);
        float3 nw = (float3)(0.0f, 0.0f, 1.0f);
        if (is_bad3(pos)) {
            atomic_inc(nan_count);
        } else {
            o.pos = (float4)(rows_point(I + INST_MODEL, pos), 0.0f);
            nw = rows_dir(I + INST_NORMAL, n);
        }
        o.normal0 = nw.x; o.normal1 = nw.y; o.normal2 = nw.z;
        o.inst = rp.inst;
        out[vert_start[lo] + (uint)l] = o;
    }
}

// local vertex of boundary side s (0..3: edges 1, 2, 3, 0, counter-clockwise from (u0, v0)), k in [0, its segments]: k = segments is
// the next side's first
inline int grid_boundary(int8 L, int s, int k) {
    int n[4] = {L.s1, L.s2, L.s3, L.s0};   // by side
    if (k == n[s]) { s = (s + 1) & 3; k = 0; }
    int at = (L.s4 - 1) * (L.s5 - 1);
    for (int i = 0; i < s; ++i) at += n[i];
    return at + k;
}

inline int grid_inner(int8 L, int i, int j) {   // i in [1, a - 1], j in [1, b - 1]
    return (j - 1) * (L.s4 - 1) + (i - 1);
}

// local vertex k in [0, A - 2] of the inner grid's side facing boundary side s, in the side's direction
inline int grid_inner_side(int8 L, int s, int k) {
    int a = L.s4, b = L.s5;
    if (s == 0) return grid_inner(L, 1 + k, 1);
    if (s == 1) return grid_inner(L, a - 1, 1 + k);
    if (s == 2) return grid_inner(L, a - 1 - k, b - 1);
    return grid_inner(L, 1, b - 1 - k);
}

inline void grid_tri(__global uint* out, uint* at, uint base, int x, int y, int z) {
    out[*at] = base + (uint)x; out[*at + 1u] = base + (uint)y; out[*at + 2u] = base + (uint)z;
    *at += 3u;
}

// One work-item per patch: its triangles' vertex indices, from 3 tri_start[p] on.
__kernel void grid_indices(uint count, __global const int8* levels, __global const uint* vert_start,
                           __global const uint* tri_start, __global uint* out) {
    uint p = get_global_id(0);
    if (p >= count) return;
    int8 L = levels[p];
    int a = L.s4, b = L.s5;
    uint base = vert_start[p];
    uint at = 3u * tri_start[p];
    for (int j = 1; j <= b - 2; ++j) {
        for (int i = 1; i <= a - 2; ++i) {
            int q = grid_inner(L, i, j), r = grid_inner(L, i + 1, j);
            int s = grid_inner(L, i + 1, j + 1), t = grid_inner(L, i, j + 1);
            grid_tri(out, &at, base, q, r, s);
            grid_tri(out, &at, base, q, s, t);
        }
    }
    // the ring: each side zips its outer vertices (t = x / n) to the inner side's (t = (y + 1) / A),
    // always advancing the one whose next vertex comes first (the outer one on a tie)
    for (int s = 0; s < 4; ++s) {
        int n = s == 0 ? L.s1 : s == 1 ? L.s2 : s == 2 ? L.s3 : L.s0;
        int A = (s & 1) ? b : a;
        int m = A - 2;
        int x = 0, y = 0;
        while (x < n || y < m) {
            if (x < n && (y == m || (x + 1) * A <= (y + 2) * n)) {
                grid_tri(out, &at, base, grid_boundary(L, s, x), grid_boundary(L, s, x + 1), grid_inner_side(L, s, y));
                ++x;
            } else {
                grid_tri(out, &at, base, grid_boundary(L, s, x), grid_inner_side(L, s, y + 1), grid_inner_side(L, s, y));
                ++y;
            }
        }
    }
}
