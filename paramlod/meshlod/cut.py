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

Multi-view frames: ``enqueue`` takes a paramlod.core.views.Views for its camera; the Selection then
also holds each pair's view mask (``masks``, bit v: drawn into view v) and per-view counters
(``view_counts``), which the rasterizer and the GL draw read to amplify each cluster into the views
that see it. With one view nothing of this is written and the kernel is the one-view cut.
"""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from paramlod.core.layouts import CUT_COUNTER
from paramlod.core.views import MAX_VIEWS, as_views
from paramlod.device.context import cl_device
from paramlod.device.programs import events_ms, kernel, launch
from paramlod.errors import CapacityError, MeshError
from paramlod.meshlod import cut_reference as ref
from paramlod.meshlod.buffers import ONE_SIDED, SIMILAR, DeviceMeshes

CUT_LOCAL = 64          # work-items per group: one local reduction and one global atomic per counter
N_COUNTERS = CUT_COUNTER.length   # ulong counters of the contract (past COUNTERS, spare)
PAIR_BYTES = 8          # one uint2 (instance, cluster)
MASK_BYTES = 8          # one ulong view mask per pair (multi-view cuts)
FRUSTUM, BACKFACE = 1, 2
EXACT = ("-cl-fp32-correctly-rounded-divide-sqrt",)   # so the numpy twin's division and sqrt match
# what both cut kernels (cut.cl, skin_cull.cl) read of the cut camera records and the counters
COMMON_DEFINES = {"CC_PLANES": ref.CC_PLANES, "CC_FLOATS": ref.CC_FLOATS,
                  "CUT_MAX_VIEWS": MAX_VIEWS}
_DEFINES = {**COMMON_DEFINES, "CUT_LOCAL": CUT_LOCAL, "CUT_CONES": f"{SIMILAR | ONE_SIDED}u", "CC_DEPTH": ref.CC_DEPTH,
            "CC_EYE": ref.CC_EYE, "CC_K": ref.CC_K, "CC_WA": ref.CC_WA, "CC_WB": ref.CC_WB,
            "CC_NEAR": ref.CC_NEAR, "CC_T": ref.CC_T}


def _counts(raw: np.ndarray) -> dict:
    return {name: int(raw[k]) for k, name in enumerate(ref.COUNTERS)}


def counters_bytes(n_views: int) -> int:
    """Bytes of a cut's counters for ``n_views`` views (the 8, then 2 per view past one)."""
    return (N_COUNTERS + (2 * n_views if n_views > 1 else 0)) * 8


class DeviceRecords:
    """A device buffer of float32 records written each frame without a wait: the host array and
    the copy's event are kept until the next write (dropping a pending copy's event would wait)."""

    def __init__(self):
        self.buf, self._pending = None, None

    def write(self, records: np.ndarray) -> cl.Buffer:
        host = np.ascontiguousarray(records, np.float32)
        if self.buf is None or self.buf.size < host.nbytes:
            self.buf = cl.Buffer(cl_device().context, cl.mem_flags.READ_ONLY, host.nbytes)
        self._pending = (host, cl.enqueue_copy(cl_device().queue, self.buf, host, is_blocking=False))
        return self.buf


