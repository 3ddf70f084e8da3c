"""The surfel prefix renderer: the splat kernel against its numpy twin, the render law and
strategies, and composition with parametric objects in one key buffer."""
import numpy as np
import pytest

trimesh = pytest.importorskip("trimesh")

import paramlod as pl  # noqa: E402
from paramlod.renderers.targets import KeyBuffer  # noqa: E402
from paramlod.core.layouts import camera_record
from paramlod.renderers.shading import LIGHT  # noqa: E402
from paramlod.surfels import (FixedCount, FixedSize, FrameTimeAdaptive, SurfelError, choose_prefix,  # noqa: E402
                              draw_surfels, render_surfels)
from paramlod.surfels.build import OrthoCamera  # noqa: E402
from helpers.surfels import ball  # noqa: E402,F401  (the fixture)
from paramlod.surfels.build import reference as ref  # noqa: E402
from paramlod.surfels.render import _DeviceSurfels, draw_records, pixel_world_size  # noqa: E402
from paramlod.core.transforms import rotate, scale, translate  # noqa: E402

ALL = np.uint64(0xFFFFFFFFFFFFFFFF)


def ortho_camera(size=(48, 40)):
    view = pl.Camera.look_at((0.4, 0.3, 4.0), (0, 0, 0), size=size).view
    return OrthoCamera(view, size, 1.3, 0.5, 10.0)


@pytest.mark.parametrize("kind", ["perspective", "orthographic", "near plane cuts the object"])
def test_splat_matches_numpy(ball, kind):
    cam = {"perspective": pl.Camera.look_at((1.5, 1.0, 3.2), (0, 0, 0), fov_y=40, size=(48, 40), near=0.5, far=20),
           "orthographic": ortho_camera(),
           "near plane cuts the object": pl.Camera.look_at((0.2, 0.1, 2.0), (0, 0, 0), fov_y=60, size=(48, 40),
                                                           near=1.2, far=20)}[kind]
    xform = translate(0.1, -0.2, 0.0) @ rotate(30, (0, 1, 1)) @ scale(1.1)
    keys = KeyBuffer(*cam.size)
    keys.clear()
    st = draw_surfels(keys, cam, ball, FixedCount(400), transform=xform, object_id=9, specular=0.3)
    ck, ak = keys.read_keys()
    xf, ip = draw_records(cam, xform)
    rck, rak = ref.splat_discs(*_DeviceSurfels(ball).host, 400, np.float32(st["radius_view"]), xf,
                               camera_record(cam), ip, LIGHT, 0.3, 9)
    covered = ck != ALL
    assert covered.sum() > 200
    assert np.array_equal(covered, rck != ALL)                    # same pixels
    assert np.array_equal(ck >> np.uint64(32), rck >> np.uint64(32))   # same depth bits
    assert np.array_equal(ak & np.uint64(0xFFF), rak & np.uint64(0xFFF))
    c = (ck[covered] & np.uint64(0xFFFFFFFF)).astype(np.uint32).view(np.uint8).astype(int)
    rc = (rck[covered] & np.uint64(0xFFFFFFFF)).astype(np.uint32).view(np.uint8).astype(int)
    assert np.abs(c - rc).max() <= 1                                # shading in float64 vs float32
    assert st["pixels_covered"] >= covered.sum()
    assert st["surfels_drawn"] == 400 or (kind.startswith("near") and 300 < st["surfels_drawn"] < 400)


def test_render_law(ball):
    cam = pl.Camera.look_at((0, 0, 12), (0, 0, 0), fov_y=40, size=(64, 64))
    ch = choose_prefix(ball, cam, FixedSize(2.0))
    c, rad = ball.bounding_sphere()
    depth = 12 - c[2] - rad
    r = 2.0 * pixel_world_size(cam, depth) / 2
    assert ch["distance"] == pytest.approx(depth) and not ch["saturated"]
    assert ch["radius"] == pytest.approx(r)
    assert ch["prefix"] == min(len(ball), int(np.ceil(ball.packing / r ** 2)))
    # twice the size in pixels, a quarter of the surfels
    ch4 = choose_prefix(ball, cam, FixedSize(4.0))
    assert ch4["prefix"] == int(np.ceil(ball.packing / (2 * r) ** 2))
    # far away: few surfels; close: all of them, with discs of the set's own spacing
    far = choose_prefix(ball, pl.Camera.look_at((0, 0, 60), (0, 0, 0), size=(200, 200)), FixedSize(2.0))
    near = choose_prefix(ball, pl.Camera.look_at((0, 0, 2.5), (0, 0, 0), size=(800, 800)), FixedSize(2.0))
    assert far["prefix"] < ch["prefix"] and not far["saturated"]
    assert near["prefix"] == len(ball) and near["saturated"]
    assert near["radius"] == pytest.approx(ball.spacing(len(ball)))
    fc = choose_prefix(ball, cam, FixedCount(100))
    assert fc["prefix"] == 100 and fc["radius"] == pytest.approx(np.sqrt(ball.packing / 100))
    # a uniformly scaled object keeps its prefix when the camera backs off by the same factor
    big = choose_prefix(ball, pl.Camera.look_at((0, 0, 24), (0, 0, 0), fov_y=40, size=(64, 64)),
                        FixedSize(2.0), transform=scale(2.0))
    assert big["prefix"] == ch["prefix"]


