"""Point renderer, direct variant (kernels/points.cl): render patches sampled on a (u, v) grid
sized from their measured extents and written with 64-bit atom_min into the KeyBuffer.

Sampling: paramlod.renderers.sampling (docs/points.md).
"""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from paramlod.device.context import cl_device
from paramlod.lod.stage import LOD_RENDER_TOTAL, LodStage
from paramlod.lod.uploads import SceneBuffers
from paramlod.renderers.registry import RendererSpec, register_renderer
from paramlod.renderers.sampling import COLOR_BY, PointSettings, grid_counts, side_counts  # noqa: F401  (re-exported)
from paramlod.renderers.shading import LIGHT
from paramlod.device.programs import launch
from paramlod.function.programs import build

LOCAL_SIZE = 64
COUNTERS = ("samples", "atomics", "nan_samples", "capped_patches")


class DirectPointRenderer:
    def __init__(self, functions, record: bool = False):
        defines = {"PL_RECORD": 1} if record else {}
        if cl_device().is_gpu:   # sum the counters per work-group (see the end of points_direct)
            defines["PL_GROUP_COUNTERS"] = 1
        prog = build(["common/keys.cl", "points/points.cl"], functions, defines)
        # own kernel objects: arguments are set only when they change (see enqueue)
        self.schedule = cl.Kernel(prog, "points_schedule")
        self.kernel = cl.Kernel(prog, "points_direct")
        self._bound = None
        self.record = record
        dev = cl_device()
        # COUNTERS, then the schedule's counter (kernels/points.cl, SCHED_AT)
        self.counters = cl.Buffer(dev.context, cl.mem_flags.READ_WRITE, 8 * (len(COUNTERS) + 1))
        self._count = cl.Buffer(dev.context, cl.mem_flags.READ_ONLY, 4)   # a host-given patch count
        self._counts = np.zeros(len(COUNTERS), np.uint64)
        self._order, self.order_capacity = None, 0   # the schedule: 8 bytes a patch
        self.events = ()
        # work-groups share the samples evenly: about one resident wave on a GPU
        self.max_groups = dev.device.max_compute_units * (32 if dev.is_gpu else 256)

    def enqueue(self, patches_buf, count_buf, count_at: int, capacity: int, inst, materials_buf, cam_buf,
                light_buf, keys, settings: PointSettings, record_args=(), n_views: int = 1, view_masks=None):
        """Enqueue the render of the ``count_buf[count_at]`` (read on the device, at most
        ``capacity``) patches of ``patches_buf`` without waiting; ``counts()`` reads the counters.
        ``n_views``: camera records in ``cam_buf``, each sample is written into layer v of
        ``keys`` for every view v that sees its patch (``view_masks``: a uint64 per patch, bit v
        for view v, as LodStage.render_views; needed with several views) and whose frustum holds
        it (``keys.layers`` must be ``n_views``)."""
        settings.validate()
        if keys.layers != n_views:
            raise ValueError(f"points: {n_views} views need key buffers of {n_views} layers, got {keys.layers}")
        if view_masks is None:
            if n_views != 1:
                raise ValueError(f"points: {n_views} views need the patches' view masks (LodStage.render_views)")
            view_masks = self.counters   # not read with one view
        q = cl_device().queue
        capacity = max(int(capacity), 1)
        if capacity > self.order_capacity:
            self._order = cl.Buffer(cl_device().context, cl.mem_flags.READ_WRITE, 8 * capacity)
            self.order_capacity = capacity
        cl.enqueue_fill_buffer(q, self.counters, np.uint64(0), 0, 8 * (len(COUNTERS) + 1))
        sampling = (settings.factor(), settings.measure(boundary=True))   # watertight on patch edges
        args = (patches_buf, count_buf, np.uint32(count_at), np.uint32(capacity), self._order,
                *inst, materials_buf, cam_buf, np.uint32(n_views), view_masks, light_buf, *sampling, np.float32(settings.widen),
                np.uint32(settings.max_side), np.uint32(COLOR_BY.index(settings.color_by)), keys.color, keys.aux,
                self.counters, *record_args)
        # the same buffers and values frame after frame: converting ~20 arguments each time was a
        # measurable share of a frame's Python time
        if args != self._bound:
            self.schedule.set_args(patches_buf, count_buf, np.uint32(count_at), np.uint32(capacity), *sampling,
                                   np.uint32(settings.max_side), self._order, self.counters)
            self.kernel.set_args(*args)
            self._bound = args
        items = min(-(-capacity // LOCAL_SIZE), self.max_groups) * LOCAL_SIZE
        self.events = (launch(q, self.schedule, (items,), (LOCAL_SIZE,)),
                       launch(q, self.kernel, (self.max_groups * LOCAL_SIZE,), (LOCAL_SIZE,)))

    def device_ms(self) -> float:
        """Device time of the last render (schedule and samples; after its wait)."""
        first, last = self.events
        return (last.profile.end - first.profile.start) * 1e-6

    def read_counts(self):
        """Enqueue the copy of the counters, read after the frame's wait by ``counts(wait=False)``."""
        cl.enqueue_copy(cl_device().queue, self._counts, self.counters, is_blocking=False)

    def counts(self, wait: bool = True) -> dict:
        """The last render's counters (COUNTERS); ``wait``: read them now (waits for the render)."""
        if wait:
            cl.enqueue_copy(cl_device().queue, self._counts, self.counters)
        return {k: int(v) for k, v in zip(COUNTERS, self._counts)}

    def draw(self, patches_buf, n_patches, inst, materials_buf, cam_buf, light_buf, keys,
             settings: PointSettings, record_args=(), n_views: int = 1):
        """Render ``n_patches`` render patches into ``keys`` and wait; returns the counters (COUNTERS)."""
        cl.enqueue_copy(cl_device().queue, self._count, np.array([n_patches], np.uint32))
        self.enqueue(patches_buf, self._count, 0, n_patches, inst, materials_buf, cam_buf, light_buf, keys,
                     settings, record_args, n_views)
        return self.counts()


class DirectPoints:
    """Per-scene state of the "points" variant: the scene's device buffers, its LOD stage and the
    sampler. The whole frame is enqueued at once; the sampler reads the patch count on the device."""

    def __init__(self, functions, record: bool = False):
        self.buffers = SceneBuffers(LIGHT)
        self.lod = LodStage(functions)
        self.points = DirectPointRenderer(functions, record=record)
        self.dev = None

    def prepare(self, scene, camera, settings):
        settings.points.validate()
        self.dev = self.buffers.upload(scene, camera)

    def enqueue(self, target, settings):
        d = self.dev
        self.lod.enqueue(d["inst"], d["domains"], d["cam"], settings.lod, n_views=d["n_views"])
        self.points.enqueue(self.lod.render.buf, self.lod.counters, LOD_RENDER_TOTAL, self.lod.render.capacity,
                            d["inst"], d["materials"], d["cam"], d["light"], target, settings.points,
                            n_views=d["n_views"], view_masks=self.lod.render_views.buf)

    def collect(self):
        self.lod.read_counters(wait=False)
        self.points.read_counts()

    def grow(self, settings) -> bool:
        return self.lod.grow(settings.lod)

    def stats(self) -> dict:
        n, steps = self.lod.result()
        return {"render_patches": n, "lod_steps": steps, "forced_patches": sum(s["forced"] for s in steps),
                **self.points.counts(wait=False),
                "ms": {"lod": self.lod.device_ms(), "render": self.points.device_ms()}}


register_renderer(RendererSpec("points", "parametric", DirectPoints, "points", "keys", PointSettings,
                               "samples on a (u, v) grid per render patch, 64-bit atom_min into the key buffers",
                               multiview=True))
