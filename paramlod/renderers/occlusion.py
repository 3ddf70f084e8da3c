"""Two-phase occlusion culling of render patches for the direct point renderer
(kernels/points/occlusion.cl; numpy twin: paramlod.renderers.occlusion_reference; docs/points.md).

Per frame: every render patch gets a conservative screen box and nearest depth, is tested against
the depth pyramid of the previous frame's keys and is drawn (phase 1) or deferred; a pyramid of
this frame's keys after phase 1 then re-tests the deferred patches, and the ones not behind it are
drawn too (phase 2). Keys only get nearer during a frame, so phase 2 never culls a patch that could
change a key, and a wrong guess in phase 1 (camera motion, animation, a first frame) costs only
time. That pyramid is the next frame's guess.
"""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from paramlod.core.layouts import OCC_COUNTER, RENDER_PATCH
from paramlod.device.context import cl_device
from paramlod.device.programs import launch

GRID = 5        # positions per side of a patch's bound
BOUND_FLOATS = 8   # floats per bound: x0, y0, x1, y1 (pixels), near depth, 3 unused
COUNTS = tuple(f.name for f in OCC_COUNTER.fields)   # occlusion.cl counts[OCC_*]
LOCAL = 64


def occlusion_span(gpu: bool) -> int:
    """Texels per side a patch's box is tested against at most (occlusion.cl OCC_SPAN). 8 on CPUs:
    it culls more than 2 x 2 texels (docs/points.md, "Occlusion culling"). 2 on GPUs: there the
    finer test made `occlusion = "auto"` cull the seashells' frames of about 1 ms, whose culling
    costs more than the samples it spares (an H100: 0.77-0.95x the frame rate)."""
    return 2 if gpu else 8


def occlusion_cl_defines(gpu: bool) -> dict:
    """The constants kernels/points/occlusion.cl is built with (its twin reads them here)."""
    return {"OCC_GRID": GRID, "OCC_FLOATS": BOUND_FLOATS, "OCC_SPAN": occlusion_span(gpu)}


def pyramid_levels(width: int, height: int) -> list[tuple[int, int]]:
    """(w, h) of each level of the pyramid of a ``width`` x ``height`` key image, down to 1 x 1."""
    out = []
    w, h = width, height
    while True:
        w, h = (w + 1) // 2, (h + 1) // 2
        out.append((w, h))
        if w == 1 and h == 1:
            return out


class DepthPyramid:
    """The max-depth pyramid of one key image size (all levels in one uint32 buffer)."""

    def __init__(self, program, width: int, height: int):
        self.size = (width, height)
        self.levels = pyramid_levels(width, height)
        self.offsets = np.cumsum([0] + [w * h for w, h in self.levels])
        self.buf = cl.Buffer(cl_device().context, cl.mem_flags.READ_WRITE, 4 * int(self.offsets[-1]))
        self._base = cl.Kernel(program, "pyramid_base")
        self._reduce = [cl.Kernel(program, "pyramid_reduce") for _ in self.levels[1:]]
        self._bound = None
        self.valid = False   # built at least once

    def enqueue_build(self, keys) -> list:
        """Build from the colour keys of ``keys`` (a KeyBuffer of this size, one layer)."""
        q = cl_device().queue
        w, h = self.size
        if self._bound is not keys.color:
            self._base.set_args(keys.color, np.uint32(w), np.uint32(h), self.buf)
            for i, k in enumerate(self._reduce):
                wi, hi = self.levels[i]
                k.set_args(self.buf, np.uint32(self.offsets[i]), np.uint32(wi), np.uint32(hi),
                           np.uint32(self.offsets[i + 1]))
            self._bound = keys.color
        w0, h0 = self.levels[0]
        events = [launch(q, self._base, (_round(w0 * h0),), (LOCAL,))]
        for i, k in enumerate(self._reduce):
            wo, ho = self.levels[i + 1]
            events.append(launch(q, k, (_round(wo * ho),), (LOCAL,)))
        self.valid = True
        return events

    def read(self) -> list[np.ndarray]:
        """The levels, uint32 (h, w) each (tests)."""
        flat = np.empty(int(self.offsets[-1]), np.uint32)
        cl.enqueue_copy(cl_device().queue, flat, self.buf)
        return [flat[self.offsets[i]:self.offsets[i + 1]].reshape(h, w) for i, (w, h) in enumerate(self.levels)]


