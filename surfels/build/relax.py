"""A final relaxation of the sampled surfels at the full count (host: numpy + scipy's cKDTree).

Farthest-point rounds leave the full set less even than a Poisson-disk set: the last rounds split
some cells and not others. Here every pair closer than D = ``spread`` x the mean nearest-neighbour
distance is pushed apart by ``omega`` x its overlap (half each), in the tangent plane, and each
surfel is put back on the surface: on the tangent plane of the covered G-buffer pixel under it in
its pixel's view (the nearest covered pixel when that view loses it). The sampling order is kept
and each surfel moves by a fraction of the full count's spacing, so a prefix of m surfels (spacing
about sqrt(n / m) times larger) stays blue noise. Making early surfels heavier, so that later ones
make the room, was tried: pairs stuck against early surfels and prefixes were no better.

Host code only (no kernel, so no twin); deterministic: exact cKDTree queries, sums in fixed order.
"""
from __future__ import annotations

import numpy as np

from paramlod.surfels.build.schedule import kd_tree

ITERATIONS = 16   # iterations for G-buffers of at least FINE x sqrt(n) pixels a side
COARSE_ITERATIONS = 24   # below that the surfels start nearer the pixel grid and need more
FINE = 1.25
SPREAD = 1.05     # pairs closer than this times the mean nearest-neighbour distance repel
OMEGA = 0.75      # fraction of a pair's overlap removed per iteration
SAME_SIDE = 0.5   # a pixel whose normal is more than 60 deg from the surfel's lies on another sheet
REUSE = 0.25      # the close pairs are found again once some surfel has moved this share of D since


def pixel_under(gbuf, x: np.ndarray, q: np.ndarray, normal: np.ndarray):
    """For surfels at x (n, 3) on pixels q (global indices): the pixel under x in q's view,
    whether it is on the surfel's sheet (covered, normal within 60 deg, x within 2 pixels of its
    tangent plane: not an occluder or a sheet behind) and its tangent plane (``_sheet``). A
    lookup in the G-buffer: O(1) a surfel."""
    k_, h, w = gbuf.shape
    vs = gbuf.views
    layer = q // (h * w)
    r = x - vs.centre
    a = np.einsum("ij,ij->i", r, vs.rights[layer]) * vs.scale + 0.5 * w
    b = 0.5 * h - np.einsum("ij,ij->i", r, vs.ups[layer]) * vs.scale
    xi, yi = np.floor(a).astype(np.int64), np.floor(b).astype(np.int64)
    inside = (xi >= 0) & (xi < w) & (yi >= 0) & (yi < h)
    qn = np.where(inside, (layer * h + np.clip(yi, 0, h - 1)) * w + np.clip(xi, 0, w - 1), q)
    ok, plane_p, plane_n = _sheet(gbuf, x, qn, normal)
    return qn, ok & inside, plane_p, plane_n


def _sheet(gbuf, x, qn, normal):
    """Whether the pixels qn are on the sheets of surfels at x with ``normal``, and their tangent
    planes: positions and normals (float64), which the caller keeps where it moves the surfels."""
    gp = gbuf.position.reshape(-1, 4)[qn]
    plane_p = gp[:, :3].astype(np.float64)
    plane_n = gbuf.normal.reshape(-1, 3)[qn].astype(np.float64)
    ok = ((gp[:, 3] > 0) & (np.einsum("ij,ij->i", plane_n, normal) > SAME_SIDE)
          & (np.abs(np.einsum("ij,ij->i", x - plane_p, plane_n)) <= 2.0 * gbuf.views.pixel_size))
    return ok, plane_p, plane_n


class _Nearest:
    """The nearest covered pixel (cKDTree over all of them), built the first time a surfel's own
    view loses it (it moved past that view's silhouette)."""

    def __init__(self, gbuf):
        self.gbuf, self.tree, self.index = gbuf, None, None

    def __call__(self, x):
        if self.tree is None:
            self.index = np.flatnonzero(self.gbuf.valid.reshape(-1))
            self.tree = kd_tree(self.gbuf.position.reshape(-1, 4)[self.index, :3])
        return self.index[self.tree.query(x)[1]]


def auto_iterations(n: int, resolution: int) -> int:
    """Iterations for n surfels from G-buffers of ``resolution``: measured on the bunny to reach
    pymeshlab's exact Poisson disk (normalised nearest-neighbour min 0.83, CV 0.053; docs/surfels.md):
    16 from 512 px at 100k (0.84 / 0.047) and from 128 px at 10k; 16 from 384 px at 100k gave 0.82,
    24 gave 0.84 / 0.049."""
    return ITERATIONS if resolution >= FINE * np.sqrt(n) else COARSE_ITERATIONS


def relax(gbuf, pix: np.ndarray, iterations: int = ITERATIONS, spread: float = SPREAD, omega: float = OMEGA):
    """Relaxed positions (float64 (n, 3), in the given order) of the surfels on the pixels ``pix``
    (global G-buffer indices, in sampling order), and the pixel each ends on (int64 (n,): its
    normal and colour). A surfel with no pixel of its sheet under its new place (it would slide
    past a border) stays where it was for that iteration."""
    gpos = gbuf.position.reshape(-1, 4)
    gnrm = gbuf.normal.reshape(-1, 3)
    q = np.asarray(pix, np.int64).copy()
    p = gpos[q, :3].astype(np.float64)
    n = len(p)
    if n < 3 or iterations <= 0:
        return p, q
    d, _ = kd_tree(p).query(p, k=2)
    D = spread * float(np.mean(d[:, 1]))
    if not D > 0:
        return p, q
    nearest = _Nearest(gbuf)
    plane_p, plane_n = gpos[q, :3].astype(np.float64), gnrm[q].astype(np.float64)
    pairs, built = None, None
    for _ in range(iterations):
        # The pairs within D + 2 REUSE D of the positions some iterations ago serve while no surfel
        # has moved more than REUSE x D since: every pair now closer than D is among them
        # (building the tree and finding the pairs was most of an iteration at 100k surfels).
        if pairs is None or np.einsum("ij,ij->i", p - built, p - built).max() > (REUSE * D) ** 2:
            built = p.copy()
            pairs = kd_tree(p).query_pairs((1 + 2 * REUSE) * D, output_type="ndarray")
        a, b = pairs[:, 0], pairs[:, 1]
        v = p[a] - p[b]
        length = np.sqrt(np.einsum("ij,ij->i", v, v))
        close = length < D
        if not close.any():
            break
        a, b, v, length = a[close], b[close], v[close], length[close]
        f = (0.5 * omega * (D - length) / np.maximum(length, 1e-12 * D))[:, None] * v   # half each
        disp = np.stack([np.bincount(a, f[:, i], n) - np.bincount(b, f[:, i], n) for i in range(3)], 1)
        disp -= np.einsum("ij,ij->i", disp, plane_n)[:, None] * plane_n       # tangent plane only
        x = p + disp
        qn, ok, under_p, under_n = pixel_under(gbuf, x, q, plane_n)
        lost = np.flatnonzero(~ok)
        if len(lost):
            qn[lost] = nearest(x[lost])
            ok[lost], under_p[lost], under_n[lost] = _sheet(gbuf, x[lost], qn[lost], plane_n[lost])
        q = np.where(ok, qn, q)
        x = np.where(ok[:, None], x, p)                  # no pixel of its sheet under it: stay
        plane_p = np.where(ok[:, None], under_p, plane_p)
        plane_n = np.where(ok[:, None], under_n, plane_n)
        p = x - np.einsum("ij,ij->i", x - plane_p, plane_n)[:, None] * plane_n    # back on the surface
    return p, q
