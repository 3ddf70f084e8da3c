"""The shared 64-bit key buffers every point producer writes into, and their resolve to a Frame.

Two ulong buffers of width x height (kernels/keys.cl): the colour key (depth | sRGB RGBA8) and the
aux key (depth | octahedral normal | object id). Renderers only ever atom_min into them. A
multi-view frame (``paramlod.render_views``) has ``layers`` of them one after another: pixel (x, y)
of view v is key ``v * width * height + y * width + x``, so the resolve and the downsample treat the
layers as one tall image and never mix two views in one work-group or block.
``Downsample`` resolves a supersampled KeyBuffer block by block into one of the frame's size;
``Upsample`` copies each key of a KeyBuffer into every subsample of one ``ratio`` times its side
(the hybrid tiers' hand-over from a coarser to a finer tier).
"""
from __future__ import annotations

import numpy as np

import weakref

import pyopencl as cl
import pyopencl.array as cla

from paramlod.core.color import linear_to_srgb8, srgb_tables
from paramlod.core.frame import Frame
from paramlod.device.context import cl_device
from paramlod.device.programs import build, launch


class KeyBuffer:
    """The colour and aux keys of ``width`` x ``height`` pixels (or subsamples), and, once
    resolved, the Frame arrays, the 8-bit image and the frame's counters on the device.

    ``ss``: subsamples per pixel side the keys' alpha stands for (the resolve counts covered
    subsamples with it). Each resolve writes into a set of output buffers that the Frame made from
    it keeps until it is dropped: a frame still alive when the next one is drawn (``f = render(...)``
    in a loop) keeps its own arrays without copying them, at the cost of device memory."""

    def __init__(self, width: int, height: int, ss: int = 1, layers: int = 1):
        self.width, self.height, self.ss, self.layers = int(width), int(height), int(ss), int(layers)
        n = self.width * self.height * self.layers
        ctx = cl_device().context
        self.color = cl.Buffer(ctx, cl.mem_flags.READ_WRITE, n * 8)
        self.aux = cl.Buffer(ctx, cl.mem_flags.READ_WRITE, n * 8)
        self._free: list[_Outputs] = []   # output sets no Frame holds
        self._last: _Outputs | None = None
        self._count_buf = None
        self._counts = np.zeros((self.layers, 2), np.uint32)   # per layer (resolve.cl)
        # pinned host arrays the resolved arrays are copied through: a copy into pageable memory
        # measured 0.35 GB/s on an H200 (17 ms for a 1080p image)
        self._staging: dict[int, np.ndarray] = {}

    @property
    def layer_pixels(self) -> int:
        return self.width * self.height

    @property
    def pixel_count(self) -> int:
        """Keys in all layers."""
        return self.width * self.height * self.layers

    def clear(self):
        """Clear the keys to all ones."""
        q = cl_device().queue
        ones = np.uint64(0xFFFFFFFFFFFFFFFF)
        cl.enqueue_fill_buffer(q, self.color, ones, 0, self.pixel_count * 8)
        cl.enqueue_fill_buffer(q, self.aux, ones, 0, self.pixel_count * 8)

    def read_keys(self) -> tuple[np.ndarray, np.ndarray]:
        """The raw colour and aux keys, uint64 (h, w) each ((layers, h, w) with several layers)."""
        q = cl_device().queue
        shape = (self.height, self.width) if self.layers == 1 else (self.layers, self.height, self.width)
        c = np.empty(shape, np.uint64)
        a = np.empty_like(c)
        cl.enqueue_copy(q, c, self.color)
        cl.enqueue_copy(q, a, self.aux)
        return c, a

    def resolve(self, background=(0.0, 0.0, 0.0)) -> Frame:
        """Decode the keys and return the Frame (waits)."""
        self.resolve_on_device(background)
        self.read_counts()
        cl_device().queue.finish()
        return self.frame()

    def resolve_on_device(self, background=(0.0, 0.0, 0.0)):
        """Enqueue the decode of the keys into colour, depth, normal, id and image buffers and the
        counters on the device (returns the kernel's event). ``background``: linear RGB the image
        is composited over. A supersampled buffer is only downsampled, never resolved."""
        if self._count_buf is None:
            self._count_buf = cl.Buffer(cl_device().context, cl.mem_flags.READ_WRITE, self._counts.nbytes)
        out = self._free.pop() if self._free else _Outputs(self)
        out.set_background(background)
        self._last = out
        q = cl_device().queue
        cl.enqueue_fill_buffer(q, self._count_buf, np.uint32(0), 0, self._counts.nbytes)
        # whole work-groups per layer (resolve.cl), so each counts into its own layer's record
        per_layer = (self.layer_pixels + 255) // 256 * 256
        return launch(q, out.kernel, (per_layer * self.layers,), (256,))

    def read_counts(self):
        """Enqueue the copy of the resolve's counters (read after the frame's wait: ``counts``)."""
        cl.enqueue_copy(cl_device().queue, self._counts, self._count_buf, is_blocking=False)

    @property
    def counts(self) -> dict:
        """{"pixels_written", "covered_subsamples"} of the last resolve, all layers together
        (after the frame's wait)."""
        total = self._counts.sum(axis=0, dtype=np.int64)
        return {"pixels_written": int(total[0]), "covered_subsamples": int(total[1])}

    def layer_counts(self, layer: int) -> dict:
        """``counts`` of one layer (one view of a multi-view frame)."""
        c = self._counts[layer]
        return {"pixels_written": int(c[0]), "covered_subsamples": int(c[1])}

    def staging(self, slot: int, shape, dtype) -> np.ndarray:
        """A pinned host array (mapped once, kept) for reading resolved array ``slot``."""
        arr = self._staging.get(slot)
        if arr is None:
            nbytes = int(np.prod(shape)) * np.dtype(dtype).itemsize
            buf = cl.Buffer(cl_device().context, cl.mem_flags.READ_WRITE | cl.mem_flags.ALLOC_HOST_PTR, nbytes)
            arr, _ = cl.enqueue_map_buffer(cl_device().queue, buf, cl.map_flags.READ | cl.map_flags.WRITE, 0,
                                           shape, dtype)
            self._staging[slot] = arr   # the mapped array holds its buffer
        return arr

    def frame(self, background=None) -> Frame:
        """A Frame that reads the last resolve lazily; its output buffers return to this key
        buffer when the Frame is dropped. One layer only (else ``frames``)."""
        if self.layers != 1:
            raise ValueError(f"KeyBuffer.frame: {self.layers} layers make {self.layers} frames (use frames())")
        return self.frames(background)[0]

    def frames(self, background=None) -> list[Frame]:
        """One lazy Frame per layer of the last resolve; the output buffers return to this key
        buffer when every one of them is dropped."""
        out, self._last = self._last, None
        if out is None:
            raise ValueError("KeyBuffer.frame: resolve_on_device first (each resolve makes one Frame)")
        holder = _Held(out)
        frames = [Frame(source=_ResolvedArrays(self, out, layer, holder), size=(self.width, self.height),
                        background=out.background if background is None else background)
                  for layer in range(self.layers)]
        weakref.finalize(holder, self._free.append, out)
        return frames


