"""Multi-view surfels (paramlod.render_views): one splat of the longest prefix any view that sees
the object asks for, each surfel written into every view whose frustum holds it (layered key
buffers), against the numpy twin and against single-view frames of the same cameras."""
import numpy as np
import pytest

trimesh = pytest.importorskip("trimesh")

import paramlod as pl  # noqa: E402
from paramlod.core.transforms import rotate, scale, translate  # noqa: E402
from paramlod.core.views import Views  # noqa: E402
from paramlod.device.context import cl_device  # noqa: E402
from paramlod.renderers.registry import renderer  # noqa: E402
from paramlod.renderers.shading import LIGHT  # noqa: E402
from paramlod.renderers.targets import KeyBuffer  # noqa: E402
from paramlod.surfels import FixedCount, FixedSize, SurfelError, draw_surfels  # noqa: E402
from paramlod.surfels.build import OrthoCamera  # noqa: E402
from helpers.surfels import ball  # noqa: E402,F401  (the fixture)
from paramlod.surfels.build import reference as ref  # noqa: E402
from paramlod.surfels.render import VIEW_FLOATS, SurfelSplats, _DeviceSurfels  # noqa: E402

ALL = np.uint64(0xFFFFFFFFFFFFFFFF)
SIZE = (64, 48)


def look(eye, target=(0, 0, 0), size=SIZE, fov=40, near=0.5, far=60):
    return pl.Camera.look_at(eye, target, fov_y=fov, size=size, near=near, far=far)


def around(ball, distance, n, size=SIZE):
    """n cameras at ``distance`` from the ball's bounding-sphere centre, looking at it."""
    c, _ = ball.bounding_sphere()
    dirs = [(0, 0, 1), (1, 0, 0), (0, 0, -1), (-1, 0, 0), (0.6, 0.8, 0), (0, 0.6, -0.8)][:n]
    return [look(c + distance * np.asarray(d, float), c, size) for d in dirs]


def splat(cameras, ball, strategy, transform=None, mesh_weight=0.0, object_id=9):
    """Splat through the renderer into cleared keys: (colour keys, aux keys, the splat), keys
    (N, H, W) for a Views, (H, W) for a Camera."""
    keys = KeyBuffer(*cameras.size, layers=len(cameras) if isinstance(cameras, Views) else 1)
    keys.clear()
    r = SurfelSplats()
    sp = r.splat(keys, cameras, ball, strategy, transform, object_id, 0.3, mesh_weight=mesh_weight)
    r._splats = [sp]
    r.collect()
    cl_device().queue.finish()
    ck, ak = keys.read_keys()
    return ck, ak, sp


def assert_twin(ck, ak, rck, rak):
    covered = ck != ALL
    np.testing.assert_array_equal(covered, rck != ALL)                       # same pixels
    np.testing.assert_array_equal(ck >> np.uint64(32), rck >> np.uint64(32))    # same depth bits
    np.testing.assert_array_equal(ak & np.uint64(0xFFF), rak & np.uint64(0xFFF))
    c = (ck[covered] & np.uint64(0xFFFFFFFF)).astype(np.uint32).view(np.uint8).astype(int)
    rc = (rck[covered] & np.uint64(0xFFFFFFFF)).astype(np.uint32).view(np.uint8).astype(int)
    assert c.size == 0 or np.abs(c - rc).max() <= 1                          # shading in float64 vs float32


def six_views(ball):
    """Near and far perspective views, one cut by its near plane, an orthographic one, one facing
    away from the ball and one with the ball beyond its far plane."""
    ortho_view = look((0.4, 0.3, 4.0)).view
    return Views([look((1.5, 1.0, 8.0)), look((9.0, 2.0, -14.0)), look((0.2, 0.1, 2.0), fov=60, near=1.2),
                  OrthoCamera(ortho_view, SIZE, 1.3, 0.5, 10.0), look((0, 0, 5), (0, 0, 10)),
                  look((0, 0, 30), far=20)])


