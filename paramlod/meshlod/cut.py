"""The per-frame LOD cut of the scene's meshes on the device (kernels/meshlod/cut.cl): for every
instance, the clusters of its mesh's DAG whose projected error is within the threshold while
their parents' is not, less those the frustum and the backface cone cull.

Driven by the mesh renderers (paramlod.meshlod.render): ``ClusterCut.enqueue`` every frame (one
launch per batch of instances of one mesh, nothing waited for), then the rasterizer reads the
selection and its count on the device, or ``Selection.collect`` and the frame's one wait for the
OpenGL path and the stats; ``Selection.grow`` after the wait when the selection overflowed (the
frame is then drawn again). ``ClusterCut.select`` is the waiting form for tests and tools.
Its numpy twin is paramlod.meshlod.cut_reference (the rule and the cut camera record are
described there).
"""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from paramlod.device.context import cl_device
from paramlod.device.programs import events_ms, kernel, launch
from paramlod.errors import CapacityError, MeshError
from paramlod.meshlod import cut_reference as ref
from paramlod.meshlod.buffers import SIMILAR, DeviceMeshes

CUT_LOCAL = 64          # work-items per group: one local reduction and one global atomic per counter
N_COUNTERS = 8          # ulong counters of the contract (the rest of COUNTERS' slots are spare)
PAIR_BYTES = 8          # one uint2 (instance, cluster)
FRUSTUM, BACKFACE = 1, 2
EXACT = ("-cl-fp32-correctly-rounded-divide-sqrt",)   # so the numpy twin's division and sqrt match
_DEFINES = {"CUT_LOCAL": CUT_LOCAL, "CUT_SIMILAR": f"{SIMILAR}u", "CC_PLANES": ref.CC_PLANES,
            "CC_DEPTH": ref.CC_DEPTH, "CC_EYE": ref.CC_EYE, "CC_K": ref.CC_K, "CC_WA": ref.CC_WA,
            "CC_WB": ref.CC_WB, "CC_NEAR": ref.CC_NEAR, "CC_T": ref.CC_T, "CC_FLOATS": ref.CC_FLOATS}


def _counts(raw: np.ndarray) -> dict:
    return {name: int(raw[k]) for k, name in enumerate(ref.COUNTERS)}


