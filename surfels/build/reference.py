"""numpy twins of kernels/surfels/surfels_sample.cl (bit-identical on small G-buffers: the tests compare
every pass and whole sampling runs), of the sampler's round loop, and of the prefix renderer's
kernels/surfels/surfels_splat.cl (splat_discs, with the hand-off dither of paramlod.scene.handoff)."""
from __future__ import annotations

import numpy as np

from paramlod.core.color import linear_to_srgb8_f64
from paramlod.core.hashing import dither
from paramlod.core.layouts import CAMERA
from paramlod.surfels.build.schedule import (ALL_ONES, HI, compact_sort, dist2, f32_bits, handover_r2, key_pixel, key_r2,
                                             level_strides, remap_keys, resume_radii, splat_r2, stop_r2, threshold_r2)


def voronoi_splat(vor, pos, samples, first, count, r2):
    """atom_min of (d2 bits << 32 | site) into every covered pixel within sqrt(r2) of each site."""
    vor = vor.copy()
    valid = np.flatnonzero(pos[:, 3] > 0)
    P = pos[valid]
    r2 = np.float32(r2)
    for site in range(first, first + count):
        d2 = dist2(P, pos[key_pixel(samples[site])])
        m = d2 <= r2
        keys = (f32_bits(d2[m]) << np.uint64(32)) | np.uint64(site)
        np.minimum.at(vor, valid[m], keys)
    return vor


def farthest(vor, pos, n_sites):
    """(cand, uncovered): each site's farthest pixel key; covered pixels no site reached."""
    cand = np.zeros(n_sites, np.uint64)
    reached = vor != ALL_ONES
    q = np.flatnonzero(reached)
    keys = (vor[q] & HI) | q.astype(np.uint64)
    np.maximum.at(cand, key_pixel(vor[q]), keys)
    uncovered = int(np.count_nonzero(~reached & (pos[:, 3] > 0)))
    return cand, uncovered


def conflict_splat(pos, cand, thr2):
    """atom_max of each eligible candidate's key into the pixels strictly inside its disc."""
    conf = np.zeros(len(pos), np.uint64)
    valid = np.flatnonzero(pos[:, 3] > 0)
    P = pos[valid]
    r2s = key_r2(cand)
    for key, r2 in zip(cand, r2s):
        if not (r2 >= np.float32(thr2) and r2 > 0):
            continue
        m = dist2(P, pos[key_pixel(key)]) < r2
        np.maximum.at(conf, valid[m], np.full(int(m.sum()), key, np.uint64))
    return conf


def survive(cand, thr2, conf):
    r2 = key_r2(cand)
    ok = (r2 >= np.float32(thr2)) & (r2 > 0)
    own = np.zeros(len(cand), bool)
    own[ok] = conf[key_pixel(cand[ok])] == cand[ok]
    return np.where(ok & own, cand, np.uint64(0))


def seed_pixel(pos, seed):
    valid = np.flatnonzero(pos[:, 3] > 0)
    return int(valid[np.random.default_rng(seed).integers(len(valid))])


def loop(pos, samples, vor, n, target, stop_r2=0.0, fix_first_radius=False, threshold=0.75):
    """Rounds as Sampler.loop: (keys, last r2max); ``samples`` has room for ``target`` keys."""
    first = fix_first_radius
    while True:
        cand, _ = farthest(vor, pos, n)
        mx = cand.max()
        r2max = key_r2(mx)
        if first:
            samples[0] = (mx & HI) | samples[0]
            first = False
        if n >= target or not r2max > stop_r2:
            break
        thr2 = threshold_r2(r2max, threshold)
        conf = conflict_splat(pos, cand, thr2)
        srt = compact_sort(survive(cand, thr2, conf))
        take = min(len(srt), target - n)
        if take == 0:
            break
        samples[n:n + take] = srt[:take]
        vor = voronoi_splat(vor, pos, samples, n, take, splat_r2(r2max))
        n += take
    return samples[:n].copy(), r2max


def sample(pos, target, seed_pixel, threshold=0.75):
    """One level from a given first pixel (Sampler.run)."""
    samples = np.zeros(target, np.uint64)
    samples[0] = np.uint64(seed_pixel)
    vor = voronoi_splat(np.full(len(pos), ALL_ONES), pos, samples, 0, 1, np.float32(np.inf))
    return loop(pos, samples, vor, 1, target, 0.0, True, threshold)[0]


