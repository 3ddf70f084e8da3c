"""Pinhole camera (OpenGL conventions: right-handed, looks down -z in view space), and the pixel
and depth facts the surfel prefix law (paramlod.surfels.render) and the surfel -> mesh hand-off
(paramlod.scene.handoff) share: pixel_world_size, sphere_depth, transform_scale."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from paramlod.errors import SceneError


@dataclass
class Camera:
    view: np.ndarray        # 4x4 world -> view
    fov_y: float            # degrees
    size: tuple[int, int]   # (width, height) in pixels
    near: float = 0.01
    far: float = 1000.0

    @classmethod
    def look_at(cls, eye, target, up=(0, 1, 0), fov_y=45.0, size=(640, 480), near=0.01, far=1000.0):
        eye, target, up = (np.asarray(x, dtype=np.float64).reshape(3) for x in (eye, target, up))
        f = target - eye
        if np.linalg.norm(f) == 0:
            raise SceneError("camera: eye and target are the same point")
        f /= np.linalg.norm(f)
        s = np.cross(f, up)
        if np.linalg.norm(s) < 1e-9:
            raise SceneError("camera: 'up' is parallel to the viewing direction; choose another up vector")
        s /= np.linalg.norm(s)
        u = np.cross(s, f)
        view = np.eye(4)
        view[0, :3], view[1, :3], view[2, :3] = s, u, -f
        view[:3, 3] = -view[:3, :3] @ eye
        w, h = (int(x) for x in size)
        if w <= 0 or h <= 0 or w > 16384 or h > 16384:
            raise SceneError(f"camera: size must be between 1x1 and 16384x16384, got {w}x{h}")
        if not 0 < fov_y < 180:
            raise SceneError(f"camera: fov_y must be in (0, 180) degrees, got {fov_y}")
        if not 0 < near < far:
            raise SceneError(f"camera: need 0 < near < far, got near={near}, far={far}")
        return cls(view, float(fov_y), (w, h), float(near), float(far))

    @property
    def width(self) -> int:
        return self.size[0]

    @property
    def height(self) -> int:
        return self.size[1]

    @property
    def eye(self) -> np.ndarray:
        return -self.view[:3, :3].T @ self.view[:3, 3]

    @property
    def projection(self) -> np.ndarray:
        w, h = self.size
        f = 1.0 / np.tan(np.radians(self.fov_y) / 2)
        n, fa = self.near, self.far
        p = np.zeros((4, 4))
        p[0, 0] = f * h / w
        p[1, 1] = f
        p[2, 2] = (fa + n) / (n - fa)
        p[2, 3] = 2 * fa * n / (n - fa)
        p[3, 2] = -1.0
        return p

    def with_size(self, size) -> "Camera":
        """The same view at another image size (the aspect ratio follows)."""
        return Camera(self.view.copy(), self.fov_y, (int(size[0]), int(size[1])), self.near, self.far)


# --- camera and geometry facts shared by the surfel prefix law and the surfel -> mesh hand-off ---------
def pixel_world_size(camera, depth: float) -> float:
    """World size of one pixel (vertically) at view depth ``depth``: 2 w / (P[1,1] H) with w the
    clip w of a point at that depth (perspective: w = depth; orthographic: w = 1)."""
    p = camera.projection
    w = -p[3, 2] * depth + p[3, 3]          # clip w of a point at that depth (z = -depth)
    return float(2.0 * w / (p[1, 1] * camera.height))


def transform_scale(transform) -> float:
    """The uniform scale of a (similarity) transform: |det of its 3x3 part|^(1/3)."""
    return float(abs(np.linalg.det(np.asarray(transform, np.float64)[:3, :3])) ** (1.0 / 3.0))


def sphere_depth(camera, centre, radius: float, transform) -> float:
    """View depth of the nearest point of an object-space sphere placed by ``transform`` (its
    radius scaled by ``transform_scale``), at least the near plane."""
    m = camera.view @ np.asarray(transform, np.float64)
    cv = m[:3, :3] @ np.asarray(centre, np.float64) + m[:3, 3]
    return float(max(-cv[2] - radius * transform_scale(transform), camera.near))
