"""The K orthographic views that enclose an object: directions on a Fibonacci sphere.

Every view looks at the centre of the object's bounding sphere from the direction ``-d`` (the
camera sits at ``centre - d * distance`` and looks along ``d``) with a square orthographic box of
half-size ``extent``. Pixel (x, y) of a view, row 0 at the top, sees the world point

    centre + right * ((x + 0.5) / W * 2 - 1) * extent + up * (1 - (y + 0.5) / H * 2) * extent + d * t

All views share centre, extent and resolution, so one world length maps to ``scale = W / (2 extent)``
pixels in every view (kernels/surfels_sample.cl projects sites with exactly these numbers).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from paramlod.core.camera import Camera
from paramlod.errors import SurfelError

MAX_VIEWS = 32
GOLDEN_ANGLE = np.pi * (3.0 - np.sqrt(5.0))


def fibonacci_directions(k: int) -> np.ndarray:
    """``k`` unit vectors spread evenly over the sphere (float64, (k, 3))."""
    i = np.arange(k, dtype=np.float64)
    z = 1.0 - (2.0 * i + 1.0) / k
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = GOLDEN_ANGLE * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def _basis(d: np.ndarray):
    """(right, up) completing the viewing direction ``d`` to a right-handed camera frame."""
    helper = np.array([0.0, 1.0, 0.0]) if abs(d[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    right = np.cross(d, helper)
    right /= np.linalg.norm(right)
    up = np.cross(right, d)
    return right, up


class OrthoCamera(Camera):
    """An orthographic paramlod camera (square pixels; ``half_height`` world units to the top edge).

    It only replaces ``projection``; view, size, near and far keep Camera's meaning, so the LOD
    stage and the point renderer take it unchanged (their depth is the linear view depth -z)."""

    def __init__(self, view, size, half_height, near, far):
        super().__init__(np.asarray(view, np.float64), 45.0, (int(size[0]), int(size[1])), float(near), float(far))
        self.half_height = float(half_height)

    @property
    def projection(self) -> np.ndarray:
        w, h = self.size
        t = self.half_height
        r = t * w / h
        n, f = self.near, self.far
        p = np.zeros((4, 4))
        p[0, 0] = 1.0 / r
        p[1, 1] = 1.0 / t
        p[2, 2] = -2.0 / (f - n)
        p[2, 3] = -(f + n) / (f - n)
        p[3, 3] = 1.0
        return p

    def with_size(self, size) -> "OrthoCamera":
        return OrthoCamera(self.view.copy(), size, self.half_height, self.near, self.far)


@dataclass
class ViewSet:
    centre: np.ndarray      # (3,) float64
    extent: float           # half-size of every view's square, world units
    directions: np.ndarray  # (K, 3) viewing directions (from the camera towards the centre)
    rights: np.ndarray      # (K, 3)
    ups: np.ndarray         # (K, 3)
    resolution: int         # W = H

    @property
    def count(self) -> int:
        return len(self.directions)

    @property
    def distance(self) -> float:
        """Camera distance from the centre (the box spans depths [distance - extent, distance + extent])."""
        return 2.0 * self.extent

    @property
    def scale(self) -> float:
        """Pixels per world unit."""
        return self.resolution / (2.0 * self.extent)

    @property
    def pixel_size(self) -> float:
        return 2.0 * self.extent / self.resolution

    def eye(self, k: int) -> np.ndarray:
        return self.centre - self.directions[k] * self.distance

    def view_matrix(self, k: int) -> np.ndarray:
        v = np.eye(4)
        v[0, :3], v[1, :3], v[2, :3] = self.rights[k], self.ups[k], -self.directions[k]
        v[:3, 3] = -v[:3, :3] @ self.eye(k)
        return v

    @property
    def near(self) -> float:
        # the LOD stage accepts a sample when clip w (1 for an orthographic camera) >= near
        return min(0.5 * self.extent, 0.5)

    @property
    def far(self) -> float:
        return self.distance + 2.0 * self.extent

    def camera(self, k: int) -> OrthoCamera:
        return OrthoCamera(self.view_matrix(k), (self.resolution, self.resolution), self.extent, self.near, self.far)

    def layer_record(self) -> np.ndarray:
        """float32 (K, 8): right.xyz, pad, up.xyz, pad for the sampling kernels."""
        rec = np.zeros((self.count, 8), np.float32)
        rec[:, 0:3] = self.rights
        rec[:, 4:7] = self.ups
        return rec

    def pixel_world(self, k: int, depth: np.ndarray) -> np.ndarray:
        """World positions of the pixel centres of view ``k`` at linear view depths ``depth`` (H, W)."""
        n = self.resolution
        c = (np.arange(n) + 0.5) / n * 2.0 - 1.0
        xs = c[None, :] * self.extent
        ys = -c[:, None] * self.extent
        return (self.eye(k) + self.rights[k] * xs[..., None] + self.ups[k] * ys[..., None]
                + self.directions[k] * depth[..., None])


def make_views(centre, radius: float, count: int = 16, resolution: int = 512, margin: float = 1.02) -> ViewSet:
    """Views on a Fibonacci sphere that enclose the sphere (centre, radius)."""
    count = int(count)
    resolution = int(resolution)
    if not 1 <= count <= MAX_VIEWS:
        raise SurfelError(f"views must be between 1 and {MAX_VIEWS}, got {count}")
    if not 8 <= resolution <= 4096:
        raise SurfelError(f"G-buffer resolution must be between 8 and 4096 pixels, got {resolution}")
    centre = np.asarray(centre, np.float64).reshape(3)
    if not (np.all(np.isfinite(centre)) and np.isfinite(radius) and radius > 0):
        raise SurfelError(f"the object has no extent to sample (bounding sphere centre {centre}, radius {radius})")
    dirs = fibonacci_directions(count)
    rights, ups = zip(*(_basis(d) for d in dirs))
    return ViewSet(centre, float(radius) * margin, dirs, np.array(rights), np.array(ups), resolution)
