// LOD stage: one PATCH SUBDIVISION step (thesis section 5.5.1), one work-group of 32 per patch.
// Per patch: 8 samples along u on 4 rows (v at 1/8, 3/8, 5/8, 7/8 of the range), 8 along v on 4
// columns, and a 5x5 grid of extra samples for the frustum test and the screen bounding box.
// Each line's screen polyline length is compared with the threshold; a line that exceeds it
// splits the half of the patch it lies in (7 patterns, docs/lod.md). The numpy twin of this
// kernel is paramlod/lod/reference.py: keep both in step.
//
// Counters: one record of LOD_COUNTERS uints per step (LOD_CHILDREN, LOD_SPLIT, ...); record 0
// holds the initial patch count and, at LOD_RENDER_TOTAL, the render list's length. These, the
// patch structs and LOD_LOCAL come from the prelude (paramlod.core.layouts).

typedef struct {
    float2 s;      // screen position in pixels
    int state;     // 0: in front of the near plane, 1: behind it, 2: NaN/inf sample
    uint code;     // frustum outcode
} Sample;

inline Sample lod_sample(uint func, __global const float* P, __global const float* I,
                         __global const float* cam, float u, float v) {
    Sample r;
    float3 p = pl_position(func, u, v, P);
    if (is_bad3(p)) { r.s = (float2)(0.0f, 0.0f); r.state = 2; r.code = 63u; return r; }
    float3 w = xform_point(I + INST_MODEL, p);
    float3 e = xform_point(cam + CAM_VIEW, w);
    float4 c = project(cam, e);
    // a finite position can still overflow float32 on its way to clip space (a function returning
    // ~1e38): such a sample is bad like a NaN one, never a reason to split forever
    if (!(isfinite(c.x) && isfinite(c.y) && isfinite(c.z) && isfinite(c.w))) {
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
    return length(b.s - a.s);
}

inline void grow_box(float4* box, Sample s) {
    if (s.state != 0) return;
    box->x = fmin(box->x, s.s.x); box->y = fmin(box->y, s.s.y);
    box->z = fmax(box->z, s.s.x); box->w = fmax(box->w, s.s.y);
}

inline void emit(__global EvalPatch* out, uint slot, uint cap, float u0, float u1, float v0, float v1, uint inst) {
    if (slot < cap) {
        EvalPatch c;
        c.range = (float4)(u0, u1, v0, v1);
        c.inst = inst; c.pad0 = c.pad1 = c.pad2 = 0u;
        out[slot] = c;
    }
}

// The decision for one measured patch: cull, render (or force out on the last step), or split
// into 2, 3 or 4 children by the 7 patterns. eu, ev: the four u- and v-polyline lengths; mu_seg,
// mv_seg: their longest segments; box: screen bounding box; code: AND of the samples' outcodes.
inline void lod_decide(EvalPatch patch, const float* eu, const float* ev, float mu_seg, float mv_seg,
                       float4 box, uint code, __global EvalPatch* out, uint out_cap,
                       __global RenderPatch* render, uint render_cap,
                       __global uint* counters, __global uint* render_count,
                       float t_u, float t_v, uint step, uint force)
{
    uint inst = patch.inst;
    float u0 = patch.range.x, u1 = patch.range.y, v0 = patch.range.z, v1 = patch.range.w;
    if (code != 0u) { atomic_inc(&counters[LOD_CULLED]); return; }  // every sample outside one clip plane

    bool a = eu[0] > t_u || eu[1] > t_u;   // u-lines in the lower v half
    bool b = eu[2] > t_u || eu[3] > t_u;   // u-lines in the upper v half
    bool c = ev[0] > t_v || ev[1] > t_v;   // v-lines in the left u half
    bool d = ev[2] > t_v || ev[3] > t_v;   // v-lines in the right u half
    bool split = a || b || c || d;

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
            r.flags = step | (split ? FLAG_FORCED : 0u);
            r.pad0 = r.pad1 = 0u;
            render[slot] = r;
        }
        atomic_inc(&counters[LOD_RENDERED]);
        if (split) atomic_inc(&counters[LOD_FORCED]);
        return;
    }

    atomic_inc(&counters[LOD_SPLIT]);
    float mu = 0.5f * (u0 + u1), mv = 0.5f * (v0 + v1);
    if ((a || b) && (c || d)) {                 // 1:4
        uint s = atomic_add(&counters[LOD_CHILDREN], 4u);
        emit(out, s + 0, out_cap, u0, mu, v0, mv, inst);
        emit(out, s + 1, out_cap, mu, u1, v0, mv, inst);
        emit(out, s + 2, out_cap, u0, mu, mv, v1, inst);
        emit(out, s + 3, out_cap, mu, u1, mv, v1, inst);
    } else if (a && b) {                        // 1:2, cut u
        uint s = atomic_add(&counters[LOD_CHILDREN], 2u);
        emit(out, s + 0, out_cap, u0, mu, v0, v1, inst);
        emit(out, s + 1, out_cap, mu, u1, v0, v1, inst);
    } else if (c && d) {                        // 1:2, cut v
        uint s = atomic_add(&counters[LOD_CHILDREN], 2u);
        emit(out, s + 0, out_cap, u0, u1, v0, mv, inst);
        emit(out, s + 1, out_cap, u0, u1, mv, v1, inst);
    } else if (a) {                             // 1:3, lower v half cut in u
        uint s = atomic_add(&counters[LOD_CHILDREN], 3u);
        emit(out, s + 0, out_cap, u0, mu, v0, mv, inst);
        emit(out, s + 1, out_cap, mu, u1, v0, mv, inst);
        emit(out, s + 2, out_cap, u0, u1, mv, v1, inst);
    } else if (b) {                             // 1:3, upper v half cut in u
        uint s = atomic_add(&counters[LOD_CHILDREN], 3u);
        emit(out, s + 0, out_cap, u0, u1, v0, mv, inst);
        emit(out, s + 1, out_cap, u0, mu, mv, v1, inst);
        emit(out, s + 2, out_cap, mu, u1, mv, v1, inst);
    } else if (c) {                             // 1:3, left u half cut in v
        uint s = atomic_add(&counters[LOD_CHILDREN], 3u);
        emit(out, s + 0, out_cap, u0, mu, v0, mv, inst);
        emit(out, s + 1, out_cap, u0, mu, mv, v1, inst);
        emit(out, s + 2, out_cap, mu, u1, v0, v1, inst);
    } else {                                    // 1:3, right u half cut in v
        uint s = atomic_add(&counters[LOD_CHILDREN], 3u);
        emit(out, s + 0, out_cap, u0, mu, v0, v1, inst);
        emit(out, s + 1, out_cap, mu, u1, v0, mv, inst);
        emit(out, s + 2, out_cap, mu, u1, mv, v1, inst);
    }
}

