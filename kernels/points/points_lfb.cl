// Point renderer, local-framebuffer variant (thesis section 5.5.5, "points-ssaa"). Built after
// keys.cl, points.cl and subsamples.cl (the per-pixel resolve). Three kernels per frame
// (paramlod/points_lfb.py drives them):
//   lfb_count  one work-item per render patch: the tiles its padded screen box touches, counted
//              per tile (an exclusive scan of those counts, pyopencl.scan, gives each tile's slot)
//   lfb_fill   one work-item per render patch: its id written into each touched tile's list
//   points_lfb one work-group per tile: every listed patch is point-rendered into a __local
//              framebuffer of PL_SS x PL_SS subsamples per pixel, then each pixel is resolved
//              (average colour of the covered subsamples, alpha = coverage, minimum depth) and
//              written with one early-depth atom_min into the shared key buffers (keys.cl).
// The numpy twin of all three is paramlod/points_reference.py: keep both in step.

// Integer twins must not depend on whether the compiler fuses a*b+c.
#pragma OPENCL FP_CONTRACT OFF

#ifndef PL_TILE
#define PL_TILE 16      // tile side in pixels (the thesis's choice; tests also use 8)
#endif
#ifndef PL_CHUNK
#define PL_CHUNK 64     // patch records staged in local memory per pass over a tile's list
#endif
#ifndef PL_LOCAL
#define PL_LOCAL 64     // work-group size of points_lfb
#endif
#define LFB_SIDE (PL_TILE * PL_SS)
#define LFB_SIZE (LFB_SIDE * LFB_SIDE)

// lfb_count / points_lfb counters (ulong): LFB_* of the prelude (paramlod.core.layouts.LFB_COUNTER)

// The tiles a patch may touch, as an inclusive rectangle (x0, y0, x1, y1) of tile indices, or
// false for none. The box holds the LOD stage's 89 samples only; between them the surface can
// bulge out by about one LOD segment (at most max(s_u, s_v) / 7 px: s is 7 x the longest
// segment), the widened range reaches widen * s further, and `margin` pixels cover the rest
// (rounding, curvature). A sample that still lands outside is counted (LFB_BBOX_MISS_SAMPLES), never hidden.
// An infinite pad means the patch touches the space behind the near plane: its projection is
// unbounded, so it goes to every tile.
inline bool tile_rect(float4 box, float4 ext, float margin, float widen, float W, float H,
                      uint tiles_x, uint tiles_y, int4* r) {
    float pad = margin + fmax(ext.z, ext.w) * (1.0f / 7.0f + widen);
    float x0 = 0.0f, y0 = 0.0f, x1 = W, y1 = H;
    if (pad < INFINITY) {
        if (!(box.x <= box.z && box.y <= box.w)) return false;   // no sample in front (or NaN)
        x0 = box.x - pad; y0 = box.y - pad; x1 = box.z + pad; y1 = box.w + pad;
        if (x1 < 0.0f || y1 < 0.0f || x0 >= W || y0 >= H) return false;
        x0 = fmax(x0, 0.0f); y0 = fmax(y0, 0.0f); x1 = fmin(x1, W); y1 = fmin(y1, H);
    }
    const float T = (float)PL_TILE;
    *r = (int4)(min((uint)floor(x0 / T), tiles_x - 1), min((uint)floor(y0 / T), tiles_y - 1),
                min((uint)floor(x1 / T), tiles_x - 1), min((uint)floor(y1 / T), tiles_y - 1));
    return true;
}

__kernel void lfb_count(__global const RenderPatch* patches, uint n_patches, __global const float* cam,
                        float margin, float widen, uint tiles_x, uint tiles_y,
                        __global int4* rects, __global uint* tile_count, __global ulong* counters)
{
    uint pid = get_global_id(0);
    if (pid >= n_patches) return;
    RenderPatch rp = patches[pid];
    int4 r;
    if (!tile_rect(rp.bbox, rp.ext, margin, widen, cam[CAM_W], cam[CAM_H], tiles_x, tiles_y, &r)) {
        rects[pid] = (int4)(0, 0, -1, -1);
        atom_add(&counters[LFB_UNPLACED_PATCHES], (ulong)1);
        return;
    }
    rects[pid] = r;
    for (int ty = r.y; ty <= r.w; ++ty)
        for (int tx = r.x; tx <= r.z; ++tx)
            atomic_inc(&tile_count[ty * tiles_x + tx]);
    atom_add(&counters[LFB_TILE_PATCH_PAIRS], (ulong)((r.z - r.x + 1) * (r.w - r.y + 1)));
}

// Each tile's list gets its patches in atomic order; the local framebuffer's atom_min and the
// resolve make the result independent of that order.
__kernel void lfb_fill(__global const int4* rects, uint n_patches, uint tiles_x,
                       __global const uint* tile_offset, __global uint* tile_fill, __global uint* pairs)
{
    uint pid = get_global_id(0);
    if (pid >= n_patches) return;
    int4 r = rects[pid];
    for (int ty = r.y; ty <= r.w; ++ty) {
        for (int tx = r.x; tx <= r.z; ++tx) {
            uint t = ty * tiles_x + tx;
            pairs[tile_offset[t] + atomic_inc(&tile_fill[t])] = pid;
        }
    }
}

