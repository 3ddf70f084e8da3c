"""The multi-view LOD stage (one pass for several cameras) against its numpy twin, and what the
shared render list promises each of its views: no view would split a patch of it, it culls only
what every view culls, and so it loses nothing a view renders alone but parts that view culls."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import paramlod as pl
from paramlod.core.layouts import camera_record
from paramlod.core.views import Views, cube_faces, quilt, stereo
from paramlod.lod import stage as stage_module
from paramlod.lod.patches import EVAL_DTYPE, FLAG_FORCED, initial_patches, sort_key
from paramlod.lod.reference import lod_step, run_lod, view_masks
from helpers.stages import ParametricStage

SIZE = (160, 120)


def cl_lod(scene, cameras, lod, stage=None):
    """(render list, per-step stats) of the device stage for ``cameras`` (a Camera or a list)."""
    stage = stage or ParametricStage(scene)
    dev = stage.upload(scene, Views(cameras))
    _, n, steps, _ = stage.lod.run(dev["inst"], dev["domains"], dev["cam"], lod, n_views=dev["n_views"])
    return stage.lod.read_render_list(n), steps


def records(cameras):
    return Views(cameras).records()


def assert_same(got, ref):
    """Integers exact (inst, ranges, flags), measures within the twin's float tolerance."""
    g, r = got[sort_key(got)], ref[sort_key(ref)]
    np.testing.assert_array_equal(g["inst"], r["inst"])
    np.testing.assert_array_equal(g["range"], r["range"])
    np.testing.assert_array_equal(g["flags"], r["flags"])
    for field in ("ext", "w", "bbox"):
        np.testing.assert_allclose(g[field], r[field], rtol=1e-3, atol=1e-3)


def two_objects():
    scene = pl.Scene()
    scene.add("sphere", transform=pl.translate(-6, 0, 0))
    scene.add("torus", transform=pl.translate(6, 0, 0) @ pl.rotate(60, (1, 0, 0)))
    return scene


def look(eye, target, **kw):
    return pl.Camera.look_at(eye, target, size=SIZE, **kw)


def camera_sets():
    """name: (scene, cameras)."""
    centre = look((0.4, 0.6, 3.2), (0, 0, 0))
    return {
        "stereo pair": (one_torus, stereo(centre, 0.3, focus=3.0)),
        "cube faces inside": (one_torus, cube_faces((0.1, 0.05, 0.0), size=96)),
        "cube faces outside": (one_torus, cube_faces((0.3, 0.2, 2.2), size=96)),
        "disjoint objects": (two_objects, [look((-6, 1, 4), (-6, 0, 0)), look((6, 1, 3), (6, 0, 0))]),
        "one view sees nothing": (one_torus, [centre, look((0, 0, 4), (0, 0, 10))]),
        # more views than one work-group projects at once (paramlod.lod.stage.lod_layout), the last
        # chunk part full; and the most views a frame takes
        "quilt of 12": (two_objects, quilt(look((0, 1, 12), (0, 0, 0)), 4, 3, view_cone=60.0)),
        "64 views": (one_torus, quilt(centre, 8, 8)),
    }


def one_torus():
    scene = pl.Scene()
    scene.add("torus", transform=pl.rotate(30, (1, 0.3, 0)))
    return scene


@pytest.mark.parametrize("per_slot", [stage_module.LOD_LOCAL_CPU, stage_module.LOD_LOCAL])
@pytest.mark.parametrize("name", list(camera_sets()))
def test_multi_view_kernel_matches_numpy_twin(name, per_slot, monkeypatch):
    # work-items a view slot: the CPU devices' layout and the GPUs' (lod_layout), both run here
    monkeypatch.setattr(stage_module, "LOD_LOCAL_CPU", per_slot)
    make, cams = camera_sets()[name]
    scene = make()
    lod = pl.LodSettings(threshold=(24.0, 24.0))
    got, steps = cl_lod(scene, cams, lod)
    ref, ref_steps = run_lod(scene, records(cams), lod)
    assert steps == ref_steps
    assert len(got) > 20
    assert_same(got, ref)
    # the twin takes the records as rows too
    ref2, _ = run_lod(scene, records(cams).reshape(len(cams), -1), lod)
    assert ref2.tobytes() == ref.tobytes()


