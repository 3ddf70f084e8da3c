"""Frame: the result of a render (colour, depth, normal, object id, stats) and its image files.

A Frame drawn into device buffers is read back lazily: ``frame.rgb8()`` (and a PNG) copies only
the 8-bit image the resolve made on the device; ``color``, ``depth``, ``normal`` and
``object_id`` are copied on first access. Reading a whole 1440x1440 frame cost about 32 ms on an
H200 against a 2 ms frame (issue 14); the image alone is 4 bytes a pixel.

``FrameStats`` is the one schema of ``frame.stats`` for every renderer and for composited frames.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from paramlod.core.color import linear_to_srgb8
from paramlod.core.files import write_atomically
from paramlod.errors import ParamlodError

ARRAYS = ("color", "depth", "normal", "object_id")
MS_KEYS = ("upload", "lod", "render", "resolve", "host", "frame", "readback", "total")


class FrameStats(dict):
    """``frame.stats``: a dict whose keys every frame has (``KEYS``; ``ms`` has ``MS_KEYS``), plus
    the keys of the renderers that drew it (their counters, listed in ``passes``).

    device: the OpenCL or OpenGL device; variant: the variant, or "composite" for a frame
    composited from several renderers' frames (``order`` names them); size: [w, h]; supersample
    and samples_per_pixel: of the finest pass; render_patches: patches the LOD stages produced;
    pixels_written: pixels any sample covered; passes: one dict per pass (its renderer's own
    counters and times), coarsest first; ms: device and host times in milliseconds (``frame``: up
    to resolved buffers on the device; ``readback``: the copy to the host, which lazy frames pay on
    access; ``total``: both)."""

    KEYS = ("device", "variant", "size", "supersample", "samples_per_pixel", "render_patches",
            "pixels_written", "warnings", "passes", "ms")

    def __init__(self, *args, **kw):
        super().__init__(*args, **kw)
        self.setdefault("device", "")
        self.setdefault("variant", "")
        self.setdefault("size", [0, 0])
        self.setdefault("supersample", 1)
        self.setdefault("samples_per_pixel", 1)
        self.setdefault("render_patches", 0)
        self.setdefault("pixels_written", 0)
        self.setdefault("warnings", [])
        self.setdefault("passes", [])
        ms = dict(self.get("ms") or {})
        for k in MS_KEYS:
            ms.setdefault(k, 0.0)
        self["ms"] = ms


def stats_aa(stats) -> str:
    """The anti-aliasing a frame (or pass) was drawn with, from its stats: tess's mode as the device
    ran it (``aa_effective``), "hybrid", the points' supersampling ("4xSS"), else "noAA"."""
    ss = int(stats.get("supersample") or 1)
    return stats.get("aa_effective") or stats.get("aa") or (f"{ss * ss}xSS" if ss > 1 else "noAA")


class Frame:
    """color: float32 (h, w, 4), linear RGB, alpha = coverage; depth: float32 (h, w), linear view
    depth, +inf = background; normal: float32 (h, w, 3), world space, facing the viewer, 0 on
    background; object_id: uint32 (h, w), 1-based scene object index, 0 = background.

    Built from arrays (``Frame(color=..., depth=..., ...)``) or from a device ``source`` with a
    ``read(name)`` method for each array name and "image" (the sRGB 8-bit RGB over
    ``background``, or None when it has none), called at most once per name."""

    def __init__(self, color=None, depth=None, normal=None, object_id=None, stats=None,
                 background=(0.0, 0.0, 0.0), source=None, size=None):
        self._arrays = {k: v for k, v in zip(ARRAYS, (color, depth, normal, object_id)) if v is not None}
        self._source = source
        self._image = self._image_background = None
        if source is None and len(self._arrays) < len(ARRAYS):
            missing = [k for k in ARRAYS if k not in self._arrays]
            raise ParamlodError(f"Frame needs all of {', '.join(ARRAYS)} (missing: {', '.join(missing)})")
        if size is None:
            c = self._arrays.get("color")
            if c is None:
                raise ParamlodError("Frame: give size=(w, h) with a device source")
            size = (c.shape[1], c.shape[0])
        self._size = (int(size[0]), int(size[1]))
        self.stats = FrameStats(stats or {})
        self.background = tuple(background)

    def _get(self, name):
        a = self._arrays.get(name)
        if a is None:
            a = self._arrays[name] = self._source.read(name)
        return a

    @property
    def color(self) -> np.ndarray:
        return self._get("color")

    @property
    def depth(self) -> np.ndarray:
        return self._get("depth")

    @property
    def normal(self) -> np.ndarray:
        return self._get("normal")

    @property
    def object_id(self) -> np.ndarray:
        return self._get("object_id")

    def materialize(self) -> "Frame":
        """Copy every array that is still on the device (the device buffers are about to be
        reused); returns self."""
        if self._source is not None:
            for name in ARRAYS:
                self._get(name)
            self._source = None
        return self

    @property
    def on_device(self) -> tuple[str, ...]:
        """Names of the arrays not copied to the host yet."""
        return tuple(k for k in ARRAYS if k not in self._arrays) if self._source is not None else ()

    @property
    def size(self) -> tuple[int, int]:
        return self._size

    @property
    def coverage(self) -> np.ndarray:
        return np.isfinite(self.depth)

    def rgb8(self) -> np.ndarray:
        """sRGB 8-bit image composited over the background colour. A device frame whose colour
        was not read gives the resolve's image (equal to the host encoding of ``color`` where a
        pixel is fully covered or empty, within one code at partly covered edges)."""
        if self._image is None and self._source is not None and "color" not in self._arrays:
            self._image = self._source.read("image")
            self._image_background = tuple(self._source.background)
        if self._image is not None and self._image_background == tuple(self.background):
            return self._image
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

            def write(tmp):
                try:
                    OpenEXR.File(header, channels).write(tmp)
                except RuntimeError as exc:   # OpenEXR's I/O errors (a full disk), which name the temporary file
                    raise OSError(str(exc).split(f'"{tmp}". ')[-1].rstrip(".")) from None

            return write_atomically(path, write)
        raise ParamlodError(f"cannot write {path}: unknown image type '{path.suffix}' (use .png or .exr)")
