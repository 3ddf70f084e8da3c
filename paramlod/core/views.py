"""Camera sets for multi-view rendering (``paramlod.render_views``): ``Views`` (N cameras of one
size, checked once) and the usual sets: ``stereo`` (a parallel pair sharing a focal plane),
``cube_faces`` (six 90-degree views) and ``quilt`` (a light-field grid, as Looking Glass displays
take it), with ``equirect`` (a panorama from the six faces) and ``quilt_image`` (the tiles in one
image). Plain numpy: the pipeline turns a Views into per-view camera records on the device.
"""
from __future__ import annotations

import numpy as np

from paramlod.core.camera import Camera
from paramlod.core.layouts import camera_record
from paramlod.errors import SceneError

# views of one frame: the GL path draws up to 32 per geometry-shader invocation set and chunks
# the rest; past 64 the layered buffers of a 1080p frame outgrow most devices' single allocation
MAX_VIEWS = 64


class Views:
    """``cameras``: one or more paramlod Cameras of the same size, rendered by one LOD pass."""

    def __init__(self, cameras):
        if isinstance(cameras, Camera):
            cameras = [cameras]
        try:
            cams = tuple(cameras)
        except TypeError:
            raise SceneError(f"render_views needs a list of paramlod.Camera, got {type(cameras).__name__}") from None
        if not cams:
            raise SceneError("render_views needs at least one camera")
        for i, c in enumerate(cams):
            if not isinstance(c, Camera):
                raise SceneError(f"render_views: camera {i} is a {type(c).__name__}, not a paramlod.Camera")
        if len(cams) > MAX_VIEWS:
            raise SceneError(f"render_views: {len(cams)} cameras, more than {MAX_VIEWS} views in one frame; "
                             "render them in several calls")
        sizes = {tuple(c.size) for c in cams}
        if len(sizes) > 1:
            raise SceneError("render_views: every camera must have the same size, got "
                             + ", ".join(f"{w}x{h}" for w, h in sorted(sizes)))
        self.cameras = cams

    def __len__(self) -> int:
        return len(self.cameras)

    def __iter__(self):
        return iter(self.cameras)

    def __getitem__(self, i) -> Camera:
        return self.cameras[i]

    @property
    def size(self) -> tuple[int, int]:
        return self.cameras[0].size

    @property
    def width(self) -> int:
        return self.size[0]

    @property
    def height(self) -> int:
        return self.size[1]

    def with_size(self, size) -> "Views":
        return Views([c.with_size(size) for c in self.cameras])

    def records(self) -> np.ndarray:
        """float32 (N * CAMERA.length,): the views' camera records one after another (a kernel
        reads view v at ``cam + v * CAM_FLOATS``)."""
        return np.concatenate([camera_record(c) for c in self.cameras]).astype(np.float32)


def as_views(camera) -> Views:
    """A Views of a Camera (one view) or of a Views / list of cameras."""
    return camera if isinstance(camera, Views) else Views(camera)


def _axes(camera: Camera):
    """(right, up, forward, eye) of ``camera`` in world space."""
    r = camera.view[:3, :3]
    return r[0].copy(), r[1].copy(), -r[2].copy(), camera.eye


def _moved(camera: Camera, offset, shift) -> Camera:
    view = camera.view.copy()
    view[:3, 3] = -view[:3, :3] @ (camera.eye + offset)
    return Camera(view, camera.fov_y, camera.size, camera.near, camera.far,
                  (camera.shift[0] + shift, camera.shift[1]))


def _positive(x, what) -> float:
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise SceneError(f"{what} must be a number, got {x!r}") from None
    if not (np.isfinite(v) and v > 0):
        raise SceneError(f"{what} must be a positive number, got {x!r}")
    return v


