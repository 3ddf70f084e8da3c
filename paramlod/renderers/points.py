"""Point renderer, direct variant (kernels/points.cl): render patches sampled on a (u, v) grid
sized from their measured extents and written with 64-bit atom_min into the KeyBuffer.

Sampling: paramlod.renderers.sampling (docs/points.md).
"""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from paramlod.core.layouts import OCC_COUNTER, POINTS_COUNTER
from paramlod.device.context import cl_device
from paramlod.errors import CapacityError
from paramlod.lod.stage import LOD_RENDER_TOTAL, LodStage
from paramlod.lod.uploads import SceneBuffers
from paramlod.renderers.aa import POINT_TIERS, tier_divisors
from paramlod.renderers.occlusion import OcclusionCuller, occlusion_cl_defines
from paramlod.renderers.registry import RendererSpec, register_renderer
from paramlod.renderers.sampling import (COLOR_BY, POINTS_LOCAL, PointSettings, grid_counts, patch_wraps,  # noqa: F401  (re-exported)
                                         points_cl_defines, side_counts)
from paramlod.renderers.shading import LIGHT
from paramlod.device.programs import launch
from paramlod.function.programs import POLY_TRIG, VECTOR, build, sample_run

# the statistics of POINTS_COUNTER (points.cl PTS_*); its last two words are the schedule's
COUNTERS = tuple(f.name for f in POINTS_COUNTER.fields if f.name not in ("sched", "units"))
COUNTER_WORDS = POINTS_COUNTER.length
SCHED_WORD, UNITS_WORD = POINTS_COUNTER.offset("sched"), POINTS_COUNTER.offset("units")
# points.cl order[]: a patch's first unit in 32 bits (and a work-item's unit may pass the last by
# POINTS_LOCAL); points_direct draws nothing of a list past it
MAX_UNITS = 0xFFFFFFFF - POINTS_LOCAL
# occlusion = "auto": culling is used while it saves at least this share of a frame's samples
# (measured on the H200, docs/points.md: culling that removed 6 % of the samples cost 7 % of the
# frame, 13-30 % paid 1.18-1.38x; the pyramid and the second pass cost 0.3-0.6 ms a frame)
AUTO_MIN_SAVED = 0.1
AUTO_PROBE = 16   # every 16th frame is drawn the other way, so the choice follows camera and scene
# GPUs draw a frame's work packed (points.cl PL_PACK) after a frame whose render patches had fewer
# samples than half a work-group on average: on an H200 packing took the fibre curtain's render
# (19-30 samples a patch) to 0.48-0.83x, and the 19,600 glyphs' at 34 a patch to 1.06x
# (docs/points.md, "Packed work")
PACK_BELOW = POINTS_LOCAL // 2


def packs(samples: int, patches: int) -> bool:
    """Whether a GPU draws the next frame packed, after a frame of ``samples`` over ``patches``."""
    return samples < PACK_BELOW * patches


class AutoOcclusion:
    """The choice of occlusion = "auto", frame by frame: the samples of the last frame drawn with
    culling and of the last one drawn without it are compared; each kind is drawn once first, and
    every AUTO_PROBE-th frame the kind not chosen is drawn again."""

    def __init__(self):
        self.samples = {True: None, False: None}
        self.on = True
        self.since = 0   # frames since the last probe

    def cull(self) -> bool:
        """Whether the next frame is drawn with culling."""
        for kind in (True, False):
            if self.samples[kind] is None:
                return kind
        return (not self.on) if self.since >= AUTO_PROBE - 1 else self.on

    def record(self, culled: bool, samples: int, judged: bool = True):
        """A frame drawn (``judged`` False: culled without a pyramid to test against, which says
        nothing of what culling saves)."""
        self.since = 0 if culled != self.on else self.since + 1
        if judged:
            self.samples[culled] = samples
        if None not in self.samples.values():
            self.on = self.samples[True] < (1 - AUTO_MIN_SAVED) * self.samples[False]


ALL_TIERS = np.uint32(0xFFFFFFFF)   # points.cl: every patch, whatever its hybrid tier


class _Launch:
    """The schedule and sample kernels of one list drawn in a frame, with the arguments bound."""

    def __init__(self, program):
        self.schedule = cl.Kernel(program, "points_schedule")
        self.kernel = cl.Kernel(program, "points_direct")
        self.bound = None


