// Blue-surfel sampler: one round of progressive farthest-point sampling on K orthographic
// G-buffer layers of W x H pixels (paramlod/surfels/sampler.py drives it; the numpy twins are in
// paramlod/surfels/reference.py and must stay bit-identical, so contraction is off).
//
// pos[q]   float4 world position of global pixel q = (k * H + y) * W + x, w > 0 where covered
// sample   ulong  (float bits of the squared insertion radius) << 32 | pixel
// vor[q]   ulong  (float bits of the squared distance to the nearest site) << 32 | site index,
//                 all ones where no site reached (background or not yet splatted)
// cand[s]  ulong  farthest pixel of site s's cell: (squared distance bits) << 32 | pixel
// conf[q]  ulong  largest candidate disc over q (a candidate key), 0 where none
#pragma OPENCL FP_CONTRACT OFF

#define TILE 16
#define ALL_ONES 0xFFFFFFFFFFFFFFFFul

inline float dist2(float4 a, float4 b) {
    float dx = a.x - b.x, dy = a.y - b.y, dz = a.z - b.z;
    return (dx * dx + dy * dy) + dz * dz;
}

// Continuous pixel coordinates of a world point in layer k (row 0 at the top).
inline float2 layer_xy(float4 p, float cx, float cy, float cz, __global const float* L,
                       float scale, float hw, float hh) {
    float rx = p.x - cx, ry = p.y - cy, rz = p.z - cz;
    float a = (rx * L[0] + ry * L[1]) + rz * L[2];
    float b = (rx * L[4] + ry * L[5]) + rz * L[6];
    return (float2)(a * scale + hw, hh - b * scale);
}

// Work-item -> (item, layer, tile) for the disc splats. Every item covers the square box of
// pixels within half_box of its projection; the box is cut along the layer's global grid of
// TILE x TILE tiles (tiles x tiles of them at most). A tile is skipped when it holds no covered
// pixel or when its 3D bounding box (tile_lo/tile_hi) lies farther than the disc radius: the
// squared distance to the box, computed with the same monotone float operations, never exceeds
// that of a pixel inside it, so the skip changes no result.
inline bool splat_box(ulong gid, uint K, uint tiles, uint count, uint* item, uint* k,
                      uint* tx, uint* ty) {
    ulong per_layer = (ulong)tiles * tiles;
    ulong per_item = per_layer * K;
    if (gid >= per_item * count) return false;
    *item = (uint)(gid / per_item);
    ulong rem = gid % per_item;
    *k = (uint)(rem / per_layer);
    uint t = (uint)(rem % per_layer);
    *tx = t % tiles;
    *ty = t / tiles;
    return true;
}

inline float box_dist2(float4 lo, float4 hi, float4 p) {
    float bx = pl_fmaxf(pl_fmaxf(lo.x - p.x, 0.0f), p.x - hi.x);
    float by = pl_fmaxf(pl_fmaxf(lo.y - p.y, 0.0f), p.y - hi.y);
    float bz = pl_fmaxf(pl_fmaxf(lo.z - p.z, 0.0f), p.z - hi.z);
    return (bx * bx + by * by) + bz * bz;
}

// The pixel rectangle [x0, x1) x [y0, y1) of work tile (tx, ty) of a box around c, or false
// when the tile lies outside the box or the layer, is empty, or is out of reach of r2.
inline bool tile_pixels(float2 c, int half_box, uint tx, uint ty, uint W, uint H, uint k,
                        __global const float4* tile_lo, __global const float4* tile_hi,
                        float4 p, float r2, int* x0, int* y0, int* x1, int* y1) {
    int bx = (int)pl_floorf(c.x), by = (int)pl_floorf(c.y);
    int bx0 = max(bx - half_box, 0), by0 = max(by - half_box, 0);
    int bx1 = min(bx + half_box, (int)W - 1), by1 = min(by + half_box, (int)H - 1);
    if (bx0 > bx1 || by0 > by1) return false;
    int gx = bx0 / TILE + (int)tx, gy = by0 / TILE + (int)ty;
    if (gx > bx1 / TILE || gy > by1 / TILE) return false;
    uint tw = (W + TILE - 1) / TILE, th = (H + TILE - 1) / TILE;
    uint t = (k * th + (uint)gy) * tw + (uint)gx;
    float4 lo = tile_lo[t];
    if (!(lo.w > 0.0f)) return false;
    if (box_dist2(lo, tile_hi[t], p) > r2) return false;
    *x0 = max(gx * TILE, bx0); *x1 = min(gx * TILE + TILE - 1, bx1) + 1;
    *y0 = max(gy * TILE, by0); *y1 = min(gy * TILE + TILE - 1, by1) + 1;
    return true;
}

