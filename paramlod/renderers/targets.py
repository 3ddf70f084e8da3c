"""The shared 64-bit key buffers every point producer writes into, and their resolve to a Frame.

Two ulong buffers of width x height (kernels/keys.cl): the colour key (depth | sRGB RGBA8) and the
aux key (depth | octahedral normal | object id). Renderers only ever atom_min into them.
``Downsample`` resolves a supersampled KeyBuffer block by block into one of the frame's size.
"""
from __future__ import annotations

import numpy as np

from paramlod.device.context import cl_device
from paramlod.core.frame import Frame
from paramlod.device.programs import build, launch


class KeyBuffer:
    def __init__(self, width: int, height: int):
        import pyopencl as cl

        self.width, self.height = int(width), int(height)
        n = self.width * self.height
        ctx = cl_device().context
        self.color = cl.Buffer(ctx, cl.mem_flags.READ_WRITE, n * 8)
        self.aux = cl.Buffer(ctx, cl.mem_flags.READ_WRITE, n * 8)
        self._out = None   # the resolved Frame arrays on the device: made by the first resolve
        self._resolve = None

    @property
    def pixel_count(self) -> int:
        return self.width * self.height

    def clear(self):
        import pyopencl as cl

        q = cl_device().queue
        ones = np.uint64(0xFFFFFFFFFFFFFFFF)
        cl.enqueue_fill_buffer(q, self.color, ones, 0, self.pixel_count * 8)
        cl.enqueue_fill_buffer(q, self.aux, ones, 0, self.pixel_count * 8)

    def read_keys(self) -> tuple[np.ndarray, np.ndarray]:
        """The raw colour and aux keys, uint64 (h, w) each."""
        import pyopencl as cl

        q = cl_device().queue
        c = np.empty((self.height, self.width), np.uint64)
        a = np.empty_like(c)
        cl.enqueue_copy(q, c, self.color)
        cl.enqueue_copy(q, a, self.aux)
        return c, a

    def resolve(self) -> Frame:
        """Decode the keys and copy the result to the host as a Frame."""
        self.resolve_on_device()
        return self.read_frame()

    def resolve_on_device(self):
        """Decode the keys into colour, depth, normal and id buffers on the device (enqueued;
        returns the kernel's event)."""
        import pyopencl as cl

        n = self.pixel_count
        if self._resolve is None:   # a supersampled buffer is only downsampled, never resolved
            self._out = [cl.Buffer(cl_device().context, cl.mem_flags.WRITE_ONLY, n * s) for s in (16, 4, 16, 4)]
            # this buffer's own kernel object, its arguments set once
            self._resolve = cl.Kernel(build(["common/keys.cl", "points/resolve.cl"]), "resolve")
            self._resolve.set_args(self.color, self.aux, np.uint32(n), *self._out)
        return launch(cl_device().queue, self._resolve, ((n + 255) // 256 * 256,))

    def read_frame(self) -> Frame:
        """Copy the resolved buffers to the host as a Frame (after resolve_on_device())."""
        import pyopencl as cl

        q = cl_device().queue
        h, w = self.height, self.width
        color = np.empty((h, w, 4), np.float32)
        depth = np.empty((h, w), np.float32)
        normal = np.empty((h, w, 4), np.float32)
        ids = np.empty((h, w), np.uint32)
        for host, dev in zip((color, depth, normal, ids), self._out):
            cl.enqueue_copy(q, host, dev)
        q.finish()
        return Frame(color=color, depth=depth, normal=np.ascontiguousarray(normal[..., :3]), object_id=ids)


_srgb_device: dict = {}


def srgb_device_tables():
    """The (lin, thr) tables of points_reference.srgb_tables on the device (uploaded once per
    context): both subsample resolves (kernels/subsamples.cl) read them."""
    import pyopencl.array as cla

    from paramlod.renderers.points_reference import srgb_tables

    dev = cl_device()
    key = id(dev.context)
    if key not in _srgb_device:
        _srgb_device[key] = tuple(cla.to_device(dev.queue, t) for t in srgb_tables())
    return _srgb_device[key]


class Downsample:
    """Resolves a KeyBuffer ``ss`` times the frame's size into the frame's KeyBuffer, one pixel per
    ss x ss block (kernels/subsamples.cl; numpy twin: points_reference.resolve_blocks): colour
    averaged over the covered subsamples in linear light, alpha = coverage, nearest depth."""

    def __init__(self, ss: int):
        import pyopencl as cl

        self.ss = int(ss)
        self.kernel = cl.Kernel(build(["common/keys.cl", "points/subsamples.cl"], defines={"PL_SS": self.ss}), "downsample_keys")
        self.tables = srgb_device_tables()
        self._bound = None

    def enqueue(self, src: KeyBuffer, dst: KeyBuffer):
        """Enqueue the downsample of ``src`` into ``dst`` (returns the kernel's event)."""
        if (src.width, src.height) != (dst.width * self.ss, dst.height * self.ss):
            raise ValueError(f"downsample by {self.ss}: {src.width}x{src.height} keys do not make "
                             f"{dst.width}x{dst.height} pixels")
        args = (src.color, src.aux, np.uint32(dst.width), np.uint32(dst.height), *(t.data for t in self.tables),
                dst.color, dst.aux)
        if args != self._bound:
            self.kernel.set_args(*args)
            self._bound = args
        n = dst.pixel_count
        return launch(cl_device().queue, self.kernel, ((n + 255) // 256 * 256,))
