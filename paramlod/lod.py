"""The LOD stage driver: PATCH INITIALIZATION and up to ``max_steps`` PATCH SUBDIVISION steps
in OpenCL (kernels/lod.cl), producing the render list for the renderers.

Buffers grow when a step overflows them (the stage is redone), up to ``max_patches``; past that
the stage stops with an error that names the limit. Nothing is dropped silently.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .device import cl_device
from .errors import CapacityError, SceneError
from .patches import EVAL_DTYPE, RENDER_DTYPE, initial_patches
from .programs import kernel


@dataclass
class LodSettings:
    threshold: tuple[float, float] = (84.0, 84.0)  # t_u, t_v in pixels
    max_steps: int = 12
    initial_grid: tuple[int, int] = (1, 1)
    max_patches: int = 1 << 24   # per buffer (eval ping-pong and render list)

    def validate(self):
        tu, tv = self.threshold
        if not (tu > 0 and tv > 0):
            raise SceneError(f"lod threshold must be positive pixels, got {self.threshold}")
        if not 1 <= self.max_steps <= 15:
            raise SceneError(f"lod max_steps must be in 1..15, got {self.max_steps}")
        gu, gv = self.initial_grid
        if not (1 <= gu <= 64 and 1 <= gv <= 64):
            raise SceneError(f"lod initial_grid must be in 1..64 per axis, got {self.initial_grid}")


class _Buffer:
    """A device buffer of records that can grow."""

    def __init__(self, dtype, capacity):
        self.dtype, self.capacity, self.buf = dtype, 0, None
        self.ensure(capacity)

    def ensure(self, n, keep=0):
        import pyopencl as cl

        if n <= self.capacity:
            return False
        cap = max(1024, 1 << int(np.ceil(np.log2(max(n, 1)))))
        new = cl.Buffer(cl_device().context, cl.mem_flags.READ_WRITE, cap * self.dtype.itemsize)
        if keep and self.buf is not None:
            cl.enqueue_copy(cl_device().queue, new, self.buf, byte_count=keep * self.dtype.itemsize)
        self.buf, self.capacity = new, cap
        return True


LOD_COUNTERS = 8  # per-step counter record in kernels/lod.cl
C_CHILDREN, C_SPLIT, C_CULLED, C_RENDERED, C_FORCED = range(5)


class LodStage:
    def __init__(self, functions):
        import pyopencl as cl

        self.kernel = kernel("lod_step", ["lod.cl"], functions)
        self.bufs = [_Buffer(EVAL_DTYPE, 4096), _Buffer(EVAL_DTYPE, 4096)]
        self.render = _Buffer(RENDER_DTYPE, 4096)
        # PATCH INITIALIZATION's output, built and uploaded only when the instances change
        # (for 358,140 fiber instances that was ~30 ms of numpy and 11 MB of upload a frame)
        self.init = _Buffer(EVAL_DTYPE, 4096)
        self._init_for = (None, None, 0)
        self.counters = cl.Buffer(cl_device().context, cl.mem_flags.READ_WRITE, 16 * LOD_COUNTERS * 4)
        dev = cl_device()
        # work-items per step (they stride over the patches): enough to fill the device
        self.grid = dev.device.max_compute_units * (2048 if dev.is_gpu else 64)

    def run(self, inst, n_instances, domains, cam_buf, settings: LodSettings, t_div: float = 1.0):
        """Returns (render buffer, render patch count, per-step stats list, ms).

        All steps are enqueued at once and the counters read back once; if a buffer overflowed,
        the buffers grow and the whole stage is redone (growth persists across frames).
        """
        import pyopencl as cl

        settings.validate()
        if len(domains) != n_instances:
            raise ValueError(f"LodStage.run: {len(domains)} domains for {n_instances} instances")
        q = cl_device().queue
        t0 = time.perf_counter()
        src_domains, grid_for, n_init = self._init_for
        if src_domains is not domains or grid_for != tuple(settings.initial_grid):
            init = initial_patches(domains, settings.initial_grid)
            n_init = len(init)
            self._check(n_init, settings, "initial patches")
            self.init.ensure(n_init)
            if n_init:
                cl.enqueue_copy(q, self.init.buf, init)
            self._init_for = (domains, tuple(settings.initial_grid), n_init)
        tu, tv = (np.float32(t / t_div) for t in settings.threshold)
        steps_n = settings.max_steps
        counts = np.zeros((steps_n + 1, LOD_COUNTERS), np.uint32)
        while True:
            for b in self.bufs:
                b.ensure(n_init)
            counts[:] = 0
            counts[0, C_CHILDREN] = n_init
            cl.enqueue_copy(q, self.counters, counts)
            cap = min(b.capacity for b in self.bufs)
            grid = min(self.grid, _round_up(max(cap, 1), 64))
            for step in range(1, steps_n + 1):
                src = self.init if step == 1 else self.bufs[(step - 1) % 2]
                dst = self.bufs[step % 2]
                self.kernel(q, (grid,), None, src.buf, dst.buf, np.uint32(cap),
                            self.render.buf, np.uint32(self.render.capacity), self.counters,
                            *inst, cam_buf, tu, tv, np.uint32(step), np.uint32(step == steps_n))
            cl.enqueue_copy(q, counts, self.counters)  # blocking: the frame's one sync
            children = counts[1:, C_CHILDREN].astype(np.int64)
            n_render = int(counts[0, 1])
            need = int(children.max(initial=0))
            grew = False
            if need > cap:
                self._check(need, settings, "patches in one LOD step")
                for b in self.bufs:
                    grew |= b.ensure(need)
            if n_render > self.render.capacity:
                self._check(n_render, settings, "render patches")
                grew |= self.render.ensure(n_render)
            if not grew:
                break
        steps = []
        n_in = n_init
        for step in range(1, steps_n + 1):
            c = counts[step]
            steps.append({"step": step, "in": n_in, "split": int(c[C_SPLIT]), "culled": int(c[C_CULLED]),
                          "out": int(c[C_RENDERED]), "forced": int(c[C_FORCED])})
            n_in = int(c[C_CHILDREN])
        return self.render.buf, n_render, steps, (time.perf_counter() - t0) * 1e3

    @staticmethod
    def _check(n, settings, what):
        if n > settings.max_patches:
            raise CapacityError(
                f"the LOD stage needs {n} {what}, more than max_patches={settings.max_patches}; "
                "raise [lod] max_patches (memory: 64 bytes a render patch, 32 an evaluated one), raise the threshold, "
                "or lower max_steps")

    def read_render_list(self, n) -> np.ndarray:
        import pyopencl as cl

        out = np.empty(n, RENDER_DTYPE)
        if n:
            cl.enqueue_copy(cl_device().queue, out, self.render.buf)
        return out


def _round_up(n, m):
    return max(m, (n + m - 1) // m * m)
