// Surfel prefix renderer: one work-item per surfel of the prefix draws an oriented disc into the
// shared 64-bit key buffers (keys.cl), so surfels and parametric objects compose by depth in one
// Frame. A multi-view frame (paramlod.render_views) reads the surfel once and splats it into every
// view whose frustum holds it, view v into layer v of the layered buffers (pixel v*W*H + y*W + x).
// Each pixel centre in the disc's conservative screen box casts its camera ray (any projection:
// through the inverse projection) against the disc's plane. With a hand-off mesh
// (paramlod/scene/handoff.py) pixels whose dither (keys.cl pl_dither) is below the view's
// mesh weight are left to the mesh (0: every pixel is the surfels'; 1: the view draws none).
// numpy twin: paramlod/surfels/build/reference.py splat_discs (coverage and depth keys bit-identical).
#pragma OPENCL FP_CONTRACT OFF
#include "common/rows.cl"

// The per-view draw record (SF_VIEW_FLOATS: SFV_XF, SFV_INV_PROJ, SFV_RADIUS, SFV_MESH_WEIGHT) and the
// per-view counters (SF_COUNTERS: SF_SURFELS_DRAWN, ...) are records of the prelude
// (paramlod.core.layouts SURFEL_VIEW, SURFEL_COUNTER).

inline float sf_dot(float3 a, float3 b) { return (a.x * b.x + a.y * b.y) + a.z * b.z; }

// A point of the camera ray through NDC (x, y) at NDC depth z (inverse projection, rows).
inline float3 sf_unproject(__global const float* ip, float x, float y, float z) {
    float4 h = (float4)(((ip[0] * x + ip[1] * y) + ip[2] * z) + ip[3],
                        ((ip[4] * x + ip[5] * y) + ip[6] * z) + ip[7],
                        ((ip[8] * x + ip[9] * y) + ip[10] * z) + ip[11],
                        ((ip[12] * x + ip[13] * y) + ip[14] * z) + ip[15]);
    return (float3)(h.x / h.w, h.y / h.w, h.z / h.w);
}

// Screen position (pixels) and clip w of a view-space point.
inline float3 sf_screen(__global const float* P, float3 e, float W, float H) {
    float cx = ((P[0] * e.x + P[1] * e.y) + P[2] * e.z) + P[3];
    float cy = ((P[4] * e.x + P[5] * e.y) + P[6] * e.z) + P[7];
    float cw = ((P[12] * e.x + P[13] * e.y) + P[14] * e.z) + P[15];
    return (float3)((cx / cw * 0.5f + 0.5f) * W, (0.5f - cy / cw * 0.5f) * H, cw);
}

