// Occlusion culling of render patches for the direct point renderer, in two phases (docs/points.md,
// "Occlusion culling"; the scheme of Nanite's two-pass culling), tile by tile: each patch's
// sampling grid is cut into up to 8 x 8 tiles on GPUs (points.cl tiles_along, tile_span). Host:
// paramlod/renderers/occlusion.py; numpy twin: paramlod/renderers/occlusion_reference.py. Built
// into the program of points.cl.
//
// A depth pyramid holds, per texel, the largest depth (the high word of the colour key, the float
// bits of the linear view depth, keys.cl) of the keys it covers: level 0 is 2x2 keys a texel, each
// next level 2x2 texels of the one before. An empty key (all ones) makes its texels 0xFFFFFFFF, so
// nothing behind an empty pixel is ever culled. A tile is occluded when its nearest possible
// depth is behind the largest depth of every key its screen box touches: every sample it could
// write then loses the atom_min, so culling it changes no key.
//   phase 1 (occlusion_first): test every tile of every render patch against the previous frame's
//     pyramid (a guess: the camera or the scene may have moved); draw the ones that pass, defer the
//     others.
//   phase 2 (occlusion_second): after the first draw, test the deferred tiles against a pyramid
//     of this frame's keys (exact: keys only get nearer) and draw the ones that pass.
// A patch is listed in a phase with a 64-bit mask of its tiles to draw (points_schedule).

#define OCC_NODES 3    // positions per side of a tile's bound (paramlod/renderers/occlusion.py NODES)
#define OCC_FLOATS 8   // floats per bound: x0, y0, x1, y1 (pixels), near depth, 3 unused
#define OCC_LOCAL 64   // work-group of the phase kernels: one work-item a tile (at most 8 x 8)

// Level l of a W x H key image: ceil(W / 2^(l+1)) x ceil(H / 2^(l+1)) texels, levels one after another.
inline uint level_size(uint n, uint l) { return (n + (2u << l) - 1u) >> (l + 1u); }

// Level 0 from the colour keys: the largest depth word of each 2x2 block (keys outside the image
// are left out: no sample lands there).
__kernel void pyramid_base(__global const ulong* keys, uint W, uint H, __global uint* level0)
{
    uint w0 = level_size(W, 0u), h0 = level_size(H, 0u);
    uint t = get_global_id(0);
    if (t >= w0 * h0) return;
    uint x = (t % w0) * 2u, y = (t / w0) * 2u;
    uint m = 0u;
    for (uint dy = 0u; dy < 2u; ++dy)
        for (uint dx = 0u; dx < 2u; ++dx)
            if (x + dx < W && y + dy < H) m = max(m, (uint)(keys[(y + dy) * W + x + dx] >> 32));
    level0[t] = m;
}

// Level l + 1 (at dst in `pyramid`) from level l (wi x hi texels at src).
__kernel void pyramid_reduce(__global uint* pyramid, uint src, uint wi, uint hi, uint dst)
{
    uint wo = (wi + 1u) / 2u, ho = (hi + 1u) / 2u;
    uint t = get_global_id(0);
    if (t >= wo * ho) return;
    uint x = (t % wo) * 2u, y = (t / wo) * 2u;
    uint m = 0u;
    for (uint dy = 0u; dy < 2u; ++dy)
        for (uint dx = 0u; dx < 2u; ++dx)
            if (x + dx < wi && y + dy < hi) m = max(m, pyramid[src + (y + dy) * wi + x + dx]);
    pyramid[dst + t] = m;
}

// A screen box and nearest depth that hold every sample (and quad corner, and pixel-centre cell)
// of one tile of a patch as point_grid samples it: the view-space box of OCC_NODES x OCC_NODES
// positions over the tile's lines and one line more on each side (clamped to the grid: those
// hold its quads' far corners and its samples' cells), grown on every side by the longest edge
// between them (a patch bulging farther than that between them would have been split by the LOD
// stage, whose 9 x 9 measure is finer), projected. near = 0 (never occluded) where a position is
// NaN or the box reaches the near plane.
typedef struct { float x0, y0, x1, y1, near; } TileBound;

