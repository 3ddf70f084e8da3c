// LOD stage: one PATCH SUBDIVISION step (thesis section 5.5.1), one work-group per patch.
// Per patch: 8 samples along u on 4 rows (v at 1/8, 3/8, 5/8, 7/8 of the range), 8 along v on 4
// columns, and a 5x5 grid of extra samples for the frustum test and the screen bounding box.
// Each line's screen polyline length is compared with the threshold; a line that exceeds it
// splits the half of the patch it lies in (7 patterns, docs/lod.md). The numpy twin of this
// kernel is paramlod/lod/reference.py: keep both in step.
//
// Views: one step serves n_views cameras at once (paramlod.render_views; n_views == 1 is the
// single-view stage, bit for bit). f is evaluated once per sample and each sample projected into
// every view. A view sees the patch when its samples' outcode AND is 0; the patch is culled only
// when no view sees it. Otherwise every measure is the most demanding over the views that see it
// (each line's length, the longest segments, w_u, w_v: maxima; the mixed lines: OR; the screen
// box: the union of those views' boxes), so a patch splits when it is too large in any of them:
// no view that sees a patch of the shared render list would split it. (The shared tree need not
// contain each view's own: where one view cuts a patch 1:3 and another needs the other half cut
// too, the patch is cut 1:2, docs/lod.md.)
//
// Boundary lines: the measured lines lie inside the patch (1/8 .. 7/8), so a patch whose screen
// speed peaks on its own edge would sample that edge too sparsely, and so would its neighbour
// across it (single-pixel holes along patch boundaries of steep surfaces). Each render patch also
// gets w_u, w_v (RenderPatch.w): s_u, s_v raised to what its four boundary lines
// need, from samples the step already has (lod_step: each line's speed extrapolated to its two ends,
// the chords of the 5x5 grid's four edges). The direct point renderer steps the outer seventh of
// the patch at each edge for w_u, w_v (kernels/points/points.cl grid_axis); the LOD decisions and
// the other renderers do not use them.
//
// Edges of the defined part: a line with both bad (NaN/inf) and good samples splits its half of
// the patch like a line over the threshold, so where a function stops being defined (a pole such
// as 0.05 / u at u = 0, a sqrt of a negative number) the patches shrink towards that edge step by
// step (while the line's good part is over a pixel long) and the part left undrawn is at most one
// last-step patch or about a pixel wide, the same in every variant
// (before, a patch reaching a pole was measured by its good samples alone: the points variant drew
// the steep sheet beside the pole as stripes, the tessellated one bridged it with long triangles).
//
// Back faces: for an instance flagged one-sided (INST_U flags bit 0, paramlod/lod/uploads.py) the
// step also evaluates pl_surface at a 5x5 grid over the patch widened as the point renderer
// samples it, bounds its normals by a cone and its points by a sphere (normal_cone: the bound and
// its one assumption are in docs/lod.md "Back-face culling") and culls the patch when every view
// that sees it sees only its back (cone_back); twin: reference.normal_cones, cone_back. With the
// flag clear, or backface = 0, nothing of this runs and the step is the step without it.
//
// Hybrid tiers (max_tier > 0; docs/hybrid.md): every patch carries its tier (EvalPatch.tier, then
// RenderPatch.flags >> TIER_SHIFT) and is measured with its tier's thresholds. One about to be
// rendered at a tier below max_tier is checked first (lod/spot.cl: a silhouette from tier 0, the
// spot check's sub-pixel detail) and, if either is found, goes back unsplit as one child of the
// next tier (LOD_PROMOTED). With max_tier 0 nothing of this runs.
//
// Counters: one record of LOD_COUNTERS uints per step (LOD_CHILDREN, LOD_SPLIT, ..., LOD_BACKFACE: the back-facing
// culls); record 0
// holds the initial patch count and, at LOD_RENDER_TOTAL, the render list's length. These, the
// patch structs and LOD_LOCAL come from the prelude (paramlod.core.layouts); LOD_GROUP, LOD_SLOTS
// (the work-group's layout, lod_step) and LOD_MAX_VIEWS from the host (paramlod/lod/stage.py), as
// are the measure's constants BOUNDARY_CAP, MIXED_MIN_PX, CURVE_MIN_PX, CURVE_MAX_PX, BOUNDARY_SHARE,
// CONE_LIPSCHITZ, CONE_EPS, SIL_GRAZE and SPOT_SUBS (lod_cl_defines, which the numpy twin reads).
#ifndef BOUNDARY_CAP
#error "build lod.cl with paramlod.lod.stage.lod_cl_defines()"
#endif

typedef struct {
    float2 s;      // screen position in pixels
    int state;     // 0: in front of the near plane, 1: behind it, 2: NaN/inf sample
    uint code;     // frustum outcode
} Sample;

#include "lod/spot.cl"

// A sample's world position (after the instance transform) from its position p, once per patch
// for every view; w is 1 for a NaN/inf position (bad in every view).
inline float4 lod_world(__global const float* I, float3 p) {
    if (is_bad3(p)) return (float4)(0.0f, 0.0f, 0.0f, 1.0f);
    return (float4)(xform_point(I + INST_MODEL, p), 0.0f);
}

// The sample at world position w seen by the camera record at cam.
inline Sample lod_project(__global const float* cam, float4 w) {
    Sample r;
    if (w.w != 0.0f) { r.s = (float2)(0.0f, 0.0f); r.state = 2; r.code = 63u; return r; }
    float3 e = xform_point(cam + CAM_VIEW, w.xyz);
    float4 c = project(cam, e);
    // a finite position can still overflow float32 on its way to clip space (a function returning
    // ~1e38): such a sample is bad like a NaN one, never a reason to split forever
    if (!(pl_finitef(c.x) && pl_finitef(c.y) && pl_finitef(c.z) && pl_finitef(c.w))) {
        r.s = (float2)(0.0f, 0.0f); r.state = 2; r.code = 63u; return r;
    }
    r.code = outcode(c);
    if (c.w >= cam[CAM_NEAR]) {
        r.state = 0;
        r.s = (float2)((c.x / c.w * 0.5f + 0.5f) * cam[CAM_W], (0.5f - c.y / c.w * 0.5f) * cam[CAM_H]);
    } else {
        r.state = 1;
        r.s = (float2)(0.0f, 0.0f);
    }
    return r;
}