class Selection:
    """The cut's output on the device: ``pairs`` (uint2 (instance, cluster) x ``capacity``) and
    ``counters`` (8 ulong, see kernels/meshlod/cut.cl); for a multi-view cut (``use_views``) also
    ``masks`` (a ulong view mask per pair) and two counters per view after the 8. ``collect``
    enqueues the counters' read-back for the frame's wait; ``counts``, ``view_counts``, ``grow``,
    ``read_pairs`` and ``read_masks`` use it after."""

    def __init__(self, capacity: int = 1 << 14):
        self.capacity, self.pairs, self.masks, self.views = 0, None, None, 1
        self.counters = cl.Buffer(cl_device().context, cl.mem_flags.READ_WRITE, N_COUNTERS * 8)
        self._raw = np.zeros(N_COUNTERS, np.uint64)
        self._alloc(max(1, int(capacity)))

    def _alloc(self, capacity: int) -> None:
        limit = cl_device().device.max_mem_alloc_size // PAIR_BYTES
        if capacity > limit:
            raise CapacityError(f"the mesh cut selected {capacity} clusters; the device holds at most {limit} "
                                "in one buffer: raise the mesh threshold_px or draw fewer instances")
        ctx = cl_device().context
        self.pairs = cl.Buffer(ctx, cl.mem_flags.READ_WRITE, capacity * PAIR_BYTES)
        if self.masks is not None:
            self.masks = cl.Buffer(ctx, cl.mem_flags.READ_WRITE, capacity * MASK_BYTES)
        self.capacity = capacity

    def use_views(self, n_views: int) -> None:
        """Make room for the view masks and per-view counters of an ``n_views``-view cut (nothing
        for one view); the counters then read back are this many views'."""
        n = int(n_views)
        if n > 1 and self.masks is None:
            self.masks = cl.Buffer(cl_device().context, cl.mem_flags.READ_WRITE, self.capacity * MASK_BYTES)
        if counters_bytes(n) > self.counters.size:
            self.counters = cl.Buffer(cl_device().context, cl.mem_flags.READ_WRITE, counters_bytes(MAX_VIEWS))
        if n != self.views:
            self.views, self._raw = n, np.zeros(counters_bytes(n) // 8, np.uint64)

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

    def view_counts(self) -> list:
        """Per view of a multi-view cut, {"clusters", "triangles"} drawn into it (after ``collect``);
        for one view, the selection's own."""
        if self.views == 1:
            c = self.counts()
            return [{"clusters": c["selected"], "triangles": c["triangles"]}]
        per = self._raw[N_COUNTERS:].reshape(self.views, 2)
        return [dict(zip(ref.VIEW_COUNTERS, (int(a), int(b)))) for a, b in per]

    def grow(self, needed: int | None = None) -> bool:
        """Make room for ``needed`` pairs (default: the count last collected); True when the buffer
        grew, so the cut must be enqueued again (its pairs are gone)."""
        need = int(self._raw[CUT_COUNTER.offset("selected")]) if needed is None else int(needed)
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

    def read_masks(self, count: int) -> np.ndarray:
        """The view masks of the first ``count`` pairs (uint64 [count], in ``read_pairs``' order)
        of a multi-view cut; all 1 (view 0) after a one-view cut."""
        n = int(count)
        if n > self.capacity:
            raise MeshError(f"read_masks: {n} masks asked for, the selection holds {self.capacity}")
        if self.views == 1:
            return np.ones(n, np.uint64)
        out = np.empty(n, np.uint64)
        if n:
            cl.enqueue_copy(cl_device().queue, out, self.masks, is_blocking=True)
        return out

    @property
    def nbytes(self) -> int:
        masks = 0 if self.masks is None else self.capacity * MASK_BYTES
        return self.capacity * PAIR_BYTES + masks + self.counters.size


class ClusterCut:
    """The cut's kernel, bound per launch (one per renderer state), and the device buffer its
    camera records are written into each frame."""

    def __init__(self):
        # the one-view program knows it has one view (kernels/meshlod/cut_common.cl: CUT_VIEWS)
        self._kernels = {True: kernel("cluster_cut", ["meshlod/cut.cl"], {**_DEFINES, "CUT_ONE_VIEW": 1}, EXACT),
                         False: kernel("cluster_cut", ["meshlod/cut.cl"], _DEFINES, EXACT)}
        self._records = DeviceRecords()
        self.events: list = []

    def enqueue(self, dev: DeviceMeshes, camera, threshold_px, selection, capacity: int | None = None,
                counters: cl.Buffer | None = None, cull_frustum: bool = True, cull_backface: bool = True,
                reset: bool = True, masks: cl.Buffer | None = None) -> list:
        """Enqueue the cut of every instance of ``dev`` for ``camera`` (a Camera, or a Views: one
        cut for all its views) at ``threshold_px`` pixels (>= 0; 0 draws the original triangles).
        ``selection``: a Selection, or a cl.Buffer of ``capacity`` uint2 pairs with ``counters``
        (8 ulong, 2 more per view for several views) and, for several views, ``masks`` (a ulong
        per pair). ``reset``: zero the counters first (False: add to them, e.g. a second cut into
        one selection). Instances whose hand-off weight (``dev.weights``, DeviceMeshes.set_weights)
        is 0 select nothing. Returns the enqueued events (the counters' reset, one kernel per
        batch); nothing is waited for."""
        views = as_views(camera)
        n = len(views)
        buf, capacity, counters, masks = cut_outputs("ClusterCut.enqueue", selection, capacity, counters, masks, n)
        q = cl_device().queue
        cc = ref.cut_cameras(views, threshold_px)
        # view 0's record goes by value with each launch (all a one-view cut reads: no host write
        # to wait on); several views' records are written to the device too
        cams = self._records.write(cc) if n > 1 else buf
        events = []
        if reset:
            events.append(cl.enqueue_fill_buffer(q, counters, np.uint64(0), 0, counters_bytes(n)))
        mode = np.uint32((FRUSTUM if cull_frustum else 0) | (BACKFACE if cull_backface else 0))
        arrays, k = dev.arrays, self._kernels[n == 1]
        for mesh, i0, ni in dev.instances.batches:
            c0, nc = (int(x) for x in arrays.ranges[mesh])
            if nc == 0 or ni == 0:
                continue
            k.set_args(dev.clusters, np.uint32(c0), np.uint32(nc), np.uint32(i0), dev.inst_f, dev.inst_u,
                       dev.scales, dev.weights, cc[:ref.CC_FLOATS], cams, np.uint32(n), mode, buf, masks,
                       np.uint32(capacity), counters)
            groups = -(-nc // CUT_LOCAL)
            events.append(launch(q, k.k, (groups * CUT_LOCAL, int(ni)), (CUT_LOCAL, 1)))
        self.events = events
        return events

    def select(self, dev: DeviceMeshes, camera, threshold_px, selection: Selection | None = None,
               cull_frustum: bool = True, cull_backface: bool = True) -> tuple[np.ndarray, dict]:
        """The cut, waited for: (pairs uint32 [n, 2] sorted by instance then cluster, counters
        dict), growing ``selection`` (a new one if None) and cutting again until it fits."""
        pairs, _, counts = self.select_views(dev, camera, threshold_px, selection, cull_frustum, cull_backface)
        counts.pop("views")
        return pairs, counts

    def select_views(self, dev: DeviceMeshes, camera, threshold_px, selection: Selection | None = None,
                     cull_frustum: bool = True, cull_backface: bool = True) -> tuple[np.ndarray, np.ndarray, dict]:
        """``select`` for a Camera or Views: (pairs, view masks uint64 [n] in the pairs' order,
        counters with "views": per view {"clusters", "triangles"}), as cut_reference.select_views."""
        selection = selection or Selection()
        selection.use_views(len(as_views(camera)))
        return collect_sorted(selection, lambda: self.enqueue(dev, camera, threshold_px, selection,
                                                               cull_frustum=cull_frustum, cull_backface=cull_backface))

    def device_ms(self) -> float:
        """Device milliseconds of the last enqueued cut (waits for it)."""
        return events_ms(self.events)


def collect_sorted(selection: Selection, enqueue) -> tuple[np.ndarray, np.ndarray, dict]:
    """Run ``enqueue`` (a cut into ``selection``), growing the selection and cutting again until it
    fits; (pairs sorted by instance then cluster, their view masks, counters with "views")."""
    while True:
        enqueue()
        counts = selection.read_counters()
        if not selection.grow():
            break
    n = counts["selected"]
    pairs, masks = selection.read_pairs(n), selection.read_masks(n)
    order = np.lexsort((pairs[:, 1], pairs[:, 0]))
    counts["views"] = selection.view_counts()
    return pairs[order], masks[order], counts


def cut_outputs(what: str, selection, capacity, counters, masks, n_views: int):
    """(pairs buffer, capacity, counters, masks) of a cut into ``selection`` (a Selection, made
    ready for ``n_views``, or a buffer with the rest given), checked; masks is a placeholder for
    one view (the kernel writes none)."""
    if isinstance(selection, Selection):
        selection.use_views(n_views)
        buf, capacity, counters = selection.pairs, selection.capacity, selection.counters
        masks = selection.masks
    else:
        buf = selection
        if capacity is None or counters is None:
            raise MeshError(f"{what}: a selection given as a buffer needs its capacity and counters")
        if int(capacity) < 0 or int(capacity) * PAIR_BYTES > buf.size:
            raise MeshError(f"{what}: capacity {capacity} pairs does not fit the selection buffer "
                            f"of {buf.size} bytes ({PAIR_BYTES} per pair)")
        if counters.size < counters_bytes(n_views):
            raise MeshError(f"{what}: the counters buffer needs {counters_bytes(n_views)} bytes for {n_views} "
                            f"view(s), has {counters.size}")
        if n_views > 1 and (masks is None or masks.size < int(capacity) * MASK_BYTES):
            raise MeshError(f"{what}: a cut of {n_views} views needs a masks buffer of {MASK_BYTES} bytes per pair "
                            f"({int(capacity) * MASK_BYTES} bytes)")
    return buf, capacity, counters, buf if masks is None else masks
