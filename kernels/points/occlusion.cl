// Occlusion culling of render patches for the direct point renderer, in two phases (docs/points.md,
// "Occlusion culling"; the scheme of Nanite's two-pass culling). Host: paramlod/renderers/occlusion.py;
// numpy twin: paramlod/renderers/occlusion_reference.py. Built into the program of points.cl.
//
// A depth pyramid holds, per texel, the largest depth (the high word of the colour key, the float
// bits of the linear view depth, keys.cl) of the keys it covers: level 0 is 2x2 keys a texel, each
// next level 2x2 texels of the one before. An empty key (all ones) makes its texels 0xFFFFFFFF, so
// nothing behind an empty pixel is ever culled. A patch is occluded when its nearest possible
// depth is behind the largest depth of every key its screen box touches: every sample it could
// write then loses the atom_min, so culling it changes no key.
//   phase 1 (occlusion_first): test every render patch against the previous frame's pyramid (a
//     guess: the camera or the scene may have moved); draw the ones that pass, defer the others.
//   phase 2 (occlusion_second): after the first draw, test the deferred patches against a pyramid
//     of this frame's keys (exact: keys only get nearer) and draw the ones that pass.

// From the host (paramlod/renderers/occlusion.py occlusion_cl_defines): OCC_GRID positions per side
// of a patch's bound; OCC_FLOATS floats per bound (x0, y0, x1, y1 in pixels, near depth, 3 unused);
// OCC_SPAN texels per side of the box's level at most (8 on CPUs, 2 on GPUs).
#ifndef OCC_GRID
#error "build occlusion.cl with paramlod.renderers.occlusion.occlusion_cl_defines()"
#endif

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

