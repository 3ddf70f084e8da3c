"""The LOD stage driver: PATCH INITIALIZATION and up to ``max_steps`` PATCH SUBDIVISION steps
in OpenCL (kernels/lod.cl), producing the render list for the renderers.

Buffers grow when a step overflows them (the stage is redone), up to ``max_patches``; past that
the stage stops with an error that names the limit. Nothing is dropped silently. ``patch_budget``
bounds the patches splitting makes in one frame: a view where every patch splits at every step
(a camera at a surface, geometry past float32's reach) would otherwise make 4^(max_steps-1)
patches, grown into by redone stages for minutes, and stops with a CapacityError instead.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import pyopencl as cl
from pyopencl import cltypes

from paramlod.core.layouts import CAMERA, LOD_COUNTER, constant
from paramlod.core.transforms import in_range, is_number
from paramlod.core.views import MAX_VIEWS
from paramlod.device.context import cl_device
from paramlod.errors import CapacityError, SceneError
from paramlod.lod.patches import EVAL_DTYPE, RENDER_DTYPE, initial_patches, render_tiers  # noqa: F401  (re-exported)
from paramlod.device.programs import launch
from paramlod.function.programs import POLY_TRIG, build


@dataclass
class LodSettings:
    threshold: tuple[float, float] = (84.0, 84.0)  # t_u, t_v in pixels
    max_steps: int = 12
    initial_grid: tuple[int, int] = (1, 1)
    max_patches: int = 1 << 24   # per buffer (eval ping-pong and render list)
    # patches made by splitting in one frame, all steps together (a 1080p frame of a detailed
    # scene makes thousands; a view where everything splits makes millions)
    patch_budget: int = 1 << 21
    # cull patches that are back-facing in every view that sees them, for instances flagged
    # one-sided (SceneBuffers: a material with two_sided False); docs/lod.md "Back-face culling"
    backface_cull: bool = True
    # the widest sampling range a renderer draws of a patch, per side as a share of its size (the
    # cone and sphere hold over it): 0.25 covers every PointSettings.widen and TessSettings.overlap
    backface_widen: float = 0.25
    # a patch also splits across a measured line whose consecutive segments turn by more than this
    # (degrees; kernels/lod/lod.cl line_turns): detail between the samples, as a thin lobe, gets
    # the patches it needs at any screen size. 180: off
    detail_angle: float = 120.0
    # hybrid anti-aliasing (aa = "hybrid"): the spot check (kernels/lod/spot.cl) sends a patch to
    # the next tier when at least spot_share of its 189 sub-samples have normals that turn by more
    # than spot_angle (degrees) from their cell's blended corner normals
    spot_angle: float = 20.0
    # 5 of 189: more than half of one cell's 9 sub-samples, so detail within one cell of the 21
    # spread over the patch is enough (docs/hybrid.md "Why spread")
    spot_share: float = 0.025
    # hybrid: a patch over which the surface turns away from a view (a silhouette edge) goes from
    # tier 0 to tier 1, so its edge pixels are anti-aliased (kernels/lod/spot.cl grid_silhouette)
    spot_silhouettes: bool = True

    def curve_cos(self) -> np.float32:
        """The kernel's ``curve_cos``: the cosine of ``detail_angle`` (-1 at 180: never below it)."""
        return np.float32(np.cos(np.radians(self.detail_angle)))

    def spot(self) -> tuple[np.float32, np.uint32]:
        """The kernel's ``spot_cos`` and ``spot_min`` (at least one sub-sample)."""
        return (np.float32(np.cos(np.radians(self.spot_angle))),
                np.uint32(max(1, int(np.ceil(self.spot_share * SPOT_SUBS)))))

    def validate(self):
        t = self.threshold
        if is_number(t):
            self.threshold = t = (float(t), float(t))   # one number for both, as a scene file's threshold
        if not (isinstance(t, (tuple, list, np.ndarray)) and len(t) == 2 and all(is_number(x) and x > 0 for x in t)):
            raise SceneError(f"lod threshold must be positive pixels, one number or two (t_u, t_v), got {t!r}")
        if not (isinstance(self.max_steps, (int, np.integer)) and in_range(self.max_steps, 1, 15)):
            raise SceneError(f"lod max_steps must be an integer in 1..15, got {self.max_steps!r}")
        g = self.initial_grid
        if not (isinstance(g, (tuple, list, np.ndarray)) and len(g) == 2
                and all(isinstance(x, (int, np.integer)) and in_range(x, 1, 64) for x in g)):
            raise SceneError(f"lod initial_grid must be two integers (gu, gv) in 1..64, got {self.initial_grid!r}")
        if not isinstance(self.backface_cull, (bool, np.bool_)):
            raise SceneError(f"lod backface_cull must be true or false, got {self.backface_cull!r}")
        if not (isinstance(self.backface_widen, (int, float, np.floating)) and 0 <= self.backface_widen <= 1):
            raise SceneError(f"lod backface_widen must be a share of a patch in [0, 1], got {self.backface_widen!r}")
        if isinstance(self.detail_angle, bool) or not isinstance(self.detail_angle, (int, float, np.floating)) \
                or not 0 < self.detail_angle <= 180:
            raise SceneError(f"lod detail_angle must be in (0, 180] degrees (180: off), got {self.detail_angle!r}")
        if isinstance(self.spot_angle, bool) or not isinstance(self.spot_angle, (int, float, np.floating)) \
                or not 0 < self.spot_angle < 180:
            raise SceneError(f"lod spot_angle must be in (0, 180) degrees, got {self.spot_angle!r}")
        if not isinstance(self.spot_silhouettes, (bool, np.bool_)):
            raise SceneError(f"lod spot_silhouettes must be true or false, got {self.spot_silhouettes!r}")
        if isinstance(self.spot_share, bool) or not isinstance(self.spot_share, (int, float, np.floating)) \
                or not 0 < self.spot_share <= 1:
            raise SceneError(f"lod spot_share must be a share in (0, 1], got {self.spot_share!r}")
        for name in ("max_patches", "patch_budget"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 1 <= v <= 1 << 31:
                raise SceneError(f"lod {name} must be an integer in 1..2^31, got {v!r}")


class _Buffer:
    """A device buffer of records that can grow."""

    def __init__(self, dtype, capacity):
        self.dtype, self.capacity, self.buf = dtype, 0, None
        self.ensure(capacity)

    def ensure(self, n, keep=0):
        if n <= self.capacity:
            return False
        cap = max(1024, 1 << int(np.ceil(np.log2(max(n, 1)))))
        new = cl.Buffer(cl_device().context, cl.mem_flags.READ_WRITE, cap * self.dtype.itemsize)
        if keep and self.buf is not None:
            cl.enqueue_copy(cl_device().queue, new, self.buf, byte_count=keep * self.dtype.itemsize)
        self.buf, self.capacity = new, cap
        return True


# the per-step counter record (paramlod.core.layouts.LOD_COUNTER; LOD_* in the kernels' prelude)
LOD_COUNTERS = LOD_COUNTER.length
C_CHILDREN, C_SPLIT, C_CULLED, C_RENDERED, C_FORCED, C_BACKFACE, C_PROMOTED, C_TIER1, C_TIER2 = (
    LOD_COUNTER.offset(f) for f in ("children", "split", "culled", "rendered", "forced", "backface", "promoted",
                                    "tier1", "tier2"))
SPOT_SUBS = 189   # kernels/lod/spot.cl: 7 x 3 cells, 9 sub-samples each
# The measure's constants: kernels/lod/lod.cl and spot.cl are built with them (lod_cl_defines) and
# the numpy twin (paramlod/lod/reference.py) reads them; the kernels say what each is for.
BOUNDARY_CAP = np.float32(2.0)
MIXED_MIN_PX = np.float32(1.0)
CURVE_MIN_PX, CURVE_MAX_PX = np.float32(14.0), np.float32(28.0)
BOUNDARY_SHARE = np.float32(0.9428090)   # sqrt(2) / 1.5
CONE_LIPSCHITZ, CONE_EPS = np.float32(2.0), np.float32(1e-3)
SIL_GRAZE = np.float32(0.17)   # cos 80 degrees


def lod_cl_defines() -> dict:
    """The constants above, as kernels/lod/lod.cl is built with them."""
    return {"BOUNDARY_CAP": BOUNDARY_CAP, "MIXED_MIN_PX": MIXED_MIN_PX, "CURVE_MIN_PX": CURVE_MIN_PX,
            "CURVE_MAX_PX": CURVE_MAX_PX, "BOUNDARY_SHARE": BOUNDARY_SHARE, "CONE_LIPSCHITZ": CONE_LIPSCHITZ,
            "CONE_EPS": CONE_EPS, "SIL_GRAZE": SIL_GRAZE, "SPOT_SUBS": SPOT_SUBS}


LOD_RENDER_TOTAL = LOD_COUNTER.constant("LOD_RENDER_TOTAL")   # counters[0, 1]: the render list's length
LOD_LOCAL = constant("LOD_LOCAL")   # work-items measuring one patch together (kernels/lod/lod.cl)
# views one work-group projects at once (local memory: 89 x 9 bytes a view)
LOD_MAX_SLOTS = 8
SAMPLE_RUNS_CPU = True   # kernels/lod/lod.cl LOD_RUN on CPU devices (GPUs: lod_axis, the split shared in local memory)
LOD_MAX_GROUP = 256   # work-items a patch at most (every OpenCL GPU takes 256)
# work-items a view slot on CPU devices: one a patch. PoCL runs a work-group's barriers as loops over
# its work-items; with 32 a patch, as GPUs take, the 2-core AMD EPYC's LOD stage took 1.4-1.6x as long
# (640 x 360, framing distance: fibre curtain 1,542 -> 953 ms, yarn curtain 179 -> 125, hardi12
# 132-141 -> 82-99; 2 and 4 a patch measured as 1; docs/lod.md)
LOD_LOCAL_CPU = 1


def lod_layout(n_views: int, max_group: int = LOD_MAX_GROUP, per_slot: int = LOD_LOCAL) -> tuple[int, int]:
    """(work-items per patch, view slots per chunk) of the LOD kernel for ``n_views`` views:
    ``per_slot`` work-items a slot (LOD_LOCAL on GPUs, LOD_LOCAL_CPU on CPU devices), as one view
    has, up to LOD_MAX_SLOTS slots and LOD_MAX_GROUP work-items; more views take chunks of slots in
    turn. A step's patches are mostly fewer than
    the device's work-groups, so a step lasts about as long as one patch takes, and more views
    need more work-items per patch to take no longer (H200, 48 views: the LOD stage 1.4-2.1x one
    view's time, 3.2-3.9x with 32 work-items). ``max_group``: the most the device takes, a power
    of two."""
    slots = min(1 << (int(n_views) - 1).bit_length(), LOD_MAX_SLOTS)
    return min(per_slot * slots, max_group, LOD_MAX_GROUP), slots


class LodStage:
    """The LOD stage for one camera or for several at once (``n_views``): with several, a patch is
    measured in every view, culled only if no view sees it, and otherwise split if it is too large
    in any view that sees it (its measures are the maxima over those views, its screen box their
    union; kernels/lod/lod.cl). One render list serves all the views."""
    # work-groups of LOD_LOCAL per compute unit and step (they stride over the patches); None: the
    # device kind's (below)
    groups_per_unit = None

    def __init__(self, functions):
        self._functions = functions
        dev = cl_device()
        # the largest power of two of work-items per group the device takes
        self._max_group = 1 << (min(dev.device.max_work_group_size, LOD_MAX_GROUP).bit_length() - 1)
        self._per_slot = LOD_LOCAL if dev.is_gpu else LOD_LOCAL_CPU
        # per kernel layout (lod_layout): one kernel object per step with its arguments bound once
        # (they change only when a buffer grows or the scene, camera buffer, views or threshold
        # change): a frame only enqueues. The program of single-view frames of two-sided materials
        # without hybrid tiers is built now, others when used.
        self._step_kernels: dict[tuple, list] = {}   # (layout, back-face test, tiers) -> kernels
        self._bound: dict[tuple, tuple] = {}
        self._kernels(1, backface=False, tiers=False)
        self.bufs = [_Buffer(EVAL_DTYPE, 4096), _Buffer(EVAL_DTYPE, 4096)]
        self.render = _Buffer(RENDER_DTYPE, 4096)
        # beside each render patch: the views that see it (bit v: view v), for renderers that skip the others
        self.render_views = _Buffer(np.dtype(np.uint64), 4096)
        # PATCH INITIALIZATION's output, built and uploaded only when the instances change
        # (for 358,140 fiber instances that was ~30 ms of numpy and 11 MB of upload a frame)
        self.init = _Buffer(EVAL_DTYPE, 4096)
        self._init_for = (None, None, 0)
        self.counters = cl.Buffer(cl_device().context, cl.mem_flags.READ_WRITE, 16 * LOD_COUNTERS * 4)
        # the counters at the start of a stage (initial patch count, zeros), kept on the device
        self._start = cl.Buffer(cl_device().context, cl.mem_flags.READ_ONLY, 16 * LOD_COUNTERS * 4)
        self._start_n = None
        self._counts = np.zeros((16, LOD_COUNTERS), np.uint32)  # read back after it
        self._max_steps = 0   # the settings' max_steps of the enqueued stage
        self._steps_n = 0     # steps enqueued: the previous stage's depth plus one (see enqueue)
        # per threshold (variants divide it differently): the last step that had input patches
        # in the previous stage with it
        self._depth: dict[tuple, int] = {}
        self._depth_key = None
        self.events = []   # the last enqueued stage's kernel events (device timing)
        # work-groups of LOD_LOCAL per step: enough to fill the device
        self.max_groups = dev.device.max_compute_units * (self.groups_per_unit or (64 if dev.is_gpu else 16))

    def run(self, inst, domains, cam_buf, settings: LodSettings, t_div: float = 1.0, n_views: int = 1,
            tiers=None, one_sided: bool = True):
        """Returns (render buffer, render patch count, per-step stats list, ms). ``cam_buf`` holds
        ``n_views`` camera records one after another (``SceneBuffers.upload``'s "cam", "n_views").

        All steps are enqueued at once and the counters read back once; if a buffer overflowed,
        the buffers grow and the whole stage is redone (growth persists across frames).
        """
        t0 = time.perf_counter()
        while True:
            self.enqueue(inst, domains, cam_buf, settings, t_div, n_views, tiers, one_sided)
            self.read_counters()
            if not self.grow(settings):
                break
        n_render, steps = self.result()
        return self.render.buf, n_render, steps, (time.perf_counter() - t0) * 1e3

    def enqueue(self, inst, domains, cam_buf, settings: LodSettings, t_div: float = 1.0, n_views: int = 1,
                tiers=None, one_sided: bool = True):
        """Enqueue the whole stage without waiting: the render list lands in ``self.render.buf``
        and its length in ``self.counters[LOD_RENDER_TOTAL]`` on the device, for a renderer that
        reads the count there. Then ``read_counters`` (waits), ``grow`` (True: enqueue the frame
        again) and ``result``. ``cam_buf``: ``n_views`` (1..MAX_VIEWS) camera records; the
        counters count each patch once, whatever the number of views that see it.

        Only the steps the previous stage needed plus one are enqueued (a view changes little
        between frames, and each step is a launch of Python and device time); if the last of them
        still splits patches, ``grow`` asks for the stage again with all ``max_steps`` steps. Only
        step ``max_steps`` forces its patches out, so nothing is rendered too coarse meanwhile.

        ``tiers``: hybrid anti-aliasing, tiers 1 and 2's (threshold divisor, spot-check scale)
        (tier 0's divisor is ``t_div``): a patch about to be rendered whose spot check finds
        sub-pixel detail is measured again at the next tier (``tier_values``); each render patch
        carries its tier in ``flags >> TIER_SHIFT``.

        ``one_sided``: whether an instance may be one-sided (``SceneBuffers.upload``'s
        "one_sided"); False builds the stage without the back-face test (lod.cl LOD_BACK_TEST)."""
        settings.validate()
        _check_views(n_views, cam_buf)
        q = cl_device().queue
        src_domains, grid_for, n_init = self._init_for
        if src_domains is not domains or grid_for != tuple(settings.initial_grid):
            init = initial_patches(domains, settings.initial_grid)
            n_init = len(init)
            self._check(n_init, settings, "initial patches")
            self.init.ensure(n_init)
            if n_init:
                cl.enqueue_copy(q, self.init.buf, init)
            self._init_for = (domains, tuple(settings.initial_grid), n_init)
        for b in self.bufs:
            b.ensure(n_init)
        max_steps = self._max_steps = settings.max_steps
        tu, tv = (np.float32(t / t_div) for t in settings.threshold)
        max_tier, tier_t, tier_scale = tier_values(settings, tiers)
        spot_cos, spot_min = settings.spot()
        self._depth_key = (float(tu), float(tv), max_steps, tuple(tier_t))
        depth = self._depth.get(self._depth_key)
        steps_n = self._steps_n = max_steps if depth is None else min(max_steps, depth + 1)
        cap = min(b.capacity for b in self.bufs)
        # the buffers themselves, not their ids: held here, they cannot be freed and their ids reused
        backface, widen = np.uint32(bool(settings.backface_cull)), np.float32(settings.backface_widen)
        curve_cos = settings.curve_cos()
        bound = (*inst, cam_buf, int(n_views), float(tu), float(tv), max_steps, cap, int(backface), float(widen),
                 float(curve_cos), max_tier, tuple(tier_t), tuple(tier_scale), float(spot_cos), int(spot_min),
                 bool(settings.spot_silhouettes),
                 *(b.buf for b in (self.init, *self.bufs, self.render, self.render_views)))
        variant = (bool(settings.backface_cull) and one_sided, max_tier > 0)
        layout, kernels = self._kernels(n_views, *variant)
        kind = (layout, *variant)   # the kernels' key
        if bound != self._bound.get(kind):
            for step, k in enumerate(kernels[:max_steps], start=1):
                src = self.init if step == 1 else self.bufs[(step - 1) % 2]
                k.set_args(src.buf, self.bufs[step % 2].buf, np.uint32(cap), self.render.buf, self.render_views.buf,
                           np.uint32(self.render.capacity), self.counters, *inst, cam_buf,
                           np.uint32(n_views), tu, tv,
                           np.uint32(step), np.uint32(step == max_steps), backface, widen, curve_cos,
                           np.uint32(max_tier), cltypes.make_float4(*tier_t), cltypes.make_float2(*tier_scale),
                           spot_cos, spot_min, np.uint32(bool(settings.spot_silhouettes)))
            self._bound[kind] = bound
        if self._start_n != n_init:
            start = np.zeros((16, LOD_COUNTERS), np.uint32)
            start[0, C_CHILDREN] = n_init
            cl.enqueue_copy(q, self._start, start)
            self._start_n = n_init
        # device-to-device: a write from host memory would make NVIDIA's driver wait here
        cl.enqueue_copy(q, self.counters, self._start)
        group = layout[0]
        # as many work-items as with LOD_LOCAL a group: empty groups cost launch time too
        grid = (min(max(1, self.max_groups * LOD_LOCAL // group), max(cap, 1)) * group,)
        self.events = [launch(q, k, grid, (group,)) for k in kernels[:steps_n]]

    def _kernels(self, n_views: int, backface: bool, tiers: bool):
        """(layout, the step kernels) for ``n_views`` views, with the back-face test and the hybrid
        tiers' checks or without them, built on first use."""
        layout = lod_layout(n_views, self._max_group, self._per_slot)
        key = (layout, backface, tiers)
        if key not in self._step_kernels:
            group, slots = layout
            # the per-view local arrays as large as this layout's views can be (lod_layout: fewer
            # slots than LOD_MAX_SLOTS only for as many views): local memory bounds the groups a
            # compute unit holds
            max_views = slots if slots < LOD_MAX_SLOTS else MAX_VIEWS
            defines = {**lod_cl_defines(), "LOD_MAX_VIEWS": max_views, "LOD_GROUP": group, "LOD_SLOTS": slots,
                       "LOD_BACK_TEST": int(backface), "LOD_TIER_CHECKS": int(tiers)}
            if not cl_device().is_gpu:   # inline trigonometry in the function code (kernels/common/poly_trig.cl)
                defines[POLY_TRIG] = 1
                # runs of samples that share the position split's steps (kernels/lod/lod.cl lod_order)
                defines["LOD_RUN"] = int(SAMPLE_RUNS_CPU)
            prog = build(["lod/lod.cl"], self._functions, defines=defines)
            self._step_kernels[key] = [cl.Kernel(prog, "lod_step") for _ in range(15)]
        return layout, self._step_kernels[key]

    def read_counters(self, wait: bool = True):
        """Read the enqueued stage's counters back: waiting for them, or (``wait=False``) enqueued
        for the frame's one wait."""
        cl.enqueue_copy(cl_device().queue, self._counts, self.counters, is_blocking=wait)

    def grow(self, settings: LodSettings) -> bool:
        """After the stage's read-back: grow the buffers that overflowed, or the step count if
        the last enqueued step split patches; True if the stage must be enqueued again."""
        counts = self._counts
        n = self._steps_n
        need = int(counts[1:n + 1, C_CHILDREN].max(initial=0))
        n_render = int(counts[0, LOD_RENDER_TOTAL])
        # children counted past a full buffer still count, so a runaway stage is stopped after
        # a few redone stages of growing buffers, not after it has made all its patches
        check_budget(int(counts[1:n + 1, C_CHILDREN].sum(dtype=np.int64)), settings)
        grew = False
        if n < self._max_steps and counts[n, C_CHILDREN]:
            self._depth.pop(self._depth_key)   # too few steps: the next stage runs all of them
            grew = True
        else:
            fed = np.flatnonzero(counts[:n, C_CHILDREN])   # fed[i] + 1: a step that had input
            self._depth[self._depth_key] = int(fed[-1]) + 1 if fed.size else 1
        if need > min(b.capacity for b in self.bufs):
            self._check(need, settings, "patches in one LOD step")
            for b in self.bufs:
                grew |= b.ensure(need)
        if n_render > self.render.capacity:
            self._check(n_render, settings, "render patches")
            grew |= self.render.ensure(n_render)
            self.render_views.ensure(self.render.capacity)
        return grew

    def result(self) -> tuple[int, list[dict]]:
        """(render patch count, per-step stats) of the last stage read back."""
        counts = self._counts
        steps = []
        n_in = int(counts[0, C_CHILDREN])
        for step in range(1, self._max_steps + 1):   # steps not enqueued had no input: zeros
            c = counts[step]
            steps.append({"step": step, "in": n_in, "split": int(c[C_SPLIT]), "culled": int(c[C_CULLED]),
                          "out": int(c[C_RENDERED]), "forced": int(c[C_FORCED]), "backface": int(c[C_BACKFACE]),
                          "promoted": int(c[C_PROMOTED]),
                          "tiers": [int(c[C_RENDERED] - c[C_TIER1] - c[C_TIER2]), int(c[C_TIER1]), int(c[C_TIER2])]})
            n_in = int(c[C_CHILDREN])
        return int(counts[0, LOD_RENDER_TOTAL]), steps

    def device_ms(self) -> float:
        """Device time of the last stage, first step start to last step end (after its sync)."""
        if not self.events:
            return 0.0
        return (self.events[-1].profile.end - self.events[0].profile.start) * 1e-6

    @staticmethod
    def _check(n, settings, what):
        if n > settings.max_patches:
            raise CapacityError(
                f"the LOD stage needs {n} {what}, more than max_patches={settings.max_patches}; "
                "raise max_patches ([render] in a scene file; memory: 64 bytes a render patch, 32 an evaluated "
                "one), raise the threshold, or lower max_steps")

    def read_render_list(self, n) -> np.ndarray:
        out = np.empty(n, RENDER_DTYPE)
        if n:
            cl.enqueue_copy(cl_device().queue, out, self.render.buf)
        return out

    def read_render_views(self, n) -> np.ndarray:
        """The views that see each of the first ``n`` render patches (uint64, bit v: view v)."""
        out = np.empty(n, np.uint64)
        if n:
            cl.enqueue_copy(cl_device().queue, out, self.render_views.buf)
        return out


def tier_values(settings: LodSettings, tiers=None) -> tuple[int, np.ndarray, np.ndarray]:
    """The LOD kernel's (max_tier, tier_t, tier_scale) for hybrid ``tiers``: tiers 1 and 2's
    (threshold divisor, spot-check scale), as ``paramlod.renderers.aa.tier_divisors`` gives them
    (None: no hybrid). Tiers 1 and 2's thresholds (t_u, t_v each) and scales, float32 as the kernel
    takes them (the twin uses the same values)."""
    if tiers is None:
        return 0, np.zeros(4, np.float32), np.ones(2, np.float32)
    try:
        (d1, s1), (d2, s2) = ((float(d), float(s)) for d, s in tiers)
    except (TypeError, ValueError):
        raise SceneError(f"hybrid tiers must be ((divisor, scale), (divisor, scale)), got {tiers!r}") from None
    if not (1 <= d1 <= d2 and 1 <= s1 <= s2):
        raise SceneError(f"hybrid tier divisors and scales must grow from 1, got {tiers!r}")
    tu, tv = settings.threshold
    return 2, np.array([tu / d1, tv / d1, tu / d2, tv / d2], np.float32), np.array([s1, s2], np.float32)


def _check_views(n_views, cam_buf) -> None:
    """SceneError unless ``n_views`` is a whole number in 1..MAX_VIEWS that ``cam_buf`` holds
    records for (the kernel reads n_views records from it)."""
    if isinstance(n_views, bool) or not isinstance(n_views, (int, np.integer)) or not 1 <= n_views <= MAX_VIEWS:
        raise SceneError(f"the LOD stage takes 1..{MAX_VIEWS} views, got n_views={n_views!r}")
    held = cam_buf.size // (CAMERA.length * 4)
    if held < n_views:
        raise SceneError(f"the LOD stage's camera buffer holds {held} camera records, fewer than n_views={n_views}")


def check_budget(made: int, settings: LodSettings) -> None:
    """CapacityError when splitting made more than ``settings.patch_budget`` patches this frame
    (shared with the numpy twin)."""
    if made > settings.patch_budget:
        raise CapacityError(
            f"the LOD stage made {made} patches by splitting in one frame, more than patch_budget="
            f"{settings.patch_budget}: every patch keeps splitting, as it does when the camera sits on a "
            "surface or an object is too far or too large for float32 to place; check the camera and the "
            "transforms, or raise patch_budget ([render] in a scene file), raise the threshold or lower max_steps")
