"""numpy twin of kernels/surfels/surfels_raster.cl: the mesh G-buffers' keys bit for bit (the
tests compare them), the resolved position, normal and colour to float32 rounding."""
from __future__ import annotations

import numpy as np

from paramlod.surfels.build.schedule import ALL_ONES, f32_bits
from paramlod.surfels.build.views import ViewSet

SUBPIXEL_BITS = 8   # window x, y snap to 1/256 pixel (kernel: SR_SUBPIXEL_BITS)
ONE = 1 << SUBPIXEL_BITS
HALF = ONE >> 1


def view_matrices(views: ViewSet) -> np.ndarray:
    """float32 (K, 3, 4): world -> window x, y (pixels, row 0 at the top; views.pixel_world's
    pixel centres) and z (the view depth, in [extent, 3 extent] inside the views' box)."""
    s, n, c = views.scale, views.resolution, views.centre
    m = np.zeros((views.count, 3, 4))
    for k in range(views.count):
        r, u, d = views.rights[k], views.ups[k], views.directions[k]
        m[k, 0] = (*(s * r), n / 2 - s * np.dot(r, c))
        m[k, 1] = (*(-s * u), n / 2 + s * np.dot(u, c))
        m[k, 2] = (*d, views.distance - np.dot(d, c))
    return m.astype(np.float32)


def window_coords(positions: np.ndarray, matrices: np.ndarray) -> np.ndarray:
    """float32 (K, F, 3 corners, 3): each corner of ``positions`` (F, 3, 3) through each of
    ``matrices`` (K, 3, 4), in the kernel's order ((a0 x + a1 y) + a2 z) + a3."""
    p = np.asarray(positions, np.float32)[None]
    a = np.asarray(matrices, np.float32)[:, None, None]
    return ((a[..., 0] * p[..., 0:1] + a[..., 1] * p[..., 1:2]) + a[..., 2] * p[..., 2:3]) + a[..., 3]


def snap(window: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fixed-point x and y (int64, ``window``'s shape less its last axis), rounded half to even."""
    w = np.asarray(window, np.float32)
    return (np.rint(w[..., 0] * np.float32(ONE)).astype(np.int64),
            np.rint(w[..., 1] * np.float32(ONE)).astype(np.int64))


def edges(X, Y, px, py):
    """The three edge functions (opposite corners 0, 1, 2) at fixed-point (px, py), >= 0 inside
    for either winding, and |area|; X, Y (..., 3) broadcast against px, py."""
    area = (X[..., 1] - X[..., 0]) * (Y[..., 2] - Y[..., 0]) - (Y[..., 1] - Y[..., 0]) * (X[..., 2] - X[..., 0])
    sign = np.where(area < 0, -1, 1)
    out = []
    for i in range(3):
        a, b = (i + 1) % 3, (i + 2) % 3
        e = (X[..., b] - X[..., a]) * (py - Y[..., a]) - (Y[..., b] - Y[..., a]) * (px - X[..., a])
        out.append(e * sign)
    return out, np.abs(area)


def _span(lo, hi, n):
    lo = np.maximum(lo, 0)
    first = (lo - HALF + ONE - 1) >> SUBPIXEL_BITS
    last = np.where(hi < HALF, -1, np.minimum((np.maximum(hi, HALF) - HALF) >> SUBPIXEL_BITS, n - 1))
    return first, last


def raster_keys(window: np.ndarray, res: int) -> np.ndarray:
    """uint64 (K, res, res) keys of kernels/surfels/surfels_raster.cl gbuffer_raster from the
    corners' window coordinates (K, F, 3, 3): depth bits << 32 | triangle at every covered pixel
    centre (the minimum over the triangles), all ones elsewhere."""
    window = np.asarray(window, np.float32)
    k, f = window.shape[:2]
    X, Y = snap(window)
    Z = window[..., 2]
    x0, x1 = _span(X.min(axis=2), X.max(axis=2), res)
    y0, y1 = _span(Y.min(axis=2), Y.max(axis=2), res)
    nx, ny = np.maximum(x1 - x0 + 1, 0), np.maximum(y1 - y0 + 1, 0)
    _, area = edges(X, Y, 0, 0)
    counts = np.where(area != 0, nx * ny, 0).reshape(-1)
    keys = np.full(k * res * res, ALL_ONES, np.uint64)
    if not counts.sum():
        return keys.reshape(k, res, res)
    item = np.repeat(np.arange(k * f), counts)            # (view, triangle) of each candidate pixel
    local = np.arange(len(item)) - np.repeat(np.cumsum(counts) - counts, counts)
    v, t = item // f, item % f
    nxi = nx.reshape(-1)[item]
    x = x0.reshape(-1)[item] + local % nxi
    y = y0.reshape(-1)[item] + local // nxi
    Xi, Yi = X.reshape(-1, 3)[item], Y.reshape(-1, 3)[item]
    (e0, e1, e2), ai = edges(Xi, Yi, x * ONE + HALF, y * ONE + HALF)
    inside = (e0 >= 0) & (e1 >= 0) & (e2 >= 0)
    Zi = Z.reshape(-1, 3)[item]
    d = ((e0.astype(np.float32) * Zi[:, 0] + e1.astype(np.float32) * Zi[:, 1])
         + e2.astype(np.float32) * Zi[:, 2]) / ai.astype(np.float32)
    d = np.maximum(d, np.float32(0.0))
    key = (f32_bits(d) << np.uint64(32)) | t.astype(np.uint64)
    np.minimum.at(keys, ((v * res + y) * res + x)[inside], key[inside])
    return keys.reshape(k, res, res)


def resolve(keys: np.ndarray, positions, normals, colors, matrices, directions):
    """(position (K, R, R, 4), normal (K, R, R, 3), colour (K, R, R, 4)) of gbuffer_resolve for
    ``keys`` (K, R, R) of the soup's corners (F, 3, 3 / 3 / 4)."""
    k, res = keys.shape[:2]
    pos = np.zeros((k, res, res, 4), np.float32)
    nrm = np.zeros((k, res, res, 3), np.float32)
    col = np.zeros((k, res, res, 4), np.float32)
    v, y, x = np.nonzero(keys != ALL_ONES)
    t = (keys[v, y, x] & np.uint64(0xFFFFFFFF)).astype(np.int64)
    X, Y = snap(window_coords(positions, matrices)[v, t])
    (e0, e1, e2), area = edges(X, Y, x * ONE + HALF, y * ONE + HALF)
    w = np.stack([e0, e1, e2], axis=1).astype(np.float32) / area.astype(np.float32)[:, None]
    p = np.einsum("ni,nic->nc", w, np.asarray(positions, np.float32)[t])
    n = np.einsum("ni,nic->nc", w, np.asarray(normals, np.float32)[t])
    c = np.einsum("ni,nic->nc", w, np.asarray(colors, np.float32)[t])
    d = np.asarray(directions, np.float32)[v]
    length = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.where(length > 1e-20, n / np.maximum(length, 1e-30), -d)
    n = np.where(np.sum(n * d, axis=1, keepdims=True) > 0, -n, n)
    pos[v, y, x] = np.concatenate([p, np.ones((len(p), 1), np.float32)], axis=1)
    nrm[v, y, x], col[v, y, x] = n, c
    return pos, nrm, col
