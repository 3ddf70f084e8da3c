"""The shading model's host-side constants, shared by every renderer (the point kernels'
``shade()`` in kernels/common/keys.cl and the tessellation fragment shader read the same
record): a key light in view space and the ambient share."""
from __future__ import annotations

import numpy as np

# towards the light: upper left, in front; the fourth value is the ambient share
_TOWARDS = np.array([-0.35, 0.5, 1.0])
LIGHT = np.array([*(_TOWARDS / np.linalg.norm(_TOWARDS)), 0.12], np.float32)
