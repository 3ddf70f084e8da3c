"""The OpenCL LOD stage against its numpy twin, and the stage's invariants."""
import numpy as np
import pytest
import sympy
from hypothesis import given, settings, strategies as st

import paramlod as pl
from paramlod.function.codegen_cl import SPLIT_U, SPLIT_V, position_split
from paramlod.lod import stage as stage_module
from paramlod.lod.reference import lod_step, run_lod
from paramlod.lod.patches import FLAG_FORCED, EVAL_DTYPE, sort_key
from paramlod.core.layouts import camera_record
from helpers.stages import ParametricStage as renderer_for  # a scene's LOD stage and buffers

CAMERAS = [
    ((0, 0, 6), (0, 0, 0)),
    ((0.5, 2.0, 2.5), (0, 0, 0)),
    ((3.0, -1.0, 1.2), (0.2, 0, 0)),
    ((0.2, 0.1, 1.6), (0, 0, 0)),      # close: many patches, some forced or culled
]


def cl_render_list(scene, camera, lod=None, stage=None):
    lod = lod or pl.LodSettings()
    r = stage or renderer_for(scene)
    dev = r.upload(scene, camera)
    _, n, steps, _ = r.lod.run(dev["inst"], dev["domains"], dev["cam"], lod)
    return r.lod.read_render_list(n), steps


def canonical(rp):
    rp = rp[sort_key(rp)]
    return rp["inst"], rp["range"], rp["flags"]


@pytest.mark.parametrize("fname", ["sphere", "torus"])
@pytest.mark.parametrize("eye,target", CAMERAS)
def test_cl_lod_matches_numpy_reference(fname, eye, target):
    scene = pl.Scene()
    scene.add(fname, transform=pl.rotate(30, (1, 0.3, 0)))
    cam = pl.Camera.look_at(eye, target, size=(320, 240))
    lod = pl.LodSettings(threshold=(40.0, 40.0))
    got, steps = cl_render_list(scene, cam, lod)
    ref, ref_steps = run_lod(scene, camera_record(cam), lod)
    assert steps == ref_steps
    gi, gr, gf = canonical(got)
    ri, rr, rf = canonical(ref)
    np.testing.assert_array_equal(gi, ri)
    np.testing.assert_array_equal(gr, rr)   # exact: children ranges are exact float32 halvings
    np.testing.assert_array_equal(gf, rf)
    gext = got["ext"][sort_key(got)]
    rext = ref["ext"][sort_key(ref)]
    np.testing.assert_allclose(gext, rext, rtol=1e-3, atol=1e-3)


@pl.parametric(u=(0, 1), v=(0, 2 * sympy.pi), name="lod_test_ring")
def ring(u, v):
    """A band whose radius costs more in v than anything costs in u: its position splits along v."""
    r = 1 + 0.2 * sympy.sin(3 * v) * sympy.cos(5 * v) + 0.1 * sympy.sqrt(2 + sympy.cos(7 * v)) * sympy.sin(2 * v)
    return u, r * sympy.cos(v), r * sympy.sin(v)


def test_runs_of_split_samples_give_the_same_render_list(monkeypatch):
    # CPU devices: one work-item a patch (LOD_LOCAL_CPU) evaluates its samples in a run, the steps
    # of the position split's parameter once for those sharing it (kernels/lod/lod.cl lod_order);
    # GPUs (SAMPLE_RUNS_CPU False and LOD_LOCAL work-items a patch here): one sample a work-item,
    # the split's 17 values of its parameter evaluated once each and shared in local memory
    # (lod_axis); and runs of 3 in the GPUs' work-groups. Fibre and glyph split along u, the ring
    # along v, the sphere not at all; the render lists are the same, bit for bit
    scene = pl.Scene()
    scene.add("fiber", transform=pl.scale(0.2))
    scene.add("sh_glyph", transform=pl.translate(1.5, 0, 0) @ pl.scale(0.5))
    scene.add("sphere", transform=pl.translate(-1.5, 0, 0) @ pl.scale(0.5))
    scene.add(ring, transform=pl.translate(0, -1.5, 0) @ pl.scale(0.4))
    assert [None if p is None else p.axis for p in map(position_split, scene.functions())] == \
        [SPLIT_U, SPLIT_U, None, SPLIT_V]
    cam = pl.Camera.look_at((0.3, 0.8, 4.0), (0, 0, 0), size=(320, 240))
    lists = []
    for runs, per_slot in ((False, stage_module.LOD_LOCAL), (True, stage_module.LOD_LOCAL_CPU),
                           (True, stage_module.LOD_LOCAL)):
        monkeypatch.setattr(stage_module, "SAMPLE_RUNS_CPU", runs)
        monkeypatch.setattr(stage_module, "LOD_LOCAL_CPU", per_slot)
        got, steps = cl_render_list(scene, cam, pl.LodSettings(threshold=(24.0, 24.0)))
        lists.append((got[sort_key(got)].view(np.uint8), steps))   # in one order (atomics append)
    assert len(lists[0][0]) > 100 * got.dtype.itemsize and len(lists[0][1]) >= 3
    for other in lists[1:]:
        np.testing.assert_array_equal(other[0], lists[0][0])
        assert other[1] == lists[0][1]