def run_levels(gbuf, target, seed=0, threshold=0.75):
    """The coarse-to-fine loop of sampler.run_levels, in numpy."""
    strides = level_strides(gbuf.views.resolution)
    pixel = gbuf.views.pixel_size
    keys = r2max = prev = None
    for stride in strides:
        g = gbuf.subsample(stride)
        pos = np.ascontiguousarray(g.position.reshape(-1, 4), np.float32)
        if stride != 1 and not np.any(pos[:, 3] > 0):
            continue
        samples = np.zeros(target, np.uint64)
        if keys is None:
            samples[0] = np.uint64(seed_pixel(pos, seed))
            vor = voronoi_splat(np.full(len(pos), ALL_ONES), pos, samples, 0, 1, np.float32(np.inf))
            n = 1
        else:
            k = remap_keys(keys, gbuf.shape, prev, stride)
            n = len(k)
            samples[:n] = k
            for r2 in resume_radii(handover_r2(r2max, prev, pixel)):
                vor = voronoi_splat(np.full(len(pos), ALL_ONES), pos, samples, 0, n, r2)
                if farthest(vor, pos, n)[1] == 0:
                    break
        last = stride == 1
        keys, r2max = loop(pos, samples, vor, n, target, 0.0 if last else stop_r2(stride, pixel),
                           keys is None, threshold)
        prev = stride
        if len(keys) >= target:
            return remap_keys(keys, gbuf.shape, stride, 1)
    return keys


# --- prefix renderer (kernels/surfels/surfels_splat.cl) ----------------------------------------------------
def _f(x):
    return np.float32(x)


def _rows_point(m, p):
    """((m0 x + m1 y) + m2 z) + m3 per row, float32, p (..., 3)."""
    m = np.asarray(m, np.float32)
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    return np.stack([((m[4 * r] * x + m[4 * r + 1] * y) + m[4 * r + 2] * z) + m[4 * r + 3] for r in range(3)], -1)


def _rows_dir(m, d):
    m = np.asarray(m, np.float32)
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    return np.stack([(m[4 * r] * x + m[4 * r + 1] * y) + m[4 * r + 2] * z for r in range(3)], -1)


def _dot(a, b):
    return (a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]) + a[..., 2] * b[..., 2]


def _unproject(ip, x, y, z):
    ip = np.asarray(ip, np.float32)
    h = [((ip[4 * r] * x + ip[4 * r + 1] * y) + ip[4 * r + 2] * z) + ip[4 * r + 3] for r in range(4)]
    return np.stack([h[0] / h[3], h[1] / h[3], h[2] / h[3]], -1)


def _oct10(n):
    s = np.abs(n).sum(-1, keepdims=True)
    p = n[..., :2] / s
    neg = n[..., 2] < 0
    sgn = np.where(p >= 0, 1.0, -1.0)
    q = np.stack([(1 - np.abs(p[..., 1])) * sgn[..., 0], (1 - np.abs(p[..., 0])) * sgn[..., 1]], -1)
    p = np.where(neg[..., None], q, p)
    u = np.clip(p * 511.5 + 511.5 + 0.5, 0, 1023).astype(np.uint64)
    return (u[..., 0] << np.uint64(10)) | u[..., 1]


def view_dir(cam, e):
    """float64 twin of common.cl view_dir(): towards the viewer, (0, 0, 1) for orthographic."""
    e = np.asarray(e, np.float64)
    if cam[16 + 15] != 0:
        return np.broadcast_to(np.array([0.0, 0.0, 1.0]), e.shape)
    return -e / np.linalg.norm(e, axis=-1, keepdims=True)


def shade(n_view, ev, mat, light):
    """float64 twin of keys.cl shade(): (sRGB RGBA8 word, viewer-facing unit normal)."""
    n_view = np.asarray(n_view, np.float64)
    ln = np.linalg.norm(n_view, axis=-1, keepdims=True)
    n = np.where(ln > 1e-30, n_view / np.where(ln > 0, ln, 1), ev)
    n = np.where(_dot(n, ev)[..., None] < 0, -n, n)
    L = np.asarray(light[:3], np.float64)
    amb = float(light[3])
    diff = np.maximum(_dot(n, np.broadcast_to(L, n.shape)), 0.0)
    hv = L + ev
    hv /= np.linalg.norm(hv, axis=-1, keepdims=True)
    spec = mat[3] * np.power(np.maximum(_dot(n, hv), 0.0), 48.0)
    rgb = np.asarray(mat[:3], np.float64) * (amb + (1 - amb) * diff)[..., None] + spec[..., None]
    c = linear_to_srgb8_f64(rgb).astype(np.uint64)
    return (c[..., 0] << np.uint64(24)) | (c[..., 1] << np.uint64(16)) | (c[..., 2] << np.uint64(8)) | np.uint64(255), n


