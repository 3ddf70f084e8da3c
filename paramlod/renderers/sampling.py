"""How a render patch is sampled by the point renderers (kit shared by the direct and the
local-framebuffer variants; kernels/points/points.cl side_count()).

Per patch side, ``ceil(m * factor) + 1`` samples, where ``m`` is the measure chosen by
``sampling`` ("segment": s_u, s_v = 7 x the longest LOD segment; "extent": the thesis's measured
polyline extents e_u, e_v) and ``factor = density * oversample / (1 - epsilon)`` (docs/points.md).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from paramlod.errors import SceneError

SAMPLING = ("segment", "extent")


@dataclass
class PointSettings:
    density: float = 1.5    # samples per pixel of s_u, s_v: spacing <= 0.67 px < 1/sqrt(2), no holes at any angle
    widen: float = 0.005    # parameter range enlarged by this fraction per side (no seams)
    max_side: int = 1024    # samples per side at most; patches that hit it are counted in stats
    # what the sample counts are measured from: "segment" (s_u, s_v; hole-free default) or
    # "extent" (e_u, e_v: the thesis's adaptive sampling, fewer samples, may leave 1-px holes)
    sampling: str = "segment"
    oversample: float = 1.0  # fixed oversampling factor on top of density (thesis Fig. 5.17: 1x, 2x, 3x)
    epsilon: float = 0.0     # step shrink: sample steps are (1 - epsilon) x the nominal step
    # anti-aliasing of the direct variant: render into keys supersample x the frame's size, then
    # resolve each block (colour averaged over covered subsamples, alpha = coverage); 1 = off
    supersample: int = 1

    def validate(self):
        if not 0.1 <= self.density <= 16:
            raise SceneError(f"points density must be in [0.1, 16] samples per pixel, got {self.density}")
        if not 0 <= self.widen <= 0.25:
            raise SceneError(f"points widen must be in [0, 0.25], got {self.widen}")
        if not 2 <= self.max_side <= 8192:
            raise SceneError(f"points max_side must be in [2, 8192], got {self.max_side}")
        if self.sampling not in SAMPLING:
            raise SceneError(f"points sampling must be one of {', '.join(SAMPLING)}, got {self.sampling!r}")
        if not 1 <= self.oversample <= 8:
            raise SceneError(f"points oversample must be in [1, 8], got {self.oversample}")
        if not 0 <= self.epsilon <= 0.9:
            raise SceneError(f"points epsilon (step shrink) must be in [0, 0.9], got {self.epsilon}")
        if self.supersample not in (1, 2, 3, 4) or isinstance(self.supersample, bool):
            raise SceneError(f"points supersample must be 1 (off), 2, 3 or 4 subsamples per pixel side, "
                             f"got {self.supersample!r}")

    def factor(self) -> np.float32:
        """Samples per measured pixel along each side, as the kernel receives it (float32)."""
        return np.float32(self.density * self.oversample / (1.0 - self.epsilon))

    @property
    def use_extent(self) -> bool:
        return self.sampling == "extent"


def side_counts(ext: np.ndarray, settings: PointSettings) -> np.ndarray:
    """numpy twin of side_count() in points.cl: samples per side for each measure in ``ext``."""
    n = np.ceil(np.asarray(ext).astype(np.float32) * settings.factor()) + np.float32(1)
    with np.errstate(invalid="ignore"):
        capped = ~(n < np.float32(settings.max_side))
    return np.where(capped, settings.max_side, np.maximum(np.nan_to_num(n), 2)).astype(np.int64)


def grid_counts(render_list: np.ndarray, settings: PointSettings) -> tuple[np.ndarray, np.ndarray]:
    """(nu, nv) per render patch, picking the measure columns ``settings.sampling`` selects."""
    ext = render_list["ext"]
    cu, cv = (0, 1) if settings.use_extent else (2, 3)
    return side_counts(ext[:, cu], settings), side_counts(ext[:, cv], settings)