// Where sample s of a patch lies (s < LOD_SAMPLES): 0..31 the four u-lines (8 samples each, at
// v = 1/8, 3/8, 5/8, 7/8 of the range), 32..63 the four v-lines, 64..88 the 5x5 extra grid.
#define LOD_SAMPLES 89
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

// One LOD step: a work-group of LOD_LOCAL work-items measures one patch at a time, each work-item
// evaluating some of its 89 samples (a patch's samples are the expensive part, and a step with a
// few hundred patches would leave most of a GPU idle with one work-item per patch). The number
// of input patches is read on the device (the previous step's child count), so the host enqueues
// all steps without waiting and reads the counters once per frame; work-groups stride over the
// patches. A step whose input overflowed its buffer only sees the first `cap` patches: the host
// detects that afterwards and redoes the stage. LOD_LOCAL: the prelude's (the host launches with it).
__kernel __attribute__((reqd_work_group_size(LOD_LOCAL, 1, 1)))
void lod_step(__global const EvalPatch* in, __global EvalPatch* out, uint cap,
              __global RenderPatch* render, uint render_cap,
              __global uint* counters,   // per step: LOD_COUNTERS uints; see paramlod/lod/stage.py
              __global const float* inst_f, __global const uint* inst_u,
              __global const float* params, __global const float* cam,
              float t_u, float t_v, uint step, uint force)
{
    __local float2 pos[LOD_SAMPLES];
    __local int state[LOD_SAMPLES];
    __local float4 box_part[LOD_LOCAL];
    __local uint code_part[LOD_LOCAL];
    __local float line[16];   // 0..3 u-line lengths, 4..7 v-line lengths, 8..15 their longest segments
    uint n_in = min(counters[(step - 1) * LOD_COUNTERS + LOD_CHILDREN], cap);
    __global uint* c = counters + step * LOD_COUNTERS;
    __global uint* render_count = counters + LOD_RENDER_TOTAL;
    uint l = get_local_id(0);
    for (uint i = get_group_id(0); i < n_in; i += get_num_groups(0)) {
        EvalPatch patch = in[i];
        uint inst = patch.inst;
        __global const float* I = inst_f + inst * INST_F;
        uint func = inst_u[inst * INST_U + INST_FUNC];
        __global const float* P = params + inst_u[inst * INST_U + INST_PARAMS];
        float u0 = patch.range.x, v0 = patch.range.z;
        float du = patch.range.y - u0, dv = patch.range.w - v0;
        float4 box = (float4)(INFINITY, INFINITY, -INFINITY, -INFINITY);
        uint code = 63u;
        for (uint s = l; s < LOD_SAMPLES; s += LOD_LOCAL) {
            float2 uv = lod_uv(s, u0, v0, du, dv);
            Sample q = lod_sample(func, P, I, cam, uv.x, uv.y);
            pos[s] = q.s; state[s] = q.state;
            code &= q.code; grow_box(&box, q);
        }
        box_part[l] = box; code_part[l] = code;
        barrier(CLK_LOCAL_MEM_FENCE);
        if (l < 8u) {   // one work-item per polyline, its segments summed in order (as the numpy twin)
            float sum = 0.0f, longest = 0.0f;
            for (uint k = 1; k < 8u; ++k) {
                Sample sa, sb;
                sa.s = pos[l * 8u + k - 1u]; sa.state = state[l * 8u + k - 1u];
                sb.s = pos[l * 8u + k]; sb.state = state[l * 8u + k];
                float len = seg_len(sa, sb);
                sum += len; longest = fmax(longest, len);
            }
            line[l] = sum; line[8u + l] = longest;
        }
        for (uint h = LOD_LOCAL / 2; h > 0; h >>= 1) {   // box and outcode over the work-group
            if (l < h) {
                float4 o = box_part[l + h], m = box_part[l];
                box_part[l] = (float4)(fmin(m.x, o.x), fmin(m.y, o.y), fmax(m.z, o.z), fmax(m.w, o.w));
                code_part[l] &= code_part[l + h];
            }
            barrier(CLK_LOCAL_MEM_FENCE);
        }
        if (l == 0u) {
            float eu[4] = {line[0], line[1], line[2], line[3]};
            float ev[4] = {line[4], line[5], line[6], line[7]};
            float mu_seg = fmax(fmax(line[8], line[9]), fmax(line[10], line[11]));
            float mv_seg = fmax(fmax(line[12], line[13]), fmax(line[14], line[15]));
            lod_decide(patch, eu, ev, mu_seg, mv_seg, box_part[0], code_part[0], out, cap, render,
                       render_cap, c, render_count, t_u, t_v, step, force);
        }
        barrier(CLK_LOCAL_MEM_FENCE);   // the next patch overwrites the local arrays
    }
}
