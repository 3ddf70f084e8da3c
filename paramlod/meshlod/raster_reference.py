"""numpy twin of the mesh rasterizer (kernels/meshlod/raster.cl, driven by paramlod.meshlod.raster):
the selected clusters' triangles drawn into colour and aux keys that equal the kernel's bit for bit.

Every float operation is the kernel's, in float32 and in its order (the kernel turns FP_CONTRACT
off and divides and takes square roots correctly rounded); the edge functions are the same exact
64-bit integers. Where the kernel calls an OpenCL built-in whose rounding the standard leaves to
the device, the twin uses what PoCL computes, measured on 2^20 random inputs each: ``dot`` is
``(x0 y0 + x1 y1) + x2 y2``, ``length`` is ``sqrt(dot(x, x))`` and ``normalize(x)`` is
``x * (1 / sqrt(dot(x, x)))`` (NVIDIA's OpenCL on an H200 gave the same keys in
tests/meshlod/test_raster.py). The shading is keys.cl ``shade()`` (common/shading.cl), the debug
colours kernels/common/debug_color.cl.

The constants the kernel is built with live here (``SUBPIXEL_BITS``, ``GUARD_PIXELS``): the host
passes them to the compiler. Several views (``rasterize_views``): layer v holds the one-view raster
of camera v over the pairs whose view mask has bit v, which is what the kernel computes per view. Used by tests/meshlod/test_raster.py; small frames only (one Python
step per clipped triangle, vectorized over the pixels of the rest).
"""
from __future__ import annotations

import numpy as np

from paramlod.core.color import srgb8_thresholds
from paramlod.core.layouts import CAMERA, INSTANCE_F, INSTANCE_U, camera_record
from paramlod.core.views import as_views
from paramlod.renderers.shading import LIGHT
from paramlod.core.debug_colors import cluster_color, level_color
from paramlod.core.hashing import dither

SUBPIXEL_BITS = 8            # snapping grid: 1/256 pixel
GUARD_PIXELS = 2 ** 20       # guard band around the screen's centre; keeps edge functions < 2^60
ALL_ONES = np.uint64(0xFFFFFFFFFFFFFFFF)

_f = np.float32
_ONE = 1 << SUBPIXEL_BITS
_HALF = _ONE // 2
_SRGB8 = srgb8_thresholds()
_VIEW, _PROJ = CAMERA.slice("view"), CAMERA.slice("proj")


# --- float32 helpers in the kernel's order ---------------------------------------------------------
def _dot(a, b):
    return (a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]) + a[..., 2] * b[..., 2]


def _normalize(x):
    """PoCL's normalize (see the module's docstring)."""
    return x * (_f(1) / np.sqrt(_dot(x, x)))[..., None]


def _point(m, p):
    """rs_point: rows of m (float32 [..., 12+]) applied to points p (float32 [..., 3])."""
    return np.stack([((m[..., 4 * r] * p[..., 0] + m[..., 4 * r + 1] * p[..., 1]) + m[..., 4 * r + 2] * p[..., 2])
                     + m[..., 4 * r + 3] for r in range(3)], axis=-1)


def _dir(m, d):
    return np.stack([(m[..., 4 * r] * d[..., 0] + m[..., 4 * r + 1] * d[..., 1]) + m[..., 4 * r + 2] * d[..., 2]
                     for r in range(3)], axis=-1)


def _row(P, r, e):
    return ((P[4 * r] * e[..., 0] + P[4 * r + 1] * e[..., 1]) + P[4 * r + 2] * e[..., 2]) + P[4 * r + 3]


def _plane(k, e, P, near, gx, gy):
    """rs_plane: distance of view-space points e to clip plane k (>= 0 inside)."""
    if k == 0:
        return -e[..., 2] - near
    cw = _row(P, 3, e)
    return [None, gx * cw - _row(P, 0, e), gx * cw + _row(P, 0, e), gy * cw - _row(P, 1, e),
            gy * cw + _row(P, 1, e)][k]


