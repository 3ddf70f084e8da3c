"""Frame: the result of a render (colour, depth, normal, object id, stats) and its image files."""
from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from paramlod.errors import ParamlodError


def linear_to_srgb8(c: np.ndarray) -> np.ndarray:
    c = np.clip(c, 0.0, 1.0)
    s = np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)
    return (s * 255.0 + 0.5).astype(np.uint8)


def write_atomically(path, write) -> Path:
    """Call ``write(tmp_path)`` on a temporary file beside ``path``, then rename it into place."""
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise ParamlodError(f"cannot write {path}: folder {folder} does not exist")
    if not os.access(folder, os.W_OK):
        raise ParamlodError(f"cannot write {path}: folder {folder} is not writable")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix, dir=folder)
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the file the usual permissions
    try:
        write(tmp)
        os.replace(tmp, path)
    except OSError as exc:
        raise ParamlodError(f"cannot write {path}: {exc.strerror or exc}") from exc
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path


@dataclass
class Frame:
    color: np.ndarray       # float32 (h, w, 4), linear RGB, alpha = coverage
    depth: np.ndarray       # float32 (h, w), linear view depth, +inf = background
    normal: np.ndarray      # float32 (h, w, 3), world space, facing the viewer; 0 on background
    object_id: np.ndarray   # uint32 (h, w), 1-based scene object index, 0 = background
    stats: dict = field(default_factory=dict)
    background: tuple = (0.0, 0.0, 0.0)

    @property
    def size(self) -> tuple[int, int]:
        return self.color.shape[1], self.color.shape[0]

    @property
    def coverage(self) -> np.ndarray:
        return np.isfinite(self.depth)

    def rgb8(self) -> np.ndarray:
        """sRGB 8-bit image composited over the background colour."""
        a = self.color[..., 3:4]
        rgb = self.color[..., :3] * a + np.asarray(self.background, np.float32) * (1 - a)
        return linear_to_srgb8(rgb)

    def save(self, path) -> Path:
        """Write ``.png`` (sRGB over the background) or ``.exr`` (all channels), atomically."""
        path = Path(path)
        ext = path.suffix.lower()
        if ext == ".png":
            from PIL import Image

            img = Image.fromarray(self.rgb8(), "RGB")
            return write_atomically(path, lambda tmp: img.save(tmp, format="PNG"))
        if ext == ".exr":
            import OpenEXR

            channels = {
                "R": self.color[..., 0], "G": self.color[..., 1], "B": self.color[..., 2],
                "A": self.color[..., 3], "Z": self.depth,
                "N.X": self.normal[..., 0], "N.Y": self.normal[..., 1], "N.Z": self.normal[..., 2],
                "objectId": self.object_id,
            }
            channels = {k: np.ascontiguousarray(v) for k, v in channels.items()}
            header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
            return write_atomically(path, lambda tmp: OpenEXR.File(header, channels).write(tmp))
        raise ParamlodError(f"cannot write {path}: unknown image type '{path.suffix}' (use .png or .exr)")
