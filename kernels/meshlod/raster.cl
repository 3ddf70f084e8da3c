// Mesh rasterizer: the triangles of the clusters the cut selected, drawn into the shared 64-bit
// key buffers (common/keys.cl) with atom_min, so meshes, parametric objects and surfels composite
// by depth in one Frame (and get the points variant's supersampling from a larger KeyBuffer).
// Driven by paramlod/meshlod/raster.py (MeshRaster); numpy twin: paramlod/meshlod/raster_reference.py,
// equal key for key: FP_CONTRACT is off, every float expression below is written in the order the
// twin evaluates it, the program is built with -cl-fp32-correctly-rounded-divide-sqrt, and the
// edge functions are exact 64-bit integers.
//
// raster_clusters: persistent work-groups of CLUSTER_MAX_TRIANGLES work-items walk the selection
// (uint2 instance, cluster; its count read here, no host wait after the cut); work-item i takes
// triangle i of the cluster: model and view transforms, clipping against the near plane and a
// guard band (a convex polygon of up to 8 vertices, fanned from its first vertex), projection,
// snapping to 1/256 pixel, then for each fan triangle either its pixels (small bounding box) or
// an entry in the large-triangle list. raster_large: one work-group per listed triangle, its
// work-items over the pixels of its bounding box (enqueued after raster_clusters).
// Coverage: pixel centres, top-left fill rule, so triangles sharing an edge cover each of its
// pixels exactly once. Depth and attributes perspective-correct (weights E_i / w_i); depth is the
// linear view depth, written only inside [near, far]. Shading: keys.cl shade() at each pixel
// (two-sided: the cut culls back-facing clusters, open scans show their backs).
// Hand-off (paramlod/scene/handoff.py): an instance of weight w < 1 (`weights`, one float per
// instance) draws only the pixels whose dither (keys.cl pl_dither) is below w; its surfels draw the
// others.
// Views (a multi-view frame): `cams` holds n_views camera records one after another and the key
// buffers n_views layers (view v's pixel (x, y) is key v W H + y W + x); each selected pair is
// drawn into the views of its mask (`masks`, from the cut: the views whose frustum and backface
// tests keep the cluster), work-item by work-item: per view its own clipping and setup of the
// triangle, into that view's layer. A large-list entry carries its view in the high half of its
// fan index. With one view `masks` is not read and everything is the one-view raster.
#pragma OPENCL FP_CONTRACT OFF
#include "common/rows.cl"
#include "common/keys.cl"
#include "common/debug_color.cl"

// the host builds with the twin's constants (paramlod/meshlod/raster_reference.py)
#if !defined(RS_SUBPIXEL_BITS) || !defined(RS_GUARD_PIXELS) || !defined(RS_LARGE_LOCAL)
#error "build with -DRS_SUBPIXEL_BITS, -DRS_GUARD_PIXELS and -DRS_LARGE_LOCAL (paramlod.meshlod.raster)"
#endif
#define RS_ONE (1L << RS_SUBPIXEL_BITS)   // fixed-point units per pixel
#define RS_HALF (RS_ONE >> 1)             // a pixel centre's offset
// guard band, pixels from the screen's centre: with 8 subpixel bits and 2^20 pixels, coordinates
// stay below 2^29 units, so edge functions (products of two differences) stay below 2^61
#define RS_GUARD ((float)RS_GUARD_PIXELS)
#define RS_POLY 8           // a triangle clipped by 5 planes has at most 8 vertices

// counters (ulong): RS_* of the prelude (paramlod.core.layouts.RASTER_COUNTER)

typedef struct {
    float3 e[RS_POLY];      // view-space positions
    float3 n[RS_POLY];      // view-space normals (not unit)
    int count;
} RsPoly;

typedef struct {
    long dx[3], dy[3];      // edge i (opposite vertex i: 1->2, 2->0, 0->1): b - a, fixed point
    long ax[3], ay[3];      // its start a
    long bias[3];           // 0 if the edge owns its pixels (top-left), else 1
    float iw[3], d[3];      // 1 / clip w, linear view depth of each vertex
    float3 e[3], n[3];      // view position, view normal of each vertex
    int x0, y0, x1, y1;     // pixel bounding box, clamped to the screen
} RsTri;

inline float rs_row(__global const float* P, int r, float3 e) {
    return ((P[4 * r] * e.x + P[4 * r + 1] * e.y) + P[4 * r + 2] * e.z) + P[4 * r + 3];
}