def stereo(camera: Camera, ipd: float, focus: float | None = None) -> list[Camera]:
    """[left, right]: ``camera`` moved by -ipd/2 and +ipd/2 along its right axis, both looking the
    same way. Without ``focus`` the pair is parallel (zero parallax at infinity); with it, a lens
    shift makes the two images meet at that view depth (off-axis stereo, no keystone)."""
    if not isinstance(camera, Camera):
        raise SceneError(f"stereo needs a paramlod.Camera, got {type(camera).__name__}")
    ipd = _positive(ipd, "stereo: ipd")
    right = _axes(camera)[0]
    shift = 0.0
    if focus is not None:
        focus = _positive(focus, "stereo: focus")
        # a point at depth `focus` straight ahead lands at x_ndc = +-(ipd/2) p00 / focus in the left and right eye
        shift = 0.5 * ipd * camera.projection[0, 0] / focus
    return [_moved(camera, -0.5 * ipd * right, -shift), _moved(camera, 0.5 * ipd * right, shift)]


# +X, -X, +Y, -Y, +Z, -Z: (direction, up); the up vectors keep the side faces upright
CUBE_FACES = (("+x", (1, 0, 0), (0, 1, 0)), ("-x", (-1, 0, 0), (0, 1, 0)),
              ("+y", (0, 1, 0), (0, 0, -1)), ("-y", (0, -1, 0), (0, 0, 1)),
              ("+z", (0, 0, 1), (0, 1, 0)), ("-z", (0, 0, -1), (0, 1, 0)))


def cube_faces(position, size: int = 512, near: float = 0.01, far: float = 1000.0) -> list[Camera]:
    """Six square 90-degree cameras at ``position`` looking along +X, -X, +Y, -Y, +Z, -Z."""
    try:
        side = int(size)
    except (TypeError, ValueError):
        raise SceneError(f"cube_faces: size must be whole pixels, got {size!r}") from None
    try:
        p = np.asarray(position, np.float64).reshape(-1)
    except (TypeError, ValueError):
        p = np.full(0, np.nan)
    if p.shape != (3,):
        raise SceneError(f"cube_faces: position must be three numbers, got {position!r}")
    return [Camera.look_at(p, p + np.asarray(d, float), up, 90.0, (side, side), near, far) for _, d, up in CUBE_FACES]


def equirect(frames, cameras, height: int | None = None) -> np.ndarray:
    """An equirectangular panorama (sRGB uint8, height x 2 height x 3) from the six frames of
    ``cube_faces`` cameras (``cameras``, in the same order): each output pixel's direction is looked
    up in the face it points into (nearest pixel). Longitude 0 looks along -Z, increasing towards +X;
    the top row looks up (+Y)."""
    def count(x):
        return len(x) if isinstance(x, (list, tuple)) else type(x).__name__
    if count(frames) != 6 or count(cameras) != 6:
        raise SceneError(f"equirect needs the six cube_faces frames and cameras (lists), got {count(frames)} and "
                         f"{count(cameras)}")
    if not all(isinstance(c, Camera) for c in cameras) or not all(hasattr(f, "rgb8") for f in frames):
        raise SceneError("equirect needs paramlod Frames (render_views' result) and the cube_faces cameras")
    side = cameras[0].size[0]
    h = int(height or side * 2)
    w = 2 * h
    lon = (np.arange(w) + 0.5) / w * 2 * np.pi - np.pi
    lat = np.pi / 2 - (np.arange(h) + 0.5) / h * np.pi
    lon, lat = np.meshgrid(lon, lat)
    d = np.stack([np.cos(lat) * np.sin(lon), np.sin(lat), -np.cos(lat) * np.cos(lon)], axis=-1)
    out = np.zeros((h, w, 3), np.uint8)
    best = np.full((h, w), -np.inf)
    for frame, cam in zip(frames, cameras):
        fwd = -cam.view[2, :3]
        along = d @ fwd
        take = along > best
        e = d[take] @ cam.view[:3, :3].T          # directions in the face's view space
        c = e @ cam.projection[:3, :3].T          # clip x, y; w = -z
        wv = -e[:, 2]
        px = np.clip(((c[:, 0] / wv) * 0.5 + 0.5) * cam.width, 0, cam.width - 1).astype(int)
        py = np.clip((0.5 - (c[:, 1] / wv) * 0.5) * cam.height, 0, cam.height - 1).astype(int)
        out[take] = frame.rgb8()[py, px]
        best[take] = along[take]
    return out


