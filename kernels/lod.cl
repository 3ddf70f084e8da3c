// LOD stage: one PATCH SUBDIVISION step (thesis section 5.5.1), one work-item per patch.
// Per patch: 8 samples along u on 4 rows (v at 1/8, 3/8, 5/8, 7/8 of the range), 8 along v on 4
// columns, and a 5x5 grid of extra samples for the frustum test and the screen bounding box.
// Each line's screen polyline length is compared with the threshold; a line that exceeds it
// splits the half of the patch it lies in (7 patterns, docs/lod.md). The numpy twin of this
// kernel is paramlod/lod_reference.py: keep both in step.

// Counter layout (paramlod/lod.py): one record of LOD_COUNTERS uints per step; record 0 holds the
// initial patch count and the render-list total.
#define LOD_COUNTERS 8
#define LOD_RENDER_TOTAL 1
#define C_CHILDREN 0
#define C_SPLIT 1
#define C_CULLED 2
#define C_RENDERED 3
#define C_FORCED 4

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

inline void lod_patch(EvalPatch patch, __global EvalPatch* out, uint out_cap,
                      __global RenderPatch* render, uint render_cap,
                      __global uint* counters, __global uint* render_count,
                      __global const float* inst_f, __global const uint* inst_u,
                      __global const float* params, __global const float* cam,
                      float t_u, float t_v, uint step, uint force)
{
    uint inst = patch.inst;
    __global const float* I = inst_f + inst * INST_F;
    uint func = inst_u[inst * INST_U + 0];
    __global const float* P = params + inst_u[inst * INST_U + 1];
    float u0 = patch.range.x, u1 = patch.range.y, v0 = patch.range.z, v1 = patch.range.w;
    float du = u1 - u0, dv = v1 - v0;

    uint code = 63u;
    float4 box = (float4)(INFINITY, INFINITY, -INFINITY, -INFINITY);
    float eu[4], ev[4], mu_seg = 0.0f, mv_seg = 0.0f;
    for (int k = 0; k < 4; ++k) {
        float fk = ((float)k + 0.5f) * 0.25f;
        // a row along u at fixed v, and a column along v at fixed u
        Sample pu = lod_sample(func, P, I, cam, u0, v0 + dv * fk);
        Sample pv = lod_sample(func, P, I, cam, u0 + du * fk, v0);
        code &= pu.code & pv.code; grow_box(&box, pu); grow_box(&box, pv);
        float su = 0.0f, sv = 0.0f;
        for (int i = 1; i < 8; ++i) {
            float fi = (float)i * (1.0f / 7.0f);
            Sample qu = lod_sample(func, P, I, cam, u0 + du * fi, v0 + dv * fk);
            Sample qv = lod_sample(func, P, I, cam, u0 + du * fk, v0 + dv * fi);
            float lu = seg_len(pu, qu), lv = seg_len(pv, qv);
            su += lu; sv += lv;
            mu_seg = fmax(mu_seg, lu); mv_seg = fmax(mv_seg, lv);
            code &= qu.code & qv.code; grow_box(&box, qu); grow_box(&box, qv);
            pu = qu; pv = qv;
        }
        eu[k] = su; ev[k] = sv;
    }
    for (int j = 0; j < 5; ++j) {
        for (int i = 0; i < 5; ++i) {
            Sample q = lod_sample(func, P, I, cam, u0 + du * ((float)i * 0.25f), v0 + dv * ((float)j * 0.25f));
            code &= q.code; grow_box(&box, q);
        }
    }
    if (code != 0u) { atomic_inc(&counters[C_CULLED]); return; }  // every sample outside one clip plane

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
        atomic_inc(&counters[C_RENDERED]);
        if (split) atomic_inc(&counters[C_FORCED]);
        return;
    }

    atomic_inc(&counters[C_SPLIT]);
    float mu = 0.5f * (u0 + u1), mv = 0.5f * (v0 + v1);
    if ((a || b) && (c || d)) {                 // 1:4
        uint s = atomic_add(&counters[C_CHILDREN], 4u);
        emit(out, s + 0, out_cap, u0, mu, v0, mv, inst);
        emit(out, s + 1, out_cap, mu, u1, v0, mv, inst);
        emit(out, s + 2, out_cap, u0, mu, mv, v1, inst);
        emit(out, s + 3, out_cap, mu, u1, mv, v1, inst);
    } else if (a && b) {                        // 1:2, cut u
        uint s = atomic_add(&counters[C_CHILDREN], 2u);
        emit(out, s + 0, out_cap, u0, mu, v0, v1, inst);
        emit(out, s + 1, out_cap, mu, u1, v0, v1, inst);
    } else if (c && d) {                        // 1:2, cut v
        uint s = atomic_add(&counters[C_CHILDREN], 2u);
        emit(out, s + 0, out_cap, u0, u1, v0, mv, inst);
        emit(out, s + 1, out_cap, u0, u1, mv, v1, inst);
    } else if (a) {                             // 1:3, lower v half cut in u
        uint s = atomic_add(&counters[C_CHILDREN], 3u);
        emit(out, s + 0, out_cap, u0, mu, v0, mv, inst);
        emit(out, s + 1, out_cap, mu, u1, v0, mv, inst);
        emit(out, s + 2, out_cap, u0, u1, mv, v1, inst);
    } else if (b) {                             // 1:3, upper v half cut in u
        uint s = atomic_add(&counters[C_CHILDREN], 3u);
        emit(out, s + 0, out_cap, u0, u1, v0, mv, inst);
        emit(out, s + 1, out_cap, u0, mu, mv, v1, inst);
        emit(out, s + 2, out_cap, mu, u1, mv, v1, inst);
    } else if (c) {                             // 1:3, left u half cut in v
        uint s = atomic_add(&counters[C_CHILDREN], 3u);
        emit(out, s + 0, out_cap, u0, mu, v0, mv, inst);
        emit(out, s + 1, out_cap, u0, mu, mv, v1, inst);
        emit(out, s + 2, out_cap, mu, u1, v0, v1, inst);
    } else {                                    // 1:3, right u half cut in v
        uint s = atomic_add(&counters[C_CHILDREN], 3u);
        emit(out, s + 0, out_cap, u0, mu, v0, v1, inst);
        emit(out, s + 1, out_cap, mu, u1, v0, mv, inst);
        emit(out, s + 2, out_cap, mu, u1, mv, v1, inst);
    }
}

// One LOD step. The number of input patches is read on the device (the previous step's child
// count), so the host records all steps without waiting for any of them and reads the counters
// once per frame; work-items stride over the patches. A step whose input overflowed its buffer
// only sees the first `cap` patches: the host detects that afterwards and redoes the stage.
__kernel void lod_step(__global const EvalPatch* in, __global EvalPatch* out, uint cap,
                       __global RenderPatch* render, uint render_cap,
                       __global uint* counters,   // per step: LOD_COUNTERS uints; see lod.py
                       __global const float* inst_f, __global const uint* inst_u,
                       __global const float* params, __global const float* cam,
                       float t_u, float t_v, uint step, uint force)
{
    uint n_in = min(counters[(step - 1) * LOD_COUNTERS + C_CHILDREN], cap);
    __global uint* c = counters + step * LOD_COUNTERS;
    __global uint* render_count = counters + LOD_RENDER_TOTAL;
    for (uint i = get_global_id(0); i < n_in; i += get_global_size(0)) {
        lod_patch(in[i], out, cap, render, render_cap, c, render_count,
                  inst_f, inst_u, params, cam, t_u, t_v, step, force);
    }
}
