"""Two-phase occlusion culling of the direct points (kernels/points/occlusion.cl,
paramlod.renderers.occlusion): the depth pyramid and the phase decisions against the numpy twin
(paramlod.renderers.occlusion_reference), bounds that hold every sample of a patch, and frames with
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
from paramlod.renderers.occlusion import DepthPyramid, occlusion_span, pyramid_levels
from paramlod.renderers.occlusion_reference import depth_pyramid, occluded, patch_bounds
from paramlod.renderers.points import AUTO_MIN_SAVED, AUTO_PROBE, AutoOcclusion, DirectPointRenderer
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
def test_bounds_and_phase_decisions_equal_the_twin():
    scene, cam = wall_scene(), camera()
    rs = settings(True)
    first = pl.render(scene, cam, "points", rs)
    keys_first, _ = scene_state(scene).keys(cam.size).read_keys()
    frame = pl.render(scene, cam, "points", rs)   # static: phase 1 tests against the first frame's keys
    state = points_state(scene)
    n = frame.stats["render_patches"]
    rl = state.lod.read_render_list(n)
    bounds = state.occlusion.read_bounds(n)
    occ = frame.stats["occlusion"]
    assert first.stats["occlusion"]["deferred"] == 0   # no previous frame: all drawn in phase 1

    # bounds: the twin's, to float rounding
    twin = patch_bounds(rl, scene.instance_buffers(), scene.functions(), camera_record(cam), rs.points.widen)
    np.testing.assert_allclose(bounds[:, :4], twin[:, :4], rtol=1e-4, atol=0.05)
    np.testing.assert_allclose(bounds[:, 4], twin[:, 4], rtol=1e-4)

    # phase 1: exactly the patches the twin finds behind the previous frame's pyramid
    deferred = np.empty(occ["deferred"], np.uint32)
    if len(deferred):
        cl.enqueue_copy(cl_device().queue, deferred, state.occlusion.deferred)
    span = occlusion_span(cl_device().is_gpu)
    want = np.flatnonzero(occluded(bounds, depth_pyramid(keys_first), *cam.size, span))
    assert sorted(deferred.tolist()) == want.tolist()
    assert occ["drawn_first"] + occ["deferred"] == n
    # phase 2: the deferred ones not behind this frame's pyramid after phase 1
    current = state.occlusion.current.read()
    assert occ["drawn_second"] == int((~occluded(bounds[deferred], current, *cam.size, span)).sum())
    assert occ["occluded"] > n // 5, "the wall hides most tori: phase 2 should cull many patches"


def test_a_box_is_tested_against_texels_near_its_size():
    # a wall at depth 1 over x < 40 of a 64 x 64 frame, background beyond. A box 13 px wide behind
    # it, 3 px from its edge, is culled by the CPUs' test: at the level where at most 8 x 8 texels
    # cover the box they lie on the wall. The 2 x 2 texels of 16 px that cover it (the GPUs' test)
    # reach the background. A box whose margin reaches the edge is culled by neither.
    w = h = 64
    keys = np.full((h, w), np.iinfo(np.uint64).max, np.uint64)
    keys[:, :40] = np.uint64(np.float32(1.0).view(np.uint32)) << np.uint64(32)
    bounds = np.zeros((3, 8), np.float32)
    bounds[:, :4] = [(24, 24, 36, 36), (24, 24, 39.2, 36), (24, 24, 36, 36)]
    bounds[:, 4] = (2.0, 2.0, 0.5)   # nearest depths: behind, behind, in front of the wall
    assert occluded(bounds, depth_pyramid(keys), w, h, 8).tolist() == [True, False, False]
    assert occluded(bounds, depth_pyramid(keys), w, h, 2).tolist() == [False, False, False]


@pytest.mark.parametrize("fname", ["sphere", "torus", "seashell3", "yarn", "sh_glyph", "giant_worm"])
def test_bounds_hold_every_sample(fname):
    """Every position of a dense grid over a render patch's sampled range projects inside its
    screen box and no nearer than its near depth."""
    scene = pl.Scene()
    scene.add(fname, transform=pl.rotate(35, (1, 0.4, 0.2)))
    cam = framing_camera(scene, (0.3, 0.5, 1.0), (0, 1, 0), 40.0, (96, 80), margin=0.7)   # partly off-screen
    rs = settings(True)
    frame = pl.render(scene, cam, "points", rs)
    state = points_state(scene)
    n = frame.stats["render_patches"]
    rl = state.lod.read_render_list(n)
    bounds = state.occlusion.read_bounds(n).astype(np.float64)
    inst_f = scene.instance_buffers()[0]
    u0, u1, v0, v1 = sampled_range(rl, inst_f, rs.points.widen)
    t = np.linspace(0, 1, 17, dtype=np.float32)
    u = np.broadcast_to(u0[:, None, None] + (u1 - u0)[:, None, None] * t[None, None, :], (n, 17, 17))
    v = np.broadcast_to(v0[:, None, None] + (v1 - v0)[:, None, None] * t[None, :, None], (n, 17, 17))
    world, bad = world_positions(scene.instance_buffers(), scene.functions(),
                        np.broadcast_to(rl["inst"].astype(np.int64)[:, None, None], u.shape), u, v)
    rec = camera_record(cam).astype(np.float64)
    view, proj = rec[0:16].reshape(4, 4), rec[16:32].reshape(4, 4)
    e = world.astype(np.float64) @ view[:3, :3].T + view[:3, 3]
    c = e @ proj[:, :3].T + proj[:, 3]
    x = (c[..., 0] / c[..., 3] * 0.5 + 0.5) * cam.size[0]
    y = (0.5 - c[..., 1] / c[..., 3] * 0.5) * cam.size[1]
    depth = -e[..., 2]
    tested = bounds[:, 4] > 0   # near 0: never culled, nothing to hold
    assert tested.sum() > n // 2
    ok = ~bad
    b = bounds[:, None, None, :]
    slack = 1e-3
    inside = (x >= b[..., 0] - slack) & (x <= b[..., 2] + slack) & (y >= b[..., 1] - slack) & (y <= b[..., 3] + slack)
    nearer = depth >= b[..., 4] * (1 - 1e-6)
    fails = tested[:, None, None] & ok & ~(inside & nearer)
    assert not fails.any(), f"{int(fails.sum())} samples outside their patch's bound"


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