// Signed distance (any scale) of a view-space point to clip plane k, >= 0 inside: the near plane,
// then the guard band's sides |x_clip| <= gx w_clip, |y_clip| <= gy w_clip.
inline float rs_plane(int k, float3 e, __global const float* P, float near, float gx, float gy) {
    if (k == 0) return -e.z - near;
    float cw = rs_row(P, 3, e);
    if (k == 1) return gx * cw - rs_row(P, 0, e);
    if (k == 2) return gx * cw + rs_row(P, 0, e);
    if (k == 3) return gy * cw - rs_row(P, 1, e);
    return gy * cw + rs_row(P, 1, e);
}

// Sutherland-Hodgman against plane k. An edge's crossing is always computed from its inside end
// towards its outside end, so two triangles sharing the edge make the same point.
inline void rs_clip(RsPoly* p, int k, __global const float* P, float near, float gx, float gy) {
    float dist[RS_POLY];
    bool out = false;
    for (int i = 0; i < p->count; ++i) {
        dist[i] = rs_plane(k, p->e[i], P, near, gx, gy);
        out = out || !(dist[i] >= 0.0f);
    }
    if (!out) return;
    RsPoly o;
    o.count = 0;
    for (int i = 0; i < p->count; ++i) {
        int j = i + 1 == p->count ? 0 : i + 1;
        bool ia = dist[i] >= 0.0f, ib = dist[j] >= 0.0f;
        if (ia) { o.e[o.count] = p->e[i]; o.n[o.count] = p->n[i]; o.count++; }
        if (ia != ib) {
            int a = ia ? i : j, b = ia ? j : i;
            float t = dist[a] / (dist[a] - dist[b]);
            float3 e = p->e[a] + t * (p->e[b] - p->e[a]);
            if (k == 0) e.z = -near;   // exactly on the near plane
            o.e[o.count] = e;
            o.n[o.count] = p->n[a] + t * (p->n[b] - p->n[a]);
            o.count++;
        }
    }
    *p = o;
}

// The clipped polygon of triangle `tri` of instance `inst`, in view space; returns its vertex
// count (0: nothing left). *near_clipped: it crossed the near plane.
inline int rs_polygon(RsPoly* p, uint tri, uint inst,
                      __global const float4* vertices, __global const float4* normals,
                      __global const uint* triangles, __global const float* inst_f,
                      __global const float* cam, bool* near_clipped) {
    __global const float* M = inst_f + inst * INST_F + INST_MODEL;
    __global const float* N = inst_f + inst * INST_F + INST_NORMAL;
    __global const float* V = cam + CAM_VIEW;
    __global const float* P = cam + CAM_PROJ;
    float near = cam[CAM_NEAR], far = cam[CAM_FAR];
    bool bad = false, beyond = true;
    for (int i = 0; i < 3; ++i) {
        uint v = triangles[3 * tri + i];
        p->e[i] = rows_point(V, rows_point(M, vertices[v].xyz));
        p->n[i] = rows_dir(V, rows_dir(N, normals[v].xyz));
        bad = bad || is_bad3(p->e[i]) || is_bad3(p->n[i]);
        beyond = beyond && -p->e[i].z > far;
    }
    p->count = 3;
    *near_clipped = false;
    if (bad || beyond) return 0;
    float d0 = rs_plane(0, p->e[0], P, near, 0.0f, 0.0f), d1 = rs_plane(0, p->e[1], P, near, 0.0f, 0.0f),
          d2 = rs_plane(0, p->e[2], P, near, 0.0f, 0.0f);
    *near_clipped = (d0 < 0.0f || d1 < 0.0f || d2 < 0.0f) && (d0 >= 0.0f || d1 >= 0.0f || d2 >= 0.0f);
    float gx = 2.0f * RS_GUARD / cam[CAM_W], gy = 2.0f * RS_GUARD / cam[CAM_H];
    // most triangles are inside every plane: test that first (the clipper would keep them as they are)
    bool all_in = d0 >= 0.0f && d1 >= 0.0f && d2 >= 0.0f;
    for (int i = 0; i < 3 && all_in; ++i) {
        float cw = rs_row(P, 3, p->e[i]), cx = rs_row(P, 0, p->e[i]), cy = rs_row(P, 1, p->e[i]);
        all_in = gx * cw - cx >= 0.0f && gx * cw + cx >= 0.0f && gy * cw - cy >= 0.0f && gy * cw + cy >= 0.0f;
    }
    if (all_in) return 3;
    for (int k = 0; k < 5 && p->count > 0; ++k) rs_clip(p, k, P, near, gx, gy);
    return p->count;
}