class Selection:
    """The cut's output on the device: ``pairs`` (uint2 (instance, cluster) x ``capacity``) and
    ``counters`` (8 ulong, see kernels/meshlod/cut.cl). ``collect`` enqueues the counters'
    read-back for the frame's wait; ``counts``, ``grow`` and ``read_pairs`` use it after."""

    def __init__(self, capacity: int = 1 << 14):
        self.capacity, self.pairs = 0, None
        self.counters = cl.Buffer(cl_device().context, cl.mem_flags.READ_WRITE, N_COUNTERS * 8)
        self._raw = np.zeros(N_COUNTERS, np.uint64)
        self._alloc(max(1, int(capacity)))

    def _alloc(self, capacity: int) -> None:
        limit = cl_device().device.max_mem_alloc_size // PAIR_BYTES
        if capacity > limit:
            raise CapacityError(f"the mesh cut selected {capacity} clusters; the device holds at most {limit} "
                                "in one buffer: raise the mesh threshold_px or draw fewer instances")
        self.pairs = cl.Buffer(cl_device().context, cl.mem_flags.READ_WRITE, capacity * PAIR_BYTES)
        self.capacity = capacity

    def collect(self) -> None:
        """Enqueue the counters' read-back without waiting (the frame's one wait completes it)."""
        cl.enqueue_copy(cl_device().queue, self._raw, self.counters, is_blocking=False)

    def read_counters(self) -> dict:
        """The counters, read back now (waits)."""
        cl.enqueue_copy(cl_device().queue, self._raw, self.counters, is_blocking=True)
        return self.counts()

    def counts(self) -> dict:
        """The counters of the last ``collect`` or ``read_counters``: {name: int}, names
        ``paramlod.meshlod.cut_reference.COUNTERS``."""
        return _counts(self._raw)

    def grow(self, needed: int | None = None) -> bool:
        """Make room for ``needed`` pairs (default: the count last collected); True when the buffer
        grew, so the cut must be enqueued again (its pairs are gone)."""
        need = int(self._raw[0]) if needed is None else int(needed)
        if need <= self.capacity:
            return False
        self._alloc(max(need + need // 4, 2 * self.capacity))
        return True

    def read_pairs(self, count: int | None = None) -> np.ndarray:
        """The selected pairs, uint32 [n, 2] in the device's (arbitrary) order; ``count``: how many
        (default: the counters read back now). Only what fits the capacity was written: a
        larger count raises (grow and cut again)."""
        n = int(self.read_counters()["selected"]) if count is None else int(count)
        if n > self.capacity:
            raise MeshError(f"the cut selected {n} clusters but the selection holds {self.capacity}; "
                            "grow it (Selection.grow) and enqueue the cut again")
        out = np.empty((n, 2), np.uint32)
        if n:
            cl.enqueue_copy(cl_device().queue, out, self.pairs, is_blocking=True)
        return out

    @property
    def nbytes(self) -> int:
        return self.capacity * PAIR_BYTES + N_COUNTERS * 8


class ClusterCut:
    """The cut's kernel, bound per launch (one per renderer state; the camera record travels by
    value with each launch)."""

    def __init__(self):
        self._kernel = kernel("cluster_cut", ["meshlod/cut.cl"], _DEFINES, EXACT)
        self.events: list = []

    def enqueue(self, dev: DeviceMeshes, camera, threshold_px, selection, capacity: int | None = None,
                counters: cl.Buffer | None = None, cull_frustum: bool = True, cull_backface: bool = True,
                reset: bool = True) -> list:
        """Enqueue the cut of every instance of ``dev`` for ``camera`` at ``threshold_px`` pixels
        (>= 0; 0 draws the original triangles). ``selection``: a Selection, or a cl.Buffer of
        ``capacity`` uint2 pairs with ``counters`` (8 ulong). ``reset``: zero the counters first
        (False: add to them, e.g. a second view into one selection). Instances whose hand-off
        weight (``dev.weights``, DeviceMeshes.set_weights) is 0 select nothing. Returns the
        enqueued events (the counters' reset, one kernel per batch); nothing is waited for."""
        if isinstance(selection, Selection):
            buf, capacity, counters = selection.pairs, selection.capacity, selection.counters
        else:
            buf = selection
            if capacity is None or counters is None:
                raise MeshError("ClusterCut.enqueue: a selection given as a buffer needs its capacity and counters")
            if int(capacity) < 0 or int(capacity) * PAIR_BYTES > buf.size:
                raise MeshError(f"ClusterCut.enqueue: capacity {capacity} pairs does not fit the selection buffer "
                                f"of {buf.size} bytes ({PAIR_BYTES} per pair)")
            if counters.size < N_COUNTERS * 8:
                raise MeshError(f"ClusterCut.enqueue: the counters buffer needs {N_COUNTERS * 8} bytes, has {counters.size}")
        q = cl_device().queue
        # the camera record goes by value with each launch: no host write to wait on per frame
        cc = ref.cut_camera(camera, threshold_px)
        events = []
        if reset:
            events.append(cl.enqueue_fill_buffer(q, counters, np.uint64(0), 0, N_COUNTERS * 8))
        mode = np.uint32((FRUSTUM if cull_frustum else 0) | (BACKFACE if cull_backface else 0))
        arrays, k = dev.arrays, self._kernel
        for mesh, i0, ni in dev.instances.batches:
            c0, nc = (int(x) for x in arrays.ranges[mesh])
            if nc == 0 or ni == 0:
                continue
            k.set_args(dev.clusters, np.uint32(c0), np.uint32(nc), np.uint32(i0), dev.inst_f, dev.inst_u,
                       dev.scales, dev.weights, cc, mode, buf, np.uint32(capacity), counters)
            groups = -(-nc // CUT_LOCAL)
            events.append(launch(q, k.k, (groups * CUT_LOCAL, int(ni)), (CUT_LOCAL, 1)))
        self.events = events
        return events

    def select(self, dev: DeviceMeshes, camera, threshold_px, selection: Selection | None = None,
               cull_frustum: bool = True, cull_backface: bool = True) -> tuple[np.ndarray, dict]:
        """The cut, waited for: (pairs uint32 [n, 2] sorted by instance then cluster, counters
        dict), growing ``selection`` (a new one if None) and cutting again until it fits."""
        selection = selection or Selection()
        while True:
            self.enqueue(dev, camera, threshold_px, selection, cull_frustum=cull_frustum, cull_backface=cull_backface)
            counts = selection.read_counters()
            if not selection.grow():
                break
        pairs = selection.read_pairs(counts["selected"])
        return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))], counts

    def device_ms(self) -> float:
        """Device milliseconds of the last enqueued cut (waits for it)."""
        return events_ms(self.events)