class _Held:
    """What the Frames of one resolve share: their output set returns when it is dropped."""

    def __init__(self, out):
        self.out = out


class _Outputs:
    """One set of resolved arrays on the device, with the resolve kernel bound to it."""

    def __init__(self, keys: KeyBuffer):
        n = keys.pixel_count
        ctx = cl_device().context
        self.bufs = [cl.Buffer(ctx, cl.mem_flags.WRITE_ONLY, n * s) for s in (16, 4, 16, 4, 3)]
        lin, thr = srgb_device_tables()
        self.kernel = cl.Kernel(build(["common/keys.cl", "points/subsamples.cl", "points/resolve.cl"],
                                      defines={"PL_SS_COUNT": keys.ss * keys.ss}), "resolve")
        self.kernel.set_args(keys.color, keys.aux, np.uint32(keys.layer_pixels), *self.bufs, np.uint32(0),
                             lin.data, thr.data, keys._count_buf)
        self.background = None

    def set_background(self, background):
        background = tuple(float(x) for x in background)
        if background != self.background:
            bg = linear_to_srgb8(np.asarray(background, np.float32)).astype(np.uint32)
            self.kernel.set_arg(8, np.uint32((bg[0] << 24) | (bg[1] << 16) | (bg[2] << 8) | 255))
            self.background = background


