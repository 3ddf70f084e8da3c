"""The LOD stage driver: PATCH INITIALIZATION and up to ``max_steps`` PATCH SUBDIVISION steps
in OpenCL (kernels/lod.cl), producing the render list for the renderers.

Buffers grow when a step overflows them (the step is redone), up to ``max_patches``; past that
the stage stops with an error that names the limit. Nothing is dropped silently.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .device import cl_device
from .errors import CapacityError, SceneError
from .patches import EVAL_DTYPE, RENDER_DTYPE, initial_patches
from .programs import build


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


class LodStage:
    def __init__(self, functions):
        self.program = build(["lod.cl"], functions)
        self.kernel = self.program.lod_step
        self.bufs = [_Buffer(EVAL_DTYPE, 4096), _Buffer(EVAL_DTYPE, 4096)]
        self.render = _Buffer(RENDER_DTYPE, 4096)
        import pyopencl as cl

        self.counters = cl.Buffer(cl_device().context, cl.mem_flags.READ_WRITE, 6 * 4)

    def run(self, inst, n_instances, domains, cam_buf, settings: LodSettings, t_div: float = 1.0):
        """Returns (render buffer, render patch count, per-step stats list, ms)."""
        import pyopencl as cl

        settings.validate()
        q = cl_device().queue
        t0 = time.perf_counter()
        init = initial_patches(domains, settings.initial_grid)
        self._check(len(init), settings, "initial patches")
        self.bufs[0].ensure(len(init))
        if len(init):
            cl.enqueue_copy(q, self.bufs[0].buf, init)
        n_in, n_render = len(init), 0
        tu, tv = (np.float32(t / t_div) for t in settings.threshold)
        steps = []
        counts = np.zeros(6, np.uint32)
        for step in range(1, settings.max_steps + 1):
            force = step == settings.max_steps
            src, dst = self.bufs[(step - 1) % 2], self.bufs[step % 2]
            if n_in == 0:
                steps.append({"step": step, "in": 0, "split": 0, "culled": 0, "out": 0, "forced": 0})
                continue
            while True:
                counts[:] = 0
                counts[1] = n_render
                cl.enqueue_copy(q, self.counters, counts)
                self.kernel(q, (_round_up(n_in, 64),), None,
                            src.buf, np.uint32(n_in), dst.buf, np.uint32(dst.capacity),
                            self.render.buf, np.uint32(self.render.capacity), self.counters,
                            *inst, cam_buf, tu, tv, np.uint32(step), np.uint32(force))
                cl.enqueue_copy(q, counts, self.counters)
                n_children, total_render = int(counts[0]), int(counts[1])
                grew = False
                if n_children > dst.capacity:
                    self._check(n_children, settings, f"patches after LOD step {step}")
                    grew |= dst.ensure(n_children)
                if total_render > self.render.capacity:
                    self._check(total_render, settings, "render patches")
                    grew |= self.render.ensure(total_render, keep=n_render)
                if not grew:
                    break  # both fitted: the step is complete; otherwise redo it with bigger buffers
            steps.append({"step": step, "in": n_in, "split": int(counts[2]), "culled": int(counts[3]),
                          "out": int(counts[4]), "forced": int(counts[5])})
            n_in, n_render = n_children, total_render
        q.finish()
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