@pytest.mark.parametrize("n_views", [2, 6])
def test_views_match_numpy(ball, n_views):
    views = Views(six_views(ball).cameras[:n_views])
    xform = translate(0.1, -0.2, 0.0) @ rotate(30, (0, 1, 1)) @ scale(1.1)
    ck, ak, sp = splat(views, ball, FixedSize(3.0), xform, mesh_weight=[0.0, 0.4, 0.0, 0.0, 0.0, 0.0][:n_views])
    assert ck.shape == (n_views, SIZE[1], SIZE[0])
    rec = sp.records
    assert rec.shape == (n_views, VIEW_FLOATS)
    rck, rak = ref.splat_discs(*_DeviceSurfels(ball).host, sp.n, rec[:, 40], rec[:, :24], views.records(),
                               rec[:, 24:40], LIGHT, 0.3, 9, mesh_weight=rec[:, 41])
    assert_twin(ck, ak, rck, rak)
    covered = (ck != ALL).reshape(n_views, -1).sum(axis=1)
    assert covered[0] > 100 and covered[1] > 10
    # the views' own laws differ (the far view asks for fewer surfels, with larger discs)
    assert len({float(r) for r in rec[:2, 40]}) == 2
    if n_views == 6:
        assert covered[2] > 500 and covered[3] > 500
        assert covered[4] == 0 and covered[5] == 0    # facing away; beyond far
        per_view = [sp.view_stats(v) for v in range(6)]
        assert [s["drawn"] for s in per_view] == [True] * 4 + [False] * 2
        assert per_view[4]["surfels_drawn"] == per_view[5]["surfels_drawn"] == 0


def test_view_equals_its_single_view_frame_when_the_prefix_is_the_same(ball):
    """Views at one distance ask for one prefix: each layer is the single-view frame's keys,
    bit for bit, also with per-view hand-off weights and a transform."""
    cams = around(ball, 9.0, 4)
    views = Views(cams)
    ck, ak, sp = splat(views, ball, FixedSize(2.0))
    prefixes = [sp.view_stats(v)["view_prefix"] for v in range(4)]
    assert len(set(prefixes)) == 1 and 100 < prefixes[0] < len(ball)
    for v, cam in enumerate(cams):
        sck, sak, one = splat(cam, ball, FixedSize(2.0))
        assert (sck != ALL).sum() > 100
        np.testing.assert_array_equal(ck[v], sck)
        np.testing.assert_array_equal(ak[v], sak)
        # per-view counters: those of the single-view frame (atomics depend on the arrival order)
        st, one_st = sp.view_stats(v), one.stats()
        for k in ("prefix", "surfels_drawn", "pixels_covered", "radius_view"):
            assert st[k] == one_st[k], k
    total = sp.stats()
    assert total["pixels_covered"] == sum(sp.view_stats(v)["pixels_covered"] for v in range(4))
    assert total["views_drawn"] == 4 and total["prefix"] == prefixes[0]

    weights = [0.0, 0.5, 0.25, 0.9]
    xform = translate(0.2, 0.0, -0.3) @ scale(1.3)
    ck, ak, _ = splat(views, ball, FixedCount(900), xform, mesh_weight=weights)
    for v, (cam, w) in enumerate(zip(cams, weights)):
        sck, sak, _ = splat(cam, ball, FixedCount(900), xform, mesh_weight=w)
        np.testing.assert_array_equal(ck[v], sck)
        np.testing.assert_array_equal(ak[v], sak)


def test_view_with_a_shorter_prefix_is_never_coarser(ball):
    """A near view asks for more surfels than a far one: the far view draws the near one's prefix
    with its own disc size, so it covers every pixel its single-view frame covers, at the same
    depth or nearer; the near view is its single-view frame."""
    c, _ = ball.bounding_sphere()
    near, far = look(c + (0, 0, 8.0), c), look(c + (-6.0, 4.0, 12.0), c)
    ck, ak, sp = splat(Views([far, near]), ball, FixedSize(2.0))
    ask = [sp.view_stats(v)["view_prefix"] for v in range(2)]
    assert ask[0] < ask[1] < len(ball)
    assert [sp.view_stats(v)["prefix"] for v in range(2)] == [ask[1], ask[1]]
    sck, sak, _ = splat(near, ball, FixedSize(2.0))
    np.testing.assert_array_equal(ck[1], sck)
    np.testing.assert_array_equal(ak[1], sak)
    fck, _, _ = splat(far, ball, FixedSize(2.0))
    alone = fck != ALL
    assert alone.sum() > 50
    assert np.all(ck[0][alone] != ALL)
    depth = (ck[0][alone] >> np.uint64(32)).astype(np.uint32).view(np.float32)
    assert np.all(depth <= (fck[alone] >> np.uint64(32)).astype(np.uint32).view(np.float32))
    assert (ck[0] != ALL).sum() < 1.3 * alone.sum()        # its own disc size: not bloated


