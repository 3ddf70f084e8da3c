"""numpy twin of kernels/common/hash.cl: the integer hash (debug colours) and the screen-door
dither of the surfel -> mesh hand-off, bit for bit."""
from __future__ import annotations

import numpy as np


def hash32(x) -> np.ndarray:
    """pl_hash32 of uint32 values (xor-shift-multiply, two rounds)."""
    x = np.asarray(x, np.uint32)
    with np.errstate(over="ignore"):
        x = x ^ (x >> np.uint32(16))
        x = x * np.uint32(0x7FEB352D)
        x = x ^ (x >> np.uint32(15))
        x = x * np.uint32(0x846CA68B)
        x = x ^ (x >> np.uint32(16))
    return x


def dither(x, y) -> np.ndarray:
    """pl_dither: float32 in [0, 1) of pixel (or subsample) column ``x`` and row ``y`` (top row 0)."""
    with np.errstate(over="ignore"):
        h = hash32(hash32(np.asarray(y, np.uint32)) + np.asarray(x, np.uint32))
    return (h >> np.uint32(8)).astype(np.float32) * np.float32(1.0 / 16777216.0)
