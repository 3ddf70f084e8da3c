"""Local-framebuffer point renderer ("points-ssaa"): bit-exact against its numpy reference,
supersampled edges, no holes, tiles with thousands of patches, the shared key buffer, errors."""
import numpy as np
import pytest

import paramlod as pl
from paramlod.renderers import points_reference as ref
from paramlod.device.context import cl_device
from paramlod.renderers.targets import KeyBuffer
from paramlod.lod.stage import LodSettings, LodStage
from helpers.holes import count_holes
from paramlod.renderers.points import DirectPointRenderer, PointSettings, grid_counts
from paramlod.renderers.points_lfb import LocalFramebufferRenderer, SsaaSettings
from paramlod.core.layouts import camera_record
from paramlod.renderers.shading import LIGHT

from conftest import sphere_disc
from test_points_adaptive import DISTANCES, SHAPES, camera_at, dense_silhouette, shape_scene

CLEAR = np.iinfo(np.uint64).max


def render_points_ssaa(scene, camera, settings=None, lod=None):
    """A frame of the local-framebuffer variant through the frame driver."""
    rs = pl.RenderSettings(lod=lod or pl.LodSettings(), ssaa=settings or SsaaSettings())
    return pl.render(scene, camera, variant="points-ssaa", settings=rs)


class Setup:
    """Device buffers and the render list of a scene, as paramlod/render.py prepares them."""

    def __init__(self, scene, cam, settings: SsaaSettings, lod: LodSettings | None = None):
        import pyopencl.array as cla

        q = cl_device().queue
        self.scene, self.cam, self.settings = scene, cam, settings
        self.funcs = scene.functions()
        inst_f, inst_u, params = scene.instance_buffers()
        self.inst = tuple(cla.to_device(q, a).data for a in (inst_f, inst_u, params))
        self.materials = cla.to_device(q, scene.materials()).data
        self.cam_buf = cla.to_device(q, camera_record(cam)).data
        self.light = cla.to_device(q, LIGHT).data
        self.stage = LodStage(self.funcs)
        self.rbuf, self.n, _, _ = self.stage.run(self.inst, inst_f[:, 28:32], self.cam_buf,
                                                 lod or LodSettings(), t_div=settings.lod_divisor)
        self.render_list = self.stage.read_render_list(self.n)

    def draw(self, renderer, keys=None, settings=None, rbuf=None, n=None, record_args=()):
        if keys is None:
            keys = KeyBuffer(*self.cam.size)
            keys.clear()
        stats = renderer.draw(self.rbuf if rbuf is None else rbuf, self.n if n is None else n, self.inst,
                              self.materials, self.cam_buf, self.light, keys, settings or self.settings,
                              record_args=record_args)
        return keys, stats

    def draw_recorded(self, **renderer_opts):
        """Draw with the PL_RECORD hook; returns (colour keys, aux keys, stats, expected colour,
        expected aux, reference stats, renderer, tile rectangles)."""
        import pyopencl as cl
        import pyopencl.array as cla

        q = cl_device().queue
        nu, nv = grid_counts(self.render_list, self.settings, boundary=False)   # as points_lfb samples
        counts = nu * nv
        total = int(counts.sum())
        off = cla.to_device(q, np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.uint32))
        sub = cla.to_device(q, np.full(total, 0xFFFFFFFF, np.uint32))
        key = cla.to_device(q, np.zeros(total, np.uint64))
        aux = cla.to_device(q, np.zeros(total, np.uint64))
        r = LocalFramebufferRenderer(self.funcs, record=True, **renderer_opts)
        keys, stats = self.draw(r, record_args=(off.data, sub.data, key.data, aux.data))
        color, attr = keys.read_keys()
        rects = np.empty((self.n, 4), np.int32)
        cl.enqueue_copy(q, rects, r.rects)
        np.testing.assert_array_equal(rects, ref.tile_rects(self.render_list, *self.cam.size, self.settings.margin,
                                                            self.settings.widen, tile=r.tile))
        patch_of = np.repeat(np.arange(self.n), counts)
        ec, ea, es = ref.lfb_keys(rects, patch_of, sub.get(), key.get(), aux.get(), *self.cam.size,
                                  self.settings.ss, tile=r.tile)
        assert stats["samples_unique"] == counts[rects[:, 2] >= rects[:, 0]].sum()
        return color, attr, stats, ec, ea, es, r, rects