// Fan triangle (0, j, j + 1) of the polygon set up for rasterizing; false if it covers no pixel
// centre's bounding box on the screen or has no area.
inline bool rs_setup(const RsPoly* p, int j, __global const float* cam, RsTri* t) {
    __global const float* P = cam + CAM_PROJ;
    float W = cam[CAM_W], H = cam[CAM_H];
    long X[3], Y[3];
    int idx[3] = {0, j, j + 1};
    for (int i = 0; i < 3; ++i) {
        float3 e = p->e[idx[i]];
        float cx = rs_row(P, 0, e), cy = rs_row(P, 1, e), cw = rs_row(P, 3, e);
        float sx = (cx / cw * 0.5f + 0.5f) * W;
        float sy = (0.5f - cy / cw * 0.5f) * H;
        X[i] = convert_long_rte(sx * (float)RS_ONE);
        Y[i] = convert_long_rte(sy * (float)RS_ONE);
        t->iw[i] = 1.0f / cw;
        t->d[i] = -e.z;
        t->e[i] = e;
        t->n[i] = p->n[idx[i]];
    }
    long area = (X[1] - X[0]) * (Y[2] - Y[0]) - (Y[1] - Y[0]) * (X[2] - X[0]);
    if (area == 0) return false;
    if (area < 0) {   // two-sided: make every triangle positive, so one inside test serves both
        long tx = X[1], ty = Y[1]; X[1] = X[2]; Y[1] = Y[2]; X[2] = tx; Y[2] = ty;
        float f = t->iw[1]; t->iw[1] = t->iw[2]; t->iw[2] = f;
        f = t->d[1]; t->d[1] = t->d[2]; t->d[2] = f;
        float3 v = t->e[1]; t->e[1] = t->e[2]; t->e[2] = v;
        v = t->n[1]; t->n[1] = t->n[2]; t->n[2] = v;
    }
    for (int i = 0; i < 3; ++i) {
        int a = (i + 1) % 3, b = (i + 2) % 3;   // edge i runs a -> b: 1->2, 2->0, 0->1
        t->ax[i] = X[a]; t->ay[i] = Y[a];
        t->dx[i] = X[b] - X[a]; t->dy[i] = Y[b] - Y[a];
        // y grows downwards; inside is where E > 0. Top edge: horizontal, going right; left
        // edge: going up. The reverse of an owned edge is never owned.
        t->bias[i] = (t->dy[i] < 0 || (t->dy[i] == 0 && t->dx[i] > 0)) ? 0 : 1;
    }
    long x0 = min(X[0], min(X[1], X[2])), x1 = max(X[0], max(X[1], X[2]));
    long y0 = min(Y[0], min(Y[1], Y[2])), y1 = max(Y[0], max(Y[1], Y[2]));
    // pixel centres c*256 + 128 inside [x0, x1]: arithmetic shifts floor negative values
    t->x0 = (int)max((x0 - RS_HALF + RS_ONE - 1) >> RS_SUBPIXEL_BITS, (long)0);
    t->x1 = (int)min((x1 - RS_HALF) >> RS_SUBPIXEL_BITS, (long)W - 1);
    t->y0 = (int)max((y0 - RS_HALF + RS_ONE - 1) >> RS_SUBPIXEL_BITS, (long)0);
    t->y1 = (int)min((y1 - RS_HALF) >> RS_SUBPIXEL_BITS, (long)H - 1);
    return t->x0 <= t->x1 && t->y0 <= t->y1;
}

// The edge function of edge i at pixel (x, y)'s centre.
inline long rs_edge(const RsTri* t, int i, int x, int y) {
    long px = (long)x * RS_ONE + RS_HALF, py = (long)y * RS_ONE + RS_HALF;
    return t->dx[i] * (py - t->ay[i]) - t->dy[i] * (px - t->ax[i]);
}