def quilt(camera: Camera, cols: int, rows: int, view_cone: float = 40.0,
          focus: float | None = None) -> list[Camera]:
    """cols x rows views of a light-field display (a Looking Glass quilt): ``camera`` moved along
    its right axis so that the views span ``view_cone`` degrees seen from the focal plane at view
    depth ``focus`` (default: the depth of the world origin, at least twice near), each with the
    lens shift that keeps that plane in place. View 0 is the leftmost; ``quilt_image`` puts it
    bottom left and fills rows left to right, bottom to top."""
    if not isinstance(camera, Camera):
        raise SceneError(f"quilt needs a paramlod.Camera, got {type(camera).__name__}")
    for x, what in ((cols, "cols"), (rows, "rows")):
        if isinstance(x, bool) or not isinstance(x, (int, np.integer)) or x < 1:
            raise SceneError(f"quilt: {what} must be a positive whole number, got {x!r}")
    n = int(cols) * int(rows)
    if n > MAX_VIEWS:
        raise SceneError(f"quilt: {cols}x{rows} = {n} views, more than {MAX_VIEWS}")
    cone = _positive(view_cone, "quilt: view_cone")
    if cone >= 180:
        raise SceneError(f"quilt: view_cone must be under 180 degrees, got {cone}")
    right = _axes(camera)[0]
    if focus is None:
        focus = max(-float(camera.view[2, 3]), 2 * camera.near)   # view depth of the origin
    else:
        focus = _positive(focus, "quilt: focus")
    out = []
    for i in range(n):
        a = np.radians(-cone / 2 + cone * (i / (n - 1) if n > 1 else 0.5))
        x = focus * np.tan(a)
        # the focal point straight ahead moves to x_ndc = -x p00 / focus: shift it back
        out.append(_moved(camera, x * right, x * camera.projection[0, 0] / focus))
    return out


def parse_grid(text: str) -> tuple[int, int]:
    """"8x6" -> (8, 6) (a quilt's columns x rows)."""
    try:
        c, r = (int(x) for x in str(text).lower().split("x"))
    except ValueError:
        raise SceneError(f"a quilt is COLSxROWS, e.g. 8x6, got {text!r}") from None
    if c < 1 or r < 1 or c * r > MAX_VIEWS:
        raise SceneError(f"a quilt needs 1..{MAX_VIEWS} views, got {text!r}")
    return c, r


def quilt_image(frames, cols: int, rows: int) -> np.ndarray:
    """The quilt's tiles in one sRGB uint8 image (rows * h, cols * w, 3): view 0 bottom left,
    left to right, then upwards."""
    if len(frames) != cols * rows:
        raise SceneError(f"quilt_image: {cols}x{rows} needs {cols * rows} frames, got {len(frames)}")
    w, h = frames[0].size
    out = np.zeros((rows * h, cols * w, 3), np.uint8)
    for i, f in enumerate(frames):
        r, c = divmod(i, cols)
        y = (rows - 1 - r) * h
        out[y:y + h, c * w:(c + 1) * w] = f.rgb8()
    return out


def strip_image(frames) -> np.ndarray:
    """Frames side by side (a stereo pair: left, right)."""
    return np.concatenate([f.rgb8() for f in frames], axis=1)


__all__ = ["MAX_VIEWS", "Views", "as_views", "stereo", "cube_faces", "equirect", "quilt", "quilt_image",
           "strip_image", "parse_grid"]