def _pair_lists(r):
    import pyopencl as cl

    counts = r.tile_count.get()
    offsets = r.tile_offset.get()
    pairs = np.empty(int(counts.sum()), np.uint32)
    if len(pairs):
        cl.enqueue_copy(cl_device().queue, pairs, r.pairs)
    return counts, offsets, pairs


# ---------------------------------------------------------------- bit for bit against numpy

@pytest.mark.parametrize("ss", [2, 3])
def test_matches_numpy_reference_bit_for_bit(ss):
    scene = pl.Scene()
    scene.add("sphere", material=pl.Material(color=(0.9, 0.4, 0.2)))
    scene.add("torus", transform=pl.translate(0.8, 0.2, 0.3) @ pl.rotate(70, (1, 0, 0)),
              material=pl.Material(color=(0.2, 0.5, 0.9)))
    # 72 x 56: the last tile column and row are partial
    cam = pl.Camera.look_at((0.5, 0.8, 3.5), (0.3, 0, 0), size=(72, 56))
    s = Setup(scene, cam, SsaaSettings(ss=ss))
    color, attr, stats, ec, ea, es, r, rects = s.draw_recorded()
    np.testing.assert_array_equal(color, ec)
    np.testing.assert_array_equal(attr, ea)
    # the tile lists: counts, their exclusive scan, and each tile's set of patches
    counts, offsets, pairs = _pair_lists(r)
    ecounts, eoffsets, epairs = ref.tile_lists(rects, *cam.size)
    np.testing.assert_array_equal(counts, ecounts)
    np.testing.assert_array_equal(offsets, eoffsets)
    for t in np.nonzero(counts)[0]:
        sl = slice(int(offsets[t]), int(offsets[t] + counts[t]))
        np.testing.assert_array_equal(np.sort(pairs[sl]), epairs[sl])
    # the order-independent counters agree with the reference
    assert stats["pixels_resolved"] == es["pixels"] > 500
    assert stats["covered_subsamples"] == es["covered"]
    assert stats["local_hits"] == es["hits"]
    assert stats["bbox_miss_samples"] == es["bbox_miss"] == 0
    assert stats["tile_patch_pairs"] == len(epairs)
    # on a cleared buffer every resolved pixel issues exactly one global atomic
    assert stats["atomics"] == stats["pixels_resolved"]
    assert es["covered"] <= stats["local_atomics"] <= stats["local_hits"]
    # both objects and partial coverage (anti-aliased edges) are present
    alpha = (color & np.uint64(255))[color != CLEAR]
    assert alpha.min() < 255 and np.count_nonzero(alpha == 255) > 300
    assert set(np.unique(attr[attr != CLEAR] & np.uint64(0xFFF))) == {1, 2}


def test_patches_crossing_the_near_plane_go_to_every_tile():
    # the camera is inside the sphere: patches through the eye plane have unmeasurable (infinite)
    # extents, so their screen box is unbounded
    scene = pl.Scene()
    scene.add("sphere", transform=pl.scale(2.0))
    cam = pl.Camera.look_at((0, 0, 0.5), (0.3, 0.2, -1), size=(40, 32), near=0.05)
    settings = SsaaSettings(max_side=12)
    s = Setup(scene, cam, settings, LodSettings(max_steps=3))
    unbounded = ~np.isfinite(s.render_list["ext"][:, 2])
    assert unbounded.any()
    color, attr, stats, ec, ea, es, r, rects = s.draw_recorded(tile=8)
    np.testing.assert_array_equal(rects[unbounded], np.tile([0, 0, 4, 3], (unbounded.sum(), 1)))
    np.testing.assert_array_equal(color, ec)
    np.testing.assert_array_equal(attr, ea)
    assert stats["capped_patches"] >= unbounded.sum()
    assert stats["pixels_resolved"] > 200


# ---------------------------------------------------------------- tiles, chunks, the shared buffer