// One covered pixel centre with edge functions E0..E2: interpolate, shade, write both keys of
// the layer whose first key is `layer`. Returns 1 when the colour atomic was issued; *covered
// counts pixels with depth in [near, far].
inline uint rs_fragment(const RsTri* t, long E0, long E1, long E2, int x, int y, uint layer,
                        __global const float* cam, __global const float* light, float4 mat, uint object_id,
                        float weight, __global ulong* color_buf, __global ulong* aux_buf, ulong* covered) {
    if (weight < 1.0f && !(pl_dither((uint)x, (uint)y) < weight)) return 0u;   // the surfels' pixel
    float u0 = (float)E0 * t->iw[0], u1 = (float)E1 * t->iw[1], u2 = (float)E2 * t->iw[2];
    float q = (u0 + u1) + u2;
    float depth = ((u0 * t->d[0] + u1 * t->d[1]) + u2 * t->d[2]) / q;
    if (!(depth >= cam[CAM_NEAR] && depth <= cam[CAM_FAR])) return 0u;
    *covered += 1;
    uint iw = (uint)cam[CAM_W];
    uint pix = layer + (uint)y * iw + (uint)x;
    if (key_hidden(color_buf, pix, depth)) return 0u;
    float r = 1.0f / q;
    float3 h = ((u0 * t->e[0] + u1 * t->e[1]) + u2 * t->e[2]) * r;
    float3 nv = ((u0 * t->n[0] + u1 * t->n[1]) + u2 * t->n[2]) * r;
    float3 nn;
    uint rgba = shade(nv, view_dir(cam, h), mat, light, &nn);
    __global const float* V = cam + CAM_VIEW;
    float3 nw = (float3)((V[0] * nn.x + V[4] * nn.y) + V[8] * nn.z,
                         (V[1] * nn.x + V[5] * nn.y) + V[9] * nn.z,
                         (V[2] * nn.x + V[6] * nn.y) + V[10] * nn.z);
    return write_point(color_buf, aux_buf, pix, color_key(depth, rgba), aux_key(depth, nw, object_id));
}

// The shading material of a cluster drawn for instance `inst`: its material, or a debug colour
// (color_by 1: per cluster, 2: per level) with the material's specular weight.
inline float4 rs_material(__global const float4* materials, uint inst, uint cluster, uint level, uint color_by) {
    float4 m = materials[inst];
    if (color_by == 1u) m.xyz = pl_cluster_color(cluster);
    else if (color_by == 2u) m.xyz = pl_level_color(level);
    return m;
}

__kernel __attribute__((reqd_work_group_size(CLUSTER_MAX_TRIANGLES, 1, 1)))
void raster_clusters(__global const float4* vertices, __global const float4* normals,
                     __global const uint* triangles, __global const Cluster* clusters,
                     __global const float* inst_f, __global const uint* inst_u,
                     __global const float4* materials, __global const float* weights,
                     __global const uint2* selection, __global const ulong* masks, uint capacity,
                     __global const ulong* cut_counters, __global const float* cams, uint n_views,
                     __global const float* light, uint color_by, uint large_pixels,
                     __global ulong* color_buf, __global ulong* aux_buf,
                     __global uint4* large, uint large_capacity, __global ulong* counters)
{
    uint lid = get_local_id(0);
    ulong n_sel = min(cut_counters[CUT_SELECTED], (ulong)capacity);
    ulong tris = 0, clipped = 0, culled = 0, covered = 0, issued = 0;
    uint layer_keys = (uint)cams[CAM_W] * (uint)cams[CAM_H];
    for (ulong s = get_group_id(0); s < n_sel; s += get_num_groups(0)) {
        uint2 pair = selection[s];
        uint inst = pair.x, cluster = pair.y;
        if (lid >= clusters[cluster].count) continue;
        uint tri = clusters[cluster].first + lid;
        float4 mat = rs_material(materials, inst, cluster, clusters[cluster].level, color_by);
        uint object_id = inst_u[inst * INST_U + INST_OBJECT];
        float weight = weights[inst];
        for (ulong views = n_views > 1u ? masks[s] : 1ul; views; views &= views - 1ul) {
            uint v = 63u - (uint)clz(views & (~views + 1ul));   // the lowest view left
            __global const float* cam = cams + v * CAM_FLOATS;
            tris++;
            RsPoly p;
            bool near_clipped;
            int nv = rs_polygon(&p, tri, inst, vertices, normals, triangles, inst_f, cam, &near_clipped);
            clipped += near_clipped ? 1 : 0;
            bool drawn = false;
            for (int j = 1; j + 1 < nv; ++j) {
                RsTri t;
                if (!rs_setup(&p, j, cam, &t)) continue;
                drawn = true;
                if ((ulong)(t.x1 - t.x0 + 1) * (ulong)(t.y1 - t.y0 + 1) > (ulong)large_pixels) {
                    ulong at = atom_inc(&counters[RS_LARGE]);
                    if (at < large_capacity) large[at] = (uint4)(inst, cluster, tri, (uint)j | (v << 16));
                    else atom_inc(&counters[RS_LARGE_OVERFLOW]);
                    continue;
                }
                long s0 = -t.dy[0] * RS_ONE, s1 = -t.dy[1] * RS_ONE, s2 = -t.dy[2] * RS_ONE;
                for (int y = t.y0; y <= t.y1; ++y) {
                    long E0 = rs_edge(&t, 0, t.x0, y), E1 = rs_edge(&t, 1, t.x0, y), E2 = rs_edge(&t, 2, t.x0, y);
                    for (int x = t.x0; x <= t.x1; ++x) {
                        if (E0 >= t.bias[0] && E1 >= t.bias[1] && E2 >= t.bias[2])
                            issued += rs_fragment(&t, E0, E1, E2, x, y, v * layer_keys, cam, light, mat, object_id,
                                                  weight, color_buf, aux_buf, &covered);
                        E0 += s0; E1 += s1; E2 += s2;
                    }
                }
            }
            culled += drawn ? 0 : 1;
        }
    }
    if (tris) {
        atom_add(&counters[RS_TRIANGLES], tris);
        atom_add(&counters[RS_NEAR_CLIPPED], clipped);
        atom_add(&counters[RS_CULLED], culled);
        atom_add(&counters[RS_PIXELS], covered);
        atom_add(&counters[RS_ATOMICS], issued);
    }
}

