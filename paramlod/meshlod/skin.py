"""Linear blend skinning on the device (kernels/meshlod/skin.cl): each frame, the posed vertices
and normals of every skinned object are written into the scene's vertex and normal buffers
(paramlod.meshlod.buffers.DeviceMeshes), which the cut, the OpenCL raster and the OpenGL draw read
as they read a static mesh's.

Driven by the mesh renderers (paramlod.meshlod.render): ``Skinning.enqueue(dev, records)`` before
the cut, with the frame's skin matrices of every skinned slot (``pose_records``), nothing waited
for (the queue is in order). ``Skinning.pose`` is the waiting form for tests and tools. Its numpy
twin is paramlod.meshlod.skin_reference (the formulas are there); both agree bit for bit.
"""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from paramlod.device.context import cl_device
from paramlod.device.programs import events_ms, kernel, launch
from paramlod.errors import MeshError
from paramlod.meshlod.buffers import DeviceMeshes
from paramlod.meshlod.skin_reference import skin_records

SKIN_LOCAL = 64
EXACT = ("-cl-fp32-correctly-rounded-divide-sqrt",)   # so the twin's sqrt and division match


def pose_records(dev: DeviceMeshes, times) -> np.ndarray:
    """float32 [J, 4, 4]: the skin matrices of every skinned slot of ``dev`` (``dev.skin.slots``,
    in order) at its time in ``times`` (one float per slot), concatenated as the joints were."""
    slots = dev.skin.slots
    times = list(times)
    if len(times) != len(slots):
        raise MeshError(f"skinning: {len(times)} times given for {len(slots)} skinned objects")
    if not slots:
        return np.zeros((0, 4, 4), np.float32)
    return skin_records(np.concatenate([s.mesh.rig.skin_matrices(float(t)) for s, t in zip(slots, times)]))


class Skinning:
    """The skinning kernel, bound per launch (one per renderer state)."""

    def __init__(self):
        self._kernel = kernel("skin_vertices", ["meshlod/skin.cl"], {}, EXACT)
        self.events: list = []
        self._host = None   # the last records sent: kept alive while the copy may be in flight

    def enqueue(self, dev: DeviceMeshes, records) -> list:
        """Send ``records`` (float32 [J, 4, 4], pose_records) and enqueue the skinning of every
        skinned slot of ``dev`` into its vertex and normal buffers. Returns the events (the
        matrices' copy, one kernel per slot); nothing is waited for."""
        sk = dev.skin
        if not sk.slots:
            self.events = []
            return []
        r = np.ascontiguousarray(records, np.float32)
        if r.shape != (sk.n_joints, 4, 4):
            raise MeshError(f"skinning: {r.shape} skin matrices given for the scene's {sk.n_joints} joints "
                            "(pose_records makes them)")
        q = cl_device().queue
        # a new host array each frame: the previous one may still be in flight
        self._host = r.copy()
        events = [cl.enqueue_copy(q, dev.skin_matrices, self._host, is_blocking=False)]
        k = self._kernel
        for s in sk.slots:
            k.set_args(dev.bind_v, dev.bind_n, dev.joints, dev.joint_weights, np.uint32(s.src_first),
                       np.uint32(s.count), dev.skin_matrices, dev.vertices, dev.normals, np.uint32(s.dst_first))
            events.append(launch(q, k.k, (-(-s.count // SKIN_LOCAL) * SKIN_LOCAL,), (SKIN_LOCAL,)))
        self.events = events
        return events

    def pose(self, dev: DeviceMeshes, records) -> tuple[np.ndarray, np.ndarray]:
        """Skin now and read back the scene's whole vertex and normal buffers (float32 [V, 4] each)."""
        self.enqueue(dev, records)
        return read_vertices(dev)

    def device_ms(self) -> float:
        """Device milliseconds of the last enqueued skinning (waits for it)."""
        return events_ms(self.events)


def read_vertices(dev: DeviceMeshes, first: int = 0, count: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, normals) float32 [count, 4] read back from the device from vertex ``first`` (waits)."""
    n = len(dev.arrays.vertices) - first if count is None else int(count)
    v, nn = np.empty((n, 4), np.float32), np.empty((n, 4), np.float32)
    if n:
        q = cl_device().queue
        cl.enqueue_copy(q, v, dev.vertices, src_offset=first * 16, is_blocking=False)
        cl.enqueue_copy(q, nn, dev.normals, src_offset=first * 16, is_blocking=True)
    return v, nn
