// Tessellation control stage: one invocation per render patch sets its tessellation levels
// (docs/tessellation.md).
//   fixed:    inner = u_level.x on both axes, outer = u_level.y on all four edges
//   adaptive: l = clamp(e * L / min(t, L), l_min, l_max) (thesis 5.5.2), with
//             inner 0 (along u) from the LOD stage's e_u, inner 1 (along v) from e_v (or from
//             s_u, s_v where larger: TessSettings.inner_measure "segment"), and each
//             outer level from the screen length of that edge itself, measured here from 8
//             samples of the edge. Two patches that share an edge measure it from the same
//             parameters, so they compute the same outer level and their vertices on it coincide.
//             Multi-view geometry-stage passes (PL_VIEWS): each outer level is the largest any
//             view that sees the edge needs (the inner levels come from the LOD stage's
//             extents, already the largest over the views).
//   chord:    (single view) each outer level from how far that edge's 8 samples bend on the
//             screen (the largest second difference |s[i-1] - 2 s[i] + s[i+1]|): enough equal
//             segments that their chords stray at most u_chord pixels from the edge (a chord of
//             step h strays about h^2 |c''| / 8); each inner level from the same measure over
//             the 6 parameter lines between the two edges across it, and at least their levels.
//             kernels/tess/grid.cl computes the same levels for the grid tessellator.
// The parameter range handed to the evaluation stage is widened by u_overlap of its size per
// side (clamped to the function's domain) so that T-junctions between patches of different size
// are covered. A hybrid tier whose targets are carried into a finer tier's is widened by
// u_overlap_px output pixels as well, from the patch's measured extents: its coverage is copied
// per pixel (noAA) or per sample index (8xMS) to samples up to a pixel away, so without it a
// pixel on its seam with a finer tier's patch kept samples neither covers.
layout(vertices = 1) out;

in vec4 vs_range[];
in vec4 vs_ext[];
flat in uint vs_inst[];

patch out vec4 tc_range;     // widened parameter range
patch out vec4 tc_core;      // the patch's own range (for pole normals)
patch out uint tc_inst;

uniform vec2 u_threshold;    // effective LOD thresholds t_u, t_v in output pixels
uniform vec2 u_level;        // fixed: (inner, outer); adaptive: base level L for (inner, outer)
uniform vec2 u_clamp;        // l_min, l_max
uniform int u_adaptive;     // 0 fixed, 1 adaptive, 2 chord
uniform float u_chord;       // chord: the most a chord may stray from the surface, pixels
uniform int u_inner_segment; // adaptive: inner levels from s_u, s_v where larger (TessSettings.inner_measure)
uniform float u_near;
uniform float u_overlap;
uniform float u_overlap_px;  // hybrid: a carried tier's widening in output pixels (0: none)

float pl_adaptive(float e, float L, float t) {
    float l = e * L / min(t, L);
    return clamp(isnan(l) ? u_clamp.x : l, u_clamp.x, u_clamp.y);
}

float pl_chord(float bend) {
    float l = 7.0 * sqrt(bend / (8.0 * u_chord));
    return clamp(isnan(l) ? u_clamp.x : l, u_clamp.x, u_clamp.y);
}

