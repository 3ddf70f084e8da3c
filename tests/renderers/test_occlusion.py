"""Two-phase occlusion culling of the direct points, tile by tile (kernels/points/occlusion.cl,
paramlod.renderers.occlusion): the depth pyramid, the tiles' bounds and the phase decisions against
the numpy twin (paramlod.renderers.occlusion_reference), bounds that hold every sample of a tile, and frames with
culling on that equal those with it off, bit for bit, for a static camera, a moving one, a jump
(what phase 1 wrongly rejects, phase 2 must draw) and an animation."""
import numpy as np
import pyopencl as cl
import pytest
import sympy as sp

import paramlod as pl
from paramlod.core.layouts import camera_record
from paramlod.device.context import cl_device
from paramlod.lod.reference import sampled_range, world_positions
from paramlod.pipeline.driver import scene_state
from paramlod.renderers.occlusion import DepthPyramid, pyramid_levels
from paramlod.renderers.occlusion_reference import (depth_pyramid, grid_at, occluded, tile_bounds, tile_grids,
                                                     tile_spans)
from paramlod.renderers.points import AUTO_MIN_SAVED, AUTO_PROBE, AutoOcclusion, DirectPointRenderer, sampling_args
from paramlod.renderers.targets import KeyBuffer
from paramlod.scene.framing import framing_camera

SIZE = (120, 96)
OUTPUTS = ("color", "depth", "normal", "object_id")


@pl.parametric(u=(0, sp.pi), v=(0, 2 * sp.pi), params={"t": 0.0})
def pulsing(u, v, t):
    """A sphere whose radius follows the scene's time: 0.45 at t = 0 (gaps in the wall), 0.8 at t = 1."""
    r = 0.45 + 0.35 * t
    return r * sp.sin(u) * sp.cos(v), r * sp.sin(u) * sp.sin(v), r * sp.cos(u)


def wall_scene(front="sphere"):
    """A 5 x 5 wall of spheres in front of 25 tori: at t = 1 (or with plain spheres) most of the
    tori are hidden."""
    s = pl.Scene()
    for i in range(5):
        for j in range(5):
            if front == "sphere":
                s.add("sphere", transform=pl.translate(i - 2, j - 2, 0) @ pl.scale(0.8))
            else:
                s.add(front, transform=pl.translate(i - 2, j - 2, 0))
            s.add("torus", transform=pl.translate(i - 2 + 0.3, j - 2, -2) @ pl.scale(0.4))
    return s


def settings(occlusion, ss: int = 1) -> pl.RenderSettings:
    rs = pl.RenderSettings()
    rs.lod.threshold = (8.0, 8.0)
    rs.points.occlusion = occlusion
    rs.points.supersample = ss
    return rs


def camera(x=0.0, y=0.1):
    return pl.Camera.look_at((x, y, 8), (0, 0, -1), size=SIZE)


def points_state(scene):
    return next(r for r in scene_state(scene).renderer_states() if getattr(r, "occlusion", None) is not None)