__kernel __attribute__((reqd_work_group_size(PL_LOCAL, 1, 1)))
void points_lfb(__global const RenderPatch* patches, __global const int4* rects,
                __global const uint* tile_offset, __global const uint* tile_count,
                __global const uint* pairs, uint tiles_x,
                __global const float* inst_f, __global const uint* inst_u,
                __global const float* params, __global const float4* materials,
                __global const float* cam, __global const float* light,
                float factor, uint measure, float widen, uint max_side,
                __global const uint* lin, __global const uint* thr,
                __global ulong* color_buf, __global ulong* aux_buf, __global ulong* counters
#ifdef PL_RECORD
                // test hook, written by the patch's first tile only: every sample's global
                // subsample index (or ~0 if not drawable), colour key and attribute key
                , __global const uint* rec_offset, __global uint* rec_sub, __global ulong* rec_key,
                __global ulong* rec_aux
#endif
                )
{
    __local ulong lc[LFB_SIZE];        // colour keys of the subsamples
    __local ulong la[LFB_SIZE];        // attribute keys of the subsamples
    __local PointGrid cg[PL_CHUNK];    // the staged chunk: grid, patch id, instance
    __local uint cpid[PL_CHUNK], cinst[PL_CHUNK], cfirst[PL_CHUNK];
    __local uint cstart[PL_CHUNK + 1]; // exclusive prefix of the chunk's sample counts

    uint tile = get_group_id(0);
    uint n = tile_count[tile];
    if (n == 0u) return;
    uint off = tile_offset[tile];
    uint lid = get_local_id(0);
    int tx = (int)(tile % tiles_x), ty = (int)(tile / tiles_x);
    uint W = (uint)cam[CAM_W], H = (uint)cam[CAM_H];
    uint SW = W * PL_SS;               // subsample rows are W * PL_SS wide
    uint sx0 = (uint)tx * LFB_SIDE, sy0 = (uint)ty * LFB_SIDE;

    for (uint i = lid; i < LFB_SIZE; i += PL_LOCAL) { lc[i] = CLEAR_KEY; la[i] = CLEAR_KEY; }

    ulong n_samples = 0, n_unique = 0, n_nan = 0, n_miss = 0, n_local = 0, n_hits = 0, n_capped = 0;
    // a tile's list can be any length: it is processed PL_CHUNK patches per pass
    for (uint c0 = 0; c0 < n; c0 += PL_CHUNK) {
        uint m = min(n - c0, (uint)PL_CHUNK);
        barrier(CLK_LOCAL_MEM_FENCE);  // the previous chunk's records are no longer read
        for (uint i = lid; i < m; i += PL_LOCAL) {
            uint pid = pairs[off + c0 + i];
            RenderPatch rp = patches[pid];
            PointGrid g = point_grid(rp, inst_f + rp.inst * INST_F, inst_u[rp.inst * INST_U + INST_FLAGS], factor,
                                     0.0f, measure, widen, max_side);   // no thin-tube curves (direct variant only)
            int4 r = rects[pid];
            cg[i] = g; cpid[i] = pid; cinst[i] = rp.inst;
            cfirst[i] = (r.x == tx && r.y == ty) ? 1u : 0u;  // per-patch statistics counted once
            cstart[i + 1] = g.nu * g.nv;
            if (cfirst[i]) {
                n_unique += g.nu * g.nv;
                if (g.capped) n_capped++;
            }
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        if (lid == 0) {
            cstart[0] = 0u;
            for (uint i = 1; i <= m; ++i) cstart[i] += cstart[i - 1];
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        uint total = cstart[m];
        // the chunk's samples are one flat range, so small patches keep every work-item busy
        for (uint j = lid; j < total; j += PL_LOCAL) {
            uint lo = 0u, hi = m - 1u;          // the patch k with cstart[k] <= j < cstart[k + 1]
            while (lo < hi) {
                uint mid = (lo + hi + 1u) >> 1;
                if (cstart[mid] <= j) lo = mid; else hi = mid - 1u;
            }
            uint k = lo, s = j - cstart[k];
            PointGrid g = cg[k];
            uint inst = cinst[k];
            __global const float* I = inst_f + inst * INST_F;
            __global const float* P = params + inst_u[inst * INST_U + INST_PARAMS];
            uint func = inst_u[inst * INST_U + INST_FUNC];
            float u = g.u0 + g.su * (float)(s % g.nu), v = g.v0 + g.sv * (float)(s / g.nu);
            bool first = cfirst[k] != 0u;
            float fx, fy;
            n_samples++;
#ifdef PL_RECORD
            bool shade_all = first;   // the recording tile computes every sample in full
#else
            bool shade_all = false;
#endif
            if (!shade_all) {
                // most samples of a patch land in other tiles: reject them from the position
                // alone, with one subsample of slack for the last-bit difference to point_sample
                // (NaN coordinates fail every test and go on to the full sample)
                float depth;
                if (point_position(func, P, I, cam, u, v, &fx, &fy, &depth) == SAMPLE_NAN) {
                    if (first) n_nan++;
                    continue;
                }
                if (!(depth > 0.0f)) continue;   // behind the eye: point_sample clips it too
                float qx = fx * (float)PL_SS, qy = fy * (float)PL_SS;
                if (first && depth >= cam[CAM_NEAR] && depth <= cam[CAM_FAR] && fx >= 0.0f && fy >= 0.0f
                        && fx < (float)W && fy < (float)H) {
                    int4 r = rects[cpid[k]];
                    int stx = (int)(min((uint)qx, SW - 1u) / LFB_SIDE);
                    int sty = (int)(min((uint)qy, H * PL_SS - 1u) / LFB_SIDE);
                    if (stx < r.x || stx > r.z || sty < r.y || sty > r.w) n_miss++;
                }
                if (qx < (float)sx0 - 1.0f || qy < (float)sy0 - 1.0f
                        || qx >= (float)(sx0 + LFB_SIDE) + 1.0f || qy >= (float)(sy0 + LFB_SIDE) + 1.0f) continue;
            }
            ulong key, aux;
            int res = point_sample(func, P, I, cam, materials[inst], light, inst_u[inst * INST_U + INST_OBJECT],
                                   u, v, &fx, &fy, &key, &aux);
#ifdef PL_RECORD
            if (first) rec_sub[rec_offset[cpid[k]] + s] = 0xFFFFFFFFu;
#endif
            if (shade_all && res == SAMPLE_NAN) n_nan++;
            if (res != SAMPLE_DRAWN) continue;
            uint sx = min((uint)(fx * (float)PL_SS), SW - 1u);
            uint sy = min((uint)(fy * (float)PL_SS), H * PL_SS - 1u);
#ifdef PL_RECORD
            if (first) {
                uint at = rec_offset[cpid[k]] + s;
                rec_sub[at] = sy * SW + sx; rec_key[at] = key; rec_aux[at] = aux;
            }
#endif
            if (shade_all) {
                int4 r = rects[cpid[k]];
                int stx = (int)(sx / LFB_SIDE), sty = (int)(sy / LFB_SIDE);
                if (stx < r.x || stx > r.z || sty < r.y || sty > r.w) n_miss++;
            }
            if (sx - sx0 >= LFB_SIDE || sy - sy0 >= LFB_SIDE) continue;  // another tile's (unsigned wrap)
            n_hits++;
            uint li = (sy - sy0) * LFB_SIDE + (sx - sx0);
            // early depth in local memory too: no atomic for a sample that is already hidden
            if (key < lc[li]) { atom_min(&lc[li], key); n_local++; }
            if (aux < la[li]) atom_min(&la[li], aux);
        }
    }
    barrier(CLK_LOCAL_MEM_FENCE);

    // resolve: one output pixel per PL_SS x PL_SS block of covered subsamples
    ulong n_atomics = 0, n_pixels = 0, n_covered = 0;
    for (uint p = lid; p < PL_TILE * PL_TILE; p += PL_LOCAL) {
        uint px = (uint)tx * PL_TILE + p % PL_TILE, py = (uint)ty * PL_TILE + p / PL_TILE;
        if (px >= W || py >= H) continue;
        ulong k[SS_COUNT], a[SS_COUNT];
        for (uint dy = 0; dy < PL_SS; ++dy) {
            for (uint dx = 0; dx < PL_SS; ++dx) {
                uint li = ((p / PL_TILE) * PL_SS + dy) * LFB_SIDE + (p % PL_TILE) * PL_SS + dx;
                k[dy * PL_SS + dx] = lc[li];
                a[dy * PL_SS + dx] = la[li];
            }
        }
        ulong key, amin;
        uint cnt = resolve_subsamples(k, a, lin, thr, &key, &amin);
        if (cnt == 0u) continue;
        n_atomics += write_point(color_buf, aux_buf, py * W + px, key, amin);
        n_pixels++;
        n_covered += cnt;
    }
    atom_add(&counters[LFB_SAMPLES], n_samples);
    atom_add(&counters[LFB_SAMPLES_UNIQUE], n_unique);
    atom_add(&counters[LFB_NAN_SAMPLES], n_nan);
    atom_add(&counters[LFB_BBOX_MISS_SAMPLES], n_miss);
    atom_add(&counters[LFB_LOCAL_ATOMICS], n_local);
    atom_add(&counters[LFB_LOCAL_HITS], n_hits);
    atom_add(&counters[LFB_ATOMICS], n_atomics);
    atom_add(&counters[LFB_PIXELS_RESOLVED], n_pixels);
    atom_add(&counters[LFB_COVERED_SUBSAMPLES], n_covered);
    atom_add(&counters[LFB_CAPPED_PATCHES], n_capped);
}