inline float grid_line(float x0, float x1, uint n, uint na, float a, float m, uint t, uint k, uint end) {
    uint i = end ? min((k + 1u) * n / t, n - 1u) : (k * n / t > 0u ? k * n / t - 1u : 0u);
    return grid_at(x0, x1, n, na, a, m, i);
}

inline TileBound tile_bound(PointGrid g, uint tu, uint tv, uint tile, uint func, __global const float* P,
                            __global const float* I, __global const float* cam) {
    __global const float* V = cam + CAM_VIEW;
    uint tx = tile % tu, ty = tile / tu;
    float u0 = grid_line(g.u0, g.u1, g.nu_grid, g.nau, g.au, g.su, tu, tx, 0u);
    float u1 = grid_line(g.u0, g.u1, g.nu_grid, g.nau, g.au, g.su, tu, tx, 1u);
    float v0 = grid_line(g.v0, g.v1, g.nv_grid, g.nav, g.av, g.sv, tv, ty, 0u);
    float v1 = grid_line(g.v0, g.v1, g.nv_grid, g.nav, g.av, g.sv, tv, ty, 1u);
    float3 lo = (float3)(INFINITY), hi = (float3)(-INFINITY);
    float3 row[OCC_NODES];
    float edge = 0.0f;
    bool bad = false;
    for (uint j = 0u; j < OCC_NODES; ++j) {
        float v = v0 + (v1 - v0) * ((float)j / (float)(OCC_NODES - 1));
        float3 left = (float3)(0.0f);
        for (uint i = 0u; i < OCC_NODES; ++i) {
            float u = u0 + (u1 - u0) * ((float)i / (float)(OCC_NODES - 1));
            float3 p = pl_position(func, u, v, P);
            bad = bad || is_bad3(p);
            float3 e = xform_point(V, xform_point(I + INST_MODEL, p));
            lo = fmin(lo, e); hi = fmax(hi, e);
            if (i > 0u) edge = fmax(edge, length(e - left));
            if (j > 0u) edge = fmax(edge, length(e - row[i]));
            row[i] = e; left = e;
        }
    }
    // the longest edge, and float rounding of positions this far from the eye
    float grow = edge + 1e-5f * fmax(length(lo), length(hi));
    lo -= grow; hi += grow;
    TileBound b;
    b.near = -hi.z;   // view space looks down -z
    float W = cam[CAM_W], H = cam[CAM_H];
    b.x0 = 0.0f; b.y0 = 0.0f; b.x1 = W; b.y1 = H;
    if (bad || !(b.near > cam[CAM_NEAR])) {
        b.near = 0.0f;
    } else {
        b.x0 = INFINITY; b.y0 = INFINITY; b.x1 = -INFINITY; b.y1 = -INFINITY;
        for (uint k = 0u; k < 8u; ++k) {
            float3 c = (float3)((k & 1u) ? hi.x : lo.x, (k & 2u) ? hi.y : lo.y, (k & 4u) ? hi.z : lo.z);
            float4 q = project(cam, c);
            float x = (q.x / q.w * 0.5f + 0.5f) * W, y = (0.5f - q.y / q.w * 0.5f) * H;
            b.x0 = fmin(b.x0, x); b.x1 = fmax(b.x1, x); b.y0 = fmin(b.y0, y); b.y1 = fmax(b.y1, y);
        }
    }
    return b;
}

