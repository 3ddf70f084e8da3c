"""The per-frame cull of skinned meshlets on the device (kernels/meshlod/skin_cull.cl): every
meshlet of every skinned mesh is drawn at full detail unless its class's tests (the offline bounds
of paramlod.meshlod.build.skin_bounds) show it outside the frustum or wholly back-facing for the
frame's pose. The rule is in the numpy twin, paramlod.meshlod.skin_cull_reference.

Driven by the mesh renderers (paramlod.meshlod.render) in place of ClusterCut for the skinned
meshes: ``SkinCull(dev, bounds)`` once per scene (uploads the bounds of ``dev.skin.slots``), then
``SkinCull.enqueue(dev_skin, camera, selection, ...)`` each frame after the skinning was given the
same skin matrices (``dev_skin``: the cl.Buffer of the frame's float32 [J, 4, 4] matrices of every
slot, as paramlod.meshlod.skin writes them: ``dev.skin_matrices``). It appends into the same
paramlod.meshlod.cut.Selection as the static cut (same pairs and counters), so MeshRaster and MeshDraw
draw it unchanged; nothing is waited for. ``select`` is the waiting form for tests and tools.
A multi-view frame's cull takes a paramlod.core.views.Views and writes each pair's view mask and the
per-view counters as the static cut does (paramlod.meshlod.cut).
"""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from paramlod.device.context import cl_device
from paramlod.device.programs import events_ms, kernel, launch
from paramlod.errors import MeshError
from paramlod.meshlod import cut_reference as cref
from paramlod.meshlod import skin_cull_reference as ref
from paramlod.meshlod.buffers import DeviceMeshes
from paramlod.core.views import as_views
from paramlod.meshlod.cut import COMMON_DEFINES, EXACT, DeviceRecords, Selection, cut_outputs, collect_sorted, counters_bytes

SC_LOCAL = 64
_DEFINES = {**COMMON_DEFINES, "SC_LOCAL": SC_LOCAL, "SC_SLACK": f"{ref.SLACK!r}f", "CC_EYE": cref.CC_EYE}