void main() {
    vec4 r = vs_range[0];
    uint inst = vs_inst[0];
    if (gl_InvocationID == 0) {
        if (u_adaptive != 0) {
            uint func = pl_inst_u[inst * PL_INST_U + PL_INST_FUNC];
            uint P = pl_inst_u[inst * PL_INST_U + PL_INST_PARAMS];
            uint M = inst * PL_INST_F + PL_INST_MODEL;
            // quad domain: outer 0 is the edge u = u0, 1 is v = v0, 2 is u = u1, 3 is v = v1;
            // each edge's screen polyline through 8 samples (one call site of pl_position, so
            // that the function's code is inlined once)
            vec4 a = vec4(r.x, r.x, r.y, r.x);   // edge start u
            vec4 b = vec4(r.x, r.y, r.y, r.y);   // edge end u
            vec4 c = vec4(r.z, r.z, r.z, r.w);   // edge start v
            vec4 d = vec4(r.w, r.z, r.w, r.w);   // edge end v
            float len[4] = float[4](0.0, 0.0, 0.0, 0.0);
#ifdef PL_VIEWS
            // the 32 samples' world positions once (one call site of pl_position), then each
            // view's screen polyline of each edge. A view counts for an edge unless every sample
            // lies beyond one of its clip planes (x = +-w, y = +-w, the near plane): such a view
            // does not see the edge, and a view beside or behind it would ask for a needlessly
            // fine level (the finest, behind its near plane)
            vec3 wp[32];
            bool ok[32];
            for (int k = 0; k < 32; ++k) {
                int e = k >> 3;
                float f = float(k & 7) / 7.0;
                vec3 p = pl_position(func, pl_lerp(a[e], b[e], f), pl_lerp(c[e], d[e], f), P);
                ok[k] = !pl_bad3(p);
                wp[k] = ok[k] ? pl_rows_point(M, p) : vec3(0.0);
            }
            for (int view = 0; view < u_n_views; ++view) {
                mat4 V = pl_views[view].view, Pr = pl_views[view].proj;
                float zn = pl_views[view].near.x;
                for (int e = 0; e < 4; ++e) {
                    float l = 0.0;
                    vec2 prev = vec2(0.0);
                    int prev_state = 2;
                    int seen = 0;   // bit per clip plane: some sample on its inner side
                    for (int i = 0; i < 8; ++i) {
                        int state = 2;                       // 0 ok, 1 behind the near plane, 2 NaN/inf
                        vec2 s = vec2(0.0);
                        if (ok[e * 8 + i]) {
                            vec4 q = Pr * (V * vec4(wp[e * 8 + i], 1.0));
                            state = q.w >= zn ? 0 : 1;
                            s = vec2((q.x / q.w * 0.5 + 0.5) * u_screen.x, (0.5 - q.y / q.w * 0.5) * u_screen.y);
                            seen |= (q.x >= -q.w ? 1 : 0) | (q.x <= q.w ? 2 : 0) | (q.y >= -q.w ? 4 : 0)
                                  | (q.y <= q.w ? 8 : 0) | (state == 0 ? 16 : 0);
                        }
                        if (i > 0) {
                            if (state == 1 || prev_state == 1) l = PL_INF;   // unmeasurable: finest
                            else if (state == 0 && prev_state == 0) l += length(s - prev);
                        }
                        prev = s;
                        prev_state = state;
                    }
                    if (seen == 31) len[e] = max(len[e], l);
                }
            }
#else
            // lines 0-3: the edges; chord adds 4-9, the lines of constant v between edges 1 and 3
            // (along u), and 10-15, those of constant u between edges 0 and 2 (along v)
            float bend[16];
            int lines = u_adaptive == 2 ? 16 : 4;
            for (int e = 0; e < lines; ++e) {
                float la = a[e & 3], lb = b[e & 3], lc = c[e & 3], ld = d[e & 3];
                if (e >= 4) {
                    float g = float(e < 10 ? e - 3 : e - 9) / 7.0;
                    la = e < 10 ? r.x : pl_lerp(r.x, r.y, g);
                    lb = e < 10 ? r.y : la;
                    lc = e < 10 ? pl_lerp(r.z, r.w, g) : r.z;
                    ld = e < 10 ? lc : r.w;
                }
                float l = 0.0;
                bend[e] = 0.0;
                vec2 prev = vec2(0.0), prev2 = vec2(0.0);
                int prev_state = 2, prev2_state = 2;
                for (int i = 0; i < 8; ++i) {
                    float f = float(i) / 7.0;
                    vec3 p = pl_position(func, pl_lerp(la, lb, f), pl_lerp(lc, ld, f), P);
                    int state = 2;                       // 0 ok, 1 behind the near plane, 2 NaN/inf
                    vec2 s = vec2(0.0);
                    if (!pl_bad3(p)) {
                        vec4 q = u_proj * (u_view * vec4(pl_rows_point(M, p), 1.0));
                        state = q.w >= u_near ? 0 : 1;
                        s = vec2((q.x / q.w * 0.5 + 0.5) * u_screen.x, (0.5 - q.y / q.w * 0.5) * u_screen.y);
                    }
                    if (i > 0) {
                        if (state == 1 || prev_state == 1) l = bend[e] = PL_INF;   // unmeasurable: finest
                        else if (state == 0 && prev_state == 0) l += length(s - prev);
                    }
                    if (i > 1 && state == 0 && prev_state == 0 && prev2_state == 0)
                        bend[e] = max(bend[e], length(prev2 - 2.0 * prev + s));
                    prev2 = prev;
                    prev2_state = prev_state;
                    prev = s;
                    prev_state = state;
                }
                if (e < 4) len[e] = l;
            }
            if (u_adaptive == 2) {
                float bu = 0.0, bv = 0.0;
                for (int e = 4; e < 10; ++e) bu = max(bu, bend[e]);
                for (int e = 10; e < 16; ++e) bv = max(bv, bend[e]);
                float o[4];
                for (int e = 0; e < 4; ++e) o[e] = ceil(pl_chord(bend[e]));
                gl_TessLevelOuter[0] = o[0]; gl_TessLevelOuter[1] = o[1];
                gl_TessLevelOuter[2] = o[2]; gl_TessLevelOuter[3] = o[3];
                gl_TessLevelInner[0] = max(max(o[1], o[3]), ceil(pl_chord(bu)));
                gl_TessLevelInner[1] = max(max(o[0], o[2]), ceil(pl_chord(bv)));
            }
#endif
            float L = u_level.y;
            if (u_adaptive == 1) {
                gl_TessLevelOuter[0] = pl_adaptive(len[0], L, u_threshold.y);
                gl_TessLevelOuter[1] = pl_adaptive(len[1], L, u_threshold.x);
                gl_TessLevelOuter[2] = pl_adaptive(len[2], L, u_threshold.y);
                gl_TessLevelOuter[3] = pl_adaptive(len[3], L, u_threshold.x);
                vec2 e = u_inner_segment != 0 ? max(vs_ext[0].xy, vs_ext[0].zw) : vs_ext[0].xy;
                gl_TessLevelInner[0] = pl_adaptive(e.x, u_level.x, u_threshold.x);
                gl_TessLevelInner[1] = pl_adaptive(e.y, u_level.x, u_threshold.y);
            }
        } else {
            gl_TessLevelOuter[0] = u_level.y; gl_TessLevelOuter[1] = u_level.y;
            gl_TessLevelOuter[2] = u_level.y; gl_TessLevelOuter[3] = u_level.y;
            gl_TessLevelInner[0] = u_level.x; gl_TessLevelInner[1] = u_level.x;
        }
        vec4 dom = pl_domain(inst);
        vec2 w = vec2(u_overlap);
        if (u_overlap_px > 0.0) {   // at most the largest overlap there is; an unmeasured extent adds none
            vec2 e = vs_ext[0].xy;
            w = max(w, vec2(e.x > 0.0 ? min(u_overlap_px / e.x, 0.25) : 0.0,
                            e.y > 0.0 ? min(u_overlap_px / e.y, 0.25) : 0.0));
        }
        float wu = (r.y - r.x) * w.x, wv = (r.w - r.z) * w.y;
        tc_range = vec4(max(r.x - wu, dom.x), min(r.y + wu, dom.y), max(r.z - wv, dom.z), min(r.w + wv, dom.w));
        tc_core = r;
        tc_inst = inst;
    }
    gl_out[gl_InvocationID].gl_Position = vec4(0.0, 0.0, 0.0, 1.0);
}
