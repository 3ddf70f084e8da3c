"""Point renderer, direct variant (kernels/points.cl): render patches sampled on a (u, v) grid
sized from their measured extents and written with 64-bit atom_min into the KeyBuffer."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .device import cl_device
from .errors import SceneError
from .programs import build

LOCAL_SIZE = 64
COUNTERS = ("samples", "atomics", "nan_samples", "capped_patches")


@dataclass
class PointSettings:
    density: float = 1.5    # samples per pixel of s_u, s_v: spacing <= 0.67 px < 1/sqrt(2), no holes at any angle
    widen: float = 0.005    # parameter range enlarged by this fraction per side (no seams)
    max_side: int = 1024    # samples per side at most; patches that hit it are counted in stats

    def validate(self):
        if not 0.1 <= self.density <= 16:
            raise SceneError(f"points density must be in [0.1, 16] samples per pixel, got {self.density}")
        if not 0 <= self.widen <= 0.25:
            raise SceneError(f"points widen must be in [0, 0.25], got {self.widen}")
        if not 2 <= self.max_side <= 8192:
            raise SceneError(f"points max_side must be in [2, 8192], got {self.max_side}")


def side_counts(ext: np.ndarray, settings: PointSettings) -> np.ndarray:
    """numpy twin of side_count() in points.cl: samples per side for each extent."""
    n = np.ceil(ext.astype(np.float32) * np.float32(settings.density)) + np.float32(1)
    with np.errstate(invalid="ignore"):
        capped = ~(n < np.float32(settings.max_side))
    return np.where(capped, settings.max_side, np.maximum(np.nan_to_num(n), 2)).astype(np.int64)


class DirectPointRenderer:
    def __init__(self, functions, record: bool = False):
        defines = {"PL_RECORD": 1} if record else None
        self.kernel = build(["keys.cl", "points.cl"], functions, defines).points_direct
        self.record = record
        import pyopencl as cl

        self.counters = cl.Buffer(cl_device().context, cl.mem_flags.READ_WRITE, 8 * len(COUNTERS))

    def draw(self, patches_buf, n_patches, inst, materials_buf, cam_buf, light_buf, keys,
             settings: PointSettings, record_args=()):
        import pyopencl as cl

        settings.validate()
        q = cl_device().queue
        zero = np.zeros(len(COUNTERS), np.uint64)
        cl.enqueue_copy(q, self.counters, zero)
        if n_patches:
            self.kernel(q, (n_patches * LOCAL_SIZE,), (LOCAL_SIZE,),
                        patches_buf, np.uint32(n_patches), *inst, materials_buf, cam_buf, light_buf,
                        np.float32(settings.density), np.float32(settings.widen), np.uint32(settings.max_side),
                        keys.color, keys.aux, self.counters, *record_args)
        cl.enqueue_copy(q, zero, self.counters)
        return {k: int(v) for k, v in zip(COUNTERS, zero)}
