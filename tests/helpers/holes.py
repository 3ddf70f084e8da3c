"""Hole counting for the point renderers' silhouette tests."""
from __future__ import annotations

import numpy as np

from paramlod.errors import SceneError


def count_holes(frame, mask: np.ndarray, depth: np.ndarray | None = None, tol: float = 0.0,
                erode: int = 1) -> int:
    """Pixels inside a known silhouette that the render failed to fill.

    ``mask`` (h, w) bool is the silhouette; it is first eroded by ``erode`` pixels (8-neighbour) so
    that pixels the silhouette only partly covers do not count. A pixel of the eroded mask is a
    hole when nothing was drawn there, or, if ``depth`` (the expected front depth, (h, w)) is
    given, when the drawn depth is farther than ``depth + tol`` (a gap in the front surface that
    shows a surface behind it).
    """
    mask = np.asarray(mask, bool)
    if mask.shape != frame.depth.shape:
        raise SceneError(f"count_holes: mask shape {mask.shape} differs from the frame's {frame.depth.shape}")
    inner = mask.copy()
    for _ in range(int(erode)):
        m = np.pad(inner, 1, constant_values=False)
        acc = np.ones_like(inner)
        for dy in (0, 1, 2):
            for dx in (0, 1, 2):
                acc &= m[dy:dy + inner.shape[0], dx:dx + inner.shape[1]]
        inner = acc
    bad = ~np.isfinite(frame.depth)
    if depth is not None:
        with np.errstate(invalid="ignore"):
            bad |= frame.depth > np.asarray(depth) + tol
    return int(np.count_nonzero(bad & inner))


def dense_silhouette(fn, cam, params=None, transform=None, n: int = 1400):
    """Silhouette (h, w) bool and the 3x3-neighbourhood maximum of the front depth of the
    parametric function ``fn`` (with ``params``, placed by the 4x4 ``transform``) seen by ``cam``,
    from an n x n numpy sampling of its domain (many samples per pixel at test sizes), and the
    (u, v) of each pixel's front sample (NaN where empty): the reference for ``count_holes``."""
    u = np.linspace(*fn.u_range, n)
    v = np.linspace(*fn.v_range, n)
    uu, vv = (a.reshape(-1) for a in np.meshgrid(u, v))
    with np.errstate(all="ignore"):
        p = np.asarray(fn.evaluate(uu, vv, **(params or {})), np.float64).reshape(-1, 3)
    ok = np.all(np.isfinite(p), axis=1)
    p, uu, vv = p[ok], uu[ok], vv[ok]
    pw = np.concatenate([p, np.ones((len(p), 1))], axis=1)
    if transform is not None:
        pw = pw @ np.asarray(transform, np.float64).T
    w, h = cam.size
    e = pw @ cam.view.T
    c = e @ cam.projection.T
    with np.errstate(all="ignore"):
        x = (c[:, 0] / c[:, 3] * 0.5 + 0.5) * w
        y = (0.5 - c[:, 1] / c[:, 3] * 0.5) * h
    ok = (x >= 0) & (y >= 0) & (x < w) & (y < h) & (-e[:, 2] > cam.near)
    pix = y[ok].astype(np.int64) * w + x[ok].astype(np.int64)
    d = -e[ok, 2]
    order = np.lexsort((d, pix))
    pix, d, uo, vo = pix[order], d[order], uu[ok][order], vv[ok][order]
    first = np.r_[True, pix[1:] != pix[:-1]] if len(pix) else np.zeros(0, bool)
    depth = np.full(w * h, np.inf)
    depth[pix[first]] = d[first]
    front_u, front_v = np.full(w * h, np.nan), np.full(w * h, np.nan)
    front_u[pix[first]], front_v[pix[first]] = uo[first], vo[first]
    depth = depth.reshape(h, w)
    mask = np.isfinite(depth)
    dd = np.pad(np.where(mask, depth, -np.inf), 1, constant_values=-np.inf)
    dmax = np.max([dd[dy:dy + h, dx:dx + w] for dy in range(3) for dx in range(3)], axis=0)
    return mask, dmax, front_u.reshape(h, w), front_v.reshape(h, w)
