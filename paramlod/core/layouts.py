"""Records shared by the host and the device, declared once.

The camera record (36 floats): view matrix (16, row-major), projection matrix (16, row-major),
then width, height, near, far. Read by kernels/lod/lod.cl, kernels/points/*.cl and
kernels/surfels/surfels_splat.cl through common.cl's CAM_* offsets.
"""
from __future__ import annotations

import numpy as np

CAMERA_FLOATS = 36


def camera_record(camera) -> np.ndarray:
    """The camera record of ``camera`` (a paramlod Camera), float32 (36,)."""
    rec = np.zeros(CAMERA_FLOATS, np.float32)
    rec[0:16] = camera.view.reshape(-1)
    rec[16:32] = camera.projection.reshape(-1)
    rec[32:36] = [camera.width, camera.height, camera.near, camera.far]
    return rec