// Screen length of one polyline segment: NaN samples add nothing; a segment touching the space
// behind the near plane is unmeasurable and counts as infinitely long (the patch must split).
inline float seg_len(Sample a, Sample b) {
    if (a.state == 2 || b.state == 2) return 0.0f;
    if (a.state == 1 || b.state == 1) return INFINITY;
    return pl_length2(b.s - a.s);
}

inline void grow_box(float4* box, Sample s) {
    if (s.state != 0) return;
    box->x = pl_fminf(box->x, s.s.x); box->y = pl_fminf(box->y, s.s.y);
    box->z = pl_fmaxf(box->z, s.s.x); box->w = pl_fmaxf(box->w, s.s.y);
}

// How far beyond the measured lines a boundary's need may raise a patch's sample measure (the
// raise only corrects the extrapolation to the edge; a boundary needing more means the patch
// should have split, and the cap keeps one bad sample from costing a whole grid): BOUNDARY_CAP.
// A line with bad and good samples splits while its good segments are longer than MIXED_MIN_PX.
// Detail between the samples (twin: reference.line_turns): a measured line whose consecutive
// world-space segments turn by more than LodSettings.detail_angle (curve_cos: its cosine) does not
// resolve the surface along it (a thin SH lobe, a shell's nodule: the segments cut across it, and
// the measure and the tessellation level taken from them fall short: lobes drawn short, holes in
// the point grid). Such a line splits the patch across it as a long line does, while it is longer
// than CURVE_MIN_PX on screen (two pixels a segment) and the patch's longest line in its
// direction is shorter than CURVE_MAX_PX: past that the renderers take 4 or more samples or
// tessellation segments per measured segment (tess level = the line's length in pixels at the
// thesis's settings, points 1.5 a pixel), fine enough to follow what the 8 samples miss (at 1080p
// an order-12 HARDI field seen close up split 10x with the bounds at 7 px and none). A sphere's or
// torus' whole circle turns 51.4 degrees a segment and never splits for it; at 120 degrees the
// yarn curtain's loops do not split either, at 90 they split 3x at 1080p.
inline bool line_turns(__local const float4* w, uint first, float curve_cos) {
    bool turns = false;
    float3 a = w[first + 1u].xyz - w[first].xyz;
    for (uint j = 1u; j < 7u; ++j) {
        float3 b = w[first + j + 1u].xyz - w[first + j].xyz;
        bool good = w[first + j - 1u].w == 0.0f && w[first + j].w == 0.0f && w[first + j + 1u].w == 0.0f;
        turns = turns || (good && dot(a, b) < curve_cos * (length(a) * length(b)));
        a = b;
    }
    return turns;
}
// BOUNDARY_SHARE: the share of a boundary's need the raise asks for. The point renderer's default density (1.5
// samples per measured pixel, steps of 0.67 px) leaves a margin below the hole-free step of
// 1/sqrt(2) px; the boundary, measured at its end rather than estimated from segment averages,
// is held to that step exactly (sqrt(2) / 1.5), so the common small excess at an edge (a few %,
// nearly every patch of a sphere) costs no samples and only a real shortfall raises the grid.

// A line's speed at its end extrapolated linearly from its two segments nearest the end (a, then
// b; their midpoints lie half and one and a half segments from the end): exact for a speed that
// changes linearly, an overestimate at a speed maximum on the edge. Unmeasurable (inf or NaN) values give 0: a patch
// with an infinite segment already has an infinite measure. Two statements, so the compiler
// cannot fuse them into an fma the numpy twin would not reproduce.
inline float edge_extrapolate(float a, float b) {
    float t = 1.5f * a;
    float r = t - 0.5f * b;
    return pl_finitef(r) ? pl_fmaxf(r, 0.0f) : 0.0f;
}

// w = max(s, min(BOUNDARY_CAP * s, BOUNDARY_SHARE * need)), as the twin (paramlod/lod/reference.py).
inline float raise_measure(float s, float need) {
    float n = BOUNDARY_SHARE * need;
    return pl_fmaxf(s, pl_fminf(BOUNDARY_CAP * s, n));
}

inline void emit(__global EvalPatch* out, uint slot, uint cap, float u0, float u1, float v0, float v1, uint inst,
                 uint tier) {
    if (slot < cap) {
        EvalPatch c;
        c.range = (float4)(u0, u1, v0, v1);
        c.inst = inst; c.tier = tier; c.pad0 = c.pad1 = 0u;
        out[slot] = c;
    }
}

// --- Back-face culling (docs/lod.md "Back-face culling"; twin: reference.normal_cones, cone_back) ---
// INST_ONE_SIDED (the prelude; set by paramlod/lod/uploads.py): back faces of this instance may be
// culled (a one-sided material, or a closed surface whose df/du x df/dv points outwards).
// The partials are assumed to vary over the patch no faster than CONE_LIPSCHITZ x the largest
// difference between neighbouring nodes of the 5x5 grid shows (the one assumption of the bound).
// CONE_EPS: float32 rounding of the partials, the cross products and the trigonometry (not proven:
// a generous allowance, far above what float32 loses on a regular patch).
#define CONE_NODES 25

// Node k of the 5x5 grid over the patch widened by `widen` of its size per side and clamped to
// the domain, as the point renderer's sampling range (kernels/points/points.cl point_grid).
inline float2 cone_uv(uint k, float4 range, __global const float* I, float widen) {
    float4 r = sampled_range(range, I, widen);
    return (float2)(r.x + (r.y - r.x) * ((float)(k % 5u) * 0.25f), r.z + (r.w - r.z) * ((float)(k / 5u) * 0.25f));
}