def test_a_tile_with_thousands_of_patches_renders_like_patches_split_across_tiles():
    # 64 x 64 initial patches of a small sphere centred in tile (1, 1): 4096 patches in one tile
    scene = pl.Scene()
    scene.add("sphere", transform=pl.translate(-1.55, 1.55, 0))
    cam = pl.Camera.look_at((0, 0, 15), (0, 0, 0), size=(64, 64))
    settings = SsaaSettings()
    s = Setup(scene, cam, settings, LodSettings(initial_grid=(64, 64), max_steps=2))
    assert s.n >= 4000
    one, st_one = s.draw(LocalFramebufferRenderer(s.funcs, tile=16))
    assert st_one["max_patches_per_tile"] == s.n and st_one["tiles_nonempty"] == 1
    assert st_one["chunks"] == -(-s.n // 64)
    split, st_split = s.draw(LocalFramebufferRenderer(s.funcs, tile=8))
    assert st_split["tiles_nonempty"] >= 4 and st_split["max_patches_per_tile"] < s.n
    small_chunks, st_small = s.draw(LocalFramebufferRenderer(s.funcs, tile=16, chunk=7))
    assert st_small["chunks"] == -(-s.n // 7)
    c1, a1 = one.read_keys()
    assert np.count_nonzero(c1 != CLEAR) > 60
    for other in (split, small_chunks):
        c2, a2 = other.read_keys()
        np.testing.assert_array_equal(c1, c2)
        np.testing.assert_array_equal(a1, a2)
    assert st_one["samples_unique"] == st_split["samples_unique"] == st_small["samples_unique"]
    assert st_one["bbox_miss_samples"] == st_split["bbox_miss_samples"] == 0
    # and the numpy reference agrees (many chunks of 5)
    color, attr, _, ec, ea, _, _, _ = s.draw_recorded(chunk=5)
    np.testing.assert_array_equal(color, ec)
    np.testing.assert_array_equal(color, c1)


def test_shares_the_key_buffer_with_the_direct_renderer():
    import pyopencl.array as cla

    scene = pl.Scene()
    scene.add("sphere", material=pl.Material(color=(0.9, 0.2, 0.2)))
    scene.add("torus", transform=pl.rotate(80, (1, 0, 0)), material=pl.Material(color=(0.2, 0.8, 0.3)))
    cam = pl.Camera.look_at((0.3, 0.6, 3.4), (0, 0, 0), size=(64, 48))
    s = Setup(scene, cam, SsaaSettings())
    q = cl_device().queue
    rl = s.render_list
    parts = [rl[rl["inst"] == i] for i in (0, 1)]
    bufs = [cla.to_device(q, p).data for p in parts]
    direct, lfb = DirectPointRenderer(s.funcs), LocalFramebufferRenderer(s.funcs)
    alone_d, _ = s.draw(direct, settings=PointSettings(), rbuf=bufs[0], n=len(parts[0]))
    alone_l, _ = s.draw(lfb, rbuf=bufs[1], n=len(parts[1]))
    both, _ = s.draw(direct, settings=PointSettings(), rbuf=bufs[0], n=len(parts[0]))
    s.draw(lfb, keys=both, rbuf=bufs[1], n=len(parts[1]))
    for got, a, b in zip(both.read_keys(), alone_d.read_keys(), alone_l.read_keys()):
        np.testing.assert_array_equal(got, np.minimum(a, b))


# ---------------------------------------------------------------- image quality

def _coverage_16x16(cam):
    """Fraction of 16 x 16 subsample centres per pixel inside the sphere's silhouette."""
    w, h = cam.size
    hit, _ = sphere_disc(cam.with_size((w * 16, h * 16)))
    return hit.reshape(h, 16, w, 16).mean(axis=(1, 3))


def test_supersampled_edges_beat_the_direct_variant():
    scene = shape_scene("sphere")
    cam = pl.Camera.look_at((0.4, 0.3, 3.2), (0, 0, 0), size=(64, 64))
    cov = _coverage_16x16(cam)
    edge = (cov > 0) & (cov < 1)
    assert edge.sum() > 100
    direct = pl.render(scene, cam)
    errors = {"direct": np.abs(direct.color[..., 3] - cov).mean()}
    for ss in (2, 3):
        f = render_points_ssaa(scene, cam, SsaaSettings(ss=ss))
        errors[ss] = np.abs(f.color[..., 3] - cov).mean()
        assert f.stats["overdraw"] == 1.0 and f.stats["bbox_miss_samples"] == 0
        # alpha is exactly coverage: k/ss^2 of the pixel's subsamples
        a = np.rint(f.color[..., 3] * 255)
        levels = {(k * 255 + ss * ss // 2) // (ss * ss) for k in range(ss * ss + 1)}
        assert set(np.unique(a)) <= levels
    assert errors["direct"] > 1.4 * errors[2] > 0
    assert errors[2] > 1.1 * errors[3]


@pytest.mark.parametrize("dist", DISTANCES)
@pytest.mark.parametrize("name", list(SHAPES))
def test_ssaa_defaults_leave_no_holes(name, dist):
    cam = camera_at(dist)
    frame = render_points_ssaa(shape_scene(name), cam)
    mask, dmax = dense_silhouette(name, cam)
    holes = count_holes(frame, mask, dmax, tol=0.02 * dist)
    assert holes == 0, f"{holes} holes in {name} at distance {dist}"
    assert frame.stats["bbox_miss_samples"] == 0
    # inside the silhouette every subsample is covered too (alpha 1)
    inner = mask & ~np.isnan(dmax)
    for _ in range(2):
        p = np.pad(inner, 1)
        inner = np.logical_and.reduce([p[dy:dy + inner.shape[0], dx:dx + inner.shape[1]]
                                       for dy in range(3) for dx in range(3)])
    partial = np.count_nonzero(frame.color[..., 3][inner] < 1)
    assert partial <= 0.002 * inner.sum(), f"{partial} partly covered pixels inside {name}"


# ---------------------------------------------------------------- errors and statistics

def test_srgb_tables_round_trip():
    lin, thr = ref.srgb_tables()
    assert np.all(np.diff(lin.astype(np.int64)) > 0) and np.all(np.diff(thr.astype(np.int64)) > 0)
    np.testing.assert_array_equal(ref.encode_srgb8(lin, thr), np.arange(256))
    assert 9 * int(lin[-1]) < 2 ** 32


@pytest.mark.parametrize("bad, match", [
    ({"ss": 4}, "ss must be 2"),
    ({"margin": -1.0}, "margin"),
    ({"lod_divisor": 0.5}, "lod_divisor"),
    ({"max_side": 8192}, "max_side"),
    ({"epsilon": 0.95}, "epsilon"),
])
def test_bad_settings_name_the_option(bad, match):
    cam = pl.Camera.look_at((0, 0, 4), (0, 0, 0), size=(32, 32))
    with pytest.raises(pl.SceneError, match=match):
        render_points_ssaa(shape_scene("sphere"), cam, SsaaSettings(**bad))


def test_too_many_tile_pairs_is_a_capacity_error_and_empty_scenes_are_refused():
    cam = pl.Camera.look_at((0, 0, 4), (0, 0, 0), size=(48, 48))
    with pytest.raises(pl.CapacityError, match="max_pairs=3"):
        render_points_ssaa(shape_scene("sphere"), cam, SsaaSettings(max_pairs=3))
    with pytest.raises(pl.SceneError, match="no objects"):
        render_points_ssaa(pl.Scene(), cam)
    with pytest.raises(pl.SceneError, match="tile"):
        LocalFramebufferRenderer([], tile=12)


def test_frame_stats_are_consistent():
    cam = pl.Camera.look_at((0, 0, 4), (0, 0, 0), size=(64, 64))
    f = render_points_ssaa(shape_scene("torus"), cam)
    st = f.stats
    assert st["variant"] == "points-ssaa" and st["ss"] == 2
    assert st["pixels_written"] == st["pixels_resolved"] == np.count_nonzero(f.coverage)
    assert st["samples"] >= st["samples_unique"] > st["pixels_written"]
    assert st["eval_redundancy"] >= 1 and st["local_overdraw"] >= 1
    assert st["tile_patch_pairs"] >= st["render_patches"] - st["unplaced_patches"]
    assert 0 < st["subsample_coverage"] <= 1
    assert st["chunks"] >= st["tiles_nonempty"]