def _round(n: int) -> int:
    return max(-(-n // LOCAL), 1) * LOCAL


class OcclusionCuller:
    """The per-renderer state of the two phases: the patches' bounds, the phase lists and the
    pyramids (the previous frame's and this frame's)."""

    def __init__(self, program):
        dev = cl_device()
        self.program = program
        self.first_k = cl.Kernel(program, "occlusion_first")
        self.second_k = cl.Kernel(program, "occlusion_second")
        self.counts_buf = cl.Buffer(dev.context, cl.mem_flags.READ_WRITE, 4 * len(COUNTS))
        self._counts = np.zeros(len(COUNTS), np.uint32)
        self.capacity = 0
        self.bounds = self.early = self.late = self.deferred = None
        self.previous = self.current = None   # DepthPyramid: last frame's keys after its phase 1, this frame's
        self.max_groups = dev.device.max_compute_units * (32 if dev.is_gpu else 256)
        self.events = []
        self.guessed = False   # the last phase 1 tested against a previous frame's pyramid

    def _ensure(self, capacity: int, size):
        ctx = cl_device().context
        if capacity > self.capacity:
            rw = cl.mem_flags.READ_WRITE
            self.bounds = cl.Buffer(ctx, rw, 4 * BOUND_FLOATS * capacity)
            self.early = cl.Buffer(ctx, rw, RENDER_PATCH.dtype.itemsize * capacity)
            self.late = cl.Buffer(ctx, rw, RENDER_PATCH.dtype.itemsize * capacity)
            self.deferred = cl.Buffer(ctx, rw, 4 * capacity)
            self.capacity = capacity
        if self.current is None or self.current.size != tuple(size):
            self.current = DepthPyramid(self.program, *size)
            self.previous = DepthPyramid(self.program, *size)   # invalid until built: phase 1 draws all

    def enqueue_first(self, patches_buf, count_buf, count_at: int, capacity: int, inst, cam_buf,
                      widen: float, size):
        """Bound and test the ``count_buf[count_at]`` render patches (at most ``capacity``);
        ``self.early`` / ``counts_buf[OCC_EARLY]`` then list the ones to draw now."""
        capacity = max(int(capacity), 1)
        self._ensure(capacity, size)
        q = cl_device().queue
        cl.enqueue_fill_buffer(q, self.counts_buf, np.uint32(0), 0, 4 * len(COUNTS))
        prev = self.previous
        self.guessed = prev.valid
        self.first_k.set_args(patches_buf, count_buf, np.uint32(count_at), np.uint32(capacity), *inst, cam_buf,
                              np.float32(widen), prev.buf, np.uint32(len(prev.levels) if prev.valid else 0),
                              self.bounds, self.early, self.deferred, self.counts_buf)
        items = min(-(-capacity // LOCAL), self.max_groups) * LOCAL
        self.events = [launch(q, self.first_k, (items,), (LOCAL,))]

    def enqueue_second(self, patches_buf, cam_buf, keys, capacity: int):
        """Build this frame's pyramid from ``keys`` and re-test the deferred patches;
        ``self.late`` / ``counts_buf[OCC_LATE]`` then list the ones to draw."""
        q = cl_device().queue
        self.events += self.current.enqueue_build(keys)
        cur = self.current
        self.second_k.set_args(patches_buf, cam_buf, cur.buf, np.uint32(len(cur.levels)), self.bounds,
                               self.deferred, self.late, self.counts_buf)
        items = min(-(-max(int(capacity), 1) // LOCAL), self.max_groups) * LOCAL
        self.events.append(launch(q, self.second_k, (items,), (LOCAL,)))

    def swap(self):
        """This frame's pyramid (after phase 1) becomes the next frame's guess: one pyramid build a
        frame instead of two (a pyramid of the final keys would be tighter only by what phase 2
        drew, which phase 2 catches anyway)."""
        self.previous, self.current = self.current, self.previous

    def read_counts(self):
        cl.enqueue_copy(cl_device().queue, self._counts, self.counts_buf, is_blocking=False)

    def counts(self) -> dict:
        """{"early", "deferred", "late"} patches of the last frame (after its wait); occluded =
        deferred - late."""
        return {k: int(v) for k, v in zip(COUNTS, self._counts)}

    def read_bounds(self, n: int) -> np.ndarray:
        """float32 (n, 8) bounds of the last frame's first ``n`` render patches (tests)."""
        out = np.empty((n, BOUND_FLOATS), np.float32)
        cl.enqueue_copy(cl_device().queue, out, self.bounds)
        return out
