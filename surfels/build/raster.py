"""Mesh G-buffers in OpenCL (kernels/surfels/surfels_raster.cl): every view of the triangle soup
rasterized into one key buffer with 64-bit atom_min, then resolved per pixel. numpy twin:
raster_reference (the same keys, bit for bit).

On the 2-core development machine (PoCL) the 16 views of the 100k-triangle bunny take about
0.06 s at 128 px and 0.1 s at 512 px, where Mesa's llvmpipe drew them in 0.35 and 0.45 s
(its triangle setup runs on one thread per draw). Not measured on a GPU yet.
A work-item walks its triangle's whole bounding box, so a mesh of few triangles, each covering
much of a view, rasterizes serially on a GPU; scans and CAD meshes at the sampler's resolutions
stay fast.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from paramlod.device.context import cl_device
from paramlod.device.programs import build
from paramlod.errors import SurfelError
from paramlod.surfels.build.raster_reference import SUBPIXEL_BITS, view_matrices
from paramlod.surfels.build.sources import TriangleSoup
from paramlod.surfels.build.views import ViewSet

LOCAL = 64   # work-items per group of both kernels
CHUNK_BYTES = 256 << 20   # the largest buffer (positions, 16 bytes a pixel) of the views rasterized at once
EXACT_DIVISION = ("-cl-fp32-correctly-rounded-divide-sqrt",)   # the twin's divisions


def _round_up(n: int, m: int) -> int:
    return -(-n // m) * m


class _Raster:
    """The soup's corners and the views' matrices on the device, the program, and the keys of
    gbuffer_raster (enqueued, not waited for)."""

    def __init__(self, soup: TriangleSoup, views: ViewSet):
        import pyopencl as cl

        f, k, res = soup.face_count, views.count, views.resolution
        if f >= 0xFFFFFFFF:
            raise SurfelError(f"mesh '{soup.name}' has {f} triangles; the G-buffer keys hold at most {0xFFFFFFFE}")
        dev = cl_device()
        self.ctx, self.q = dev.context, dev.queue
        self.prog = build(["surfels/surfels_raster.cl"], defines={"SR_SUBPIXEL_BITS": SUBPIXEL_BITS},
                          options=EXACT_DIVISION)
        self.n_pix = k * res * res
        self.corners = self.upload(soup.positions)
        self.mats = self.upload(view_matrices(views))
        self.keys = cl.Buffer(self.ctx, cl.mem_flags.READ_WRITE, self.n_pix * 8)
        cl.enqueue_fill_buffer(self.q, self.keys, np.uint64(0xFFFFFFFFFFFFFFFF), 0, self.n_pix * 8)
        cl.Kernel(self.prog, "gbuffer_raster")(self.q, (_round_up(f, LOCAL), k), (LOCAL, 1), self.corners,
                                               np.uint32(f), self.mats, np.uint32(res), self.keys)

    def upload(self, a: np.ndarray):
        import pyopencl as cl

        return cl.Buffer(self.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                         hostbuf=np.ascontiguousarray(a, np.float32))


def gbuffer_keys(soup: TriangleSoup, views: ViewSet) -> np.ndarray:
    """uint64 (K, R, R): depth bits << 32 | triangle of every covered pixel centre, all ones
    elsewhere (twin: raster_reference.raster_keys)."""
    import pyopencl as cl

    r = _Raster(soup, views)
    res = views.resolution
    keys = np.empty((views.count, res, res), np.uint64)
    cl.enqueue_copy(r.q, keys, r.keys)
    return keys


def gbuffer_arrays(soup: TriangleSoup, views: ViewSet):
    """(position (K, R, R, 4), normal (K, R, R, 3), colour (K, R, R, 4)) of the soup in the views,
    as GBuffer holds them (twin: raster_reference.resolve of the keys). Views go to the device a
    few at a time, so that no buffer outgrows CHUNK_BYTES."""
    import pyopencl as cl

    k, res = views.count, views.resolution
    arrays = (np.empty((k, res, res, 4), np.float32), np.empty((k, res, res, 3), np.float32),
              np.empty((k, res, res, 4), np.float32))
    per = max(1, min(CHUNK_BYTES, cl_device().device.max_mem_alloc_size) // (res * res * 16))
    for first in range(0, k, per):
        part = slice(first, min(k, first + per))
        chunk = replace(views, directions=views.directions[part], rights=views.rights[part], ups=views.ups[part])
        r = _Raster(soup, chunk)
        # the device writes into the host's arrays where it can (CPU devices: no second copy)
        host = [a[part] for a in arrays]
        outs = [cl.Buffer(r.ctx, cl.mem_flags.WRITE_ONLY | cl.mem_flags.USE_HOST_PTR, hostbuf=a) for a in host]
        cl.Kernel(r.prog, "gbuffer_resolve")(r.q, (_round_up(r.n_pix, LOCAL),), (LOCAL,), r.keys,
                                             np.uint32(r.n_pix), np.uint32(res), r.mats,
                                             r.upload(chunk.directions), r.corners, r.upload(soup.normals),
                                             r.upload(soup.colors), *outs)
        for a, b in zip(host, outs):
            cl.enqueue_copy(r.q, a, b)
    return arrays
