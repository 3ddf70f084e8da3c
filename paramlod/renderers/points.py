"""Point renderer, direct variant (kernels/points.cl): render patches sampled on a (u, v) grid
sized from their measured extents and written with 64-bit atom_min into the KeyBuffer.

Sampling (docs/points.md): per patch side, ``ceil(m * factor) + 1`` samples, where ``m`` is the
measure chosen by ``sampling`` ("segment": s_u, s_v = 7 x the longest LOD segment; "extent": the
thesis's measured polyline extents e_u, e_v) and ``factor = density * oversample / (1 - epsilon)``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from paramlod.device.context import cl_device
from paramlod.errors import SceneError
from paramlod.device.programs import launch
from paramlod.function.programs import build

LOCAL_SIZE = 64
COUNTERS = ("samples", "atomics", "nan_samples", "capped_patches")
SAMPLING = ("segment", "extent")


@dataclass
class PointSettings:
    density: float = 1.5    # samples per pixel of s_u, s_v: spacing <= 0.67 px < 1/sqrt(2), no holes at any angle
    widen: float = 0.005    # parameter range enlarged by this fraction per side (no seams)
    max_side: int = 1024    # samples per side at most; patches that hit it are counted in stats
    # what the sample counts are measured from: "segment" (s_u, s_v; hole-free default) or
    # "extent" (e_u, e_v: the thesis's adaptive sampling, fewer samples, may leave 1-px holes)
    sampling: str = "segment"
    oversample: float = 1.0  # fixed oversampling factor on top of density (thesis Fig. 5.17: 1x, 2x, 3x)
    epsilon: float = 0.0     # step shrink: sample steps are (1 - epsilon) x the nominal step
    # anti-aliasing of the direct variant: render into keys supersample x the frame's size, then
    # resolve each block (colour averaged over covered subsamples, alpha = coverage); 1 = off
    supersample: int = 1

    def validate(self):
        if not 0.1 <= self.density <= 16:
            raise SceneError(f"points density must be in [0.1, 16] samples per pixel, got {self.density}")
        if not 0 <= self.widen <= 0.25:
            raise SceneError(f"points widen must be in [0, 0.25], got {self.widen}")
        if not 2 <= self.max_side <= 8192:
            raise SceneError(f"points max_side must be in [2, 8192], got {self.max_side}")
        if self.sampling not in SAMPLING:
            raise SceneError(f"points sampling must be one of {', '.join(SAMPLING)}, got {self.sampling!r}")
        if not 1 <= self.oversample <= 8:
            raise SceneError(f"points oversample must be in [1, 8], got {self.oversample}")
        if not 0 <= self.epsilon <= 0.9:
            raise SceneError(f"points epsilon (step shrink) must be in [0, 0.9], got {self.epsilon}")
        if self.supersample not in (1, 2, 3, 4) or isinstance(self.supersample, bool):
            raise SceneError(f"points supersample must be 1 (off), 2, 3 or 4 subsamples per pixel side, "
                             f"got {self.supersample!r}")

    def factor(self) -> np.float32:
        """Samples per measured pixel along each side, as the kernel receives it (float32)."""
        return np.float32(self.density * self.oversample / (1.0 - self.epsilon))

    @property
    def use_extent(self) -> bool:
        return self.sampling == "extent"


def side_counts(ext: np.ndarray, settings: PointSettings) -> np.ndarray:
    """numpy twin of side_count() in points.cl: samples per side for each measure in ``ext``."""
    n = np.ceil(np.asarray(ext).astype(np.float32) * settings.factor()) + np.float32(1)
    with np.errstate(invalid="ignore"):
        capped = ~(n < np.float32(settings.max_side))
    return np.where(capped, settings.max_side, np.maximum(np.nan_to_num(n), 2)).astype(np.int64)


def grid_counts(render_list: np.ndarray, settings: PointSettings) -> tuple[np.ndarray, np.ndarray]:
    """(nu, nv) per render patch, picking the measure columns ``settings.sampling`` selects."""
    ext = render_list["ext"]
    cu, cv = (0, 1) if settings.use_extent else (2, 3)
    return side_counts(ext[:, cu], settings), side_counts(ext[:, cv], settings)


def count_holes(frame, mask: np.ndarray, depth: np.ndarray | None = None, tol: float = 0.0,
                erode: int = 1) -> int:
    """Pixels inside a known silhouette that the render failed to fill.

    ``mask`` (h, w) bool is the silhouette; it is first eroded by ``erode`` pixels (8-neighbour) so
    that pixels the silhouette only partly covers do not count. A pixel of the eroded mask is a
    hole when nothing was drawn there, or, if ``depth`` (the expected front depth, (h, w)) is
    given, when the drawn depth is farther than ``depth + tol`` (a gap in the front surface that
    shows a surface behind it).
    """
    mask = np.asarray(mask, bool)
    if mask.shape != frame.depth.shape:
        raise SceneError(f"count_holes: mask shape {mask.shape} differs from the frame's {frame.depth.shape}")
    inner = mask.copy()
    for _ in range(int(erode)):
        m = np.pad(inner, 1, constant_values=False)
        acc = np.ones_like(inner)
        for dy in (0, 1, 2):
            for dx in (0, 1, 2):
                acc &= m[dy:dy + inner.shape[0], dx:dx + inner.shape[1]]
        inner = acc
    bad = ~np.isfinite(frame.depth)
    if depth is not None:
        with np.errstate(invalid="ignore"):
            bad |= frame.depth > np.asarray(depth) + tol
    return int(np.count_nonzero(bad & inner))


class DirectPointRenderer:
    def __init__(self, functions, record: bool = False):
        import pyopencl as cl

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
                light_buf, keys, settings: PointSettings, record_args=()):
        """Enqueue the render of the ``count_buf[count_at]`` (read on the device, at most
        ``capacity``) patches of ``patches_buf`` without waiting; ``counts()`` reads the counters."""
        import pyopencl as cl

        settings.validate()
        q = cl_device().queue
        capacity = max(int(capacity), 1)
        if capacity > self.order_capacity:
            self._order = cl.Buffer(cl_device().context, cl.mem_flags.READ_WRITE, 8 * capacity)
            self.order_capacity = capacity
        cl.enqueue_fill_buffer(q, self.counters, np.uint64(0), 0, 8 * (len(COUNTERS) + 1))
        sampling = (settings.factor(), np.uint32(settings.use_extent))
        args = (patches_buf, count_buf, np.uint32(count_at), np.uint32(capacity), self._order,
                *inst, materials_buf, cam_buf, light_buf, *sampling, np.float32(settings.widen),
                np.uint32(settings.max_side), keys.color, keys.aux, self.counters, *record_args)
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

    def counts(self) -> dict:
        """Wait for the last render and return its counters (COUNTERS)."""
        import pyopencl as cl

        cl.enqueue_copy(cl_device().queue, self._counts, self.counters)
        return {k: int(v) for k, v in zip(COUNTERS, self._counts)}

    def draw(self, patches_buf, n_patches, inst, materials_buf, cam_buf, light_buf, keys,
             settings: PointSettings, record_args=()):
        """Render ``n_patches`` render patches into ``keys`` and wait; returns the counters (COUNTERS)."""
        import pyopencl as cl

        cl.enqueue_copy(cl_device().queue, self._count, np.array([n_patches], np.uint32))
        self.enqueue(patches_buf, self._count, 0, n_patches, inst, materials_buf, cam_buf, light_buf, keys,
                     settings, record_args)
        return self.counts()
