"""4x4 transform helpers (column vectors: p' = M @ p). Compose with ``@``."""
from __future__ import annotations

import numpy as np

from paramlod.errors import SceneError


def identity() -> np.ndarray:
    return np.eye(4)


def translate(x, y=None, z=None) -> np.ndarray:
    t = np.asarray([x, y, z] if y is not None else x, dtype=np.float64).reshape(3)
    m = np.eye(4)
    m[:3, 3] = t
    return m


def scale(sx, sy=None, sz=None) -> np.ndarray:
    if sy is None and np.ndim(sx) == 0:
        s = np.array([sx, sx, sx], dtype=np.float64)
    else:
        s = np.asarray([sx, sy, sz] if sy is not None else sx, dtype=np.float64).reshape(3)
    return np.diag([*s, 1.0])


def rotate(angle_deg: float, axis=(0, 0, 1)) -> np.ndarray:
    """Rotation by ``angle_deg`` degrees about ``axis`` (right-handed)."""
    a = np.asarray(axis, dtype=np.float64)
    n = np.linalg.norm(a)
    if n == 0:
        raise SceneError("rotate: the axis must not be zero")
    x, y, z = a / n
    t = np.radians(angle_deg)
    c, s, C = np.cos(t), np.sin(t), 1 - np.cos(t)
    m = np.eye(4)
    m[:3, :3] = [[c + x * x * C, x * y * C - z * s, x * z * C + y * s],
                 [y * x * C + z * s, c + y * y * C, y * z * C - x * s],
                 [z * x * C - y * s, z * y * C + x * s, c + z * z * C]]
    return m


def matrix(m) -> np.ndarray:
    """A 4x4 matrix from nested lists (rows), checked."""
    a = np.asarray(m, dtype=np.float64)
    if a.shape != (4, 4) or not np.all(np.isfinite(a)):
        raise SceneError(f"a transform must be a finite 4x4 matrix, got shape {a.shape}")
    if abs(np.linalg.det(a[:3, :3])) < 1e-12:
        raise SceneError("a transform must be invertible (its 3x3 part has determinant 0)")
    return a