class DirectPointRenderer:
    # CPU devices: a run's samples (or quad corners) evaluated on vector lanes (points.cl
    # surface_lanes); False, one at a time, as GPUs do: the tests' reference for the vector path
    vector_lanes = True
    # points.cl PL_PACK: each work-item its own runs across patches, or a pass of the work-group
    # per patch. None: CPUs always pack; GPUs choose frame by frame (packs, choose_packing)
    pack = None
    groups_per_unit = None   # work-groups per compute unit; None: the device's (below)
    # points.cl PL_GROUP_SCHEDULE: a work-group's patches scheduled with one atomic; None: GPUs only
    # (PoCL runs a barrier as a loop over the work-items)
    group_schedule = None

    def __init__(self, functions, record: bool = False):
        defines = points_cl_defines()
        if record:
            defines["PL_RECORD"] = 1
        gpu = cl_device().is_gpu
        if gpu:   # sum the counters per work-group (see the end of points_direct)
            defines["PL_GROUP_COUNTERS"] = 1
        else:   # inline trigonometry in the function code (kernels/common/poly_trig.cl)
            defines[POLY_TRIG] = 1
        if gpu if self.group_schedule is None else self.group_schedule:
            defines["PL_GROUP_SCHEDULE"] = 1
        defines["PL_RUN"] = sample_run(gpu)   # points.cl patch_runs
        defines.update(occlusion_cl_defines(gpu))
        self._functions, self._defines = functions, defines
        self._auto_pack = self.pack is None and gpu
        self.packed = not gpu if self.pack is None else bool(self.pack)
        self._program_packed = self.packed
        # the program of one-view frames with pixel coverage, which occlusion.cl shares (the
        # function code is compiled once; OcclusionCuller takes its kernels whatever the frame's
        # kind); the other kinds are built when first drawn (program_for)
        self.program = build(["common/keys.cl", "points/points.cl", "points/occlusion.cl"], functions,
                             self._kind_defines("pixel", False, self.packed))
        # own kernel objects per list drawn in a frame (all patches, the two occlusion phases, the
        # hybrid tiers) and kind of frame: arguments are set only when they change (see enqueue)
        self._launches: dict = {}
        self.record = record
        dev = cl_device()
        # COUNTERS, then the schedule's counter and the largest list's units (PTS_SCHED, PTS_UNITS)
        self.counters = cl.Buffer(dev.context, cl.mem_flags.READ_WRITE, 8 * COUNTER_WORDS)
        self._count = cl.Buffer(dev.context, cl.mem_flags.READ_ONLY, 4)   # a host-given patch count
        self._counts = np.zeros(COUNTER_WORDS, np.uint64)
        self._order, self.order_capacity = None, 0   # the schedule: 8 bytes a patch
        self.events = ()
        # work-groups share the samples evenly: about one resident wave on a GPU
        per_unit = self.groups_per_unit or (32 if dev.is_gpu else 256)
        self.max_groups = dev.device.max_compute_units * per_unit

    def _kind_defines(self, coverage: str, views: bool, packed: bool) -> dict:
        defines = {**self._defines, "PL_CENTRE": int(coverage == "centre"), "PL_QUADS": int(coverage == "quad"),
                   "PL_VIEWS": int(views), "PL_PACK": int(packed)}
        if self._defines["PL_RUN"] > 1 and self.vector_lanes:   # CPUs: samples on vector lanes (points.cl surface_lanes)
            defines[VECTOR] = 1
        return defines

    def program_for(self, coverage: str, views: bool, packed: bool):
        """The program whose points_direct is compiled for ``coverage`` (PointSettings.coverage),
        for several views a frame (``views``) or without them, packed or not (points.cl PL_CENTRE,
        PL_QUADS, PL_VIEWS, PL_PACK: the GPU draws much faster without code it does not run)."""
        if coverage == "pixel" and not views and packed == self._program_packed:
            return self.program
        return build(["common/keys.cl", "points/points.cl"], self._functions,
                     self._kind_defines(coverage, views, packed))

    def choose_packing(self, samples: int, patches: int):
        """After a frame (its samples and render patches): whether the next is drawn packed (GPUs
        with ``pack`` None: ``packs``)."""
        if self._auto_pack and patches:
            self.packed = packs(samples, patches)

    def enqueue(self, patches_buf, count_buf, count_at: int, capacity: int, inst, materials_buf, cam_buf,
                light_buf, keys, settings: PointSettings, record_args=(), n_views: int = 1, view_masks=None,
                phase: int = 0, tier: int | None = None, scale: int = 1):
        """Enqueue the render of the ``count_buf[count_at]`` (read on the device, at most
        ``capacity``) patches of ``patches_buf`` without waiting; ``counts()`` reads the counters.
        ``phase`` > 0: a later list of the same frame (occlusion culling's phase 2, a finer hybrid
        tier), whose counts and device time add to the first's. ``tier``: only the patches of that
        hybrid tier, drawn into ``keys`` ``scale`` times the measured pixels (``cam_buf``: its
        camera).
        ``n_views``: camera records in ``cam_buf``, each sample is written into layer v of
        ``keys`` for every view v that sees its patch (``view_masks``: a uint64 per patch, bit v
        for view v, as LodStage.render_views; needed with several views) and whose frustum holds
        it (``keys.layers`` must be ``n_views``)."""
        settings.validate()
        if settings.coverage == "quad" and self.record:
            raise ValueError("points: the record hook records one pixel a sample, not quad coverage")
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
        if phase == 0:
            cl.enqueue_fill_buffer(q, self.counters, np.uint64(0), 0, 8 * COUNTER_WORDS)
        else:   # only the schedule's counter
            cl.enqueue_fill_buffer(q, self.counters, np.uint64(0), 8 * SCHED_WORD, 8)
        sampling = (settings.factor(scale), settings.curve_factor(scale),
                    settings.measure(boundary=True))   # watertight on patch edges
        args = (patches_buf, self._order,
                *inst, materials_buf, cam_buf, view_masks, light_buf, *sampling, np.float32(settings.widen),
                np.uint32(settings.max_side), np.uint32(COLOR_BY.index(settings.color_by)), keys.color, keys.aux,
                self.counters, *record_args)
        # the same buffers and values frame after frame: converting ~20 arguments each time was a
        # measurable share of a frame's Python time
        # quads ignore PL_PACK (points.cl PL_PACKED): one program for them
        kind = (settings.coverage, n_views > 1, self.packed and settings.coverage != "quad")
        k = self._launches.get((phase, tier, kind))
        if k is None:
            k = self._launches[(phase, tier, kind)] = _Launch(self.program_for(*kind))
        bound = (count_buf, count_at, capacity, tier, args)
        if bound != k.bound:
            k.schedule.set_args(patches_buf, count_buf, np.uint32(count_at), np.uint32(capacity), inst[0], inst[1],
                                *sampling, np.uint32(settings.max_side), ALL_TIERS if tier is None else np.uint32(tier),
                                self._order, self.counters)
            k.kernel.set_args(*args)
            k.bound = bound
        items = min(-(-capacity // POINTS_LOCAL), self.max_groups) * POINTS_LOCAL
        events = (launch(q, k.schedule, (items,), (POINTS_LOCAL,)),
                  launch(q, k.kernel, (self.max_groups * POINTS_LOCAL,), (POINTS_LOCAL,)))
        self.events = events if phase == 0 else (self.events[0], events[1])

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
        units = int(self._counts[UNITS_WORD])   # the largest list's
        if units > MAX_UNITS:
            raise CapacityError(f"points: a frame of {units:,} sample runs, more than the schedule numbers "
                                f"({MAX_UNITS:,}); draw at a smaller size or supersampling, or with fewer samples "
                                f"(PointSettings.density)")
        return {k: int(self._counts[POINTS_COUNTER.offset(k)]) for k in COUNTERS}

    def draw(self, patches_buf, n_patches, inst, materials_buf, cam_buf, light_buf, keys,
             settings: PointSettings, record_args=(), n_views: int = 1):
        """Render ``n_patches`` render patches into ``keys`` and wait; returns the counters (COUNTERS)."""
        cl.enqueue_copy(cl_device().queue, self._count, np.array([n_patches], np.uint32))
        self.enqueue(patches_buf, self._count, 0, n_patches, inst, materials_buf, cam_buf, light_buf, keys,
                     settings, record_args, n_views)
        return self.counts()


class DirectPoints:
    """Per-scene state of the "points" variant: the scene's device buffers, its LOD stage and the
    sampler. The whole frame is enqueued at once; the sampler reads the patch count on the device.

    Hybrid anti-aliasing (``tiered``): the driver calls ``enqueue`` once per tier of POINT_TIERS,
    coarsest first, with that tier's key buffers (1x, 2x, 4x the frame's side, each starting from
    a per-subsample copy of the coarser one): tier 0 runs the LOD stage with the tiers' divisors,
    and each tier draws its own patches, sampled for its target's pixels."""

    tiered = True

    def __init__(self, functions, record: bool = False):
        self.buffers = SceneBuffers(LIGHT)
        self.lod = LodStage(functions)
        self.points = DirectPointRenderer(functions, record=record)
        # the recording test hook indexes samples by render-list place: no culling with it
        self.occlusion = None if record else OcclusionCuller(self.points.program)
        self.culled = False   # the last frame was drawn in two occlusion phases
        self.auto_frame = False   # the last frame's culling was chosen by self.auto
        self.auto = AutoOcclusion()
        self.dev = None

    def prepare(self, scene, camera, settings):
        settings.points.validate()
        self.dev = self.buffers.upload(scene, camera)
        self.camera = camera

    def enqueue(self, target, settings, tier: int | None = None):
        if tier is not None:
            self._enqueue_tier(target, settings, tier)
            return
        d = self.dev
        lod, pts = self.lod, self.points
        lod.enqueue(d["inst"], d["domains"], d["cam"], settings.lod, n_views=d["n_views"], one_sided=d["one_sided"])
        draw = (d["inst"], d["materials"], d["cam"], d["light"], target, settings.points)
        mode = settings.points.occlusion
        self.culled = self.occlusion is not None and mode is not False and d["n_views"] == 1 \
            and (mode is True or self.auto.cull())
        self.auto_frame = mode == "auto" and self.occlusion is not None and d["n_views"] == 1
        if not self.culled:
            pts.enqueue(lod.render.buf, lod.counters, LOD_RENDER_TOTAL, lod.render.capacity, *draw,
                        n_views=d["n_views"], view_masks=lod.render_views.buf)
            return
        occ, cap = self.occlusion, lod.render.capacity
        occ.enqueue_first(lod.render.buf, lod.counters, LOD_RENDER_TOTAL, cap, d["inst"], d["cam"],
                          settings.points.widen, (target.width, target.height))
        pts.enqueue(occ.early, occ.counts_buf, OCC_COUNTER.offset("early"), cap, *draw)
        occ.enqueue_second(lod.render.buf, d["cam"], target, cap)
        pts.enqueue(occ.late, occ.counts_buf, OCC_COUNTER.offset("late"), cap, *draw, phase=1)
        occ.swap()

    def _enqueue_tier(self, target, settings, tier: int):
        d, lod = self.dev, self.lod
        if tier == 0:
            lod.enqueue(d["inst"], d["domains"], d["cam"], settings.lod, n_views=d["n_views"],
                        tiers=tier_divisors(POINT_TIERS), one_sided=d["one_sided"])
            self.culled = self.auto_frame = False   # the tiers are drawn without occlusion culling
        scale = POINT_TIERS[tier].ss
        cam = d["cam"] if scale == 1 else self.buffers.camera(self.camera.with_size((target.width, target.height)),
                                                               slot=tier)
        self.points.enqueue(lod.render.buf, lod.counters, LOD_RENDER_TOTAL, lod.render.capacity, d["inst"],
                            d["materials"], cam, d["light"], target, settings.points, n_views=d["n_views"],
                            view_masks=lod.render_views.buf, phase=tier, tier=tier, scale=scale)

    def collect(self):
        self.lod.read_counters(wait=False)
        self.points.read_counts()
        if self.culled:
            self.occlusion.read_counts()

    def grow(self, settings) -> bool:
        return self.lod.grow(settings.lod)

    def stats(self) -> dict:
        n, steps = self.lod.result()
        out = {"render_patches": n, "lod_steps": steps, "forced_patches": sum(s["forced"] for s in steps),
               "tier_patches": [sum(s["tiers"][t] for s in steps) for t in range(3)],
               **self.points.counts(wait=False),
               "ms": {"lod": self.lod.device_ms(), "render": self.points.device_ms()}}
        self.points.choose_packing(out["samples"], n)
        if self.culled:   # render: from the first bound to the last sample
            c = self.occlusion.counts()
            out["occlusion"] = {"drawn_first": c["early"], "deferred": c["deferred"], "drawn_second": c["late"],
                                "occluded": c["deferred"] - c["late"]}
            first, last = self.occlusion.events[0], self.points.events[-1]
            out["ms"]["render"] = (last.profile.end - first.profile.start) * 1e-6
        if self.auto_frame:
            self.auto.record(self.culled, out["samples"], not self.culled or self.occlusion.guessed)
        return out


register_renderer(RendererSpec("points", "parametric", DirectPoints, "points", "keys", PointSettings,
                               "samples on a (u, v) grid per render patch, 64-bit atom_min into the key buffers",
                               multiview=True))
