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
import pyopencl as cl

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
    """The program and the soup's corners on the device, uploaded once; ``keys`` enqueues
    gbuffer_raster for some views (not waited for)."""

    def __init__(self, soup: TriangleSoup):
        if soup.face_count >= 0xFFFFFFFF:
            raise SurfelError(f"mesh '{soup.name}' has {soup.face_count} triangles; the G-buffer keys hold at most "
                              f"{0xFFFFFFFE}")
        dev = cl_device()
        self.ctx, self.q = dev.context, dev.queue
        self.prog = build(["surfels/surfels_raster.cl"], defines={"SR_SUBPIXEL_BITS": SUBPIXEL_BITS},
                          options=EXACT_DIVISION)
        self.faces = soup.face_count
        self.corners = self.upload(soup.positions)

    def upload(self, a: np.ndarray) -> cl.Buffer:
        return cl_device().copy_of(np.ascontiguousarray(a, np.float32))

    def keys(self, views: ViewSet) -> tuple[cl.Buffer, cl.Buffer]:
        """(the keys of ``views``, their matrices on the device)."""
        k, res = views.count, views.resolution
        mats = self.upload(view_matrices(views))
        keys = cl.Buffer(self.ctx, cl.mem_flags.READ_WRITE, k * res * res * 8)
        cl.enqueue_fill_buffer(self.q, keys, np.uint64(0xFFFFFFFFFFFFFFFF), 0, k * res * res * 8)
        cl.Kernel(self.prog, "gbuffer_raster")(self.q, (_round_up(self.faces, LOCAL), k), (LOCAL, 1), self.corners,
                                               np.uint32(self.faces), mats, np.uint32(res), keys)
        return keys, mats


def gbuffer_keys(soup: TriangleSoup, views: ViewSet) -> np.ndarray:
    """uint64 (K, R, R): depth bits << 32 | triangle of every covered pixel centre, all ones
    elsewhere (twin: raster_reference.raster_keys)."""
    r = _Raster(soup)
    keys = np.empty((views.count, views.resolution, views.resolution), np.uint64)
    cl.enqueue_copy(r.q, keys, r.keys(views)[0])
    return keys


def gbuffer_arrays(soup: TriangleSoup, views: ViewSet):
    """(position (K, R, R, 4), normal (K, R, R, 3), colour (K, R, R, 4)) of the soup in the views,
    as GBuffer holds them (twin: raster_reference.resolve of the keys). Views go to the device a
    few at a time, so that no buffer outgrows CHUNK_BYTES."""
    k, res = views.count, views.resolution
    arrays = (np.empty((k, res, res, 4), np.float32), np.empty((k, res, res, 3), np.float32),
              np.empty((k, res, res, 4), np.float32))
    r = _Raster(soup)
    normals, colors = r.upload(soup.normals), r.upload(soup.colors)
    resolve = cl.Kernel(r.prog, "gbuffer_resolve")
    per = max(1, min(CHUNK_BYTES, cl_device().device.max_mem_alloc_size) // (res * res * 16))
    for first in range(0, k, per):
        part = slice(first, min(k, first + per))
        chunk = replace(views, directions=views.directions[part], rights=views.rights[part], ups=views.ups[part])
        keys, mats = r.keys(chunk)
        n_pix = chunk.count * res * res
        # the device writes into the host's arrays where it can (CPU devices: no second copy)
        host = [a[part] for a in arrays]
        outs = [cl.Buffer(r.ctx, cl.mem_flags.WRITE_ONLY | cl.mem_flags.USE_HOST_PTR, hostbuf=a) for a in host]
        resolve(r.q, (_round_up(n_pix, LOCAL),), (LOCAL,), keys, np.uint32(n_pix), np.uint32(res), mats,
                r.upload(chunk.directions), r.corners, normals, colors, *outs)
        for a, b in zip(host, outs):
            cl.enqueue_copy(r.q, a, b)
    return arrays