@pytest.mark.parametrize("name", ["cube faces outside", "disjoint objects", "one view sees nothing", "64 views"])
def test_each_render_patch_names_the_views_that_see_it(name):
    """render_views, beside the render list: bit v set where view v sees the patch (kernel ==
    twin exactly); every patch is seen by some view, and a cube face sees only its own side."""
    make, cams = camera_sets()[name]
    scene = make()
    lod = pl.LodSettings(threshold=(24.0, 24.0))
    stage = ParametricStage(scene)
    dev = stage.upload(scene, Views(cams))
    _, n, _, _ = stage.lod.run(dev["inst"], dev["domains"], dev["cam"], lod, n_views=dev["n_views"])
    got, masks = stage.lod.read_render_list(n), stage.lod.read_render_views(n)
    ref = view_masks(got, scene.instance_buffers(), scene.functions(), records(cams))
    np.testing.assert_array_equal(masks, ref)
    assert np.all(masks != 0) and np.all(masks >> np.uint64(len(cams)) == 0)
    per_view = [(masks >> np.uint64(v)) & np.uint64(1) for v in range(len(cams))]
    if name == "cube faces outside":       # the object lies in front of one face, or near its edges
        assert max(int(p.sum()) for p in per_view) > 2 * np.median([int(p.sum()) for p in per_view])
    if name == "one view sees nothing":
        assert int(per_view[1].sum()) == 0 and int(per_view[0].sum()) == n
    best = cams[int(np.argmax([int(p.sum()) for p in per_view]))]
    _, n1, _, _ = stage.lod.run(dev["inst"], dev["domains"], stage.upload(scene, best)["cam"], lod)
    assert n1 and np.all(stage.lod.read_render_views(n1) == 1)   # one view: it sees every patch


def test_a_view_that_sees_nothing_changes_nothing():
    """Adding a camera that looks away from everything gives the other view's list exactly."""
    scene = one_torus()
    cam = look((0.4, 0.6, 3.2), (0, 0, 0))
    away = look((0, 0, 4), (0, 0, 10))
    lod = pl.LodSettings(threshold=(24.0, 24.0))
    alone, steps = cl_lod(scene, [cam], lod)
    both, both_steps = cl_lod(scene, [cam, away], lod)
    assert steps == both_steps
    assert both[sort_key(both)].tobytes() == alone[sort_key(alone)].tobytes()
    nothing, nothing_steps = cl_lod(scene, [away, away], lod)
    assert len(nothing) == 0 and nothing_steps[0]["culled"] == 1


def test_disjoint_views_render_what_each_view_renders():
    """Two cameras that see different objects: the shared list is the union of their own lists."""
    scene = two_objects()
    left, right = look((-6, 1, 4), (-6, 0, 0)), look((6, 1, 3), (6, 0, 0))
    lod = pl.LodSettings(threshold=(24.0, 24.0))
    both, _ = cl_lod(scene, [left, right], lod)
    a, _ = cl_lod(scene, [left], lod)
    b, _ = cl_lod(scene, [right], lod)
    assert set(a["inst"]) == {0} and set(b["inst"]) == {1}
    union = np.concatenate([a, b])
    key = lambda rp: sorted(zip(rp["inst"], map(tuple, rp["range"])))   # noqa: E731
    assert key(both) == key(union)


def test_one_view_through_views_is_the_single_view_stage():
    """One camera as a Views: the twin gives the single record's results bit for bit, the device
    the same patches."""
    scene = pl.Scene()
    scene.add("sphere", transform=pl.rotate(30, (1, 0.3, 0)))
    cam = look((0.2, 0.1, 1.6), (0, 0, 0))
    lod = pl.LodSettings(threshold=(16.0, 16.0))
    got, steps = cl_lod(scene, cam, lod)
    ref, ref_steps = run_lod(scene, camera_record(cam), lod)
    ref1, ref1_steps = run_lod(scene, records([cam]), lod)
    assert ref_steps == ref1_steps == steps
    assert ref.tobytes() == ref1.tobytes()
    assert_same(got, ref)


