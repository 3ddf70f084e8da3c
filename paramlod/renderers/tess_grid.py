"""The grid tessellator (``TessSettings.tessellator = "grid"``, kernels/tess/grid.cl): the render
patches tessellated in OpenCL into an indexed triangle list that the tessellation renderer draws
with a plain vertex stage instead of GL's tessellation stages.

Why: Mesa's llvmpipe runs the tessellation control and evaluation stages on one thread, where
the function is evaluated for every generated vertex; the OpenCL device (PoCL: every core, the
function code vectorized) evaluates them faster, and llvmpipe then only rasterizes triangles.
``tessellator = "auto"`` picks it on llvmpipe (measured in docs/tessellation.md).

The levels and the triangles: see kernels/tess/grid.cl. The vertices come back to the host (the
OpenCL and GL devices share no memory), as the render list does. Twin:
``paramlod.renderers.tess_grid_reference``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyopencl as cl
import pyopencl.cltypes as cltypes

from paramlod.core.layouts import GRID_VERTEX
from paramlod.device.context import cl_device
from paramlod.device.programs import launch
from paramlod.errors import SceneError
from paramlod.function.programs import POLY_TRIG, build, sample_run
from paramlod.lod.patches import RENDER_DTYPE
from paramlod.lod.uploads import SceneBuffers
from paramlod.renderers.shading import LIGHT

# the columns of a patch's levels record (grid.cl's int8)
LEVELS = ("n0", "n1", "n2", "n3", "a", "b", "vertices", "triangles")
VERTICES, TRIANGLES = LEVELS.index("vertices"), LEVELS.index("triangles")
# most vertices one list may make (32 bytes each: 2 GiB); more is an error that names the way out
MAX_VERTICES = 1 << 26
LOCAL_SIZE = 64
# grid_levels' work-group on CPU devices: a patch's levels take 80-128 evaluations, and a few
# hundred patches in groups of 64 leave a core idle for the last group (the close-up torus of the
# peers bench, 141 patches, 2-core AMD EPYC, PoCL: 0.9-1.0 ms in groups of 64, 0.65-0.69 in 16)
CPU_LEVELS_LOCAL = 16


@dataclass
class Grid:
    """One list's triangles: ``vertices`` (GRID_VERTEX.dtype), ``indices`` (uint32, 3 a
    triangle), ``levels`` (int32, a LEVELS row per patch), ``nan_vertices``."""
    vertices: np.ndarray
    indices: np.ndarray
    levels: np.ndarray
    nan_vertices: int


def level_rule(settings, threshold) -> tuple[tuple, int]:
    """(rule, kind) as grid_levels takes them: the fixed (inner, outer) levels (kind 0), (L inner,
    L outer, t_u, t_v) of the adaptive ones (1), or the chord error (2)."""
    if settings.mode == "fixed":
        inner, outer = (float(x) for x in settings.levels)
        return (inner, outer, 0.0, 0.0), 0
    if settings.mode == "chord":
        return (float(settings.chord_px), 0.0, 0.0, 0.0), 2
    L = float(settings.base_level)
    return (L, L, float(threshold[0]), float(threshold[1])), 1


def starts(counts: np.ndarray) -> np.ndarray:
    """uint32 first index of each patch's run and the total, of per-patch ``counts``."""
    out = np.zeros(len(counts) + 1, np.int64)
    np.cumsum(counts, out=out[1:])
    return out.astype(np.uint32)