// Whether a bound is behind every key of its box in a pyramid of a W x H key image: the level
// whose texels cover the box (one pixel more on each side) with at most 2 x 2 of them.
inline bool occluded(TileBound b, __global const uint* pyramid, uint W, uint H, uint levels)
{
    uint near = as_uint(b.near);
    if (near == 0u) return false;
    int x0 = (int)floor(b.x0) - 1, x1 = (int)floor(b.x1) + 1;
    int y0 = (int)floor(b.y0) - 1, y1 = (int)floor(b.y1) + 1;
    uint ux0 = (uint)clamp(x0, 0, (int)W - 1), ux1 = (uint)clamp(x1, 0, (int)W - 1);
    uint uy0 = (uint)clamp(y0, 0, (int)H - 1), uy1 = (uint)clamp(y1, 0, (int)H - 1);
    uint offset = 0u;
    for (uint l = 0u; l < levels; ++l) {
        uint wl = level_size(W, l);
        uint tx0 = ux0 >> (l + 1u), tx1 = ux1 >> (l + 1u), ty0 = uy0 >> (l + 1u), ty1 = uy1 >> (l + 1u);
        if (tx1 - tx0 <= 1u && ty1 - ty0 <= 1u) {
            uint m = max(max(pyramid[offset + ty0 * wl + tx0], pyramid[offset + ty0 * wl + tx1]),
                         max(pyramid[offset + ty1 * wl + tx0], pyramid[offset + ty1 * wl + tx1]));
            return near > m;
        }
        offset += wl * level_size(H, l);
    }
    return false;   // larger than the pyramid's top level allows
}

// The sampling grid and tiles of one listed patch, as points_direct draws them.
typedef struct { PointGrid g; uint tu, tv, func; __global const float* P; __global const float* I; } PatchTiles;

inline PatchTiles patch_tiles(RenderPatch rp, __global const float* inst_f, __global const uint* inst_u,
                              __global const float* params, float factor, uint measure, float widen, uint max_side) {
    PatchTiles t;
    t.I = inst_f + rp.inst * INST_F;
    __global const uint* U = inst_u + rp.inst * INST_U;
    t.func = U[INST_FUNC];
    t.P = params + U[INST_PARAMS];
    t.g = point_grid(rp, t.I, U[INST_FLAGS], factor, measure, widen, max_side);
    t.tu = tiles_along(t.g.nu_grid);
    t.tv = tiles_along(t.g.nv_grid);
    return t;
}