@pytest.mark.parametrize("n_views", [0, 65, 2.0, True, -1])
def test_n_views_is_checked(n_views):
    scene = one_torus()
    stage = ParametricStage(scene)
    dev = stage.upload(scene, Views([look((0, 0, 4), (0, 0, 0))] * 2))
    with pytest.raises(pl.SceneError, match=f"n_views={n_views!r}"):
        stage.lod.run(dev["inst"], dev["domains"], dev["cam"], pl.LodSettings(), n_views=n_views)


def test_more_views_than_camera_records_is_an_error():
    scene = one_torus()
    stage = ParametricStage(scene)
    dev = stage.upload(scene, look((0, 0, 4), (0, 0, 0)))
    with pytest.raises(pl.SceneError, match="holds 1 camera records, fewer than n_views=3"):
        stage.lod.run(dev["inst"], dev["domains"], dev["cam"], pl.LodSettings(), n_views=3)


# --- never coarser than a single view -----------------------------------------------------------
#
# The shared tree is not always a refinement of each view's own tree, so these tests do not ask
# for one. Where view v would split a patch 1:3 (its lower half cut in u) and another view needs
# the upper half cut too, the shared patch is cut in u as a whole (1:2), and those halves may then
# be fine enough for v while v's own tree holds a patch that is only part of one of them (about 3 %
# of a view's patches, random camera pairs); and a patch v renders whole may be split for another
# view and a part of it culled, a part outside v's frustum too. What the stage promises, and these
# tests check: no view would split a patch of the shared list; it holds nothing that no view sees;
# it culls a patch only if every view culls it; so nothing v renders is lost but parts v culls.

def _area(rng):
    return (rng[..., 1] - rng[..., 0]).astype(np.float64) * (rng[..., 3] - rng[..., 2])


def _overlap(a, b):
    """Area of the overlaps of range a (4,) with ranges b (m, 4)."""
    du = np.minimum(a[1], b[:, 1]) - np.maximum(a[0], b[:, 0])
    dv = np.minimum(a[3], b[:, 3]) - np.maximum(a[2], b[:, 2])
    return (np.maximum(du, 0).astype(np.float64) * np.maximum(dv, 0)).sum()


def _keys(rp):
    return {(int(i), r.tobytes()) for i, r in zip(rp["inst"], rp["range"])}


def _as_eval(rp):
    out = np.zeros(len(rp), EVAL_DTYPE)
    out["range"], out["inst"] = rp["range"], rp["inst"]
    return out


def seen_by(scene, patches, cams):
    """Keys of ``patches`` (eval patches) that some camera of ``cams`` sees (all forced out)."""
    return _keys(lod_step(patches, scene.instance_buffers(), scene.functions(), records(cams), 1.0, 1.0, 1, True)[1])


def stage_with_culled(scene, cams, lod):
    """The twin's multi-view stage step by step: (render list, the patches it culled)."""
    patches = initial_patches(scene.instance_buffers()[0][:, 28:32])
    rendered, culled = [], []
    for step in range(1, lod.max_steps + 1):
        if len(patches) == 0:
            break
        seen = seen_by(scene, patches, cams)
        culled.append(patches[[k not in seen for k in _keys_list(patches)]])
        patches, rp, _ = lod_step(patches, scene.instance_buffers(), scene.functions(), records(cams),
                                  *lod.threshold, step, step == lod.max_steps)
        rendered.append(rp)
    return np.concatenate(rendered), np.concatenate(culled)


def _keys_list(p):
    return [(int(i), r.tobytes()) for i, r in zip(p["inst"], p["range"])]