__kernel __attribute__((reqd_work_group_size(RS_LARGE_LOCAL, 1, 1)))
void raster_large(__global const float4* vertices, __global const float4* normals,
                  __global const uint* triangles, __global const Cluster* clusters,
                  __global const float* inst_f, __global const uint* inst_u,
                  __global const float4* materials, __global const float* weights,
                  __global const float* cams, __global const float* light, uint color_by,
                  __global ulong* color_buf, __global ulong* aux_buf,
                  __global const uint4* large, uint large_capacity, __global ulong* counters)
{
    __local RsTri shared_t;
    __local float4 shared_mat;
    __local uint shared_id, shared_view;
    __local float shared_weight;
    uint layer_keys = (uint)cams[CAM_W] * (uint)cams[CAM_H];
    uint lid = get_local_id(0);
    ulong n = min(counters[RS_LARGE], (ulong)large_capacity);
    ulong covered = 0, issued = 0;
    for (ulong k = get_group_id(0); k < n; k += get_num_groups(0)) {
        if (lid == 0) {   // the setup once per group; its work-items share it
            uint4 item = large[k];
            uint v = item.w >> 16;   // the view, above the fan index
            __global const float* cam = cams + v * CAM_FLOATS;
            RsPoly p;
            RsTri t;
            bool near_clipped;
            rs_polygon(&p, item.z, item.x, vertices, normals, triangles, inst_f, cam, &near_clipped);
            rs_setup(&p, (int)(item.w & 0xFFFFu), cam, &t);
            shared_t = t;
            shared_view = v;
            shared_mat = rs_material(materials, item.x, item.y, clusters[item.y].level, color_by);
            shared_id = inst_u[item.x * INST_U + INST_OBJECT];
            shared_weight = weights[item.x];
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        RsTri t = shared_t;
        float4 mat = shared_mat;
        uint object_id = shared_id;
        float weight = shared_weight;
        uint v = shared_view;
        __global const float* cam = cams + v * CAM_FLOATS;
        int bw = t.x1 - t.x0 + 1;
        long count = (long)bw * (long)(t.y1 - t.y0 + 1);
        for (long i = lid; i < count; i += RS_LARGE_LOCAL) {
            int x = t.x0 + (int)(i % bw), y = t.y0 + (int)(i / bw);
            long E0 = rs_edge(&t, 0, x, y), E1 = rs_edge(&t, 1, x, y), E2 = rs_edge(&t, 2, x, y);
            if (E0 >= t.bias[0] && E1 >= t.bias[1] && E2 >= t.bias[2])
                issued += rs_fragment(&t, E0, E1, E2, x, y, v * layer_keys, cam, light, mat, object_id, weight,
                                      color_buf, aux_buf, &covered);
        }
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (covered) {
        atom_add(&counters[RS_PIXELS], covered);
        atom_add(&counters[RS_ATOMICS], issued);
    }
}
