"""The OpenCL mesh rasterizer (kernels/meshlod/raster.cl): the triangles of the clusters the cut
selected, drawn with 64-bit atom_min into the shared key buffers (paramlod.renderers.targets
KeyBuffer), so meshes composite by depth with parametric objects and surfels, and a KeyBuffer ss
times the frame's size gives them the points variant's supersampling.

Driven by the "meshlets" renderer (paramlod.pipeline through the registry) after the cut, in the
same enqueue: ``enqueue`` reads the cut's selection count on the device (no wait), ``collect``
enqueues the copy of the counters, and after the frame's one wait ``grow`` says whether the
large-triangle list overflowed (it has grown; draw the frame again) and ``stats`` reads the
counters. numpy twin: paramlod.meshlod.raster_reference (the same keys, bit for bit).

A multi-view frame gives a paramlod.core.views.Views, a KeyBuffer of as many layers and the cut's
view masks (paramlod.meshlod.cut.Selection.masks): each cluster is drawn into the layers of the
views its mask names, with that view's clipping and triangle setup.
"""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from paramlod.core.layouts import CAMERA, CAMERA_FLOATS, CLUSTER, RASTER_COUNTER, camera_record
from paramlod.core.views import Views
from paramlod.device.context import cl_device
from paramlod.device.programs import build, launch
from paramlod.errors import MeshError
from paramlod.meshlod.cut import MASK_BYTES, DeviceRecords
from paramlod.meshlod.raster_reference import GUARD_PIXELS, SUBPIXEL_BITS
from paramlod.renderers.shading import LIGHT

# the kernel's counters (RS_* of the prelude), one ulong each, then one spare
COUNTERS = tuple(f.name for f in RASTER_COUNTER.fields if f.name != "spare")
COLOR_BY = {"material": 0, "cluster": 1, "level": 2}
LOCAL = CLUSTER.constant("CLUSTER_MAX_TRIANGLES")   # raster_clusters: one work-item per triangle
LARGE_LOCAL = 64                                     # raster_large: work-items over one triangle's pixels
EXACT_DIVISION = ("-cl-fp32-correctly-rounded-divide-sqrt",)   # the twin's divisions and square roots


