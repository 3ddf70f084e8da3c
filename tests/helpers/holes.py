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