// The normal cone and bounding sphere of one patch from its 25 nodes (world positions; world
// partials A df/du, A df/dv with A the instance's linear part; sgn: the sign of det A, so that
// sgn (A fu x A fv) points as the renderer's normal A^-T (fu x fv)). hu, hv: the node spacing in
// u and v. Writes cone = (axis, half-angle) and sphere = (centre, radius); a half-angle of 4
// (> pi/2) means no cone (a bad node, a degenerate normal, or a bound wider than the normal).
inline void normal_cone(__local const float4* np, __local const float4* pu, __local const float4* pv,
                        float sgn, float hu, float hv, __local float4* cone, __local float4* sphere) {
    float dup = 0.0f, dvp = 0.0f, duq = 0.0f, dvq = 0.0f, mp = 0.0f, mq = 0.0f;
    bool ok = true;
    for (uint k = 0; k < CONE_NODES; ++k) {
        float3 p = pu[k].xyz, q = pv[k].xyz;
        ok = ok && np[k].w == 0.0f && !is_bad3(p) && !is_bad3(q);
        mp = fmax(mp, length(p)); mq = fmax(mq, length(q));
        if (k % 5u < 4u) { dup = fmax(dup, length(pu[k + 1u].xyz - p)); duq = fmax(duq, length(pv[k + 1u].xyz - q)); }
        if (k < 20u) { dvp = fmax(dvp, length(pu[k + 5u].xyz - p)); dvq = fmax(dvq, length(pv[k + 5u].xyz - q)); }
    }
    // how far either partial can be from its value at the nearest node (at most half a spacing
    // away in u and in v)
    float ep = 0.5f * CONE_LIPSCHITZ * (dup + dvp), eq = 0.5f * CONE_LIPSCHITZ * (duq + dvq);
    float3 a = sgn * cross(pu[12].xyz, pv[12].xyz);
    float ha = 0.0f, r = 0.0f;
    float3 c = np[12].xyz;
    for (uint k = 0; k < CONE_NODES && ok; ++k) {
        float3 p = pu[k].xyz, q = pv[k].xyz;
        float3 n = sgn * cross(p, q);
        float ln = length(n);
        // |n(x) - n_k| <= ep |q| + |p| eq + ep eq for every x the node is nearest to
        float e = ep * length(q) + length(p) * eq + ep * eq;
        ok = e < ln;
        ha = fmax(ha, atan2(length(cross(a, n)), dot(a, n)) + asin(fmin(e / ln, 1.0f)));
        r = fmax(r, length(np[k].xyz - c));
    }
    // a point is within half a spacing of a node in u and in v, and |df/du| <= mp + ep there
    r += (mp + ep) * (0.5f * hu) + (mq + eq) * (0.5f * hv);
    ok = ok && isfinite(ha) && isfinite(r) && isfinite(c.x) && isfinite(c.y) && isfinite(c.z);
    *cone = (float4)(a, ok ? ha + CONE_EPS : 4.0f);
    *sphere = (float4)(c, r * (1.0f + CONE_EPS));
}

// Whether every normal of the cone faces away from the camera at every point of the sphere
// (the view matrix a rotation and translation, as the renderers assume when they turn normals with it).
// Perspective: the angle between a normal and the eye-to-point direction is at most the axis'
// angle to the centre + the half-angle + the sphere's angular radius; back-facing when < pi/2.
// Orthographic: every point is seen along -z.
inline bool cone_back(__global const float* cam, float4 cone, float4 sphere) {
    if (!(cone.w < M_PI_2_F)) return false;
    __global const float* V = cam + CAM_VIEW;
    float3 a = xform_dir(V, cone.xyz);
    float ang;
    if (cam[CAM_PROJ + 15] != 0.0f) {
        ang = atan2(length(a.xy), -a.z);
    } else {
        float3 c = xform_point(V, sphere.xyz);
        float d = length(c);
        if (!(d > sphere.w)) return false;
        ang = atan2(length(cross(a, c)), dot(a, c)) + asin(sphere.w / d);
    }
    return ang + cone.w < M_PI_2_F;
}

// Whether lines k, k + 1 of one direction (lengths e, mixed flags m) split their half of the patch.
inline bool split_half(const float* e, const bool* m, uint k, float t) {
    return e[k] > t || e[k + 1u] > t || m[k] || m[k + 1u];
}

inline bool splits(const float* eu, const float* ev, const bool* mixed, float t_u, float t_v) {
    return split_half(eu, mixed, 0u, t_u) || split_half(eu, mixed, 2u, t_u)
        || split_half(ev, mixed + 4, 0u, t_v) || split_half(ev, mixed + 4, 2u, t_v);
}