// Phase 1: every tile of every render patch against the previous frame's pyramid (levels 0: none,
// draw everything); one work-group a patch, one work-item a tile. A patch with tiles to draw now
// goes to `early` with their mask, one with deferred tiles to `deferred` with theirs (both is
// possible). counts: [0] patches listed in early, [1] in deferred, [2] in late (phase 2), [3] tiles
// deferred, [4] tiles drawn in phase 2; zeroed by the host.
__kernel __attribute__((reqd_work_group_size(OCC_LOCAL, 1, 1)))
void occlusion_first(__global const RenderPatch* patches, __global const uint* count, uint count_at,
                     uint capacity, __global const float* inst_f, __global const uint* inst_u,
                     __global const float* params, __global const float* cam, float factor, uint measure,
                     float widen, uint max_side, __global const uint* pyramid, uint levels,
                     __global RenderPatch* early, __global ulong* early_masks, __global uint* deferred,
                     __global ulong* deferred_masks, __global uint* counts)
{
    __local uint bits[4];   // drawn, deferred: low and high words
    uint n = min(count[count_at], capacity);
    uint W = (uint)cam[CAM_W], H = (uint)cam[CAM_H], slot = get_local_id(0);
    for (uint pid = get_group_id(0); pid < n; pid += get_num_groups(0)) {
        if (slot < 4u) bits[slot] = 0u;
        barrier(CLK_LOCAL_MEM_FENCE);
        RenderPatch rp = patches[pid];
        PatchTiles t = patch_tiles(rp, inst_f, inst_u, params, factor, measure, widen, max_side);
        if (slot < t.tu * t.tv) {
            bool hidden = levels && occluded(tile_bound(t.g, t.tu, t.tv, slot, t.func, t.P, t.I, cam), pyramid, W, H,
                                             levels);
            atomic_or(&bits[(hidden ? 2u : 0u) + slot / 32u], 1u << (slot % 32u));
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        if (slot == 0u) {
            ulong drawn = (ulong)bits[1] << 32 | bits[0], later = (ulong)bits[3] << 32 | bits[2];
            if (drawn) {
                uint i = atomic_inc(&counts[0]);
                early[i] = rp; early_masks[i] = drawn;
            }
            if (later) {
                uint i = atomic_inc(&counts[1]);
                deferred[i] = pid; deferred_masks[i] = later;
                atomic_add(&counts[3], (uint)popcount(later));
            }
        }
        barrier(CLK_LOCAL_MEM_FENCE);   // before the next patch clears `bits`
    }
}

// Phase 2: the deferred tiles against this frame's pyramid; patches with tiles that pass go to
// `late` with their mask.
__kernel __attribute__((reqd_work_group_size(OCC_LOCAL, 1, 1)))
void occlusion_second(__global const RenderPatch* patches, __global const float* inst_f,
                      __global const uint* inst_u, __global const float* params, __global const float* cam,
                      float factor, uint measure, float widen, uint max_side, __global const uint* pyramid,
                      uint levels, __global const uint* deferred, __global const ulong* deferred_masks,
                      __global RenderPatch* late, __global ulong* late_masks, __global uint* counts)
{
    __local uint bits[2];
    uint n = counts[1];
    uint W = (uint)cam[CAM_W], H = (uint)cam[CAM_H], slot = get_local_id(0);
    for (uint i = get_group_id(0); i < n; i += get_num_groups(0)) {
        if (slot < 2u) bits[slot] = 0u;
        barrier(CLK_LOCAL_MEM_FENCE);
        RenderPatch rp = patches[deferred[i]];
        ulong mask = deferred_masks[i];
        if ((mask >> slot) & 1ul) {
            PatchTiles t = patch_tiles(rp, inst_f, inst_u, params, factor, measure, widen, max_side);
            if (!occluded(tile_bound(t.g, t.tu, t.tv, slot, t.func, t.P, t.I, cam), pyramid, W, H, levels))
                atomic_or(&bits[slot / 32u], 1u << (slot % 32u));
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        if (slot == 0u) {
            ulong drawn = (ulong)bits[1] << 32 | bits[0];
            if (drawn) {
                uint k = atomic_inc(&counts[2]);
                late[k] = rp; late_masks[k] = drawn;
                atomic_add(&counts[4], (uint)popcount(drawn));
            }
        }
        barrier(CLK_LOCAL_MEM_FENCE);
    }
}

// Tests: the bounds of every tile of the first n render patches (out: OCC_LOCAL bounds of
// OCC_FLOATS a patch, slots past its tiles zero).
__kernel void occlusion_bounds(__global const RenderPatch* patches, uint n, __global const float* inst_f,
                               __global const uint* inst_u, __global const float* params,
                               __global const float* cam, float factor, uint measure, float widen, uint max_side,
                               __global float* out)
{
    uint k = get_global_id(0);
    if (k >= n * OCC_LOCAL) return;
    uint pid = k / OCC_LOCAL, slot = k % OCC_LOCAL;
    PatchTiles t = patch_tiles(patches[pid], inst_f, inst_u, params, factor, measure, widen, max_side);
    __global float* o = out + k * OCC_FLOATS;
    TileBound b = {0.0f, 0.0f, 0.0f, 0.0f, 0.0f};
    if (slot < t.tu * t.tv) b = tile_bound(t.g, t.tu, t.tv, slot, t.func, t.P, t.I, cam);
    o[0] = b.x0; o[1] = b.y0; o[2] = b.x1; o[3] = b.y1; o[4] = b.near;
    o[5] = 0.0f; o[6] = 0.0f; o[7] = 0.0f;
}
