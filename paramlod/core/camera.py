"""Pinhole camera (OpenGL conventions: right-handed, looks down -z in view space), and the pixel
and depth facts the surfel prefix law (paramlod.surfels.render) and the surfel -> mesh hand-off
(paramlod.scene.handoff) share: pixel_world_size, sphere_depth, transform_scale."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from paramlod.core.transforms import PLACE_LIMIT, check_values
from paramlod.errors import SceneError


MAX_SIZE = 16384


def _pixels(size) -> tuple[int, int]:
    """(width, height) as whole pixels in 1..MAX_SIZE; 10.5 is refused, not rounded."""
    try:
        w, h = size
    except (TypeError, ValueError):
        raise SceneError(f"camera: size must be (width, height) in pixels, got {size!r}") from None
    out = []
    for x in (w, h):
        if isinstance(x, (bool, np.bool_)) or not isinstance(x, (int, float, np.integer, np.floating)) \
                or not np.isfinite(x) or float(x) != int(x):
            raise SceneError(f"camera: size must be whole pixels, got {w!r}x{h!r}")
        out.append(int(x))
    if not all(1 <= x <= MAX_SIZE for x in out):
        raise SceneError(f"camera: size must be between 1x1 and {MAX_SIZE}x{MAX_SIZE}, got {out[0]}x{out[1]}")
    return out[0], out[1]


def _number(x, what: str) -> float:
    if isinstance(x, (bool, np.bool_)):
        raise SceneError(f"camera: {what} must be a number, got {x!r}")
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise SceneError(f"camera: {what} must be a number, got {x!r}") from None
    if not np.isfinite(v):
        raise SceneError(f"camera: {what} must be finite, got {v}")
    return v


@dataclass
class Camera:
    """Checked when made (``look_at``, the constructor, ``with_size``): a camera with a NaN or
    far-off eye made every LOD patch measure infinite and split at every step."""

    view: np.ndarray        # 4x4 world -> view
    fov_y: float            # degrees
    size: tuple[int, int]   # (width, height) in pixels
    near: float = 0.01
    far: float = 1000.0
    # off-axis lens shift in normalised device coordinates (added to x and y after the divide):
    # the views of a light-field quilt or of a stereo pair share one focal plane this way
    shift: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self):
        try:
            view = np.array(self.view, dtype=np.float64)
        except (TypeError, ValueError):
            raise SceneError("camera: view must be a 4x4 matrix of numbers") from None
        if view.shape != (4, 4):
            raise SceneError(f"camera: view must be a 4x4 matrix, got shape {view.shape}")
        self.view = check_values(view, "camera: view")
        self.size = _pixels(self.size)
        self.fov_y = _number(self.fov_y, "fov_y")
        if not 0 < self.fov_y < 180:
            raise SceneError(f"camera: fov_y must be in (0, 180) degrees, got {self.fov_y}")
        self.near, self.far = _number(self.near, "near"), _number(self.far, "far")
        if not 0 < self.near < self.far:
            raise SceneError(f"camera: need 0 < near < far, got near={self.near}, far={self.far}")
        if self.far > PLACE_LIMIT:
            raise SceneError(f"camera: far must be at most {PLACE_LIMIT:.0e}, got {self.far:.3g}")
        try:
            sx, sy = self.shift
        except (TypeError, ValueError):
            raise SceneError(f"camera: shift must be two numbers (NDC x, y), got {self.shift!r}") from None
        self.shift = (_number(sx, "shift x"), _number(sy, "shift y"))

    @classmethod
    def look_at(cls, eye, target, up=(0, 1, 0), fov_y=45.0, size=(640, 480), near=0.01, far=1000.0,
                shift=(0.0, 0.0)):
        eye, target, up = (check_values(x, f"camera: {n}").reshape(-1)
                           for x, n in ((eye, "eye"), (target, "target"), (up, "up")))
        for x, n in ((eye, "eye"), (target, "target"), (up, "up")):
            if x.shape != (3,):
                raise SceneError(f"camera: {n} must be three numbers, got {x.size}")
        f = target - eye
        if np.linalg.norm(f) == 0:
            raise SceneError("camera: eye and target are the same point")
        f /= np.linalg.norm(f)
        if np.linalg.norm(up) == 0:
            raise SceneError("camera: 'up' must not be zero")
        s = np.cross(f, up / np.linalg.norm(up))
        if np.linalg.norm(s) < 1e-9:
            raise SceneError("camera: 'up' is parallel to the viewing direction; choose another up vector")
        s /= np.linalg.norm(s)
        u = np.cross(s, f)
        view = np.eye(4)
        view[0, :3], view[1, :3], view[2, :3] = s, u, -f
        view[:3, 3] = -view[:3, :3] @ eye
        return cls(view, fov_y, size, near, far, shift)

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
        # x_ndc = p00 x / -z - p02: a shift s moves the image by +s
        p[0, 2], p[1, 2] = -self.shift[0], -self.shift[1]
        return p

    def with_size(self, size) -> "Camera":
        """The same view at another image size (the aspect ratio follows)."""
        return Camera(self.view.copy(), self.fov_y, size, self.near, self.far, self.shift)   # checked as any camera


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