class _ResolvedArrays:
    """Reads one resolved array of a KeyBuffer's output set on request (a Frame's device source)."""

    _SLOTS = {"color": (0, np.float32, 4), "depth": (1, np.float32, 0), "normal": (2, np.float32, 4),
              "object_id": (3, np.uint32, 0), "image": (4, np.uint8, 3)}

    def __init__(self, keys: KeyBuffer, out: _Outputs, layer: int = 0, holder=None):
        self.keys, self.out, self.background = keys, out, out.background
        self.layer, self.holder = layer, holder

    def read(self, name: str) -> np.ndarray:
        k = self.keys
        slot, dtype, channels = self._SLOTS[name]
        shape = (k.height, k.width, channels) if channels else (k.height, k.width)
        staged = k.staging(slot, shape, dtype)
        cl.enqueue_copy(cl_device().queue, staged, self.out.bufs[slot], src_offset=self.layer * staged.nbytes)
        return np.array(staged[..., :3] if name == "normal" else staged)


def srgb_device_tables():
    """The (lin, thr) tables of paramlod.core.color.srgb_tables on the device (uploaded once per
    context): both subsample resolves (kernels/subsamples.cl) read them."""
    dev = cl_device()
    if "srgb_tables" not in dev.cache:
        dev.cache["srgb_tables"] = tuple(cla.to_device(dev.queue, t) for t in srgb_tables())
    return dev.cache["srgb_tables"]


class Downsample:
    """Resolves a KeyBuffer ``ss`` times the frame's size into the frame's KeyBuffer, one pixel per
    ss x ss block (kernels/subsamples.cl; numpy twin: points_reference.resolve_blocks): colour
    averaged over the covered subsamples in linear light, alpha = coverage, nearest depth."""

    def __init__(self, ss: int):
        self.ss = int(ss)
        self.kernel = cl.Kernel(build(["common/keys.cl", "points/subsamples.cl"], defines={"PL_SS": self.ss}), "downsample_keys")
        self.tables = srgb_device_tables()
        self._bound = None

    def enqueue(self, src: KeyBuffer, dst: KeyBuffer):
        """Enqueue the downsample of ``src`` into ``dst`` (returns the kernel's event); layers are
        rows of one tall image, and a block never spans two of them (ss divides a layer's height)."""
        if (src.width, src.height, src.layers) != (dst.width * self.ss, dst.height * self.ss, dst.layers):
            raise ValueError(f"downsample by {self.ss}: {src.width}x{src.height} keys do not make "
                             f"{dst.width}x{dst.height} pixels")
        args = (src.color, src.aux, np.uint32(dst.width), np.uint32(dst.height * dst.layers), *(t.data for t in self.tables),
                dst.color, dst.aux)
        if args != self._bound:
            self.kernel.set_args(*args)
            self._bound = args
        n = dst.pixel_count
        return launch(cl_device().queue, self.kernel, ((n + 255) // 256 * 256,))


class Upsample:
    """Copies each key of a KeyBuffer into its ``ratio`` x ``ratio`` block of one ``ratio`` times its
    side (kernels/points/subsamples.cl upsample_keys; numpy twin: points_reference.upsample_keys):
    a finer hybrid tier starts from the coarser tier's samples."""

    def __init__(self, ratio: int):
        self.ratio = int(ratio)
        self.kernel = cl.Kernel(build(["common/keys.cl", "points/subsamples.cl"], defines={"PL_RATIO": self.ratio}),
                                "upsample_keys")
        self._bound = None

    def enqueue(self, src: KeyBuffer, dst: KeyBuffer):
        """Enqueue the copy of ``src`` into ``dst`` (returns the kernel's event)."""
        if (dst.width, dst.height, dst.layers) != (src.width * self.ratio, src.height * self.ratio, src.layers):
            raise ValueError(f"upsample by {self.ratio}: {src.width}x{src.height} keys do not fill "
                             f"{dst.width}x{dst.height}")
        args = (src.color, src.aux, np.uint32(src.width), np.uint32(src.height * src.layers), dst.color, dst.aux)
        if args != self._bound:
            self.kernel.set_args(*args)
            self._bound = args
        n = dst.pixel_count
        return launch(cl_device().queue, self.kernel, ((n + 255) // 256 * 256,))