def _clip(es, ns, k, P, near, gx, gy):
    """rs_clip: Sutherland-Hodgman of the polygon (lists of float32 [3]) against plane k."""
    dist = [_plane(k, e, P, near, gx, gy) for e in es]
    if all(d >= 0 for d in dist):
        return es, ns
    oe, on = [], []
    n = len(es)
    for i in range(n):
        j = 0 if i + 1 == n else i + 1
        ia, ib = dist[i] >= 0, dist[j] >= 0
        if ia:
            oe.append(es[i])
            on.append(ns[i])
        if ia != ib:
            a, b = (i, j) if ia else (j, i)
            t = dist[a] / (dist[a] - dist[b])
            e = es[a] + t * (es[b] - es[a])
            if k == 0:
                e = e.copy()
                e[2] = -near
            oe.append(e)
            on.append(ns[a] + t * (ns[b] - ns[a]))
    return oe, on


def _srgb8(x):
    """keys.cl srgb8(): the count of SRGB8_THRESHOLDS[1:] at or below x (0 for NaN), here by a
    binary search; the kernel reads it from its bucket table (tests/renderers/test_points.py)."""
    k = np.zeros(x.shape, np.int64)
    step = 128
    while step:
        k = np.where(_SRGB8[k + step] <= x, k + step, k)
        step >>= 1
    return k.astype(np.uint64)


def _oct10(n):
    s = (np.abs(n[..., 0]) + np.abs(n[..., 1])) + np.abs(n[..., 2])
    px, py = n[..., 0] / s, n[..., 1] / s
    neg = n[..., 2] < 0
    sx = np.where(px >= 0, _f(1), _f(-1))
    sy = np.where(py >= 0, _f(1), _f(-1))
    px, py = (np.where(neg, (_f(1) - np.abs(py)) * sx, px), np.where(neg, (_f(1) - np.abs(px)) * sy, py))

    def code(p):
        v = ((p * _f(511.5)) + _f(511.5)) + _f(0.5)
        return np.minimum(np.maximum(v, _f(0)), _f(1023)).astype(np.uint64)

    return (code(px) << np.uint64(10)) | code(py)


def shade(n_view, ev, mat, light):
    """keys.cl shade() in float32: (sRGB RGBA8 word uint64, viewer-facing unit normal)."""
    ln = np.sqrt(_dot(n_view, n_view))
    ok = (ln > _f(1e-30)) & ~np.isnan(ln)
    with np.errstate(all="ignore"):
        n = np.where(ok[..., None], n_view / np.where(ok, ln, _f(1))[..., None], ev)
    n = np.where((_dot(n, ev) < 0)[..., None], -n, n)
    L = np.asarray(light[:3], np.float32)
    amb = _f(light[3])
    diff = np.fmax(_dot(n, np.broadcast_to(L, n.shape)), _f(0))
    c = np.fmax(_dot(n, _normalize(L + ev)), _f(0))
    c4 = (c * c) * (c * c)
    c16 = (c4 * c4) * (c4 * c4)
    spec = ((mat[..., 3] * c16) * c16) * c16
    rgb = mat[..., :3] * (amb + (_f(1) - amb) * diff)[..., None] + spec[..., None]
    code = _srgb8(rgb)
    word = (code[..., 0] << np.uint64(24)) | (code[..., 1] << np.uint64(16)) | (code[..., 2] << np.uint64(8))
    return word | np.uint64(255), n


def materials(instances, clusters, inst, cluster, color_by: int) -> np.ndarray:
    """rs_material: float32 [n, 4] (RGB, specular) of (instance, global cluster) pairs."""
    m = np.asarray(instances.materials, np.float32)[inst].copy()
    if color_by == 1:
        m[:, :3] = cluster_color(cluster)
    elif color_by == 2:
        m[:, :3] = level_color(clusters["level"][cluster])
    return m


# --- the rasterizer ------------------------------------------------------------------------------------
def _cam(camera):
    return camera_record(camera) if hasattr(camera, "view") else np.asarray(camera, np.float32)