// Voronoi: every site in samples[first, first + count) splats its distance to the pixels within
// sqrt(r2) with atom_min. Adding sites only lowers the keys, so sites are splatted once, when
// inserted, with r2 >= the covering radius of that moment (every cell they take lies inside).
__kernel void voronoi_splat(__global const float4* pos, uint W, uint H, uint K,
                            __global const float* layers, float cx, float cy, float cz, float scale,
                            __global const float4* tile_lo, __global const float4* tile_hi,
                            __global const ulong* samples, uint first, uint count,
                            float r2, int half_box, uint tiles,
                            __global ulong* vor)
{
    uint item, k, tx, ty;
    if (!splat_box(get_global_id(0), K, tiles, count, &item, &k, &tx, &ty)) return;
    uint site = first + item;
    float4 ps = pos[(uint)samples[site]];
    float2 c = layer_xy(ps, cx, cy, cz, layers + 8 * k, scale, 0.5f * (float)W, 0.5f * (float)H);
    int x0, y0, x1, y1;
    if (!tile_pixels(c, half_box, tx, ty, W, H, k, tile_lo, tile_hi, ps, r2, &x0, &y0, &x1, &y1)) return;
    ulong base = (ulong)k * W * H;
    for (int y = y0; y < y1; ++y) {
        for (int x = x0; x < x1; ++x) {
            ulong q = base + (ulong)y * W + (ulong)x;
            float4 pq = pos[q];
            if (!(pq.w > 0.0f)) continue;
            float d2 = dist2(pq, ps);
            if (d2 <= r2) {
                ulong key = ((ulong)as_uint(d2) << 32) | (ulong)site;
                if (key < vor[q]) atom_min(&vor[q], key);
            }
        }
    }
}

// Each cell's farthest pixel (ties: the larger pixel index) becomes its site's candidate.
// counters[SMP_UNREACHED] counts covered pixels no site reached (must stay 0).
__kernel void farthest(__global const float4* pos, __global const ulong* vor, uint n_pix,
                       __global ulong* cand, __global uint* counters)
{
    uint q = get_global_id(0);
    if (q >= n_pix) return;
    ulong v = vor[q];
    if (v == ALL_ONES) {
        if (pos[q].w > 0.0f) atomic_inc(&counters[SMP_UNREACHED]);
        return;
    }
    uint s = (uint)v;
    ulong key = (v & 0xFFFFFFFF00000000ul) | (ulong)q;
    if (key > cand[s]) atom_max(&cand[s], key);
}

// The largest candidate key (its high half is the largest squared radius).
__kernel void max_key(__global const ulong* cand, uint n, __global ulong* out)
{
    uint s = get_global_id(0);
    if (s >= n) return;
    ulong c = cand[s];
    if (c > *out) atom_max(out, c);
}

// Poisson conflict removal: every candidate with r2 >= thr2 (and r2 > 0) writes its key with
// atom_max into the pixels strictly inside its disc; the largest disc (then the larger pixel) wins.
__kernel void conflict_splat(__global const float4* pos, uint W, uint H, uint K,
                             __global const float* layers, float cx, float cy, float cz, float scale,
                             __global const float4* tile_lo, __global const float4* tile_hi,
                             __global const ulong* cand, uint n, float thr2, uint tiles,
                             __global ulong* conf)
{
    uint s, k, tx, ty;
    if (!splat_box(get_global_id(0), K, tiles, n, &s, &k, &tx, &ty)) return;
    ulong key = cand[s];
    float r2 = as_float((uint)(key >> 32));
    if (!(r2 >= thr2 && r2 > 0.0f)) return;
    int half_box = (int)pl_ceilf(pl_sqrtf(r2) * scale) + 3;
    float4 pc = pos[(uint)key];
    float2 c = layer_xy(pc, cx, cy, cz, layers + 8 * k, scale, 0.5f * (float)W, 0.5f * (float)H);
    int x0, y0, x1, y1;
    if (!tile_pixels(c, half_box, tx, ty, W, H, k, tile_lo, tile_hi, pc, r2, &x0, &y0, &x1, &y1)) return;
    ulong base = (ulong)k * W * H;
    for (int y = y0; y < y1; ++y) {
        for (int x = x0; x < x1; ++x) {
            ulong q = base + (ulong)y * W + (ulong)x;
            float4 pq = pos[q];
            if (!(pq.w > 0.0f)) continue;
            if (dist2(pq, pc) < r2 && key > conf[q]) atom_max(&conf[q], key);
        }
    }
}

// A candidate survives when it owns its own pixel; out[s] = its key, or 0.
// counters[SMP_ELIGIBLE] counts the candidates that passed the radius threshold.
__kernel void survive(__global const ulong* cand, uint n, float thr2, __global const ulong* conf,
                      __global ulong* out, __global uint* counters)
{
    uint s = get_global_id(0);
    if (s >= n) return;
    ulong key = cand[s];
    float r2 = as_float((uint)(key >> 32));
    bool eligible = r2 >= thr2 && r2 > 0.0f;
    if (eligible) atomic_inc(&counters[SMP_ELIGIBLE]);
    out[s] = (eligible && conf[(uint)key] == key) ? key : 0ul;
}
