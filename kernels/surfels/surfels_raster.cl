// G-buffers of a triangle soup for the surfel sampler: K orthographic views of R x R pixels.
// Driven by paramlod/surfels/build/raster.py; numpy twin: paramlod/surfels/build/raster_reference.py,
// equal key for key (FP_CONTRACT off, every float expression in the twin's order, built with
// -cl-fp32-correctly-rounded-divide-sqrt; edge functions are exact 64-bit integers).
//
// gbuffer_raster: one work-item per (triangle, view). Corners go to window space with the view's
// 3 x 4 matrix (x, y in pixels with row 0 at the top, z the view depth), x and y snapped to
// 1/2^SR_SUBPIXEL_BITS pixel; every pixel centre inside or on the triangle gets
// atom_min(depth bits << 32 | triangle). No fill rule is needed: a centre on a shared edge goes
// to the nearer triangle, or the lower index at equal depth, so a closed mesh has no cracks.
// gbuffer_resolve: one work-item per pixel. The winning triangle is set up again (the same
// integers), and its exact edge functions at the pixel centre weight the corners: the position
// lies on the triangle (no extrapolation off the surface at edge-on triangles), the normal is
// turned towards the viewer.
#pragma OPENCL FP_CONTRACT OFF

#ifndef SR_SUBPIXEL_BITS
#error "build with paramlod.surfels.build.raster (SR_SUBPIXEL_BITS)"
#endif
#define SR_ONE (1L << SR_SUBPIXEL_BITS)
#define SR_HALF (SR_ONE >> 1)
#define SR_EMPTY 0xFFFFFFFFFFFFFFFFul

typedef struct { long x[3], y[3]; float z[3]; long area; } SrTri;

// Triangle t in the view of matrix A (12 floats, row-major): false when it has no area.
// Counter-clockwise and clockwise triangles alike: the area's sign is folded into the edges.
inline bool sr_setup(__global const float* P, uint t, __global const float* A, SrTri* s) {
    for (int i = 0; i < 3; i++) {
        float px = P[9 * t + 3 * i], py = P[9 * t + 3 * i + 1], pz = P[9 * t + 3 * i + 2];
        float wx = ((A[0] * px + A[1] * py) + A[2] * pz) + A[3];
        float wy = ((A[4] * px + A[5] * py) + A[6] * pz) + A[7];
        s->z[i] = ((A[8] * px + A[9] * py) + A[10] * pz) + A[11];
        s->x[i] = (long)rint(wx * (float)SR_ONE);
        s->y[i] = (long)rint(wy * (float)SR_ONE);
    }
    s->area = (s->x[1] - s->x[0]) * (s->y[2] - s->y[0]) - (s->y[1] - s->y[0]) * (s->x[2] - s->x[0]);
    return s->area != 0;
}

// Edge function of the edge opposite corner i at (px, py) (fixed point), >= 0 inside for either
// winding; the three sum to |area|.
inline long sr_edge(const SrTri* s, int i, long px, long py) {
    int a = (i + 1) % 3, b = (i + 2) % 3;
    long e = (s->x[b] - s->x[a]) * (py - s->y[a]) - (s->y[b] - s->y[a]) * (px - s->x[a]);
    return s->area < 0 ? -e : e;
}

// First and last pixel whose centre lies in [lo, hi] (fixed point), clamped to [0, n - 1].
inline int2 sr_span(long lo, long hi, int n) {
    lo = max(lo, 0L);
    int first = (int)((lo - SR_HALF + SR_ONE - 1) >> SR_SUBPIXEL_BITS);
    int last = hi < SR_HALF ? -1 : (int)min((hi - SR_HALF) >> SR_SUBPIXEL_BITS, (long)n - 1);
    return (int2)(first, last);
}

__kernel void gbuffer_raster(__global const float* P, uint n_tris, __global const float* views, uint res,
                             __global ulong* keys) {
    uint t = get_global_id(0), v = get_global_id(1);
    if (t >= n_tris) return;
    SrTri s;
    if (!sr_setup(P, t, views + 12 * v, &s)) return;
    int2 xs = sr_span(min(min(s.x[0], s.x[1]), s.x[2]), max(max(s.x[0], s.x[1]), s.x[2]), (int)res);
    int2 ys = sr_span(min(min(s.y[0], s.y[1]), s.y[2]), max(max(s.y[0], s.y[1]), s.y[2]), (int)res);
    float area = (float)(s.area < 0 ? -s.area : s.area);
    __global ulong* layer = keys + (ulong)v * res * res;
    for (int y = ys.x; y <= ys.y; y++) {
        long py = (long)y * SR_ONE + SR_HALF;
        for (int x = xs.x; x <= xs.y; x++) {
            long px = (long)x * SR_ONE + SR_HALF;
            long e0 = sr_edge(&s, 0, px, py), e1 = sr_edge(&s, 1, px, py), e2 = sr_edge(&s, 2, px, py);
            if (e0 < 0 || e1 < 0 || e2 < 0) continue;
            float d = (((float)e0 * s.z[0] + (float)e1 * s.z[1]) + (float)e2 * s.z[2]) / area;
            d = fmax(d, 0.0f);   // the views' box keeps depths positive; keys need it
            atom_min(layer + (ulong)y * res + x, ((ulong)as_uint(d) << 32) | t);
        }
    }
}

// Pixel q = (v R + row) R + x: position (w = 1 where covered), unit normal towards the viewer
// (view v looks along dirs[v]), colour; zeros where no triangle covers the centre.
__kernel void gbuffer_resolve(__global const ulong* keys, uint n_pix, uint res, __global const float* views,
                              __global const float* dirs, __global const float* P, __global const float* N,
                              __global const float* C, __global float4* pos, __global float* nrm,
                              __global float4* col) {
    uint q = get_global_id(0);
    if (q >= n_pix) return;
    ulong key = keys[q];
    if (key == SR_EMPTY) {
        pos[q] = (float4)(0.0f);
        vstore3((float3)(0.0f), q, nrm);
        col[q] = (float4)(0.0f);
        return;
    }
    uint t = (uint)key, v = q / (res * res), rest = q - v * res * res;
    SrTri s;
    sr_setup(P, t, views + 12 * v, &s);
    long px = (long)(rest % res) * SR_ONE + SR_HALF, py = (long)(rest / res) * SR_ONE + SR_HALF;
    float area = (float)(s.area < 0 ? -s.area : s.area);
    float w[3];
    for (int i = 0; i < 3; i++) w[i] = (float)sr_edge(&s, i, px, py) / area;
    float3 p = (float3)(0.0f), n = (float3)(0.0f);
    float4 c = (float4)(0.0f);
    for (int i = 0; i < 3; i++) {
        p += w[i] * vload3(3 * t + i, P);
        n += w[i] * vload3(3 * t + i, N);
        c += w[i] * vload4(3 * t + i, C);
    }
    float3 d = vload3(v, dirs);
    float len = length(n);
    n = len > 1e-20f ? n / len : -d;
    if (dot(n, d) > 0.0f) n = -n;
    pos[q] = (float4)(p, 1.0f);
    vstore3(n, q, nrm);
    col[q] = c;
}