// A screen box and nearest depth that hold every sample the point renderer takes of the patch
// (points.cl point_grid: the range widened by `widen` per side, clamped to the domain): the view-
// space box of an OCC_GRID x OCC_GRID grid of positions, grown on every side by the longest grid
// edge (a patch bulging farther than that between grid lines would have been split by the LOD
// stage, whose 9 x 9 measure is finer), projected. near = 0 (never occluded) where a position is
// NaN or the box reaches the near plane.
inline void patch_bound(RenderPatch rp, uint func, __global const float* P, __global const float* I,
                        __global const float* cam, float widen, __global float* out)
{
    __global const float* V = cam + CAM_VIEW;
    float4 r = sampled_range(rp.range, I, widen);
    float u0 = r.x, u1 = r.y, v0 = r.z, v1 = r.w;
    float3 lo = (float3)(INFINITY), hi = (float3)(-INFINITY);
    float3 row[OCC_GRID];
    float edge = 0.0f;
    bool bad = false;
    for (uint j = 0u; j < OCC_GRID; ++j) {
        float v = v0 + (v1 - v0) * ((float)j / (float)(OCC_GRID - 1));
        float3 left = (float3)(0.0f);
        for (uint i = 0u; i < OCC_GRID; ++i) {
            float u = u0 + (u1 - u0) * ((float)i / (float)(OCC_GRID - 1));
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
    float near = -hi.z;   // view space looks down -z
    float W = cam[CAM_W], H = cam[CAM_H];
    float x0 = 0.0f, y0 = 0.0f, x1 = W, y1 = H;
    if (bad || !(near > cam[CAM_NEAR])) {
        near = 0.0f;
    } else {
        x0 = INFINITY; y0 = INFINITY; x1 = -INFINITY; y1 = -INFINITY;
        for (uint k = 0u; k < 8u; ++k) {
            float3 c = (float3)((k & 1u) ? hi.x : lo.x, (k & 2u) ? hi.y : lo.y, (k & 4u) ? hi.z : lo.z);
            float4 q = project(cam, c);
            float x = (q.x / q.w * 0.5f + 0.5f) * W, y = (0.5f - q.y / q.w * 0.5f) * H;
            x0 = fmin(x0, x); x1 = fmax(x1, x); y0 = fmin(y0, y); y1 = fmax(y1, y);
        }
    }
    out[0] = x0; out[1] = y0; out[2] = x1; out[3] = y1; out[4] = near;
    out[5] = 0.0f; out[6] = 0.0f; out[7] = 0.0f;
}

// Whether a bound is behind every key of its box in a pyramid of a W x H key image: the finest
// level whose texels cover the box (one pixel more on each side) with at most OCC_SPAN x OCC_SPAN
// of them. With 2 x 2, as Nanite tests, coarse texels reached past the seashells' whorls to the
// background: a static camera culled 13 % of their samples, 8 x 8 26 %, where the keys showed
// 30 % culled by such a box at full resolution. GPUs keep 2 x 2 (occlusion_span).
inline bool occluded(__global const float* b, __global const uint* pyramid, uint W, uint H, uint levels)
{
    uint near = as_uint(b[4]);
    if (near == 0u) return false;
    int x0 = (int)floor(b[0]) - 1, x1 = (int)floor(b[2]) + 1;
    int y0 = (int)floor(b[1]) - 1, y1 = (int)floor(b[3]) + 1;
    uint ux0 = (uint)clamp(x0, 0, (int)W - 1), ux1 = (uint)clamp(x1, 0, (int)W - 1);
    uint uy0 = (uint)clamp(y0, 0, (int)H - 1), uy1 = (uint)clamp(y1, 0, (int)H - 1);
    uint offset = 0u;
    for (uint l = 0u; l < levels; ++l) {
        uint wl = level_size(W, l);
        uint tx0 = ux0 >> (l + 1u), tx1 = ux1 >> (l + 1u), ty0 = uy0 >> (l + 1u), ty1 = uy1 >> (l + 1u);
        if (tx1 - tx0 < (uint)OCC_SPAN && ty1 - ty0 < (uint)OCC_SPAN) {
            for (uint ty = ty0; ty <= ty1; ++ty)
                for (uint tx = tx0; tx <= tx1; ++tx)
                    if (near <= pyramid[offset + ty * wl + tx]) return false;
            return true;
        }
        offset += wl * level_size(H, l);
    }
    return false;   // larger than the pyramid's top level allows
}

// Phase 1: bound every render patch (kept for phase 2) and test it against the previous frame's
// pyramid (levels 0: none, draw everything). counts: OCC_EARLY patches drawn now (copied to
// `early`), OCC_DEFERRED (their indices in `deferred`), OCC_LATE drawn in phase 2 (the prelude's
// OCC_COUNTER); zeroed by the host.
__kernel void occlusion_first(__global const RenderPatch* patches, __global const uint* count, uint count_at,
                              uint capacity, __global const float* inst_f, __global const uint* inst_u,
                              __global const float* params, __global const float* cam, float widen,
                              __global const uint* pyramid, uint levels,
                              __global float* bounds, __global RenderPatch* early, __global uint* deferred,
                              __global uint* counts)
{
    uint n = min(count[count_at], capacity);
    uint W = (uint)cam[CAM_W], H = (uint)cam[CAM_H];
    for (uint pid = get_global_id(0); pid < n; pid += get_global_size(0)) {
        RenderPatch rp = patches[pid];
        __global const float* I = inst_f + rp.inst * INST_F;
        uint func = inst_u[rp.inst * INST_U + INST_FUNC];
        __global const float* P = params + inst_u[rp.inst * INST_U + INST_PARAMS];
        __global float* b = bounds + pid * OCC_FLOATS;
        patch_bound(rp, func, P, I, cam, widen, b);
        if (levels && occluded(b, pyramid, W, H, levels)) deferred[atomic_inc(&counts[OCC_DEFERRED])] = pid;
        else early[atomic_inc(&counts[OCC_EARLY])] = rp;
    }
}

// Phase 2: the deferred patches against this frame's pyramid; the ones that pass go to `late`.
__kernel void occlusion_second(__global const RenderPatch* patches, __global const float* cam,
                               __global const uint* pyramid, uint levels, __global const float* bounds,
                               __global const uint* deferred, __global RenderPatch* late, __global uint* counts)
{
    uint n = counts[OCC_DEFERRED];
    uint W = (uint)cam[CAM_W], H = (uint)cam[CAM_H];
    for (uint i = get_global_id(0); i < n; i += get_global_size(0)) {
        uint pid = deferred[i];
        if (!occluded(bounds + pid * OCC_FLOATS, pyramid, W, H, levels)) late[atomic_inc(&counts[OCC_LATE])] = patches[pid];
    }
}