// The decision for one measured patch: cull, render (or force out on the last step), or split
// into 2, 3 or 4 children by the 7 patterns. seen: the views that see the patch (bit v: view v;
// none: culled), written beside the render patch (render_views) so that the renderers skip the
// views it is outside of; the measures are the
// maxima over the views that see it: eu, ev: the four u- and v-polyline lengths; mixed: the 8
// lines (u then v) that have both bad and good samples (in some view), split like a long line;
// mu_seg, mv_seg: their longest segments; w_u, w_v: 7 x those raised to the boundary lines' need;
// box: the union of those views' screen bounding boxes. The step's statistics go to the work-group's
// tally (added to the counters once, at the end of lod_step); the counts that hand out places in
// the output (LOD_CHILDREN, the render list's length) stay atomics on the counters.
inline void lod_decide(EvalPatch patch, const float* eu, const float* ev, const bool* mixed,
                       float mu_seg, float mv_seg, float w_u, float w_v, float4 box, ulong seen, bool back,
                       __global EvalPatch* out, uint out_cap,
                       __global RenderPatch* render, __global ulong* render_views, uint render_cap,
                       __global uint* counters, __global uint* render_count, uint* tally,
                       float t_u, float t_v, uint step, uint force, bool promote)
{
    uint inst = patch.inst;
    float u0 = patch.range.x, u1 = patch.range.y, v0 = patch.range.z, v1 = patch.range.w;
    if (seen == 0ul) { ++tally[LOD_CULLED]; return; }  // in every view all samples outside one clip plane
    // back-facing in every view that sees it (one-sided instances only): culled, counted as such too
    if (back) { ++tally[LOD_CULLED]; ++tally[LOD_BACKFACE]; return; }

    bool a = split_half(eu, mixed, 0u, t_u);       // u-lines in the lower v half
    bool b = split_half(eu, mixed, 2u, t_u);       // u-lines in the upper v half
    bool c = split_half(ev, mixed + 4, 0u, t_v);   // v-lines in the left u half
    bool d = split_half(ev, mixed + 4, 2u, t_v);   // v-lines in the right u half
    bool split = a || b || c || d;

    if (promote) {   // a silhouette or sub-pixel detail (lod/spot.cl): measured again at the next tier
        ++tally[LOD_PROMOTED];
        uint s = atomic_add(&counters[LOD_CHILDREN], 1u);
        emit(out, s, out_cap, u0, u1, v0, v1, inst, patch.tier + 1u);
        return;
    }
    if (!split || force) {
        uint slot = atomic_inc(render_count);
        if (slot < render_cap) {
            RenderPatch r;
            r.range = patch.range;
            r.bbox = box;
            r.ext = (float4)(fmax(fmax(eu[0], eu[1]), fmax(eu[2], eu[3])),
                             fmax(fmax(ev[0], ev[1]), fmax(ev[2], ev[3])),
                             7.0f * mu_seg, 7.0f * mv_seg);
            r.inst = inst;
            r.flags = step | (split ? FLAG_FORCED : 0u) | (patch.tier << TIER_SHIFT);
            r.w = (float2)(w_u, w_v);
            render[slot] = r;
            render_views[slot] = seen;
        }
        ++tally[LOD_RENDERED];
        if (split) ++tally[LOD_FORCED];
        if (patch.tier == 1u) ++tally[LOD_TIER1];
        if (patch.tier == 2u) ++tally[LOD_TIER2];
        return;
    }

    ++tally[LOD_SPLIT];
    float mu = 0.5f * (u0 + u1), mv = 0.5f * (v0 + v1);
    if ((a || b) && (c || d)) {                 // 1:4
        uint s = atomic_add(&counters[LOD_CHILDREN], 4u);
        emit(out, s + 0, out_cap, u0, mu, v0, mv, inst, patch.tier);
        emit(out, s + 1, out_cap, mu, u1, v0, mv, inst, patch.tier);
        emit(out, s + 2, out_cap, u0, mu, mv, v1, inst, patch.tier);
        emit(out, s + 3, out_cap, mu, u1, mv, v1, inst, patch.tier);
    } else if (a && b) {                        // 1:2, cut u
        uint s = atomic_add(&counters[LOD_CHILDREN], 2u);
        emit(out, s + 0, out_cap, u0, mu, v0, v1, inst, patch.tier);
        emit(out, s + 1, out_cap, mu, u1, v0, v1, inst, patch.tier);
    } else if (c && d) {                        // 1:2, cut v
        uint s = atomic_add(&counters[LOD_CHILDREN], 2u);
        emit(out, s + 0, out_cap, u0, u1, v0, mv, inst, patch.tier);
        emit(out, s + 1, out_cap, u0, u1, mv, v1, inst, patch.tier);
    } else if (a) {                             // 1:3, lower v half cut in u
        uint s = atomic_add(&counters[LOD_CHILDREN], 3u);
        emit(out, s + 0, out_cap, u0, mu, v0, mv, inst, patch.tier);
        emit(out, s + 1, out_cap, mu, u1, v0, mv, inst, patch.tier);
        emit(out, s + 2, out_cap, u0, u1, mv, v1, inst, patch.tier);
    } else if (b) {                             // 1:3, upper v half cut in u
        uint s = atomic_add(&counters[LOD_CHILDREN], 3u);
        emit(out, s + 0, out_cap, u0, u1, v0, mv, inst, patch.tier);
        emit(out, s + 1, out_cap, u0, mu, mv, v1, inst, patch.tier);
        emit(out, s + 2, out_cap, mu, u1, mv, v1, inst, patch.tier);
    } else if (c) {                             // 1:3, left u half cut in v
        uint s = atomic_add(&counters[LOD_CHILDREN], 3u);
        emit(out, s + 0, out_cap, u0, mu, v0, mv, inst, patch.tier);
        emit(out, s + 1, out_cap, u0, mu, mv, v1, inst, patch.tier);
        emit(out, s + 2, out_cap, mu, u1, v0, v1, inst, patch.tier);
    } else {                                    // 1:3, right u half cut in v
        uint s = atomic_add(&counters[LOD_CHILDREN], 3u);
        emit(out, s + 0, out_cap, u0, mu, v0, v1, inst, patch.tier);
        emit(out, s + 1, out_cap, mu, u1, v0, mv, inst, patch.tier);
        emit(out, s + 2, out_cap, mu, u1, mv, v1, inst, patch.tier);
    }
}

// Where sample s of a patch lies (s < LOD_SAMPLES): 0..31 the four u-lines (8 samples each, at
// v = 1/8, 3/8, 5/8, 7/8 of the range), 32..63 the four v-lines, 64..88 the 5x5 extra grid.
#define LOD_SAMPLES 89
#ifndef LOD_RUN   // set by the host on CPU devices (paramlod/lod/stage.py SAMPLE_RUNS_CPU)
#define LOD_RUN 0
#endif
#define LOD_RUN_LENGTH ((LOD_SAMPLES + LOD_GROUP - 1) / LOD_GROUP)
inline float2 lod_uv(uint s, float u0, float v0, float du, float dv) {
    if (s < 64u) {
        uint k = (s & 31u) >> 3, i = s & 7u;
        float fk = ((float)k + 0.5f) * 0.25f;
        float fi = (float)i * (1.0f / 7.0f);
        if (s < 32u) return (float2)(i == 0u ? u0 : u0 + du * fi, v0 + dv * fk);
        return (float2)(u0 + du * fk, i == 0u ? v0 : v0 + dv * fi);
    }
    uint e = s - 64u;
    return (float2)(u0 + du * ((float)(e % 5u) * 0.25f), v0 + dv * ((float)(e / 5u) * 0.25f));
}

