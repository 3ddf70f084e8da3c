"""The debug colours of kernels/common/debug_color.cl (a colour per cluster or patch, a colour per
LOD level), their numpy twin: the same float32 operations in the same order, bit for bit on
OpenCL. Used by the mesh raster's twin (paramlod.meshlod.raster_reference) and the direct points'
(paramlod.renderers.sampling.patch_debug_color)."""
from __future__ import annotations

import numpy as np

from paramlod.core.hashing import hash32

_f = np.float32


def cluster_color(cluster) -> np.ndarray:
    """pl_cluster_color: float32 [..., 3] linear RGB of global cluster indices."""
    h = hash32(cluster)
    hue = (h & np.uint32(255)).astype(np.float32) / _f(256)
    sat = _f(0.55) + _f(0.45) * (((h >> np.uint32(8)) & np.uint32(255)).astype(np.float32) / _f(255))
    val = _f(0.55) + _f(0.45) * (((h >> np.uint32(16)) & np.uint32(255)).astype(np.float32) / _f(255))
    k = np.stack([hue, hue + _f(0.6666667), hue + _f(0.33333334)], axis=-1)
    rgb = np.clip(np.abs((k - np.floor(k)) * _f(6) - _f(3)) - _f(1), _f(0), _f(1))
    return (_f(1) + (rgb - _f(1)) * sat[..., None]) * val[..., None]


LEVEL_COLORS = np.array([[0.85, 0.85, 0.85], [0.90, 0.12, 0.10], [0.10, 0.70, 0.15], [0.12, 0.30, 0.95],
                         [0.95, 0.80, 0.05], [0.80, 0.15, 0.85], [0.05, 0.80, 0.85], [0.95, 0.45, 0.05]],
                        np.float32)


def level_color(level) -> np.ndarray:
    """pl_level_color: float32 [..., 3] of LOD levels (eight colours, repeating)."""
    return LEVEL_COLORS[np.asarray(level, np.int64) % 8]


TIER_COLORS = np.array([[0.12, 0.30, 0.95], [0.10, 0.70, 0.15], [0.90, 0.12, 0.10]], np.float32)


def tier_color(tier) -> np.ndarray:
    """pl_tier_color: float32 [..., 3] of hybrid anti-aliasing tiers (0 blue, 1 green, 2 red)."""
    return TIER_COLORS[np.minimum(np.asarray(tier, np.int64), 2)]