def test_frame_time_adaptive_update():
    a = FrameTimeAdaptive(target_ms=10.0, size_px=2.0, max_size_px=4.0)
    a.update(10.5)                    # inside [0.9, 1.1]: unchanged
    assert a.size_px == 2.0
    a.update(20.0)                    # factor 2: (3 s + 2 s) / 4
    assert a.size_px == pytest.approx(2.5)
    a.update(5.0)                     # factor 0.5: (3 s + 0.5 s) / 4
    assert a.size_px == pytest.approx(2.5 * 3.5 / 4)
    for _ in range(20):
        a.update(100.0)
    assert a.size_px == 4.0           # clamped to max
    for _ in range(40):
        a.update(0.0)
    assert a.size_px == 1.0           # clamped to min
    ext = FrameTimeAdaptive(target_ms=10.0, external=True)
    ext.observe(40.0)                 # the draw's own time is ignored...
    assert ext.size_px == 2.0
    ext.observe(40.0, external=True)  # ...the application's frame time is used
    assert ext.size_px == pytest.approx(3.5)


def test_adaptive_strategy_in_draws(ball):
    cam = pl.Camera.look_at((0, 0, 4), (0, 0, 0), size=(64, 64))
    a = FrameTimeAdaptive(target_ms=1e-6, size_px=2.0, max_size_px=8.0)   # every frame is too slow
    stats = [render_surfels(ball, cam, a).stats["surfels"] for _ in range(3)]
    # each draw is far slower than the target: the size grows (here straight to the clamp)
    assert [s["size_px"] for s in stats] == [2.0, 8.0, 8.0]
    assert stats[1]["prefix"] < stats[0]["prefix"]


def test_surfels_and_parametric_objects_share_one_buffer(ball):
    """A parametric sphere through the point renderer and a surfel ball in front of it, in one
    Scene: drawn into the same KeyBuffer and resolved once, depth decides per pixel, ids tell them
    apart; with the tess variant the two are composited by depth the same way."""
    scene = pl.Scene()
    scene.add("sphere", transform=translate(0, 0, -1.5) @ scale(1.5))
    placed = translate(0.6, 0, 0.5) @ scale(0.6)
    so = scene.add_surfels(ball, transform=placed, strategy=FixedSize(2.0))
    assert so.object_id == 2
    cam = pl.Camera.look_at((0, 0, 6), (0, 0, 0), fov_y=40, size=(96, 96), near=0.1, far=50)
    frame = pl.render(scene, cam)
    ids = frame.object_id
    assert (ids == 1).sum() > 500 and (ids == 2).sum() > 300
    alone = render_surfels(ball, cam, FixedSize(2.0), transform=placed)
    # the ball is in front: wherever it is drawn alone, it wins in the shared buffer
    assert np.all(ids[alone.coverage] == 2)
    assert np.array_equal(frame.depth[alone.coverage], alone.depth[alone.coverage])
    assert frame.stats["surfels"][0]["prefix"] > 0
    # supersampled points: the surfels are splatted into the same supersampled buffers
    rs = pl.RenderSettings()
    rs.points.supersample = 2
    aa = pl.render(scene, cam, settings=rs)
    assert aa.stats["surfels"][0]["prefix"] > 0
    assert abs(int((aa.object_id == 2).sum()) - int((ids == 2).sum())) < 0.1 * (ids == 2).sum()
    tess = pl.render(scene, cam, variant="tess")
    assert np.all(tess.object_id[alone.coverage] == 2) and (tess.object_id == 1).sum() > 500


def test_render_surfels_and_errors(ball, tmp_path):
    f = render_surfels(ball, size=(64, 48))
    assert f.size == (64, 48) and f.coverage.sum() > 100
    assert np.all(f.object_id[f.coverage] == 1)
    f.save(tmp_path / "ball.png")
    assert (tmp_path / "ball.png").stat().st_size > 0
    keys = KeyBuffer(32, 32)
    cam = pl.Camera.look_at((0, 0, 4), (0, 0, 0), size=(64, 64))
    with pytest.raises(SurfelError, match="key buffer is 32x32"):
        draw_surfels(keys, cam, ball)
    with pytest.raises(SurfelError, match="object_id"):
        draw_surfels(KeyBuffer(64, 64), cam, ball, object_id=5000)
    with pytest.raises(SurfelError, match="count"):
        FixedCount(0)
    with pytest.raises(SurfelError, match="size"):
        FixedSize(0.0)