// LOD_RUN (CPU devices): a work-item evaluates a run of consecutive samples in this order, which
// puts the samples that share the position split's parameter (pl_position_split) next to each
// other, so that parameter's steps are evaluated once for them: along u, the u-lines' samples by
// index, then the v-lines, then the 5x5 grid by column; along v, the u-lines, the v-lines'
// samples by index, the grid by row. Returns the sample at place j.
inline uint lod_order(uint split, uint j) {
    if (split == PL_SPLIT_U && j < 32u) return (j & 3u) * 8u + (j >> 2);
    if (split == PL_SPLIT_V && j >= 32u && j < 64u) return 32u + ((j - 32u) & 3u) * 8u + ((j - 32u) >> 2);
    if (split == PL_SPLIT_U && j >= 64u) return 64u + ((j - 64u) % 5u) * 5u + (j - 64u) / 5u;
    return j;
}

// GPUs (not LOD_RUN): the work-items share the split's steps through local memory instead. The 89
// samples take 17 values of the split's parameter (8 along its lines, 4 of the lines across, 5 of
// the grid): LOD_AXES work-items evaluate one each, then every sample evaluates the rest.
// lod_axis: the value a sample takes; lod_axis_sample: a sample that takes value a (its
// parameter from lod_uv, so the same float as the sample's, and the positions pl_position's).
#define LOD_AXES 17
inline uint lod_axis(uint split, uint s) {
    if (s >= 64u) return 12u + (split == PL_SPLIT_U ? (s - 64u) % 5u : (s - 64u) / 5u);
    bool along = (s < 32u) == (split == PL_SPLIT_U);   // a line along the split's parameter
    return along ? (s & 7u) : 8u + ((s & 31u) >> 3);
}

inline uint lod_axis_sample(uint split, uint a) {
    uint along = split == PL_SPLIT_U ? 0u : 32u, across = 32u - along;
    if (a < 8u) return along + a;
    if (a < 12u) return across + (a - 8u) * 8u;
    return 64u + (split == PL_SPLIT_U ? a - 12u : (a - 12u) * 5u);
}

inline Sample lod_at(__local const float2* pos, __local const uchar* state, uint s) {
    Sample q;
    q.s = pos[s]; q.state = state[s]; q.code = 0u;
    return q;
}

// A screen coordinate as an int that orders like the float (for local atomic_min / max; screen
// coordinates are never NaN).
inline int box_key(float f) {
    int i = as_int(f);
    return i >= 0 ? i : i ^ 0x7fffffff;
}

inline float box_float(int k) {
    return as_float(k >= 0 ? k : k ^ 0x7fffffff);
}

// The measures over the views that see the patch (local, reduced with atomics): 0..7 each line's
// length, 8, 9 the longest u- and v-segment, 10, 11 w_u, w_v (float bits: maxima of floats >= 0 are
// maxima of their bits, and one view's own value), 12 the mixed lines (bit k: line k), 13..16 the
// screen box (box_key: min x, min y, max x, max y), 17, 18 the views that see the patch (bit v of
// their 64: view v), 19 set when some view that sees the patch may see its front (back-face test),
// 20 the lines that turn (line_turns; bit k: line k).
#define COMB 21

