"""4x4 transform helpers (column vectors: p' = M @ p). Compose with ``@``.

Every helper checks its numbers: finite and at most ``PLACE_LIMIT`` in magnitude. The kernels
place points in float32; far beyond that an object collapses to a point or its patches measure
NaN (an object at 1e20 made the LOD stage split every patch at every step)."""
from __future__ import annotations

import numpy as np

from paramlod.errors import SceneError

PLACE_LIMIT = 1e15   # largest |coordinate| / |scale| a transform or camera may hold
MIN_SCALE = 1e-15    # smallest |scale| of a transform's 3x3 part (its determinant's cube root)
AFFINE_TOL = 1e-9    # how far a bottom row may stray from [0, 0, 0, 1] (rounding in a product)
# the largest magnitude whose square float32 holds (1.8e19): code that squares coordinates or
# distances in float32 (meshoptimizer's build, the surfel sampler's keys) needs its inputs below it
SQUARE_LIMIT = float(np.sqrt(np.finfo(np.float32).max))


def is_number(x) -> bool:
    """A real number (Python's or numpy's), not a bool (True passes for 1 in int)."""
    return isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, (bool, np.bool_))


def in_range(x, lo, hi) -> bool:
    """``x`` is a real number (``is_number``) in [lo, hi]: settings' checks, which a string or a
    list given by mistake would otherwise meet with a TypeError."""
    return is_number(x) and lo <= x <= hi


def check_values(values, what: str, stacked: bool = False) -> np.ndarray:
    """``values`` as float64, refused (SceneError naming ``what``) unless finite and within
    PLACE_LIMIT. ``stacked``: ``values`` is a stack of matrices, and the error names the first bad
    one's index and shows it alone."""
    try:
        a = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise SceneError(f"{what} must be numbers, got {values!r}") from None
    stack = stacked and a.ndim == 3 and a.size > 0
    rows = a.reshape(len(a), -1) if stack else a.reshape(1, -1)   # one row a matrix, or one in all
    name = (lambda k: f"{what} [{k}]") if stack else (lambda k: what)
    bad = ~np.isfinite(rows).all(axis=1)
    if bad.any():
        k = int(np.argmax(bad))
        raise SceneError(f"{name(k)} must be finite, got {np.array2string(rows[k], precision=6)}")
    big = np.abs(rows).max(axis=1, initial=0.0)
    if (big > PLACE_LIMIT).any():
        k = int(np.argmax(big))
        raise SceneError(f"{name(k)} has a value of magnitude {big[k]:.3g}, beyond {PLACE_LIMIT:.0e}: float32 "
                         "cannot place geometry there (move the object or the camera nearer the origin)")
    return a


def check_transform(m, what: str = "a transform") -> np.ndarray:
    """A finite, invertible 4x4 (or [n, 4, 4]) matrix within PLACE_LIMIT, else a SceneError
    naming ``what`` (and in a stack the index of the first bad matrix)."""
    a = check_values(m, what, stacked=True)
    if a.shape[-2:] != (4, 4):
        raise SceneError(f"{what} must be a 4x4 matrix, got shape {a.shape}")
    # the renderers apply a transform's top three rows (affine); a projective bottom row would be ignored
    off = np.flatnonzero(np.atleast_1d(np.abs(a[..., 3, :] - (0.0, 0.0, 0.0, 1.0)).max(axis=-1) > AFFINE_TOL))
    if off.size:
        which, row = (what, a[3]) if a.ndim == 2 else (f"{what} [{int(off[0])}]", a.reshape(-1, 4, 4)[off[0], 3])
        raise SceneError(f"{which} must be affine: its bottom row must be [0, 0, 0, 1], got "
                         f"{np.array2string(row, precision=6, separator=', ')}")
    det = np.abs(np.linalg.det(a[..., :3, :3]))
    # a uniform scale s has det s^3: 1e-45 is a scale of 1e-15
    bad = np.flatnonzero(np.atleast_1d(det < MIN_SCALE ** 3))
    if bad.size:
        which = what if a.ndim == 2 else f"{what} [{int(bad[0])}]"
        raise SceneError(f"{which} must be invertible with a scale above {MIN_SCALE:.0e} "
                         f"(its 3x3 part has determinant {float(np.atleast_1d(det)[bad[0]]):.3g})")
    return a


def identity() -> np.ndarray:
    return np.eye(4)


def translate(x, y=None, z=None) -> np.ndarray:
    t = check_values([x, y, z] if y is not None else x, "translate").reshape(-1)
    if t.shape != (3,):
        raise SceneError(f"translate needs three numbers, got {t.size}")
    m = np.eye(4)
    m[:3, 3] = t
    return m


def scale(sx, sy=None, sz=None) -> np.ndarray:
    if sy is None and np.ndim(sx) == 0:
        s = check_values([sx, sx, sx], "scale")
    else:
        s = check_values([sx, sy, sz] if sy is not None else sx, "scale").reshape(-1)
        if s.shape != (3,):
            raise SceneError(f"scale needs one or three numbers, got {s.size}")
    return np.diag([*s, 1.0])


def rotate(angle_deg: float, axis=(0, 0, 1)) -> np.ndarray:
    """Rotation by ``angle_deg`` degrees about ``axis`` (right-handed)."""
    a = check_values(axis, "rotate axis").reshape(-1)
    t = float(check_values(angle_deg, "rotate angle"))
    n = np.linalg.norm(a)
    if a.shape != (3,) or n == 0:
        raise SceneError("rotate: the axis must be three numbers, not zero")
    x, y, z = a / n
    t = np.radians(t)
    c, s, C = np.cos(t), np.sin(t), 1 - np.cos(t)
    m = np.eye(4)
    m[:3, :3] = [[c + x * x * C, x * y * C - z * s, x * z * C + y * s],
                 [y * x * C + z * s, c + y * y * C, y * z * C - x * s],
                 [z * x * C - y * s, z * y * C + x * s, c + z * z * C]]
    return m


def matrix(m, what: str = "a transform") -> np.ndarray:
    """A 4x4 matrix from nested lists (rows), checked (``check_transform``)."""
    a = check_transform(m, what)
    if a.shape != (4, 4):
        raise SceneError(f"{what} must be a finite 4x4 matrix, got shape {a.shape}")
    return a