# --- the pyramid ---------------------------------------------------------------------------------
@pytest.mark.parametrize("size", [(37, 23), (1, 5), (64, 64), (2, 1)])
def test_pyramid_levels_end_at_one_texel(size):
    levels = pyramid_levels(*size)
    assert levels[-1] == (1, 1)
    assert levels[0] == (-(-size[0] // 2), -(-size[1] // 2))
    assert all(a[0] >= b[0] and a[1] >= b[1] for a, b in zip(levels, levels[1:]))


def test_pyramid_equals_the_twin():
    w, h = 37, 23   # odd sides: the last column and row of each level have no partner
    rng = np.random.default_rng(3)
    keys = rng.integers(0, 2 ** 63, size=(h, w), dtype=np.uint64)
    keys[rng.random((h, w)) < 0.3] = np.uint64(0xFFFFFFFFFFFFFFFF)   # cleared pixels: farthest
    keys[:4, :5] = np.uint64(0xFFFFFFFFFFFFFFFF)
    program = DirectPointRenderer(wall_scene().functions()).program
    buf = KeyBuffer(w, h)
    cl.enqueue_copy(cl_device().queue, buf.color, keys)
    pyr = DepthPyramid(program, w, h)
    pyr.enqueue_build(buf)
    got, want = pyr.read(), depth_pyramid(keys)
    assert len(got) == len(want) == len(pyramid_levels(w, h))
    for g, t in zip(got, want):
        np.testing.assert_array_equal(g, t)
    assert want[0][0, 0] == 0xFFFFFFFF and want[-1][0, 0] == 0xFFFFFFFF


# --- the phases against the twin ---------------------------------------------------------------
def _tile_bounds(scene, state, cam, rs, n):
    """The kernel's bounds of every tile of the frame's n render patches, and the render list."""
    d = state.dev
    return state.occlusion.tile_bounds(state.lod.render.buf, n, d["inst"], d["cam"]), state.lod.read_render_list(n)


def _masks(bits: np.ndarray) -> np.ndarray:
    """uint64 masks from bool (n, 64) tile decisions."""
    return (bits.astype(np.uint64) << np.arange(64, dtype=np.uint64)).sum(axis=1, dtype=np.uint64)


@pytest.mark.parametrize("gpu_tiles", [False, True])
def test_bounds_and_phase_decisions_equal_the_twin(gpu_tiles, monkeypatch):
    if gpu_tiles:   # up to 8 x 8 tiles a patch, as GPUs cut them
        monkeypatch.setattr("paramlod.renderers.points.max_tiles", lambda is_gpu: 8)
    scene, cam = wall_scene(), camera()
    rs = settings(True)
    first = pl.render(scene, cam, "points", rs)
    keys_first, _ = scene_state(scene).keys(cam.size).read_keys()
    frame = pl.render(scene, cam, "points", rs)   # static: phase 1 tests against the first frame's keys
    state = points_state(scene)
    n = frame.stats["render_patches"]
    bounds, rl = _tile_bounds(scene, state, cam, rs, n)
    occ = frame.stats["occlusion"]
    assert first.stats["occlusion"]["deferred"] == 0   # no previous frame: all drawn in phase 1

    # the tiles, exactly, and their bounds: the twin's, to float rounding
    most = state.points.occlusion_tiles
    grids = tile_grids(rl, scene.instance_buffers()[0], rs.points, most)
    tiles = grids["u"]["tiles"] * grids["v"]["tiles"]
    used = np.arange(64)[None, :] < tiles[:, None]
    assert tiles.max() > 1, "the tori's patches should have several tiles"
    assert (bounds[~used] == 0).all() and (bounds[used][:, 2] > 0).all()
    twin = tile_bounds(rl, scene.instance_buffers(), scene.functions(), camera_record(cam), rs.points, most)
    np.testing.assert_allclose(bounds[used][:, :4], twin[used][:, :4], rtol=1e-4, atol=0.05)
    np.testing.assert_allclose(bounds[used][:, 4], twin[used][:, 4], rtol=1e-4)

    # phase 1: exactly the tiles the twin finds behind the previous frame's pyramid
    flat = bounds.reshape(-1, 8)
    hidden = occluded(flat, depth_pyramid(keys_first), *cam.size).reshape(n, 64) & used
    early, early_masks = state.occlusion.read_list("early", occ["drawn_first"])
    deferred, deferred_masks = state.occlusion.read_list("deferred", occ["deferred"])
    want_drawn, want_later = _masks(used & ~hidden), _masks(hidden)
    got_later = dict(zip(deferred.tolist(), deferred_masks.tolist()))
    assert got_later == {int(p): int(want_later[p]) for p in np.flatnonzero(want_later)}
    place = {(tuple(r["range"]), int(r["inst"])): k for k, r in enumerate(rl)}
    got_drawn = {place[(tuple(r["range"]), int(r["inst"]))]: int(m) for r, m in zip(early, early_masks)}
    assert got_drawn == {int(p): int(want_drawn[p]) for p in np.flatnonzero(want_drawn)}
    assert occ["tiles_deferred"] == int(hidden.sum())
    # phase 2: the deferred tiles not behind this frame's pyramid after phase 1
    current = state.occlusion.current.read()
    late_bits = ~occluded(flat, current, *cam.size).reshape(n, 64) & hidden
    late, late_masks = state.occlusion.read_list("late", occ["drawn_second"])
    got_late = {place[(tuple(r["range"]), int(r["inst"]))]: int(m) for r, m in zip(late, late_masks)}
    want_late = _masks(late_bits)
    assert got_late == {int(p): int(want_late[p]) for p in np.flatnonzero(want_late)}
    assert occ["occluded"] == int((hidden & ~late_bits).sum())
    assert occ["occluded"] > used.sum() // 5, "the wall hides most tori: phase 2 should cull many tiles"


@pytest.mark.parametrize("fname", ["sphere", "torus", "seashell3", "yarn", "sh_glyph", "giant_worm"])
def test_bounds_hold_every_sample(fname):
    """Every position of a dense grid over a tile (from the line before its first to the line
    after its last: its samples, its quads' corners, its samples' pixel-centre cells) projects
    inside the tile's screen box and no nearer than its near depth."""
    scene = pl.Scene()
    scene.add(fname, transform=pl.rotate(35, (1, 0.4, 0.2)))
    cam = framing_camera(scene, (0.3, 0.5, 1.0), (0, 1, 0), 40.0, (96, 80), margin=0.7)   # partly off-screen
    rs = settings(True)
    frame = pl.render(scene, cam, "points", rs)
    state = points_state(scene)
    n = frame.stats["render_patches"]
    bounds, rl = _tile_bounds(scene, state, cam, rs, n)
    bounds = bounds.astype(np.float64)
    grids = tile_grids(rl, scene.instance_buffers()[0], rs.points, state.points.occlusion_tiles)
    tiles = grids["u"]["tiles"] * grids["v"]["tiles"]
    assert tiles.max() > 1
    rec = camera_record(cam).astype(np.float64)
    view, proj = rec[0:16].reshape(4, 4), rec[16:32].reshape(4, 4)
    t = np.linspace(0, 1, 9, dtype=np.float32)
    tested = fails = 0
    for slot in range(int(tiles.max())):
        p = np.flatnonzero(slot < tiles)
        sub = {axis: {key: val[p] for key, val in grids[axis].items()} for axis in "uv"}
        u0, u1 = tile_spans(sub["u"], slot % sub["u"]["tiles"])
        v0, v1 = tile_spans(sub["v"], slot // sub["u"]["tiles"])
        m = len(p)
        u = np.broadcast_to(u0[:, None, None] + (u1 - u0)[:, None, None] * t[None, None, :], (m, 9, 9))
        v = np.broadcast_to(v0[:, None, None] + (v1 - v0)[:, None, None] * t[None, :, None], (m, 9, 9))
        world, bad = world_positions(scene.instance_buffers(), scene.functions(),
                                     np.broadcast_to(rl["inst"][p].astype(np.int64)[:, None, None], u.shape), u, v)
        e = world.astype(np.float64) @ view[:3, :3].T + view[:3, 3]
        c = e @ proj[:, :3].T + proj[:, 3]
        x = (c[..., 0] / c[..., 3] * 0.5 + 0.5) * cam.size[0]
        y = (0.5 - c[..., 1] / c[..., 3] * 0.5) * cam.size[1]
        depth = -e[..., 2]
        b = bounds[p, slot][:, None, None, :]
        live = (bounds[p, slot, 4] > 0)[:, None, None]   # near 0: never culled, nothing to hold
        slack = 1e-3
        inside = (x >= b[..., 0] - slack) & (x <= b[..., 2] + slack) & (y >= b[..., 1] - slack) & (y <= b[..., 3] + slack)
        nearer = depth >= b[..., 4] * (1 - 1e-6)
        fails += int((live & ~bad & ~(inside & nearer)).sum())
        tested += int(live.sum())
    assert tested > tiles.sum() // 2
    assert fails == 0, f"{fails} positions outside their tile's bound"


def test_grid_lines_equal_the_samples():
    """The twin's grid lines (tile spans are made of them) are the parameters the renderer samples:
    a patch's first and last line are its sampled range, and the line before tile k's first one
    and after its last one stay in it."""
    scene, cam = wall_scene(), camera()
    rs = settings(True)
    frame = pl.render(scene, cam, "points", rs)
    rl = points_state(scene).lod.read_render_list(frame.stats["render_patches"])
    u0, u1, v0, v1 = sampled_range(rl, scene.instance_buffers()[0], rs.points.widen)
    g = tile_grids(rl, scene.instance_buffers()[0], rs.points)
    np.testing.assert_allclose(grid_at(g["u"], np.zeros(len(rl), np.int64)), u0, rtol=0, atol=0)
    np.testing.assert_allclose(grid_at(g["u"], g["u"]["n"] - 1), u1, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(grid_at(g["v"], g["v"]["n"] - 1), v1, rtol=1e-5, atol=1e-6)
    lo, hi = tile_spans(g["v"], g["v"]["tiles"] - 1)
    assert (lo >= v0).all() and (hi <= v1 * (1 + 1e-6) + 1e-6).all() and (lo < hi).all()


# --- the same frames with culling on and off ---------------------------------------------------
def _frames(scene_of, cameras, times, occlusion, ss):
    scene = scene_of()
    rs = settings(occlusion, ss)
    out = []
    for cam, time in zip(cameras, times):
        f = pl.render(scene, cam, "points", rs, time=time).materialize()
        out.append(f)
    return out


STATIC = [camera()] * 3
MOVING = [camera(0.15 * k, 0.1 + 0.05 * k) for k in range(5)]
JUMP = [camera(), camera(), camera(2.5, 1.5), camera(-2.0, -1.0)]   # tori behind the wall come into view


@pytest.mark.parametrize("ss", [1, 2])
@pytest.mark.parametrize("case", ["static", "moving", "jump", "animation"])
def test_frames_equal_without_culling(case, ss):
    if case == "animation":   # the wall shrinks and grows: last frame's pyramid hides tori now seen
        scene_of, cams, times = (lambda: wall_scene(pulsing)), [camera()] * 5, [1.0, 1.0, 0.3, 0.0, 1.0]
    else:
        scene_of, cams = wall_scene, {"static": STATIC, "moving": MOVING, "jump": JUMP}[case]
        times = [0.0] * len(cams)
    on = _frames(scene_of, cams, times, True, ss)
    off = _frames(scene_of, cams, times, False, ss)
    for k, (a, b) in enumerate(zip(on, off)):
        for name in OUTPUTS:
            assert np.array_equal(getattr(a, name), getattr(b, name), equal_nan=True), \
                f"frame {k}: {name} differs with occlusion culling"
        assert "occlusion" in a.stats and "occlusion" not in b.stats
    stats = [f.stats["occlusion"] for f in on]
    assert sum(s["occluded"] for s in stats) > 0
    samples_on, samples_off = (sum(f.stats["samples"] for f in frames) for frames in (on, off))
    if case in ("jump", "animation"):   # phase 1 guessed wrong and phase 2 drew what it rejected
        assert sum(s["drawn_second"] for s in stats[1:]) > 0
        assert samples_on < samples_off
    else:   # a good guess: the hidden tori cost nothing
        assert samples_on < 0.8 * samples_off


@pytest.mark.parametrize("gpu_shape", [False, True])
@pytest.mark.parametrize("coverage", ["pixel", "centre", "quad"])
def test_tiles_draw_the_same_frames_in_every_kernel_shape(coverage, gpu_shape, monkeypatch):
    """Each coverage's tile-by-tile drawing (samples, pixel-centre cells, quads between lines of
    neighbouring tiles), with runs down the grid lines (CPUs) and one sample a work-item (GPUs,
    here compiled for PoCL), along the jumping camera path."""
    if gpu_shape:
        monkeypatch.setattr("paramlod.renderers.points.sample_run", lambda is_gpu: 1)
    frames = {}
    for occlusion in (True, False):
        scene = wall_scene()
        rs = settings(occlusion)
        rs.points.coverage = coverage
        frames[occlusion] = [pl.render(scene, cam, "points", rs).materialize() for cam in JUMP]
    for k, (a, b) in enumerate(zip(frames[True], frames[False])):
        for name in OUTPUTS:
            assert np.array_equal(getattr(a, name), getattr(b, name), equal_nan=True), \
                f"frame {k}: {name} differs with occlusion culling"
    assert sum(f.stats["occlusion"]["occluded"] for f in frames[True]) > 0
    assert sum(f.stats["samples"] for f in frames[True]) < sum(f.stats["samples"] for f in frames[False])


def test_multi_view_frames_and_occlusion_off_draw_in_one_pass():
    scene, cam = wall_scene(), camera()
    assert "occlusion" not in pl.render(scene, cam, "points", settings(False)).stats
    views = pl.render_views(scene, [cam, camera(0.5)], "points", settings(True))
    assert all("occlusion" not in f.stats for f in views)
    with pytest.raises(pl.SceneError, match="occlusion must be true, false or \"auto\""):
        pl.PointSettings(occlusion="yes").validate()


def test_auto_culls_while_it_pays_and_probes_again():
    """occlusion = "auto" (the default): a lone plane hides nothing, so once a culled frame (with a
    pyramid to test against) and an unculled one have been compared, frames are drawn in one pass
    until the probe; the wall of spheres hides most tori, so culling stays on. Images equal those
    drawn without culling."""
    assert pl.PointSettings().occlusion == "auto"
    lone = pl.Scene()
    lone.add("plane")
    frames = [pl.render(lone, camera(), "points", settings("auto")) for _ in range(AUTO_PROBE + 4)]
    culled = ["occlusion" in f.stats for f in frames]
    # frame 0 has no pyramid (it cannot judge), 1 is culled, 2 is not: then one pass until the probe
    assert culled[:3] == [True, True, False]
    probe = 3 + culled[3:].index(True)
    assert culled[3:probe] == [False] * (probe - 3) and probe - 2 == AUTO_PROBE
    off = pl.render(lone, camera(), "points", settings(False)).materialize()
    for f in (frames[1], frames[2], frames[probe]):
        f = f.materialize()
        for name in OUTPUTS:
            assert np.array_equal(getattr(f, name), getattr(off, name), equal_nan=True), name
    wall = wall_scene()
    stats = [pl.render(wall, camera(), "points", settings("auto")).stats for _ in range(6)]
    assert ["occlusion" in st for st in stats] == [True, True, False, True, True, True]
    assert stats[-1]["samples"] < (1 - AUTO_MIN_SAVED) * stats[2]["samples"]


def test_auto_choice_follows_the_samples():
    auto = AutoOcclusion()
    assert auto.cull()
    auto.record(True, 900, judged=False)   # a first frame: nothing to judge by
    assert auto.cull()
    auto.record(True, 900)
    assert not auto.cull()                 # the other kind is measured once
    auto.record(False, 950)                # culling saved 5 %: not enough
    assert not auto.on and not auto.cull()
    for _ in range(AUTO_PROBE - 2):
        auto.record(False, 950)
    assert not auto.cull()
    auto.record(False, 950)
    assert auto.cull()                     # the probe, AUTO_PROBE frames after the last
    auto.record(True, 500)                 # now culling saves half
    assert auto.on and auto.cull()