class SkinCull:
    """The skinned cull of one scene's uploads: the bounds of each skinned slot on the device."""

    def __init__(self, dev: DeviceMeshes, bounds):
        slots = dev.skin.slots
        bounds = list(bounds)
        if len(bounds) != len(slots):
            raise MeshError(f"skin cull: {len(bounds)} skin bounds given for {len(slots)} skinned meshes")
        self.slots = []
        for s, b in zip(slots, bounds):
            c0, nc = (int(x) for x in dev.arrays.ranges[s.index])
            if nc != len(b.principal):
                raise MeshError(f"skin cull: skinned mesh '{s.mesh.name}' has {nc} meshlets but its bounds "
                                f"have {len(b.principal)}: build them from this mesh (skin_bounds)")
            if len(b.principal) and int(b.principal.max()) >= s.n_joints:
                raise MeshError(f"skin cull: the bounds of '{s.mesh.name}' name joint {int(b.principal.max())}; "
                                f"the mesh has {s.n_joints}")
            self.slots.append((s.index, c0, s.joint_first))
        self.bounds, self.dev = bounds, dev
        sph, con, meta, self.srs, self.first = ref.records(bounds)
        ctx, mf = cl_device().context, cl.mem_flags

        def up(a):
            a = np.ascontiguousarray(a)
            return cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=a if a.nbytes else np.zeros(4, np.uint32))

        self.spheres, self.cones, self.meta = up(sph), up(con), up(meta)
        self.n_joints = dev.skin.n_joints
        # the one-view program knows it has one view (kernels/meshlod/cut_common.cl: CUT_VIEWS)
        self._kernels = {True: kernel("skin_cull", ["meshlod/skin_cull.cl"], {**_DEFINES, "CUT_ONE_VIEW": 1}, EXACT),
                         False: kernel("skin_cull", ["meshlod/skin_cull.cl"], _DEFINES, EXACT)}
        self._records = DeviceRecords()
        self.events: list = []

    def enqueue(self, dev_skin: cl.Buffer, camera, selection, capacity: int | None = None,
                counters: cl.Buffer | None = None, cull_frustum: bool = True, cull_backface: bool = True,
                reset: bool = False, masks: cl.Buffer | None = None) -> list:
        """Enqueue the cull of every instance of every skinned slot for ``camera`` (a Camera or a
        Views) with the frame's skin matrices ``dev_skin``. ``selection``: a Selection, or a
        cl.Buffer of ``capacity`` pairs with ``counters`` (and ``masks`` for several views, as
        ClusterCut.enqueue). ``reset``: zero the counters first (default False: added to the static
        cut's, into one selection). Returns the enqueued events; nothing is waited for."""
        views = as_views(camera)
        n = len(views)
        buf, capacity, counters, masks = cut_outputs("SkinCull.enqueue", selection, capacity, counters, masks, n)
        if not isinstance(dev_skin, cl.Buffer) or dev_skin.size < self.n_joints * 64:
            raise MeshError(f"SkinCull.enqueue: the skin matrices must be a device buffer of {self.n_joints} "
                            "float32 4x4 matrices (dev.skin_matrices)")
        q = cl_device().queue
        cc = cref.cut_cameras(views, 0.0)
        cams = self._records.write(cc) if n > 1 else buf   # view 0's record goes by value (cut.py)
        events = []
        if reset:
            events.append(cl.enqueue_fill_buffer(q, counters, np.uint64(0), 0, counters_bytes(n)))
        mode = np.uint32((1 if cull_frustum else 0) | (2 if cull_backface else 0))
        dev, k = self.dev, self._kernels[n == 1]
        for (mesh, c0, j0), sr, first in zip(self.slots, self.srs, self.first):
            nc = int(dev.arrays.ranges[mesh][1])
            for m, i0, ni in dev.instances.batches:
                if m != mesh or nc == 0 or ni == 0:
                    continue
                # a batch with a two-sided material shows its back faces: frustum test only (mode bit 2)
                batch_mode = mode if ref.one_sided(dev.instances, i0, ni) else mode & np.uint32(1)
                k.set_args(self.spheres, self.cones, self.meta, np.uint32(first), np.uint32(nc), np.uint32(c0),
                           np.uint32(i0), np.uint32(j0), np.float32(sr), dev.inst_f, dev.scales, dev.weights,
                           dev_skin, cc[:cref.CC_FLOATS], cams, np.uint32(n), batch_mode, buf, masks,
                           np.uint32(capacity), counters)
                groups = -(-nc // SC_LOCAL)
                events.append(launch(q, k.k, (groups * SC_LOCAL, int(ni)), (SC_LOCAL, 1)))
        self.events = events
        return events

    def select(self, dev_skin: cl.Buffer, camera, selection: Selection | None = None, cull_frustum: bool = True,
               cull_backface: bool = True) -> tuple[np.ndarray, dict]:
        """The cull alone, waited for: (pairs uint32 [n, 2] sorted by instance then cluster, counters)."""
        pairs, _, counts = self.select_views(dev_skin, camera, selection, cull_frustum, cull_backface)
        counts.pop("views")
        return pairs, counts

    def select_views(self, dev_skin: cl.Buffer, camera, selection: Selection | None = None,
                     cull_frustum: bool = True, cull_backface: bool = True) -> tuple[np.ndarray, np.ndarray, dict]:
        """``select`` for a Camera or Views: (pairs, view masks, counters with "views"), as
        skin_cull_reference.select_views."""
        selection = selection or Selection()
        selection.use_views(len(as_views(camera)))
        return collect_sorted(selection, lambda: self.enqueue(dev_skin, camera, selection, cull_frustum=cull_frustum,
                                                               cull_backface=cull_backface, reset=True))

    def device_ms(self) -> float:
        """Device milliseconds of the last enqueued cull (waits for it)."""
        return events_ms(self.events)