def test_views_that_see_nothing(ball):
    """A view that faces away from the object, even one right next to it (whose law would ask for
    the whole set), draws nothing and asks for nothing; with no view that sees it, nothing is
    splatted at all."""
    c, _ = ball.bounding_sphere()
    seeing = look(c + (0, 0, 20.0), c)
    # just outside the bounding sphere (radius 2: the first surfel's disc covers the ball), looking away
    away = look(c + (0, 0, 2.6), c + (0, 0, 10.0))
    behind_far = look(c + (30.0, 0, 0), c, far=25.0)
    ck, ak, sp = splat(Views([away, seeing, behind_far]), ball, FixedSize(2.0))
    st = [sp.view_stats(v) for v in range(3)]
    assert st[0]["view_prefix"] == len(ball)                # what it would ask for if it saw the ball
    assert [s["drawn"] for s in st] == [False, True, False]
    assert sp.n == st[1]["view_prefix"] < len(ball)
    assert not np.any(ck[0] != ALL) and not np.any(ck[2] != ALL)
    assert st[0]["surfels_drawn"] == st[2]["surfels_drawn"] == 0 and st[1]["surfels_drawn"] > 0
    sck, _, _ = splat(seeing, ball, FixedSize(2.0))
    np.testing.assert_array_equal(ck[1], sck)

    ck, _, sp = splat(Views([away, behind_far]), ball, FixedSize(2.0))
    assert sp.n == 0 and sp.stats()["views_drawn"] == 0 and not np.any(ck != ALL)
    assert sp.stats()["surfels_drawn"] == 0


def test_render_views_through_the_pipeline(ball):
    """pl.render_views with a surfel object: the keys pass draws the layered targets, each view's
    frame has the single-view render's coverage and depth, and its stats the view's counters."""
    assert renderer("surfels").multiview
    scene = pl.Scene()
    so = scene.add_surfels(ball, strategy=FixedSize(2.0))
    cams = around(ball, 9.0, 3, size=(80, 60)) + [look((0, 0, 6), (0, 0, 12), size=(80, 60))]
    frames = pl.render_views(scene, cams)
    assert len(frames) == 4
    for v, (f, cam) in enumerate(zip(frames, cams)):
        one = pl.render(scene, cam)
        np.testing.assert_array_equal(f.coverage, one.coverage)
        np.testing.assert_array_equal(f.depth, one.depth)
        assert np.all(f.object_id[f.coverage] == so.object_id)
        counts = f.stats["view_counts"]["surfels"][0]
        assert counts["pixels_covered"] >= int(f.coverage.sum())
        assert counts["drawn"] == (v < 3)
    assert frames[3].coverage.sum() == 0 and frames[0].coverage.sum() > 200


def test_bad_multiview_input(ball):
    views = Views(around(ball, 9.0, 2))
    with pytest.raises(SurfelError, match="2 views need a key buffer of 2 layers, got 1"):
        draw_surfels(KeyBuffer(*SIZE), views, ball)
    with pytest.raises(SurfelError, match="2 views need one weight each, got 3"):
        splat(views, ball, FixedSize(2.0), mesh_weight=[0.0, 0.1, 0.2])
    with pytest.raises(SurfelError, match="mesh_weight must be in"):
        splat(views, ball, FixedSize(2.0), mesh_weight=[0.0, 1.5])
    st = draw_surfels(KeyBuffer(*SIZE, layers=2), views, ball)
    assert len(st["views"]) == 2 and st["views_drawn"] == 2