class GridTessellator:
    """The grid tessellator's program and the scene's device copy, for one set of functions."""

    def __init__(self, functions):
        dev = cl_device()
        # on a CPU device the function code gets inline sin/cos, as the point renderer's does
        self.run = sample_run(dev.is_gpu)   # grid_vertices visits down a grid row or column
        self.levels_local = LOCAL_SIZE if dev.is_gpu else CPU_LEVELS_LOCAL
        defines = {"PL_RUN": self.run}
        if not dev.is_gpu:
            defines[POLY_TRIG] = 1
        program = build(["tess/grid.cl"], functions, defines)
        self._levels = cl.Kernel(program, "grid_levels")
        self._vertices = cl.Kernel(program, "grid_vertices")
        self._indices = cl.Kernel(program, "grid_indices")
        self.buffers = SceneBuffers(LIGHT)

    def tessellate(self, records: np.ndarray, scene, camera, settings, threshold, levels=None,
                   overlap_px: float = 0.0) -> Grid:
        """The triangles of the render ``records`` (RENDER_DTYPE) of ``scene`` seen by ``camera``,
        with the levels ``settings`` (TessSettings) and ``threshold`` (t_u, t_v in output pixels)
        give, or with the given ``levels`` records (int32 (n, 8), LEVELS; tests); ``overlap_px``:
        a hybrid tier's widening in output pixels where its targets are carried (grid.cl grid_range)."""
        dev = cl_device()
        q = dev.queue
        d = self.buffers.upload(scene, camera)
        n = len(records)
        if not n:
            return Grid(np.zeros(0, GRID_VERTEX.dtype), np.zeros(0, np.uint32), np.zeros((0, len(LEVELS)), np.int32), 0)
        # inputs copied as their buffers are made, the outputs read with one wait: on PoCL each
        # blocking transfer waits for its threads (the close-up torus of the peers bench, 141
        # patches, 2-core AMD EPYC: 2.7-2.9 -> 1.8-2.1 ms, with CPU_LEVELS_LOCAL)
        patches = dev.copy_of(np.ascontiguousarray(records, RENDER_DTYPE))
        if levels is None:
            levels = cl.Buffer(dev.context, cl.mem_flags.READ_WRITE, len(LEVELS) * 4 * n)
            rule, kind = level_rule(settings, threshold)
            self._levels.set_args(patches, np.uint32(n), *d["inst"], d["cam"], cltypes.make_float4(*rule),
                                  cltypes.make_float2(float(settings.l_min), float(settings.l_max)),
                                  np.uint32(kind), np.uint32(settings.inner_levels_for(False) == "segment"), levels)
            launch(q, self._levels, (-(-n // self.levels_local) * self.levels_local,), (self.levels_local,))
            lv = np.empty((n, len(LEVELS)), np.int32)
            cl.enqueue_copy(q, lv, levels)
        else:
            lv = np.ascontiguousarray(levels, np.int32).reshape(n, len(LEVELS))
            levels = dev.copy_of(lv)
        n_vertices, n_triangles = int(lv[:, VERTICES].sum()), int(lv[:, TRIANGLES].sum())
        if n_vertices > MAX_VERTICES:
            raise SceneError(f"the grid tessellator would make {n_vertices:,} vertices, more than "
                             f"its limit of {MAX_VERTICES:,} (paramlod.renderers.tess_grid.MAX_VERTICES); raise "
                             "the LOD threshold, lower tess l_max, or use tessellator 'hardware'")
        vert_start = dev.copy_of(starts(lv[:, VERTICES]))
        tri_start = dev.copy_of(starts(lv[:, TRIANGLES]))
        vertices = np.empty(n_vertices, GRID_VERTEX.dtype)
        indices = np.empty(3 * n_triangles, np.uint32)
        nan = np.zeros(1, np.uint32)
        vertices_d = cl.Buffer(dev.context, cl.mem_flags.WRITE_ONLY, max(vertices.nbytes, 4))
        indices_d = cl.Buffer(dev.context, cl.mem_flags.WRITE_ONLY, max(indices.nbytes, 4))
        nan_d = dev.copy_of(nan, writable=True)
        self._vertices.set_args(patches, np.uint32(n), levels, vert_start, *d["inst"],
                                np.float32(settings.overlap), np.float32(overlap_px), vertices_d, nan_d)
        items = -(-n_vertices // self.run)
        launch(q, self._vertices, (-(-items // LOCAL_SIZE) * LOCAL_SIZE,), (LOCAL_SIZE,))
        self._indices.set_args(np.uint32(n), levels, vert_start, tri_start, indices_d)
        launch(q, self._indices, (-(-n // LOCAL_SIZE) * LOCAL_SIZE,), (LOCAL_SIZE,))
        cl.enqueue_copy(q, vertices, vertices_d, is_blocking=False)
        cl.enqueue_copy(q, indices, indices_d, is_blocking=False)
        cl.enqueue_copy(q, nan, nan_d)   # in order: the one wait, for all three
        return Grid(vertices, indices, lv, int(nan[0]))
