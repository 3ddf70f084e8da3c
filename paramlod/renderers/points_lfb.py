"""Point renderer, local-framebuffer supersampling variant ("points-ssaa", kernels/points_lfb.cl).

The screen is cut into 16x16-pixel tiles. Each render patch is assigned to the tiles its padded
screen box touches (a counting pass, an exclusive scan with pyopencl.scan, a fill pass); then one
work-group per tile point-renders every assigned patch into a ``__local`` framebuffer of 2x2 or
3x3 subsamples per pixel and resolves it: average colour of the covered subsamples, alpha =
coverage, minimum depth, one early-depth atom_min per pixel into the shared KeyBuffer (so other
point producers can write into the same buffers). A tile's list of any length is processed in
chunks of ``chunk`` patches, so no patch is ever skipped. The numpy twin is points_reference.py;
options and statistics are described in docs/points.md.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import time

import pyopencl as cl
import pyopencl.array as cla
from pyopencl.scan import ExclusiveScanKernel

from paramlod.core.layouts import LFB_COUNTER
from paramlod.core.transforms import in_range
from paramlod.device.context import cl_device
from paramlod.errors import CapacityError, DeviceError, SceneError
from paramlod.function.programs import kernel
from paramlod.lod.stage import LodStage
from paramlod.lod.uploads import SceneBuffers
from paramlod.renderers.aa import LFB_MODES, local_framebuffer_ss
from paramlod.renderers.registry import RendererSpec, register_renderer
from paramlod.renderers.sampling import PointSettings, points_cl_defines
from paramlod.renderers.shading import LIGHT
from paramlod.renderers.targets import srgb_device_tables

# the counters of points_lfb.cl (LFB_* of the prelude), in order
LFB_COUNTERS = tuple(f.name for f in LFB_COUNTER.fields)
TILE = 16


@dataclass
class SsaaSettings(PointSettings):
    """PointSettings (density is per subsample here) plus the local-framebuffer options."""
    ss: int = 2                # subsamples per pixel side: 2 (2x2, 32x32 local framebuffer) or 3 (3x3, 48x48)
    margin: float = 1.0        # pixels added to each patch's padded screen box (rounding, curvature)
    # the LOD threshold is divided by this for this variant. The thesis used 2 for 4xSS; every tile
    # a patch touches evaluates all of its samples again, so smaller patches pay off: 4 measured
    # about twice as fast as 2 on PoCL (docs/points.md)
    lod_divisor: float = 4.0
    max_pairs: int = 1 << 26   # (tile, patch) pairs per frame at most (4 bytes each); more is an error

    def validate(self):
        super().validate()
        if self.ss not in (2, 3):
            raise SceneError(f"points-ssaa ss must be 2 (2x2 subsamples) or 3 (3x3), got {self.ss}")
        if self.max_side > 4096:
            raise SceneError(f"points-ssaa max_side must be at most 4096, got {self.max_side}")
        if not in_range(self.margin, 0, 64):
            raise SceneError(f"points-ssaa margin must be in [0, 64] pixels, got {self.margin}")
        if not in_range(self.lod_divisor, 1, 16):
            raise SceneError(f"points-ssaa lod_divisor must be in [1, 16], got {self.lod_divisor}")
        if not in_range(self.max_pairs, 1, 1 << 31):
            raise SceneError(f"points-ssaa max_pairs must be in [1, 2^31], got {self.max_pairs}")

    def factor(self) -> np.float32:
        """Samples per measured pixel along each side: density per subsample x ss."""
        return np.float32(self.density * self.oversample * self.ss / (1.0 - self.epsilon))


def tile_grid(width: int, height: int, tile: int = TILE) -> tuple[int, int]:
    """Tiles across and down a width x height frame."""
    return -(-int(width) // tile), -(-int(height) // tile)


def _round_up(n, m):
    return max(m, (n + m - 1) // m * m)


class LocalFramebufferRenderer:
    """Compiled kernels and reusable buffers; ``tile``, ``chunk`` and ``local_size`` are fixed at
    compile time (tests use small values to force many chunks or more tiles)."""

    def __init__(self, functions, record: bool = False, tile: int = TILE, chunk: int = 64,
                 local_size: int = 64):
        if tile not in (4, 8, 16, 32):
            raise SceneError(f"points-ssaa tile must be 4, 8, 16 or 32 pixels, got {tile}")
        if not 1 <= chunk <= 1024:
            raise SceneError(f"points-ssaa chunk must be in 1..1024 patches, got {chunk}")
        if local_size not in (32, 64, 128, 256):
            raise SceneError(f"points-ssaa local_size must be 32, 64, 128 or 256, got {local_size}")
        self.functions = list(functions)
        self.record, self.tile, self.chunk, self.local_size = record, tile, chunk, local_size
        dev = cl_device()
        self._kernels: dict[int, tuple] = {}
        self.counters = cl.Buffer(dev.context, cl.mem_flags.READ_WRITE, 8 * len(LFB_COUNTERS))
        self.scan = ExclusiveScanKernel(dev.context, np.uint32, "a+b", "0")
        self.lin, self.thr = srgb_device_tables()
        self.n_tiles = 0
        self.rect_cap = self.pair_cap = 0
        self.rects = self.pairs = None
        self.last_tile_counts: np.ndarray | None = None

    def local_bytes(self, ss: int) -> int:
        """__local memory one work-group of points_lfb uses (two key buffers + the staged chunk)."""
        side = self.tile * ss
        return 2 * 8 * side * side + self.chunk * (24 + 3 * 4) + (self.chunk + 1) * 4

    def kernels(self, ss: int):
        k = self._kernels.get(ss)
        if k is None:
            need, have = self.local_bytes(ss), cl_device().device.local_mem_size
            if need > have:
                raise DeviceError(f"points-ssaa with {ss}x{ss} subsamples, {self.tile}-px tiles and chunks of "
                                  f"{self.chunk} needs {need} bytes of local memory; the device has {have}. "
                                  "Use ss=2, a smaller tile or a smaller chunk.")
            defines = {**points_cl_defines(), "PL_SS": ss, "PL_TILE": self.tile, "PL_CHUNK": self.chunk,
                       "PL_LOCAL": self.local_size}
            if self.record:
                defines["PL_RECORD"] = 1
            files = ["common/keys.cl", "points/points.cl", "points/subsamples.cl", "points/points_lfb.cl"]
            k = self._kernels[ss] = tuple(kernel(name, files, self.functions, defines)
                                          for name in ("lfb_count", "lfb_fill", "points_lfb"))
        return k

    def _ensure(self, n_tiles, n_patches, n_pairs):
        q, ctx = cl_device().queue, cl_device().context
        if n_tiles != self.n_tiles:
            self.tile_count = cla.empty(q, n_tiles, np.uint32)
            self.tile_fill = cla.empty(q, n_tiles, np.uint32)
            self.tile_offset = cla.empty(q, n_tiles, np.uint32)
            self.n_tiles = n_tiles
        if n_patches > self.rect_cap:
            self.rect_cap = 1 << int(np.ceil(np.log2(max(n_patches, 1024))))
            self.rects = cl.Buffer(ctx, cl.mem_flags.READ_WRITE, 16 * self.rect_cap)
        if n_pairs > self.pair_cap:
            self.pair_cap = 1 << int(np.ceil(np.log2(max(n_pairs, 1024))))
            self.pairs = cl.Buffer(ctx, cl.mem_flags.READ_WRITE, 4 * self.pair_cap)

    def draw(self, patches_buf, n_patches, inst, materials_buf, cam_buf, light_buf, keys,
             settings: SsaaSettings, record_args=()) -> dict:
        """Render ``n_patches`` render patches into ``keys`` (atom_min, nothing is cleared).

        Returns the counters (LFB_COUNTERS) plus tile statistics. ``record_args`` (with
        ``record=True``): rec_offset, rec_sub, rec_key, rec_aux buffers, see points_lfb.cl."""
        settings.validate()
        k_count, k_fill, k_render = self.kernels(settings.ss)
        q = cl_device().queue
        W, H = keys.width, keys.height
        tiles_x, tiles_y = tile_grid(W, H, self.tile)
        n_tiles = tiles_x * tiles_y
        self._ensure(n_tiles, n_patches, 0)
        counters = np.zeros(len(LFB_COUNTERS), np.uint64)
        cl.enqueue_copy(q, self.counters, counters)
        self.tile_count.fill(0)
        self.tile_fill.fill(0)
        if n_patches:
            k_count(q, (_round_up(n_patches, 64),), None, patches_buf, np.uint32(n_patches), cam_buf,
                    np.float32(settings.margin), np.float32(settings.widen), np.uint32(tiles_x),
                    np.uint32(tiles_y), self.rects, self.tile_count.data, self.counters)
            cl.enqueue_copy(q, counters, self.counters)
            n_pairs = int(counters[0])
            if n_pairs > settings.max_pairs:
                raise CapacityError(
                    f"points-ssaa needs {n_pairs} (tile, patch) pairs, more than max_pairs={settings.max_pairs}; "
                    "raise max_pairs (4 bytes a pair), or lower lod_divisor (larger patches make fewer pairs)")
            self._ensure(n_tiles, n_patches, n_pairs)
            self.scan(self.tile_count, self.tile_offset, queue=q)
            if n_pairs:
                k_fill(q, (_round_up(n_patches, 64),), None, self.rects, np.uint32(n_patches),
                       np.uint32(tiles_x), self.tile_offset.data, self.tile_fill.data, self.pairs)
                k_render(q, (n_tiles * self.local_size,), (self.local_size,),
                         patches_buf, self.rects, self.tile_offset.data, self.tile_count.data, self.pairs,
                         np.uint32(tiles_x), *inst, materials_buf, cam_buf, light_buf,
                         settings.factor(), settings.measure(boundary=False), np.float32(settings.widen),
                         np.uint32(settings.max_side), self.lin.data, self.thr.data,
                         keys.color, keys.aux, self.counters, *record_args)
        cl.enqueue_copy(q, counters, self.counters)
        tc = self.tile_count.get(queue=q)
        self.last_tile_counts = tc.reshape(tiles_y, tiles_x)
        stats = {k: int(v) for k, v in zip(LFB_COUNTERS, counters)}
        c = stats["covered_subsamples"]
        stats.update({
            "ss": settings.ss,
            "tiles": n_tiles,
            "tiles_nonempty": int(np.count_nonzero(tc)),
            "max_patches_per_tile": int(tc.max()) if n_tiles else 0,
            "chunks": int(np.sum((tc.astype(np.int64) + self.chunk - 1) // self.chunk)),
            "eval_redundancy": stats["samples"] / stats["samples_unique"] if stats["samples_unique"] else 0.0,
            "local_overdraw": stats["local_atomics"] / c if c else 0.0,
            "subsample_coverage": c / (stats["pixels_resolved"] * settings.ss ** 2) if c else 0.0,
        })
        return stats


class LocalFramebufferPoints:
    """Per-scene state of the "points-ssaa" variant. Its tile lists are sized on the host, so it
    waits for the LOD stage's patch count and for its scan inside the frame (the one variant that
    does; the LOD thresholds are divided by ``SsaaSettings.lod_divisor``)."""

    def __init__(self, functions, record: bool = False):
        self.buffers = SceneBuffers(LIGHT)
        self.lod = LodStage(functions)
        self.lfb = LocalFramebufferRenderer(functions, record=record)
        self.dev, self._counters, self._ms = None, {}, 0.0

    def prepare(self, scene, camera, settings):
        settings.ssaa.validate()
        if settings.points.color_by != "material":   # refused, not silently drawn in materials
            raise SceneError(f"points color_by {settings.points.color_by!r} is drawn by the direct variant "
                             f"\"points\" (and the mesh renderers), not by points-ssaa")
        aa = getattr(settings, "aa", None)   # the frame's mode (RenderSettings.apply_aa)
        if aa is not None:
            # a mode it cannot draw is refused, never drawn as 4xSS; in a frame mixed with tess, a
            # multisampled mode is tess's, and its supersampling must still be one of points-ssaa's
            if aa.msaa == 1 or aa.ss not in LFB_MODES.values():
                local_framebuffer_ss(aa)
            if aa.ss != settings.ssaa.ss:
                raise SceneError(f"anti-aliasing {aa.name} asks for {aa.ss}x{aa.ss} subsamples, but "
                                 f"settings.ssaa.ss is {settings.ssaa.ss}")
        self.dev = self.buffers.upload(scene, camera)

    def enqueue(self, target, settings):
        d = self.dev
        while True:
            self.lod.enqueue(d["inst"], d["domains"], d["cam"], settings.lod, t_div=settings.ssaa.lod_divisor,
                             one_sided=d["one_sided"])
            self.lod.read_counters()
            if not self.lod.grow(settings.lod):
                break
        t0 = time.perf_counter()
        self._counters = self.lfb.draw(self.lod.render.buf, self.lod.result()[0], d["inst"], d["materials"],
                                       d["cam"], d["light"], target, settings.ssaa)
        self._ms = (time.perf_counter() - t0) * 1e3   # wall time: it waits for its scan and bins

    def collect(self):
        pass

    def grow(self, settings) -> bool:
        return False

    def stats(self) -> dict:
        n, steps = self.lod.result()
        return {"render_patches": n, "lod_steps": steps, "forced_patches": sum(s["forced"] for s in steps),
                **self._counters, "ms": {"lod": self.lod.device_ms(), "render": self._ms}}


register_renderer(RendererSpec("points-ssaa", "parametric", LocalFramebufferPoints, "ssaa", "keys", SsaaSettings,
                               "2x2 or 3x3 subsamples per pixel in a local framebuffer per 16x16 tile"))