def splat_discs(pos4, nrm4, albedo4, n, radius, xf, cam, inv_proj, light, specular, object_id, mesh_weight=0.0):
    """(colour keys, aux keys), uint64 (H, W): the discs of the first n surfels, atom_min'd into
    cleared buffers, less the pixels whose hand-off dither is below ``mesh_weight`` (the mesh's).
    Coverage and depth bits follow the kernel's float32 operations exactly; colour and normal
    bits are float64 (they may differ by one unit).

    Several views: ``cam`` holds N camera records one after another, ``xf`` and ``inv_proj`` N
    records of 24 and 16 floats, ``radius`` and ``mesh_weight`` one number for all or one per
    view; the keys are (N, H, W), layer v view v's (a weight of 1: the view draws nothing)."""
    cams = np.asarray(cam, np.float32).reshape(-1, CAMERA.length)
    nv = len(cams)
    xfs = np.asarray(xf, np.float32).reshape(nv, 24)
    ips = np.asarray(inv_proj, np.float32).reshape(nv, 16)
    radii = np.broadcast_to(np.asarray(radius, np.float32), (nv,))
    weights = np.broadcast_to(np.asarray(mesh_weight, np.float32), (nv,))
    layers = [_splat_view(pos4, nrm4, albedo4, n, radii[v], xfs[v], cams[v], ips[v], light, specular, object_id,
                          weights[v]) for v in range(nv)]
    if nv == 1:
        return layers[0]
    return np.stack([c for c, _ in layers]), np.stack([a for _, a in layers])


def _splat_view(pos4, nrm4, albedo4, n, radius, xf, cam, inv_proj, light, specular, object_id, mesh_weight):
    """One view of splat_discs: its keys, uint64 (H, W) each."""
    W, H = int(cam[32]), int(cam[33])
    near, far = _f(cam[34]), _f(cam[35])
    V = np.asarray(cam[0:16], np.float64)
    ck = np.full(H * W, ALL_ONES)
    ak = np.full(H * W, ALL_ONES)
    ys, xs = np.divmod(np.arange(H * W), W)
    ny = _f(1) - (ys.astype(np.float32) + _f(0.5)) / _f(H) * _f(2)
    nx = (xs.astype(np.float32) + _f(0.5)) / _f(W) * _f(2) - _f(1)
    o = _unproject(inv_proj, nx, ny, _f(-1))
    d = _unproject(inv_proj, nx, ny, _f(1)) - o
    r = _f(radius)
    r2 = r * r
    w = _f(mesh_weight)
    mine = ~(dither(xs, ys) < w) if w > 0 else np.ones(H * W, bool)
    with np.errstate(all="ignore"):
        for i in range(n if w < 1 else 0):   # weight 1: the kernel skips the view
            e = _rows_point(xf[:12], pos4[i, :3].astype(np.float32))
            nv = _rows_dir(xf[12:24], nrm4[i, :3].astype(np.float32))
            den = _dot(d, nv)
            t = _dot(e - o, nv) / den
            h = o + t[:, None] * d
            dh = h - e
            depth = -h[:, 2]
            hit = mine & (den != 0) & (_dot(dh, dh) <= r2) & (depth >= near) & (depth <= far)
            if -e[2] - r > far or -e[2] + r < near:
                hit[:] = False
            q = np.flatnonzero(hit)
            if not len(q):
                continue
            mat = np.array([*albedo4[i, :3], specular], np.float64)
            rgba, nn = shade(nv.astype(np.float64), view_dir(cam, h[q]), mat, light)
            nw = nn @ V.reshape(4, 4)[:3, :3]
            dbits = depth[q].view(np.uint32).astype(np.uint64) << np.uint64(32)
            np.minimum.at(ck, q, dbits | rgba)
            np.minimum.at(ak, q, dbits | (_oct10(nw) << np.uint64(12)) | np.uint64(object_id & 0xFFF))
    return ck.reshape(H, W), ak.reshape(H, W)
