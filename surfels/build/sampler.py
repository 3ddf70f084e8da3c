"""Progressive farthest-point sampling of G-buffers in OpenCL (kernels/surfels/surfels_sample.cl).

Per round: (1) the sites inserted last round splat their distance discs into the Voronoi buffer
(64-bit atom_min of d^2 bits << 32 | site); (2) each cell's farthest pixel becomes its site's
candidate (atom_max of d^2 bits << 32 | pixel); (3) candidates under 0.75 x the largest radius
are dropped; (4) Poisson conflict removal: candidates splat their discs with atom_max of their key,
a candidate survives when it owns its own pixel; (5) survivors are compacted (scan, copy_if) and
radix-sorted by decreasing radius, then appended. Rounds repeat until the target count is reached
or no pixel is farther than 0 from its site. Everything is order-independent (atomics on keys,
stable scan and sort), so a run is deterministic for a given input, seed and device.

Rounds with large radii run on point-subsampled G-buffers (strides 8, 4, 2, then 1: coarse to
fine), and the disc splats skip 16x16 tiles that hold no covered pixel or lie out of reach
(their 3D bounding box is farther than the radius). Both only save work: the numpy twin in
reference.py runs the same schedule by brute force and matches bit for bit. On CPU devices steps (4)
and (5) run on the host: the conflicts from the candidates' pairs (schedule.pair_survivors), then
numpy's stable sort: the same keys, without a disc splat into every view and dozens of launches a
round.

The rounds fix the order; relax.py then evens out the full set on the host (sample_gbuffer's
``relax_iterations``), moving each surfel by a fraction of the final spacing.
"""
from __future__ import annotations

import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from paramlod.app.scenefile import load_scene
from paramlod.core.color import linear_rgba_to_srgb8_f64
from paramlod.core.layouts import SAMPLER_COUNTER
from paramlod.device.context import cl_device
from paramlod.device.programs import build
from paramlod.errors import SurfelError
from paramlod.scene.scene import Scene
from paramlod.surfels.build.gbuffer import GBuffer, mesh_gbuffer, scene_gbuffer
from paramlod.surfels.build.relax import auto_iterations, relax
from paramlod.surfels.build.schedule import (HI, THRESHOLD, auto_resolution, compact_sort, handover_r2, key_pixel,
                                             key_r2, level_strides, pair_survivors, remap_keys, resume_radii, splat_r2,
                                             stop_r2, threshold_r2)
from paramlod.surfels.build.sources import TriangleSoup, load_mesh, soup_from_trimesh
from paramlod.surfels.format import SurfelSet

LOCAL = 64                  # work-group size of every sampling kernel (one compiled variant on PoCL)
TILE = 16                   # must match kernels/surfels/surfels_sample.cl
MAX_SURFELS = 1 << 26