def selected_triangles(arrays, pairs):
    """(instance, cluster, global triangle) per triangle of the selected (instance, cluster) pairs,
    in selection order."""
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    cl = arrays.clusters
    counts = cl["count"][pairs[:, 1]].astype(np.int64)
    starts = np.cumsum(counts) - counts
    k = np.arange(int(counts.sum())) - np.repeat(starts, counts)
    tri = np.repeat(cl["first"][pairs[:, 1]].astype(np.int64), counts) + k
    return np.repeat(pairs[:, 0], counts), np.repeat(pairs[:, 1], counts), tri


def rasterize(width, height, camera, arrays, instances, pairs, light=LIGHT, color_by: int = 0, weights=None):
    """(colour keys, aux keys), uint64 [height, width]: the triangles of the selected (instance,
    cluster) ``pairs`` of ``arrays`` (MeshArrays) and ``instances`` (MeshInstances) drawn into
    cleared keys, as raster_clusters and raster_large draw them; ``weights``: the instances'
    hand-off weights (None: all 1), an instance of weight w < 1 drawing the pixels of dither < w."""
    d = rasterize_detail(width, height, camera, arrays, instances, pairs, light, color_by, weights=weights)
    return d["color"], d["aux"]


def rasterize_detail(width, height, camera, arrays, instances, pairs, light=LIGHT, color_by: int = 0,
                     large_pixels: int | None = None, weights=None) -> dict:
    """``rasterize`` with what the kernels count: {"color", "aux", "coverage" (uint32 [h, w]:
    fragments that covered each pixel, depth in range), "counters": {"triangles", "near_clipped",
    "culled", "pixels", "large" when ``large_pixels`` (the kernel's threshold) is given, and
    "guard_clipped", which the kernel does not count: triangles cut by the guard band's sides}}."""
    cam = _cam(camera)
    W, H = int(width), int(height)
    if (int(cam[CAMERA.offset("w")]), int(cam[CAMERA.offset("h")])) != (W, H):
        raise ValueError(f"the camera record is {int(cam[CAMERA.offset('w')])}x{int(cam[CAMERA.offset('h')])}, "
                         f"not {W}x{H}")
    V, P = cam[_VIEW], cam[_PROJ]
    Wf, Hf = _f(cam[CAMERA.offset("w")]), _f(cam[CAMERA.offset("h")])
    near, far = _f(cam[CAMERA.offset("near")]), _f(cam[CAMERA.offset("far")])
    gx, gy = _f(2 * GUARD_PIXELS) / Wf, _f(2 * GUARD_PIXELS) / Hf
    light = np.asarray(light, np.float32)

    inst, clus, tri = selected_triangles(arrays, pairs)
    T = len(tri)
    idx = arrays.triangles.reshape(-1, 3)[tri].astype(np.int64)                 # [T, 3]
    M = instances.inst_f[inst][:, INSTANCE_F.slice("model")].astype(np.float32)[:, None, :]
    N = instances.inst_f[inst][:, INSTANCE_F.slice("normal")].astype(np.float32)[:, None, :]
    with np.errstate(all="ignore"):
        e = _point(V, _point(M, arrays.vertices[idx][..., :3].astype(np.float32)))   # [T, 3, 3]
        nv = _dir(V, _dir(N, arrays.normals[idx][..., :3].astype(np.float32)))
        bad = ~(np.isfinite(e).all(axis=(1, 2)) & np.isfinite(nv).all(axis=(1, 2)))
        beyond = (-e[..., 2] > far).all(axis=1)
        dn = _plane(0, e, P, near, gx, gy)
        near_clipped = (dn < 0).any(axis=1) & (dn >= 0).any(axis=1) & ~bad & ~beyond
        inside = np.ones(T, bool)
        for k in range(5):
            inside &= (_plane(k, e, P, near, gx, gy) >= 0).all(axis=1)
    live = ~bad & ~beyond

    # fan triangles (0, j, j + 1) of each polygon: source triangle, j, three view positions and normals
    src, fan_j, fe, fn = [np.flatnonzero(live & inside)], [np.ones(int((live & inside).sum()), np.int64)], \
        [e[live & inside]], [nv[live & inside]]
    guard_clipped = 0
    for t in np.flatnonzero(live & ~inside):
        es, ns = list(e[t]), list(nv[t])
        for k in range(5):
            if not es:
                break
            guard_clipped += k > 0 and any(_plane(k, p, P, near, gx, gy) < 0 for p in es)
            es, ns = _clip(es, ns, k, P, near, gx, gy)
        for j in range(1, len(es) - 1):
            src.append(np.array([t]))
            fan_j.append(np.array([j]))
            fe.append(np.stack([es[0], es[j], es[j + 1]])[None])
            fn.append(np.stack([ns[0], ns[j], ns[j + 1]])[None])
    src, fan_j = np.concatenate(src), np.concatenate(fan_j)
    fe = np.concatenate(fe).astype(np.float32).reshape(-1, 3, 3)
    fn = np.concatenate(fn).astype(np.float32).reshape(-1, 3, 3)

    # rs_setup
    cx, cy, cw = _row(P, 0, fe), _row(P, 1, fe), _row(P, 3, fe)
    sx = (cx / cw * _f(0.5) + _f(0.5)) * Wf
    sy = (_f(0.5) - cy / cw * _f(0.5)) * Hf
    X = np.rint(sx * _f(_ONE)).astype(np.int64)
    Y = np.rint(sy * _f(_ONE)).astype(np.int64)
    iw, dd = _f(1) / cw, -fe[..., 2]
    area = (X[:, 1] - X[:, 0]) * (Y[:, 2] - Y[:, 0]) - (Y[:, 1] - Y[:, 0]) * (X[:, 2] - X[:, 0])
    swap = area < 0
    order = np.where(swap[:, None], [0, 2, 1], [0, 1, 2])
    take = lambda a: np.take_along_axis(a, order.reshape(order.shape + (1,) * (a.ndim - 2)), axis=1)  # noqa: E731
    X, Y, iw, dd, fe, fn = take(X), take(Y), take(iw), take(dd), take(fe), take(fn)
    a_i, b_i = [1, 2, 0], [2, 0, 1]
    ax, ay = X[:, a_i], Y[:, a_i]
    dx, dy = X[:, b_i] - ax, Y[:, b_i] - ay
    bias = np.where((dy < 0) | ((dy == 0) & (dx > 0)), 0, 1)
    x0 = np.maximum((X.min(axis=1) - _HALF + _ONE - 1) >> SUBPIXEL_BITS, 0)
    x1 = np.minimum((X.max(axis=1) - _HALF) >> SUBPIXEL_BITS, W - 1)
    y0 = np.maximum((Y.min(axis=1) - _HALF + _ONE - 1) >> SUBPIXEL_BITS, 0)
    y1 = np.minimum((Y.max(axis=1) - _HALF) >> SUBPIXEL_BITS, H - 1)
    ok = (area != 0) & (x0 <= x1) & (y0 <= y1)
    drawn = np.zeros(T, bool)
    drawn[src[ok]] = True
    counters = {"triangles": T, "near_clipped": int(near_clipped.sum()), "culled": int(T - drawn.sum()),
                "guard_clipped": int(guard_clipped)}
    boxes = np.where(ok, (x1 - x0 + 1) * (y1 - y0 + 1), 0)
    if large_pixels is not None:
        counters["large"] = int((boxes > large_pixels).sum())

    mats = materials(instances, arrays.clusters, inst[src], clus[src], color_by)
    oid = instances.inst_u[inst[src], INSTANCE_U.offset("object")].astype(np.uint64) & np.uint64(0xFFF)
    wts = (np.ones(len(instances.inst_f), np.float32) if weights is None
           else np.asarray(weights, np.float32).reshape(-1))[inst[src]]          # per sub-triangle
    Vm = V.reshape(4, 4)
    ortho = P[15] != 0
    ck = np.full(H * W, ALL_ONES)
    ak = np.full(H * W, ALL_ONES)
    cov = np.zeros(H * W, np.uint32)

    # the fragments: every pixel centre of every bounding box, in chunks of sub-triangles
    order_ok = np.flatnonzero(ok)
    chunks = np.split(order_ok, np.searchsorted(np.cumsum(boxes[order_ok]), np.arange(1, 64) * 2 ** 20))
    for s_ids in chunks:
        if not len(s_ids):
            continue
        nb = boxes[s_ids]
        s = np.repeat(s_ids, nb)
        k = np.arange(len(s)) - np.repeat(np.cumsum(nb) - nb, nb)
        bw = (x1 - x0 + 1)[s]
        x, y = x0[s] + k % bw, y0[s] + k // bw
        px, py = x * _ONE + _HALF, y * _ONE + _HALF
        E = dx[s] * (py[:, None] - ay[s]) - dy[s] * (px[:, None] - ax[s])   # [n, 3] edge functions
        hit = (E >= bias[s]).all(axis=1)
        w = wts[s]
        hit &= (w >= 1) | (dither(x, y) < w)          # rs_fragment's hand-off test
        s, x, y, E = s[hit], x[hit], y[hit], E[hit]
        u = E.astype(np.float32) * iw[s]
        q = (u[:, 0] + u[:, 1]) + u[:, 2]
        with np.errstate(all="ignore"):
            depth = ((u[:, 0] * dd[s, 0] + u[:, 1] * dd[s, 1]) + u[:, 2] * dd[s, 2]) / q
            keep = (depth >= near) & (depth <= far)
            s, x, y, u, q, depth = s[keep], x[keep], y[keep], u[keep], q[keep], depth[keep]
            r = (_f(1) / q)[:, None]
            h = ((u[:, 0, None] * fe[s, 0] + u[:, 1, None] * fe[s, 1]) + u[:, 2, None] * fe[s, 2]) * r
            n = ((u[:, 0, None] * fn[s, 0] + u[:, 1, None] * fn[s, 1]) + u[:, 2, None] * fn[s, 2]) * r
            ev = np.broadcast_to(np.array([0, 0, 1], np.float32), h.shape) if ortho else _normalize(-h)
            rgba, nn = shade(n, ev, mats[s], light)
        nw = np.stack([(Vm[0, c] * nn[:, 0] + Vm[1, c] * nn[:, 1]) + Vm[2, c] * nn[:, 2] for c in range(3)], axis=-1)
        dbits = depth.view(np.uint32).astype(np.uint64) << np.uint64(32)
        pix = y * W + x
        np.minimum.at(ck, pix, dbits | rgba)
        np.minimum.at(ak, pix, dbits | (_oct10(nw) << np.uint64(12)) | oid[s])
        np.add.at(cov, pix, 1)
    counters["pixels"] = int(cov.sum())
    return {"color": ck.reshape(H, W), "aux": ak.reshape(H, W), "coverage": cov.reshape(H, W),
            "counters": counters}


def rasterize_views(width, height, cameras, arrays, instances, pairs, masks, light=LIGHT, color_by: int = 0,
                    large_pixels: int | None = None, weights=None) -> dict:
    """The multi-view raster: ``rasterize_detail`` of each view v of ``cameras`` (a Views or a
    list of cameras) over the ``pairs`` whose view mask (``masks``, uint64 per pair) has bit v.
    {"color", "aux" (uint64 [N, height, width], layer v = view v), "counters" summed over views}."""
    views = as_views(cameras)
    pairs = np.asarray(pairs, np.uint32).reshape(-1, 2)
    masks = np.asarray(masks, np.uint64).reshape(-1)
    if len(masks) != len(pairs):
        raise ValueError(f"rasterize_views: {len(masks)} view masks for {len(pairs)} pairs")
    layers = [rasterize_detail(width, height, cam, arrays, instances,
                               pairs[((masks >> np.uint64(v)) & np.uint64(1)) != 0], light, color_by, large_pixels,
                               weights) for v, cam in enumerate(views)]
    counters = {k: sum(d["counters"][k] for d in layers) for k in layers[0]["counters"]}
    return {"color": np.stack([d["color"] for d in layers]), "aux": np.stack([d["aux"] for d in layers]),
            "counters": counters}