// One surfel (object-space position p and normal n_obj) into one view: `rec` its draw record,
// `cam` its camera record, `layer` the first key of its layer, `counters` its SF_COUNTERS.
inline void sf_splat_view(float3 p, float3 n_obj, float4 mat, __global const float* rec,
                          __global const float* cam, __global const float* light, uint object_id,
                          __global ulong* color_buf, __global ulong* aux_buf, uint layer,
                          __global ulong* counters) {
    float W = cam[CAM_W], H = cam[CAM_H], near = cam[CAM_NEAR], far = cam[CAM_FAR];
    uint iw = (uint)W, ih = (uint)H;
    __global const float* P = cam + CAM_PROJ;
    __global const float* V = cam + CAM_VIEW;
    __global const float* inv_proj = rec + SFV_INV_PROJ;
    float radius = rec[SFV_RADIUS], mesh_weight = rec[SFV_MESH_WEIGHT];
    float3 e = rows_point(rec + SFV_XF, p);
    float3 nv = rows_dir(rec + SFV_XF + 12, n_obj);
    float r2 = radius * radius;

    if (is_bad3(e) || is_bad3(nv) || !(radius > 0.0f)) { atom_add(&counters[SF_SURFELS_NOT_FINITE], (ulong)1); return; }
    if (-e.z - radius > far || -e.z + radius < near) return;   // wholly beyond far or before near

    // conservative screen box: the 8 corners of the cube around the disc's bounding sphere, with
    // corners in front of the near plane moved onto it (where the cube's visible part is largest)
    float x0 = INFINITY, y0 = INFINITY, x1 = -INFINITY, y1 = -INFINITY;
    bool whole = false;
    for (int c = 0; c < 8; ++c) {
        float3 q = e + (float3)((c & 1) ? radius : -radius, (c & 2) ? radius : -radius, (c & 4) ? radius : -radius);
        q.z = fmin(q.z, -near);
        float3 s = sf_screen(P, q, W, H);
        if (!(s.z > 0.0f) || is_bad3(s)) { whole = true; break; }
        x0 = fmin(x0, s.x); y0 = fmin(y0, s.y); x1 = fmax(x1, s.x); y1 = fmax(y1, s.y);
    }
    int px0 = 0, py0 = 0, px1 = (int)iw - 1, py1 = (int)ih - 1;
    if (!whole) {
        if (!(x1 >= -1.0f && y1 >= -1.0f && x0 <= W + 1.0f && y0 <= H + 1.0f)) return;  // off screen
        px0 = max((int)floor(fmax(x0, -2.0f)) - 1, 0); py0 = max((int)floor(fmax(y0, -2.0f)) - 1, 0);
        px1 = min((int)ceil(fmin(x1, W + 2.0f)) + 1, (int)iw - 1); py1 = min((int)ceil(fmin(y1, H + 2.0f)) + 1, (int)ih - 1);
    }

    ulong issued = 0, covered = 0;
    for (int y = py0; y <= py1; ++y) {
        float ny = 1.0f - ((float)y + 0.5f) / H * 2.0f;
        for (int x = px0; x <= px1; ++x) {
            if (mesh_weight > 0.0f && pl_dither((uint)x, (uint)y) < mesh_weight) continue;   // the mesh's pixel
            float nx = ((float)x + 0.5f) / W * 2.0f - 1.0f;
            float3 o = sf_unproject(inv_proj, nx, ny, -1.0f);
            float3 d = sf_unproject(inv_proj, nx, ny, 1.0f) - o;
            float den = sf_dot(d, nv);
            if (den == 0.0f) continue;                 // the ray runs in the disc's plane
            float t = sf_dot(e - o, nv) / den;
            float3 h = o + t * d;
            float3 dh = h - e;
            if (!(sf_dot(dh, dh) <= r2)) continue;
            float depth = -h.z;
            if (!(depth >= near && depth <= far)) continue;
            covered++;
            uint pix = layer + (uint)y * iw + (uint)x;
            if (key_hidden(color_buf, pix, depth)) continue;
            float3 nn;
            uint rgba = shade(nv, view_dir(cam, h), mat, light, &nn);
            float3 n_world = (float3)(V[0] * nn.x + V[4] * nn.y + V[8] * nn.z,
                                      V[1] * nn.x + V[5] * nn.y + V[9] * nn.z,
                                      V[2] * nn.x + V[6] * nn.y + V[10] * nn.z);
            issued += write_point(color_buf, aux_buf, pix, color_key(depth, rgba), aux_key(depth, n_world, object_id));
        }
    }
    atom_add(&counters[SF_SURFELS_DRAWN], (ulong)1);
    atom_add(&counters[SF_ATOMICS], issued);
    atom_add(&counters[SF_PIXELS_COVERED], covered);
}

// views: n_views draw records of SF_VIEW_FLOATS; cam: n_views camera records; counters:
// SF_COUNTERS per view.
__kernel void surfels_splat(__global const float4* pos, __global const float4* nrm,
                            __global const float4* albedo, uint n,
                            __global const float* views, __global const float* cam, uint n_views,
                            __global const float* light, float specular, uint object_id,
                            __global ulong* color_buf, __global ulong* aux_buf,
                            __global ulong* counters)
{
    uint i = get_global_id(0);
    if (i >= n) return;
    float3 p = pos[i].xyz, n_obj = nrm[i].xyz;
    float4 mat = albedo[i];
    mat.w = specular;
    uint layer_pixels = (uint)cam[CAM_W] * (uint)cam[CAM_H];
    for (uint v = 0; v < n_views; ++v) {
        __global const float* rec = views + v * SF_VIEW_FLOATS;
        if (!(rec[SFV_MESH_WEIGHT] < 1.0f)) continue;   // the object is outside the view, or the mesh's there
        sf_splat_view(p, n_obj, mat, rec, cam + v * CAM_FLOATS, light, object_id, color_buf, aux_buf,
                      v * layer_pixels, counters + v * SF_COUNTERS);
    }
}