def tile_bounds(position: np.ndarray):
    """Per layer and TILE x TILE tile, the 3D bounding box of the covered pixels: float32
    (K, th, tw, 4) lo and hi; lo.w = 1 where the tile has a covered pixel."""
    k, h, w = position.shape[:3]
    th, tw = -(-h // TILE), -(-w // TILE)
    valid = position[..., 3] > 0
    lo = np.zeros((k, th, tw, 4), np.float32)
    hi = np.zeros((k, th, tw, 4), np.float32)
    pad = ((0, 0), (0, th * TILE - h), (0, tw * TILE - w))
    for c in range(3):   # one channel at a time: min/max over the two tile axes, no nan handling
        ch = np.pad(position[..., c], pad).reshape(k, th, TILE, tw, TILE)
        v = np.pad(valid, pad).reshape(k, th, TILE, tw, TILE)
        lo[..., c] = np.where(v, ch, np.inf).min(axis=(2, 4))
        hi[..., c] = np.where(v, ch, -np.inf).max(axis=(2, 4))
    any_ = np.pad(valid, pad).reshape(k, th, TILE, tw, TILE).any(axis=(2, 4))
    lo[~any_], hi[~any_] = 0.0, 0.0
    lo[..., 3] = hi[..., 3] = any_
    return lo, hi


def half_box(r2: float, scale: float) -> int:
    """Half-size in pixels of the square that holds a disc of squared radius r2 in every view."""
    if not np.isfinite(r2):
        return -1
    return int(np.ceil(np.sqrt(float(r2)) * scale)) + 3


def _sorter():
    """Radix sort of ulong keys by decreasing high half (the squared radius), stable; built once
    per CL context (kept in its cache)."""
    from pyopencl.algorithm import RadixSort

    dev = cl_device()
    s = dev.cache.get("surfels.radix_sort")
    if s is None:
        s = dev.cache["surfels.radix_sort"] = RadixSort(dev.context, "ulong *keys", key_expr="~(uint)(keys[i] >> 32)",
                                                        sort_arg_names=["keys"], key_dtype=np.uint32, bits_at_a_time=4)
    return s


@dataclass
class RoundStats:
    round: int
    sites: int
    candidates: int
    survivors: int
    inserted: int
    radius: float
    ms: float
    stride: int = 1


class Sampler:
    """Device state of one sampling run; the passes are methods so that tests can check each."""

    def __init__(self, gbuf: GBuffer, target: int, seed: int = 0, threshold: float = THRESHOLD,
                 host_survivors: bool | None = None):
        import pyopencl as cl
        import pyopencl.array as cla

        target = _check_count(target)
        if not 0.0 < threshold <= 1.0:
            raise SurfelError(f"threshold must be in (0, 1], got {threshold}")
        self.n_valid = gbuf.check()
        self.gbuf, self.target, self.seed, self.threshold = gbuf, target, _check_seed(seed), float(threshold)
        k, h, w = gbuf.shape
        if gbuf.pixel_count >= 1 << 32:
            raise SurfelError(f"G-buffers of {gbuf.pixel_count} pixels exceed the 32-bit pixel index")
        self.K, self.H, self.W = k, h, w
        self.n_pix = gbuf.pixel_count
        vs = gbuf.views
        self.pos_host = np.ascontiguousarray(gbuf.position.reshape(-1, 4), np.float32)
        self.geom = (np.uint32(w), np.uint32(h), np.uint32(k))
        self.frame = (*[np.float32(x) for x in vs.centre], np.float32(vs.scale))
        self.scale = float(np.float32(vs.scale))
        dev = cl_device()
        # Find the survivors on the host on CPU devices: conflicts from the candidates' pairs
        # (schedule.pair_survivors; the discs' splats into every view were half of a 100k run on
        # two cores), then compaction and sort (pyopencl's scan and radix sort are dozens of launches
        # a round there). The same survivors either way.
        self.host_survivors = (not dev.is_gpu) if host_survivors is None else bool(host_survivors)
        self.eligible = 0   # candidates of the last round that passed the radius threshold
        self.q = q = dev.queue
        prog = build(["surfels/surfels_sample.cl"])
        self.k = {name: cl.Kernel(prog, name) for name in
                  ("voronoi_splat", "farthest", "max_key", "conflict_splat", "survive")}
        self.pos = dev.copy_of(self.pos_host)
        self.layers = dev.copy_of(vs.layer_record())
        lo, hi = tile_bounds(gbuf.position)
        self.tiles_dev = (dev.copy_of(lo), dev.copy_of(hi))
        self.tile_grid = (lo.shape[2], lo.shape[1])
        self.vor = cla.empty(q, self.n_pix, np.uint64)
        self.conf = None if self.host_survivors else cla.empty(q, self.n_pix, np.uint64)   # device conflicts
        self.samples = cla.zeros(q, target, np.uint64)
        self.cand = cla.zeros(q, target, np.uint64)
        self.counters = cla.zeros(q, SAMPLER_COUNTER.length, np.uint32)
        self.maxbuf = cla.zeros(q, 1, np.uint64)
        self.n = 0
        self.rounds: list[RoundStats] = []

    # --- passes --------------------------------------------------------------------------------
    def seed_pixel(self) -> int:
        valid = np.flatnonzero(self.pos_host[:, 3] > 0)
        return int(valid[np.random.default_rng(self.seed).integers(len(valid))])

    def start(self, pixel: int | None = None):
        """Clear the Voronoi buffer and place the first sample (a seeded random covered pixel)."""
        self.vor.fill(np.uint64(0xFFFFFFFFFFFFFFFF))
        self.samples[0:1].set(np.array([self.seed_pixel() if pixel is None else pixel], np.uint64))
        self.n = 1
        self.splat_voronoi(0, 1, np.float32(np.inf))

    def splat_voronoi(self, first: int, count: int, r2):
        hb = half_box(r2, self.scale)
        if hb < 0 or hb > max(self.W, self.H):
            hb = max(self.W, self.H)
        tiles = self._tiles(hb)
        total = count * self.K * tiles * tiles
        if total:
            self.k["voronoi_splat"](self.q, (_round_up(total, LOCAL),), (LOCAL,), self.pos, *self.geom, self.layers,
                                    *self.frame, *self.tiles_dev, self.samples.data, np.uint32(first),
                                    np.uint32(count), np.float32(r2), np.int32(hb), np.uint32(tiles), self.vor.data)

    def _tiles(self, hb: int) -> int:
        """Work tiles per side for boxes of half-size hb (a box may straddle one more tile)."""
        return min((2 * hb + 1 + TILE - 1) // TILE + 1, max(self.tile_grid))

    def farthest(self):
        """Candidates of the current sites; returns (largest candidate key, uncovered pixel count)."""
        n = self.n
        self.cand[:n].fill(np.uint64(0))
        self.counters.fill(np.uint32(0))
        self.k["farthest"](self.q, (_round_up(self.n_pix, LOCAL),), (LOCAL,), self.pos, self.vor.data,
                           np.uint32(self.n_pix), self.cand.data, self.counters.data)
        self.maxbuf.fill(np.uint64(0))
        self.k["max_key"](self.q, (_round_up(n, LOCAL),), (LOCAL,), self.cand.data, np.uint32(n), self.maxbuf.data)
        return np.uint64(self.maxbuf.get()[0]), int(self.counters.get()[SAMPLER_COUNTER.offset("unreached")])

    def conflicts(self, thr2, r2max):
        n = self.n
        self.conf.fill(np.uint64(0))
        hb = min(half_box(r2max, self.scale) + 1, max(self.W, self.H))
        tiles = self._tiles(hb)
        self.k["conflict_splat"](self.q, (_round_up(n * self.K * tiles * tiles, LOCAL),), (LOCAL,), self.pos,
                                 *self.geom, self.layers, *self.frame, *self.tiles_dev, self.cand.data,
                                 np.uint32(n), np.float32(thr2), np.uint32(tiles), self.conf.data)

    def survivors(self, thr2, r2max):
        """Surviving candidate keys of this round, compacted in site order and sorted by
        decreasing radius, and their count; sets ``eligible``."""
        import pyopencl.array as cla
        from pyopencl.algorithm import copy_if

        n = self.n
        if self.host_survivors:
            out, self.eligible = pair_survivors(self.cand[:n].get(), self.pos_host, thr2)
            srt = compact_sort(out)
            keys = cla.empty(self.q, max(len(srt), 1), np.uint64)
            if len(srt):
                keys[:len(srt)].set(srt)
            return keys, len(srt)
        self.conflicts(thr2, r2max)
        out = cla.empty(self.q, n, np.uint64)
        self.k["survive"](self.q, (_round_up(n, LOCAL),), (LOCAL,), self.cand.data, np.uint32(n), np.float32(thr2),
                          self.conf.data, out.data, self.counters.data)
        self.eligible = int(self.counters.get()[SAMPLER_COUNTER.offset("eligible")])
        packed, count, _ = copy_if(out, "ary[i] != 0", queue=self.q)
        m = int(count.get())
        if m == 0:
            return packed[:0], 0
        (srt,), _ = _sorter()(packed[:m], key_bits=32, queue=self.q)
        return srt, m

    def append(self, keys, count: int):
        import pyopencl as cl

        if count:
            cl.enqueue_copy(self.q, self.samples.data, keys.data, byte_count=count * 8, dst_offset=self.n * 8)
        first = self.n
        self.n += count
        return first

    def resume(self, keys: np.ndarray, r2):
        """Continue from samples of a coarser level (keys already remapped to this level's pixels):
        splat them all with squared radius r2, quadrupled until every covered pixel is reached."""
        keys = np.ascontiguousarray(keys, np.uint64)
        self.samples[0:len(keys)].set(keys)
        self.n = len(keys)
        self.vor.fill(np.uint64(0xFFFFFFFFFFFFFFFF))
        for r2 in resume_radii(r2):
            self.splat_voronoi(0, self.n, r2)
            if self.farthest()[1] == 0:
                return
        raise SurfelError("internal error: the samples of the coarser level do not reach every pixel")

    # --- the loop -------------------------------------------------------------------------------
    def loop(self, stop_r2=0.0, fix_first_radius=False, progress=None):
        """Rounds until the target count, r2max <= stop_r2 (a coarser level hands over) or r2max = 0.
        Returns (sample keys in order, uint64 (n,); the last r2max)."""
        first_round = fix_first_radius
        while True:
            t0 = time.perf_counter()
            mx, uncovered = self.farthest()
            if uncovered:
                raise SurfelError(f"internal error: {uncovered} covered pixels were not reached by any site")
            r2max = key_r2(mx)
            if first_round:  # the first sample's radius: the farthest distance from it
                self.samples[0:1].set(np.array([(mx & HI) | np.uint64(self.samples[0:1].get()[0])], np.uint64))
                first_round = False
            if self.n >= self.target or not r2max > stop_r2:
                break
            thr2 = threshold_r2(r2max, self.threshold)
            keys, m = self.survivors(thr2, r2max)
            take = min(m, self.target - self.n)
            if take == 0:
                break
            first = self.append(keys, take)
            self.splat_voronoi(first, take, splat_r2(r2max))
            self.q.finish()
            self.rounds.append(RoundStats(len(self.rounds) + 1, first, self.eligible, m, take,
                                          float(np.sqrt(r2max)), (time.perf_counter() - t0) * 1e3))
            if progress is not None:
                progress(self.n, float(np.sqrt(r2max)))
        return self.samples[:self.n].get(), r2max

    def run(self, progress=None) -> np.ndarray:
        """Single-level run from a seeded first sample: the ordered sample keys."""
        self.start()
        return self.loop(0.0, True, progress)[0]

def _round_up(n, m):
    return max(m, (n + m - 1) // m * m)


def _check_count(n) -> int:
    try:
        ni = int(n)
    except (TypeError, ValueError):
        raise SurfelError(f"surfel count must be a positive integer, got {n!r}") from None
    if ni != n or ni <= 0:
        raise SurfelError(f"surfel count must be a positive integer, got {n!r}")
    if ni > MAX_SURFELS:
        raise SurfelError(f"surfel count {ni} exceeds the limit of {MAX_SURFELS}")
    return ni


def _check_seed(seed) -> int:
    # numpy's generator refuses negative seeds with a ValueError of its own
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise SurfelError(f"seed must be a non-negative integer, got {seed!r}")
    return int(seed)


def run_levels(gbuf: GBuffer, n: int, seed: int = 0, threshold: float = THRESHOLD, progress=None):
    """The coarse-to-fine sampling loop: (keys at full resolution, per-round stats, strides)."""
    strides = level_strides(gbuf.views.resolution)
    pixel = gbuf.views.pixel_size
    keys = r2max = prev = None
    rounds = []
    for stride in strides:
        g = gbuf.subsample(stride)
        if stride != 1 and not np.any(g.valid):
            continue    # a thin object may fall between the pixels of a coarse level
        s = Sampler(g, n, seed, threshold)
        if keys is None:
            s.start()
        else:
            s.resume(remap_keys(keys, gbuf.shape, prev, stride), handover_r2(r2max, prev, pixel))
        last = stride == 1
        keys, r2max = s.loop(0.0 if last else stop_r2(stride, pixel), fix_first_radius=keys is None,
                             progress=progress)
        for rs in s.rounds:
            rs.round = len(rounds) + 1
            rs.stride = stride
            rounds.append(rs)
        prev = stride
        if len(keys) >= n:
            keys = remap_keys(keys, gbuf.shape, stride, 1)
            break
    return keys, rounds, strides


def sample_gbuffer(gbuf: GBuffer, n: int, seed: int = 0, progress: bool = False,
                   threshold: float = THRESHOLD, relax_iterations: int | None = None) -> SurfelSet:
    """Sample ``n`` blue surfels from G-buffers (fewer when the G-buffers hold fewer distinct
    points: then ``meta['requested']`` keeps n and a warning says so). The farthest-point rounds
    give the order; ``relax_iterations`` of relax.relax then even out the full set (0: the
    surfels stay on their pixels; None: relax.auto_iterations for n and the resolution)."""
    n = _check_count(n)
    seed = _check_seed(seed)
    if not 0.0 < threshold <= 1.0:
        raise SurfelError(f"threshold must be in (0, 1], got {threshold}")
    if relax_iterations is None:
        relax_iterations = auto_iterations(n, gbuf.views.resolution)
    if isinstance(relax_iterations, bool) or not isinstance(relax_iterations, (int, np.integer)) \
            or relax_iterations < 0:
        raise SurfelError(f"relax_iterations must be an integer >= 0, got {relax_iterations!r}")
    covered = gbuf.check()
    relax_iterations = int(relax_iterations)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=n, unit="surfel", desc="sampling", dynamic_ncols=True)
        bar.update(1)
    state = {"round": 0}

    def report(count, radius):
        state["round"] += 1
        if bar is not None:
            bar.update(count - bar.n)
            bar.set_postfix(round=state["round"], radius=f"{radius:.4g}")

    try:
        keys, rounds, strides = run_levels(gbuf, n, seed, threshold, report)
    finally:
        if bar is not None:
            bar.close()
    if len(keys) < n:
        warnings.warn(f"only {len(keys)} of {n} surfels: every covered G-buffer pixel is taken "
                      "(raise the resolution for more)", stacklevel=2)
    meta = {"seed": int(seed), "requested": n, "threshold": threshold, "rounds": len(rounds), "levels": strides,
            "covered_pixels": covered, "relax_iterations": relax_iterations}
    return surfel_set(gbuf, keys, meta, relax_iterations)


def surfel_set(gbuf: GBuffer, keys: np.ndarray, meta: dict | None = None, relax_iterations: int = 0) -> SurfelSet:
    """The SurfelSet of full-resolution sample keys, relaxed with ``relax_iterations`` (normal and
    colour: those of the covered pixel nearest to the relaxed position)."""
    p, pix = relax(gbuf, key_pixel(keys), relax_iterations)
    pos = p.astype(np.float32)
    nrm = gbuf.normal.reshape(-1, 3)[pix]
    col = gbuf.color.reshape(-1, 4)[pix]
    radii = np.sqrt(key_r2(keys).astype(np.float64))
    vs = gbuf.views
    info = {"source": gbuf.source, "views": vs.count, "resolution": vs.resolution, "pixel_size": vs.pixel_size}
    info.update(meta or {})
    return SurfelSet.build(pos, nrm, linear_rgba_to_srgb8_f64(col), radii, info)


def sample_mesh(mesh, n: int, views: int = 16, resolution: int | None = None, seed: int = 0,
                progress: bool = False) -> SurfelSet:
    """Blue surfels of a mesh: a file path, a ``trimesh.Trimesh`` or a TriangleSoup. ``resolution``
    None: schedule.auto_resolution(n) (128 for 10k, 512 for 100k)."""
    n = _check_count(n)
    seed = _check_seed(seed)
    resolution = auto_resolution(n) if resolution is None else resolution
    if isinstance(mesh, TriangleSoup):
        soup = mesh
    elif hasattr(mesh, "faces") and hasattr(mesh, "vertices"):
        soup = soup_from_trimesh(mesh, getattr(mesh, "metadata", {}).get("file_name", "mesh"))
    else:
        soup = load_mesh(mesh)
    return sample_gbuffer(mesh_gbuffer(soup, views, resolution), n, seed, progress)


def sample_scene(scene, n: int, views: int = 16, resolution: int | None = None, seed: int = 0,
                 progress: bool = False, name: str = "scene") -> SurfelSet:
    """Blue surfels of a parametric paramlod.Scene (G-buffers from the point renderer)."""
    n = _check_count(n)
    seed = _check_seed(seed)
    resolution = auto_resolution(n) if resolution is None else resolution
    return sample_gbuffer(scene_gbuffer(scene, views, resolution, name=name), n, seed, progress)


def sample(source, n: int, views: int = 16, resolution: int | None = None, seed: int = 0,
           progress: bool = False) -> SurfelSet:
    """Blue surfels of a mesh file, a scene file (.toml), a trimesh mesh or a paramlod.Scene
    (``resolution`` None: chosen from n, see schedule.auto_resolution)."""
    if isinstance(source, Scene):
        return sample_scene(source, n, views, resolution, seed, progress)
    if isinstance(source, (str, Path)) and Path(source).suffix.lower() == ".toml":
        _check_count(n)
        _check_seed(seed)
        return sample_scene(load_scene(source).scene, n, views, resolution, seed, progress, name=Path(source).name)
    return sample_mesh(source, n, views, resolution, seed, progress)