def test_stage_follows_the_view_from_far_to_near_and_back():
    """A stage enqueues only the steps the previous one needed, plus one: zooming in past that
    must redo the stage with all steps, never force patches out early."""
    scene = pl.Scene()
    scene.add("torus")
    lod = pl.LodSettings(threshold=(30.0, 30.0))
    far = pl.Camera.look_at((0, 0, 40), (0, 0, 0), size=(320, 240))
    near = pl.Camera.look_at((0, 0.3, 1.4), (0, 0, 0), size=(320, 240))
    owner = renderer_for(scene)
    stage = owner.lod
    depths = []
    for cam in (far, near, near, far):
        got, steps = cl_render_list(scene, cam, lod, owner)
        ref, ref_steps = run_lod(scene, camera_record(cam), lod)
        assert steps == ref_steps
        np.testing.assert_array_equal(canonical(got)[1], canonical(ref)[1])
        assert not (got["flags"] & FLAG_FORCED).any()
        depths.append(max(s["step"] for s in steps if s["in"]))
    assert depths[0] + 2 <= depths[1]          # the near view needs more steps than far + 1
    assert stage._steps_n == depths[1] + 1     # the last stage ran the near view's depth + 1 steps


def test_render_patches_respect_thresholds_unless_forced():
    scene = pl.Scene()
    scene.add("torus")
    cam = pl.Camera.look_at((0, 1.5, 2.2), (0, 0, 0), size=(400, 300))
    lod = pl.LodSettings(threshold=(30.0, 30.0), max_steps=12)
    rp, steps = cl_render_list(scene, cam, lod)
    assert len(rp) > 20
    forced = (rp["flags"] & FLAG_FORCED) != 0
    assert not forced.any()
    assert np.all(rp["ext"][:, 0] <= 30.0) and np.all(rp["ext"][:, 1] <= 30.0)
    # forcing: with only 2 steps the remaining patches come out at step 2, flagged
    rp2, steps2 = cl_render_list(scene, cam, pl.LodSettings(threshold=(30.0, 30.0), max_steps=2))
    f2 = (rp2["flags"] & FLAG_FORCED) != 0
    assert f2.any() and np.all(rp2["flags"][f2] & 15 == 2)
    over = (rp2["ext"][:, 0] > 30) | (rp2["ext"][:, 1] > 30)
    assert np.all(f2[over])
    assert steps2[-1]["forced"] == int(f2.sum())


def test_object_outside_frustum_yields_no_patches():
    scene = pl.Scene()
    scene.add("sphere", transform=pl.translate(0, 0, 20))  # behind the camera
    scene.add("torus", transform=pl.translate(50, 0, 0))   # far to the side
    cam = pl.Camera.look_at((0, 0, 5), (0, 0, 0), size=(128, 128))
    rp, steps = cl_render_list(scene, cam)
    assert len(rp) == 0
    assert steps[0]["culled"] == 2
    frame = pl.render(scene, cam)
    assert not frame.coverage.any()


def _area(rng):
    return (rng[..., 1] - rng[..., 0]).astype(np.float64) * (rng[..., 3] - rng[..., 2])