def assert_fine_enough_for_each_view(scene, multi, cams, lod):
    """Measured by each camera alone (the single-view twin step), no patch of the shared list
    splits, unless forced out at the last step; and every patch is seen by some view."""
    patches = _as_eval(multi[(multi["flags"] & FLAG_FORCED) == 0])
    seen = set()
    for cam in cams:
        children, rendered, _ = lod_step(patches, scene.instance_buffers(), scene.functions(),
                                         camera_record(cam), *lod.threshold, 1, False)
        assert len(children) == 0, "a view would split a patch of the shared render list"
        seen |= _keys(rendered)
    assert seen == _keys(patches), "the shared render list holds a patch that no view sees"


def _camera(eye, target, fov):
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    n = np.linalg.norm(eye)
    if not 2.0 <= n <= 6.0:   # off the surfaces (and under the patch budget), near enough to see detail
        eye = (eye / n if n > 1e-3 else np.array([1.0, 0.0, 0.0])) * np.clip(n, 2.0, 6.0)
    if np.linalg.norm(target - eye) < 0.5:
        target = eye * 0.5
    up = (0, 1, 0) if abs((target - eye)[1]) < 0.99 * np.linalg.norm(target - eye) else (0, 0, 1)
    return pl.Camera.look_at(eye, target, up, fov_y=fov, size=(96, 72))


def property_scene():
    scene = pl.Scene()
    scene.add("sphere", transform=pl.translate(-1.5, 0, 0) @ pl.scale(0.7))
    scene.add("torus", transform=pl.translate(1.5, 0, 0) @ pl.rotate(50, (1, 0, 0)) @ pl.scale(0.6))
    return scene


# cameras 2 to 6 away from the scene's centre, looking at a point near the two objects
eye = st.tuples(*(st.floats(-6.0, 6.0) for _ in range(3)))
target = st.tuples(st.floats(-2.5, 2.5), st.floats(-1.0, 1.0), st.floats(-1.0, 1.0))


@settings(max_examples=25, deadline=None)
@given(views=st.lists(st.tuples(eye, target, st.sampled_from([30.0, 60.0, 100.0])), min_size=2, max_size=3),
       t=st.sampled_from([12.0, 30.0]))
def test_multi_view_list_is_never_coarser_than_a_single_view(views, t):
    cams = [_camera(*v) for v in views]
    scene = property_scene()
    lod = pl.LodSettings(threshold=(t, t), max_steps=10)
    multi, culled = stage_with_culled(scene, cams, lod)
    assert multi.tobytes() == run_lod(scene, records(cams), lod)[0].tobytes()
    assert_fine_enough_for_each_view(scene, multi, cams, lod)
    for cam in cams:
        # culled only where this view (like every other) culls
        assert not seen_by(scene, culled, [cam]), "the shared stage culled a patch a view sees"
        # so a patch the view renders alone lies in shared patches, or in culled ones it culls
        single, _ = run_lod(scene, camera_record(cam), lod)
        for p in single:
            mine = (multi["inst"] == p["inst"]), (culled["inst"] == p["inst"])
            got = _overlap(p["range"], multi["range"][mine[0]]) + _overlap(p["range"], culled["range"][mine[1]])
            np.testing.assert_allclose(got, _area(p["range"]), rtol=1e-6)


def test_kernel_matches_twin_for_random_camera_triples():
    """Random camera triples through the device stage too (the property test uses the twin)."""
    rng = np.random.default_rng(7)
    scene = property_scene()
    stage = ParametricStage(scene)
    lod = pl.LodSettings(threshold=(16.0, 16.0), max_steps=10)
    for _ in range(4):
        cams = []
        for _ in range(3):
            d = rng.normal(size=3)
            cams.append(_camera(d / np.linalg.norm(d) * rng.uniform(2.5, 6), rng.normal(size=3) * 0.8,
                                float(rng.choice([40.0, 90.0]))))
        got, steps = cl_lod(scene, cams, lod, stage)
        ref, ref_steps = run_lod(scene, records(cams), lod)
        assert steps == ref_steps
        assert_same(got, ref)
        assert_fine_enough_for_each_view(scene, got, cams, lod)