// One LOD step: a work-group of LOD_GROUP work-items measures one patch at a time (a patch's
// samples are the expensive part, and a step with a few hundred patches would leave most of a GPU
// idle with one work-item per patch). The number of input patches is read on the device (the
// previous step's child count), so the host enqueues all steps without waiting and reads the
// counters once per frame; work-groups stride over the patches. A step whose input overflowed its
// buffer only sees the first `cap` patches: the host detects that afterwards and redoes the stage.
//
// Views: cam holds n_views camera records (CAM_FLOATS each, at most LOD_MAX_VIEWS). Per patch the
// work-items evaluate f at the 89 samples, once each, and keep the world positions; then the views
// are taken LOD_SLOTS at a time (a chunk): work-item l projects the samples l / LOD_SLOTS,
// + LOD_GROUP / LOD_SLOTS, ... into view slot l % LOD_SLOTS and keeps the screen positions; the
// outcode AND and screen box of each slot are reduced over its work-items; then one work-item per
// line and slot (8 lines, the 5x5 grid's 4 edges) measures it as the single-view step does, for the
// slots whose view sees the patch, and adds it to the measures over the views (atomic max). Once
// every chunk is done, w_u, w_v of each view that sees the patch go in, and work-item 0 decides.
// The host picks LOD_GROUP and LOD_SLOTS for the number of views (paramlod/lod/stage.py: more
// views, more work-items, 32 a slot on GPUs, up to (256, 8): a step's few patches make its time
// one patch's, so the work-items a view has stay those one view has; one a slot on CPU devices,
// where PoCL runs each barrier as a loop over the work-items); with one view, (32, 1), this is
// the single-view step bit for bit (the same operations in the same order, a maximum over one
// view), and so is (1, 1): every loop over the work-items strides by LOD_GROUP. Local memory:
// 4.3 KB at (32, 1), 14.4 KB at (256, 8) for up to 64 views; on GPUs 68 bytes more for each float
// the split carries (axis_c: 2.2 KB for the glyphs' 32).
// Compiled per kind of stage (paramlod/lod/stage.py LodStage._kernels): LOD_BACK_TEST 0 leaves the
// back-face test out (no instance is one-sided, or culling is off), LOD_TIER_CHECKS 0 the hybrid
// tiers' checks (no hybrid frame). Code a stage never runs still costs the GPU: with both in, the
// H100's LOD stage took 1.44x as long on the fibre curtain (docs/lod.md).
#ifndef LOD_BACK_TEST
#define LOD_BACK_TEST 1
#endif
#ifndef LOD_TIER_CHECKS
#define LOD_TIER_CHECKS 1
#endif
__kernel __attribute__((reqd_work_group_size(LOD_GROUP, 1, 1)))
void lod_step(__global const EvalPatch* in, __global EvalPatch* out, uint cap,
              __global RenderPatch* render, __global ulong* render_views, uint render_cap,
              __global uint* counters,   // per step: LOD_COUNTERS uints; see paramlod/lod/stage.py
              __global const float* inst_f, __global const uint* inst_u,
              __global const float* params, __global const float* cam, uint n_views,
              float t_u, float t_v, uint step, uint force,
              uint backface, float widen,   // back-face culling on; the sampling range's widening
              float curve_cos,   // cos of LodSettings.detail_angle (line_turns)
              // hybrid tiers (max_tier 0: off): tiers 1, 2's thresholds (t_u, t_v each) and pixel
              // divisors, the spot check's cosine and count (lod/spot.cl)
              uint max_tier, float4 tier_t, float2 tier_scale, float spot_cos, uint spot_min,
              uint silhouettes)   // hybrid: patches with a silhouette go from tier 0 to tier 1
{
    __local float4 wpos[LOD_SAMPLES];                      // world position; w: 1 for a bad sample
#if !LOD_RUN
    __local float axis_c[LOD_AXES * PL_SPLIT_FLOATS];      // the split's carried values (lod_axis)
#endif
    __local float2 pos[LOD_SLOTS * LOD_SAMPLES];           // screen positions of a chunk's views
    __local uchar state[LOD_SLOTS * LOD_SAMPLES];          // Sample.state
    __local float4 box_part[LOD_GROUP];
    __local uint code_part[LOD_GROUP];
    // per view: the u- and v-lines' longest segment and boundary need (float bits), whether it sees
    // the patch
    __local uint vseg[LOD_MAX_VIEWS * 2];
    __local uint vneed[LOD_MAX_VIEWS * 2];
    __local uint vseen[LOD_MAX_VIEWS];
    // two sets, one per patch parity: work-item 0 still reads one when the others clear the next
    __local uint comb_sets[2 * COMB];
    // back-face culling: the 25 nodes' world positions and partials, the cone and sphere
    // (one element where the stage is compiled without them: local memory bounds the work-groups
    // a compute unit holds, and a single-view step's 32 work-items hold little else)
    __local float4 cnode[LOD_BACK_TEST ? 3 * CONE_NODES : 1];
    __local float4 cone[2];
    __local float4 spot_n[LOD_TIER_CHECKS ? SPOT_CORNERS : 1];   // the spot check's corner normals
    __local uint spot_count;
    uint tally[LOD_COUNTERS] = {0u};   // work-item 0's: the group's statistics (lod_decide)
    uint n_in = min(counters[(step - 1) * LOD_COUNTERS + LOD_CHILDREN], cap);
    __global uint* c = counters + step * LOD_COUNTERS;
    __global uint* render_count = counters + LOD_RENDER_TOTAL;
    uint l = get_local_id(0);
    uint slot = l % LOD_SLOTS;
    __local uint* comb = comb_sets;
    for (uint i = get_group_id(0); i < n_in; i += get_num_groups(0)) {
        comb = comb_sets + COMB - (comb - comb_sets);   // the other set
        EvalPatch patch = in[i];
        uint inst = patch.inst;
        __global const float* I = inst_f + inst * INST_F;
        uint func = inst_u[inst * INST_U + INST_FUNC];
        __global const float* P = params + inst_u[inst * INST_U + INST_PARAMS];
        float u0 = patch.range.x, v0 = patch.range.z;
        float du = patch.range.y - u0, dv = patch.range.w - v0;
#if LOD_RUN
        {   // a run of samples a work-item (lod_order), the split's steps once for those sharing them:
            // the positions pl_position gives, bit for bit
            uint split = pl_position_split(func);
            float C[PL_SPLIT_FLOATS];
            float carried_at = NAN;   // never equal: the first sample evaluates the steps
            uint first = l * LOD_RUN_LENGTH, end = min(first + LOD_RUN_LENGTH, (uint)LOD_SAMPLES);
            for (uint j = first; j < end; ++j) {
                uint s = lod_order(split, j);
                float2 uv = lod_uv(s, u0, v0, du, dv);
                float3 p;
                if (split) {
                    float at = split == PL_SPLIT_U ? uv.x : uv.y;
                    if (at != carried_at) { pl_position_axis(func, at, P, C); carried_at = at; }
                    p = pl_position_rest(func, uv.x, uv.y, P, C);
                } else {
                    p = pl_position(func, uv.x, uv.y, P);
                }
                wpos[s] = lod_world(I, p);
            }
        }
#else
        uint split = pl_position_split(func);   // the group's: one patch, so the barrier is uniform
        if (split) {
            for (uint a = l; a < LOD_AXES; a += LOD_GROUP) {
                float2 uv = lod_uv(lod_axis_sample(split, a), u0, v0, du, dv);
                float C[PL_SPLIT_FLOATS];
                pl_position_axis(func, split == PL_SPLIT_U ? uv.x : uv.y, P, C);
                for (uint k = 0; k < PL_SPLIT_FLOATS; ++k) axis_c[a * PL_SPLIT_FLOATS + k] = C[k];
            }
            barrier(CLK_LOCAL_MEM_FENCE);
            for (uint s = l; s < LOD_SAMPLES; s += LOD_GROUP) {
                float2 uv = lod_uv(s, u0, v0, du, dv);
                float C[PL_SPLIT_FLOATS];
                __local const float* c = axis_c + lod_axis(split, s) * PL_SPLIT_FLOATS;
                for (uint k = 0; k < PL_SPLIT_FLOATS; ++k) C[k] = c[k];
                wpos[s] = lod_world(I, pl_position_rest(func, uv.x, uv.y, P, C));
            }
        } else {
            for (uint s = l; s < LOD_SAMPLES; s += LOD_GROUP) {
                float2 uv = lod_uv(s, u0, v0, du, dv);
                wpos[s] = lod_world(I, pl_position(func, uv.x, uv.y, P));
            }
        }
#endif
        // the same for every work-item of the group (one patch), so barriers stay uniform
        bool one_sided = LOD_BACK_TEST && backface != 0u && (inst_u[inst * INST_U + INST_FLAGS] & INST_ONE_SIDED) != 0u;
        if (one_sided) {
            for (uint k = l; k < CONE_NODES; k += LOD_GROUP) {
                float2 uv = cone_uv(k, patch.range, I, widen);
                float3 p, fu, fv;
                pl_surface(func, uv.x, uv.y, P, &p, &fu, &fv);
                cnode[k] = is_bad3(p) ? (float4)(0.0f, 0.0f, 0.0f, 1.0f) : (float4)(xform_point(I + INST_MODEL, p), 0.0f);
                cnode[CONE_NODES + k] = (float4)(xform_dir(I + INST_MODEL, fu), 0.0f);
                cnode[2 * CONE_NODES + k] = (float4)(xform_dir(I + INST_MODEL, fv), 0.0f);
            }
        }
#if LOD_GROUP >= COMB   // GPUs: a work-item each
        if (l < COMB) comb[l] = l == 13u || l == 14u ? (uint)box_key(INFINITY)
                              : l == 15u || l == 16u ? (uint)box_key(-INFINITY) : 0u;
#else   // CPU devices' smaller groups
        for (uint k = l; k < COMB; k += LOD_GROUP)
            comb[k] = k == 13u || k == 14u ? (uint)box_key(INFINITY) : k == 15u || k == 16u ? (uint)box_key(-INFINITY) : 0u;
#endif
        for (uint v = l; v < n_views; v += LOD_GROUP) vseg[2u * v] = vseg[2u * v + 1u] = vneed[2u * v] = vneed[2u * v + 1u] = 0u;
        barrier(CLK_LOCAL_MEM_FENCE);
        if (one_sided && l == 0u) {   // read after the chunks' barriers
            __global const float* M = I + INST_MODEL;
            float det = M[0] * (M[5] * M[10] - M[6] * M[9]) - M[1] * (M[4] * M[10] - M[6] * M[8])
                      + M[2] * (M[4] * M[9] - M[5] * M[8]);
            float2 uv0 = cone_uv(0u, patch.range, I, widen), uv1 = cone_uv(24u, patch.range, I, widen);
            normal_cone(cnode, cnode + CONE_NODES, cnode + 2 * CONE_NODES, det < 0.0f ? -1.0f : 1.0f,
                        0.25f * (uv1.x - uv0.x), 0.25f * (uv1.y - uv0.y), &cone[0], &cone[1]);
        }
        for (uint c0 = 0; c0 < n_views; c0 += LOD_SLOTS) {
            uint nc = min((uint)LOD_SLOTS, n_views - c0);
            float4 box = (float4)(INFINITY, INFINITY, -INFINITY, -INFINITY);
            uint code = 63u;
            if (slot < nc) {
                __global const float* cv = cam + (c0 + slot) * CAM_FLOATS;
                for (uint s = l / LOD_SLOTS; s < LOD_SAMPLES; s += LOD_GROUP / LOD_SLOTS) {
                    Sample q = lod_project(cv, wpos[s]);
                    pos[slot * LOD_SAMPLES + s] = q.s; state[slot * LOD_SAMPLES + s] = (uchar)q.state;
                    code &= q.code; grow_box(&box, q);
                }
            }
            box_part[l] = box; code_part[l] = code;
            barrier(CLK_LOCAL_MEM_FENCE);
            for (uint h = LOD_GROUP / 2; h >= LOD_SLOTS; h >>= 1) {   // box and outcode over each slot's work-items
                if (l < h) {
                    float4 o = box_part[l + h], m = box_part[l];
                    box_part[l] = (float4)(fmin(m.x, o.x), fmin(m.y, o.y), fmax(m.z, o.z), fmax(m.w, o.w));
                    code_part[l] &= code_part[l + h];
                }
                barrier(CLK_LOCAL_MEM_FENCE);
            }
            // box_part, code_part [0, nc): the chunk's views'. One work-item per line (or edge) and
            // view seeing the patch; line-major, so the work-items of a round mostly run one kind.
            for (uint t = l; t < 12u * nc; t += LOD_GROUP) {
                uint k = t / nc, q = t - k * nc, v = c0 + q;
                if (code_part[q] != 0u) continue;
                __local const float2* sp = pos + q * LOD_SAMPLES;
                __local const uchar* st = state + q * LOD_SAMPLES;
                if (k < 8u) {   // line k: 0..3 along u, 4..7 along v; segments summed in order (as the numpy twin)
                    float seg[7];
                    uint n_bad = st[k * 8u] == 2 ? 1u : 0u;
                    for (uint j = 1; j < 8u; ++j) {
                        seg[j - 1u] = seg_len(lod_at(sp, st, k * 8u + j - 1u), lod_at(sp, st, k * 8u + j));
                        n_bad += st[k * 8u + j] == 2 ? 1u : 0u;
                    }
                    float sum = 0.0f, longest = 0.0f;
                    for (uint j = 0; j < 7u; ++j) { sum += seg[j]; longest = pl_fmaxf(longest, seg[j]); }
                    atomic_max(&comb[k], as_uint(sum));
                    // ... while its good part is longer than a pixel: past that, the undefined rest of the
                    // line beside it is sub-pixel too (a finite edge, as a dome's rim, stops splitting there)
                    if (n_bad > 0u && n_bad < 8u && sum > MIXED_MIN_PX) atomic_or(&comb[12], 1u << k);
                    if (sum > CURVE_MIN_PX && line_turns(wpos, k * 8u, curve_cos)) atomic_or(&comb[20], 1u << k);
                    // the line's speed at its two ends (on the patch's edges across it), from its first and
                    // last two segments: 7 segments span the line, so 7 x a segment is a whole-line measure
                    float need = 7.0f * fmax(edge_extrapolate(seg[0], seg[1]), edge_extrapolate(seg[6], seg[5]));
                    atomic_max(&vseg[2u * v + (k >> 2)], as_uint(longest));
                    atomic_max(&vneed[2u * v + (k >> 2)], as_uint(need));
                } else {
                    // the 5x5 grid's four edges (v = v0, v = v1 along u; u = u0, u = u1 along v):
                    // 4 x the longest of each edge's 4 chords, a whole-line measure of the edge itself
                    uint e = k - 8u;
                    uint first = 64u + (e == 0u ? 0u : e == 1u ? 20u : e == 2u ? 0u : 4u);
                    uint stride = e < 2u ? 1u : 5u;
                    float longest = 0.0f;
                    for (uint j = 0; j < 4u; ++j) {
                        uint at = first + j * stride;
                        longest = pl_fmaxf(longest, seg_len(lod_at(sp, st, at), lod_at(sp, st, at + stride)));
                    }
                    atomic_max(&vneed[2u * v + (e >> 1)], as_uint(4.0f * longest));
                }
            }
            if (l < nc) {
                vseen[c0 + l] = code_part[l] == 0u;
                if (code_part[l] == 0u) {   // the union of the boxes of the views that see the patch
                    float4 b = box_part[l];
                    atomic_min((__local int*)&comb[13], box_key(b.x)); atomic_min((__local int*)&comb[14], box_key(b.y));
                    atomic_max((__local int*)&comb[15], box_key(b.z)); atomic_max((__local int*)&comb[16], box_key(b.w));
                    atomic_or(&comb[17u + ((c0 + l) >> 5)], 1u << ((c0 + l) & 31u));
                }
            }
            barrier(CLK_LOCAL_MEM_FENCE);   // the next chunk overwrites pos, state and the parts
        }
        for (uint v = l; v < n_views; v += LOD_GROUP) {
            if (!vseen[v]) continue;
            // what the boundary lines need along u: the u-lines' speeds at u0 and u1 (across those
            // edges) and the chords of the edges v = v0, v1 (along them); along v the same with the
            // v-lines and the edges u = u0, u1. (Extrapolating the u-lines' measure to v0 and v1
            // as well added samples, 1-6 %, and closed no hole the chords left.)
            for (uint d = 0; d < 2u; ++d) {
                float longest = as_float(vseg[2u * v + d]);
                atomic_max(&comb[8u + d], as_uint(longest));
                atomic_max(&comb[10u + d], as_uint(raise_measure(7.0f * longest, as_float(vneed[2u * v + d]))));
            }
            if (one_sided && !cone_back(cam + v * CAM_FLOATS, cone[0], cone[1])) atomic_or(&comb[19], 1u);
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        // every work-item reads the measures (the spot check's branch must be the group's)
        float eu[4], ev[4];
        bool mixed[8];
        for (uint k = 0; k < 4u; ++k) { eu[k] = as_float(comb[k]); ev[k] = as_float(comb[4u + k]); }
        float most_u = fmax(fmax(eu[0], eu[1]), fmax(eu[2], eu[3]));
        float most_v = fmax(fmax(ev[0], ev[1]), fmax(ev[2], ev[3]));
        for (uint k = 0; k < 8u; ++k)
            mixed[k] = ((comb[12] >> k) & 1u) || (((comb[20] >> k) & 1u) && (k < 4u ? most_u : most_v) < CURVE_MAX_PX);
        ulong seen = (ulong)comb[17] | ((ulong)comb[18] << 32);
        bool back = one_sided && comb[19] == 0u;
        // the patch's tier's thresholds (tier 0: t_u, t_v; hybrid tiers 1, 2: tier_t)
        uint tier = patch.tier;
        float tu = tier == 0u ? t_u : tier == 1u ? tier_t.x : tier_t.z;
        float tv = tier == 0u ? t_v : tier == 1u ? tier_t.y : tier_t.w;
        // about to be rendered at a tier that has a finer one: a silhouette in a view that sees it
        // (tier 0 only) or the spot check (lod/spot.cl) sends it on
        bool candidate = LOD_TIER_CHECKS && tier < max_tier && !force && seen != 0ul && !back
                         && !splits(eu, ev, mixed, tu, tv);
        bool promote = false;
        if (candidate && tier == 0u && silhouettes != 0u)
            for (uint v = 0; v < n_views && !promote; ++v)
                promote = vseen[v] && grid_silhouette(wpos + 64, cam + v * CAM_FLOATS);
        if (candidate && !promote) {
            float scale = tier == 0u ? 1.0f : tier_scale.x;
            float cu = spot_cell(patch.range.y - patch.range.x, most_u, scale, 7.0f);
            float cv = spot_cell(patch.range.w - patch.range.z, most_v, scale, 3.0f);
#if LOD_GROUP == 1   // CPU devices: a cell's corners only when its sub-samples are reached
            uint mine = 0u;
            for (uint cell = 0u; cell < SPOT_SUBS / 9u && mine < spot_min; ++cell) {
                for (uint k = 4u * cell; k < 4u * cell + 4u; ++k)
                    spot_n[k] = spot_corner_normal(func, P, I, patch.range, cu, cv, k);
                for (uint k = 9u * cell; k < 9u * cell + 9u && mine < spot_min; ++k)
                    mine += spot_turns(func, P, I, patch.range, cu, cv, spot_n, k, spot_cos) ? 1u : 0u;
            }
            spot_count = mine;
#else
            if (l == 0u) spot_count = 0u;
            for (uint k = l; k < SPOT_CORNERS; k += LOD_GROUP)
                spot_n[k] = spot_corner_normal(func, P, I, patch.range, cu, cv, k);
            barrier(CLK_LOCAL_MEM_FENCE);
            // a work-item stops once its own count decides the patch (the group's is at least its
            // own); the decision, all the stage keeps of the count, is the same
            uint mine = 0u;
            for (uint k = l; k < SPOT_SUBS && mine < spot_min; k += LOD_GROUP)
                mine += spot_turns(func, P, I, patch.range, cu, cv, spot_n, k, spot_cos) ? 1u : 0u;
            if (mine) atomic_add(&spot_count, mine);
            barrier(CLK_LOCAL_MEM_FENCE);
#endif
            promote = spot_count >= spot_min;
        }
        if (l == 0u) {
            float4 box = (float4)(box_float((int)comb[13]), box_float((int)comb[14]),
                                  box_float((int)comb[15]), box_float((int)comb[16]));
            lod_decide(patch, eu, ev, mixed, as_float(comb[8]), as_float(comb[9]),
                       as_float(comb[10]), as_float(comb[11]), box, seen,
                       back, out, cap, render, render_views, render_cap, c, render_count, tally, tu, tv, step, force,
                       promote);
        }
        // no barrier here: the next patch clears the other set of comb
    }
    // one atomic per statistic and work-group, not one per patch: a step of the fibre curtain
    // renders 342,000 patches, and same-address atomics serialize
    if (l == 0u)
        for (uint k = 0; k < LOD_COUNTERS; ++k)
            if (tally[k]) atomic_add(&c[k], tally[k]);
}