@settings(max_examples=25, deadline=None)
@given(
    u0=st.floats(0, 3), du=st.floats(0.05, 3), v0=st.floats(0, 6), dv=st.floats(0.05, 6),
    t=st.sampled_from([5.0, 20.0, 80.0]), dist=st.floats(1.6, 8.0),
)
def test_children_tile_their_parent_exactly(u0, du, v0, dv, t, dist):
    """One subdivision step: the children of a patch cover it exactly, without overlap."""
    scene = pl.Scene()
    scene.add("sphere")
    cam = pl.Camera.look_at((0.3, 0.4, dist), (0, 0, 0), size=(200, 200))
    p = np.zeros(1, EVAL_DTYPE)
    p["range"] = [u0, u0 + du, v0, v0 + dv]
    children, rp, stats = lod_step(p, scene.instance_buffers(), scene.functions(),
                                   camera_record(cam).astype(np.float32), t, t, 1, False)
    if stats["culled"] or len(rp):
        assert len(children) == 0
        return
    assert len(children) in (2, 3, 4)
    r = children["range"]
    assert np.isclose(_area(r).sum(), _area(p["range"]).sum(), rtol=1e-6)
    assert np.all(r[:, 0] >= p["range"][0, 0]) and np.all(r[:, 1] <= p["range"][0, 1])
    assert np.all(r[:, 2] >= p["range"][0, 2]) and np.all(r[:, 3] <= p["range"][0, 3])
    # no two children overlap with positive area
    for i in range(len(r)):
        for j in range(i + 1, len(r)):
            ou = min(r[i, 1], r[j, 1]) - max(r[i, 0], r[j, 0])
            ov = min(r[i, 3], r[j, 3]) - max(r[i, 2], r[j, 2])
            assert ou <= 0 or ov <= 0


def test_render_list_tiles_the_visible_domain():
    """No patch is lost: with nothing culled, render patches cover the whole domain exactly."""
    scene = pl.Scene()
    scene.add("sphere")
    cam = pl.Camera.look_at((0, 0, 4.0), (0, 0, 0), size=(256, 256))
    rp, steps = cl_render_list(scene, cam, pl.LodSettings(threshold=(24.0, 24.0)))
    assert sum(s["culled"] for s in steps) == 0
    total = _area(rp["range"]).sum()
    assert np.isclose(total, np.pi * 2 * np.pi, rtol=1e-5)


def test_buffers_grow_instead_of_dropping_patches():
    scene = pl.Scene()
    scene.add("sphere")
    cam = pl.Camera.look_at((0, 0, 3.0), (0, 0, 0), size=(512, 512))
    r = renderer_for(scene)
    # shrink the buffers to force overflow, then check nothing was lost
    from paramlod.lod.stage import _Buffer
    from paramlod.lod.patches import RENDER_DTYPE
    r.lod.bufs = [_Buffer(EVAL_DTYPE, 1), _Buffer(EVAL_DTYPE, 1)]
    r.lod.render = _Buffer(RENDER_DTYPE, 1)
    for b in (*r.lod.bufs, r.lod.render):
        b.capacity = 2  # pretend tiny: the stage must grow and redo the step
    rp, _ = cl_render_list(scene, cam, pl.LodSettings(threshold=(10.0, 10.0)))
    assert len(rp) > 1000
    assert np.isclose(_area(rp["range"]).sum(), 2 * np.pi ** 2, rtol=1e-5)


def test_capacity_limit_is_named():
    scene = pl.Scene()
    scene.add("sphere")
    cam = pl.Camera.look_at((0, 0, 3.0), (0, 0, 0), size=(512, 512))
    with pytest.raises(pl.CapacityError, match="max_patches=100"):
        cl_render_list(scene, cam, pl.LodSettings(threshold=(4.0, 4.0), max_patches=100))


@pl.parametric(u=(0, 1), v=(0, 1))
def overflowing_sheet(u, v):
    # a flat sheet whose far half sits at 3e38: finite in object space, beyond float32 once the
    # instance's scale of 2 is applied on the way to clip space
    return u, v, pl.dsl.where(u > 0.5, 3e38, 0.0)


def test_samples_that_overflow_in_clip_space_are_bad_not_split_forever():
    scene = pl.Scene()
    scene.add(overflowing_sheet, transform=pl.rotate(20, (1, 0, 0)) @ pl.scale(2))
    cam = pl.Camera.look_at((0.5, 0.5, 3), (0.5, 0.5, 0), size=(160, 120))
    lod = pl.LodSettings(threshold=(20.0, 20.0))
    got, steps = cl_render_list(scene, cam, lod)   # before: 2.8 M patches, stopped by patch_budget
    ref, ref_steps = run_lod(scene, camera_record(cam), lod)
    assert steps == ref_steps
    for g, r in zip(canonical(got), canonical(ref)):
        np.testing.assert_array_equal(g, r)
    assert sum(s["in"] for s in steps) < 1_000
    f = pl.render(scene, cam)
    assert (f.object_id == 1).sum() > 0   # the finite half is drawn