class MeshRaster:
    """Rasterizes a cut's selection into a KeyBuffer.

    ``large_pixels``: fan triangles whose clamped bounding box has more pixels go to the large
    list, drawn by a work-group each (``large_capacity`` entries of 16 bytes; grown on overflow).
    Measured with the 100k-triangle bunny at 1920x1080: 64 sends 13k triangles there and costs
    +8% on an H200 and +30% on PoCL (2 cores) against 256; 1024 is no faster than 256.
    ``groups``: persistent work-groups of raster_clusters (default: by the device's compute units).
    """

    def __init__(self, large_pixels: int = 256, large_capacity: int = 4096, groups: int | None = None):
        dev = cl_device()
        if int(large_pixels) < 1 or int(large_capacity) < 1:
            raise MeshError(f"MeshRaster: large_pixels ({large_pixels}) and large_capacity ({large_capacity}) "
                            "must be at least 1")
        self.large_pixels, self.large_capacity = int(large_pixels), int(large_capacity)
        prog = build(["meshlod/raster.cl"], defines={"RS_SUBPIXEL_BITS": SUBPIXEL_BITS,
                                                     "RS_GUARD_PIXELS": GUARD_PIXELS,
                                                     "RS_LARGE_LOCAL": LARGE_LOCAL,
                                                     "PL_EXACT_VECTORS": 1}, options=EXACT_DIVISION)
        # own kernel objects: arguments are set only when they change (see enqueue)
        self.k_clusters = cl.Kernel(prog, "raster_clusters")
        self.k_large = cl.Kernel(prog, "raster_large")
        self._bound = None
        cu = dev.device.max_compute_units
        # GPU: a few resident groups per compute unit; CPU (PoCL runs a group on one thread):
        # enough groups per core that clusters of uneven cost still balance
        self.groups = int(groups) if groups else cu * (16 if dev.is_gpu else 8)
        self.large_groups = cu * (16 if dev.is_gpu else 4)
        ctx = dev.context
        self.counters = cl.Buffer(ctx, cl.mem_flags.READ_WRITE, 8 * RASTER_COUNTER.length)
        self._counts = np.zeros(RASTER_COUNTER.length, np.uint64)
        self.large = cl.Buffer(ctx, cl.mem_flags.READ_WRITE, 16 * self.large_capacity)
        self._cams, self._light = DeviceRecords(), DeviceRecords()   # written each frame, no wait
        self.events = ()

    def _camera(self, camera, keys) -> cl.Buffer:
        """The device buffer of the camera records, one per layer of ``keys`` (uploaded from a
        Camera, a Views or records)."""
        if isinstance(camera, cl.Buffer):
            return camera
        if isinstance(camera, Views):
            rec = camera.records()
        else:
            rec = camera_record(camera) if hasattr(camera, "view") else np.asarray(camera, np.float32).reshape(-1)
        if rec.size % CAMERA_FLOATS or rec.size // CAMERA_FLOATS != keys.layers:
            raise MeshError(f"MeshRaster: the key buffer has {keys.layers} layer(s): it takes as many camera records "
                            f"of {CAMERA_FLOATS} floats (paramlod.core.layouts.camera_record), got {rec.size} floats")
        per_view = rec.reshape(keys.layers, CAMERA_FLOATS)
        sizes = {(int(r[CAMERA.offset("w")]), int(r[CAMERA.offset("h")])) for r in per_view}
        if sizes != {(keys.width, keys.height)}:
            got = ", ".join(f"{w}x{h}" for w, h in sorted(sizes))
            raise MeshError(f"MeshRaster: the camera is {got} but the key buffer is "
                            f"{keys.width}x{keys.height}; draw with a camera of the key buffer's size "
                            "(camera.with_size)")
        return self._cams.write(rec)

    def enqueue(self, keys, camera, dev, selection, capacity: int, cut_counters, light=None,
                color_by: int = 0, masks: cl.Buffer | None = None) -> list:
        """Enqueue the raster of the selection (no wait); returns the kernels' events.

        ``keys``: the KeyBuffer; ``camera``: a Camera, its record or a device buffer holding it
        (then of the keys' size), or for a KeyBuffer of N layers a Views of N cameras (or N
        records one after another); ``dev``: the scene's DeviceMeshes; ``selection``: device buffer
        of uint2 (instance, cluster) pairs with room for ``capacity``; ``cut_counters``: the cut's
        ulong counters, [0] the selected count (read on the device, at most ``capacity`` drawn);
        ``light``: the light record (paramlod.renderers.shading.LIGHT) or a buffer holding it;
        ``color_by``: 0 material, 1 a colour per cluster, 2 per LOD level (or those names);
        ``masks``: with several layers, the pairs' view masks (a ulong each, bit v: drawn into
        layer v; Selection.masks of a multi-view cut). Each instance draws the share of its
        pixels that ``dev.weights`` gives it (the hand-off dither; DeviceMeshes.set_weights, all 1
        by default)."""
        color_by = COLOR_BY.get(color_by, color_by)
        if color_by not in (0, 1, 2):
            raise MeshError(f"color_by must be 0 / 'material', 1 / 'cluster' or 2 / 'level', got {color_by!r}")
        q = cl_device().queue
        capacity = max(int(capacity), 0)
        n_views = keys.layers
        if n_views > 1 and (not isinstance(masks, cl.Buffer) or masks.size < capacity * MASK_BYTES):
            raise MeshError(f"MeshRaster: a key buffer of {n_views} layers needs the cut's view masks, a device buffer "
                            f"of {MASK_BYTES} bytes per pair (Selection.masks)")
        cam_buf = self._camera(camera, keys)
        if isinstance(light, cl.Buffer):
            light_buf = light
        else:
            light_host = np.ascontiguousarray(LIGHT if light is None else light, np.float32)
            if light_host.shape != (4,):
                raise MeshError(f"MeshRaster: the light record has 4 floats (towards the light, ambient), "
                                f"got shape {light_host.shape}")
            light_buf = self._light.write(light_host)
        cl.enqueue_fill_buffer(q, self.counters, np.uint64(0), 0, 8 * RASTER_COUNTER.length)
        masks = selection if n_views == 1 else masks   # one view: not read
        geometry = (dev.vertices, dev.normals, dev.triangles, dev.clusters, dev.inst_f, dev.inst_u, dev.materials,
                    dev.weights)
        args = (geometry, selection, masks, capacity, cut_counters, cam_buf, n_views, light_buf, color_by, keys.color,
                keys.aux, self.large, self.large_capacity, self.large_pixels)
        # the same buffers and values frame after frame: converting the arguments each time costs
        # a measurable share of a small frame's Python time
        if args != self._bound:
            self.k_clusters.set_args(*geometry, selection, masks, np.uint32(capacity), cut_counters, cam_buf,
                                     np.uint32(n_views), light_buf, np.uint32(color_by), np.uint32(self.large_pixels),
                                     keys.color, keys.aux, self.large, np.uint32(self.large_capacity), self.counters)
            self.k_large.set_args(*geometry, cam_buf, light_buf, np.uint32(color_by), keys.color, keys.aux,
                                  self.large, np.uint32(self.large_capacity), self.counters)
            self._bound = args
        groups = max(1, min(self.groups, capacity))
        self.events = (launch(q, self.k_clusters, (groups * LOCAL,), (LOCAL,)),
                       launch(q, self.k_large, (self.large_groups * LARGE_LOCAL,), (LARGE_LOCAL,)))
        return list(self.events)

    def collect(self):
        """Enqueue the copy of the counters (read after the frame's wait by ``stats``)."""
        cl.enqueue_copy(cl_device().queue, self._counts, self.counters, is_blocking=False)

    def grow(self) -> bool:
        """After the frame's wait (and ``collect``): True if the large list overflowed; it has
        grown to hold this frame's large triangles with room to spare, so draw the frame again."""
        need = int(self._counts[RASTER_COUNTER.offset("large")])
        if need <= self.large_capacity:
            return False
        self.large_capacity = 1 << int(np.ceil(np.log2(need * 1.25)))
        self.large = cl.Buffer(cl_device().context, cl.mem_flags.READ_WRITE, 16 * self.large_capacity)
        self._bound = None
        return True

    def counts(self) -> dict:
        """The last frame's counters (COUNTERS), as collected."""
        return {k: int(v) for k, v in zip(COUNTERS, self._counts)}

    def device_ms(self) -> dict:
        """Device milliseconds of the last frame's two kernels (after its wait)."""
        if not self.events:
            return {"raster": 0.0, "raster_large": 0.0}
        small, large = self.events
        return {"raster": (small.profile.end - small.profile.start) * 1e-6,
                "raster_large": (large.profile.end - large.profile.start) * 1e-6}

    def stats(self) -> dict:
        """Counters, the large list's capacity and device times of the last frame (after its wait)."""
        return {**self.counts(), "large_capacity": self.large_capacity, "ms": self.device_ms()}
