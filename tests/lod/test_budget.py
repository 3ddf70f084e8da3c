"""The LOD stage's per-frame patch budget: a view where every patch keeps splitting stops with a
CapacityError naming patch_budget (device stage and numpy twin alike), through every variant, and
no sane frame comes near the default."""
import re

import numpy as np
import pytest

import paramlod as pl
from paramlod.core.layouts import camera_record
from paramlod.lod.reference import run_lod
from paramlod.lod.stage import LodSettings
from helpers.stages import ParametricStage

SIZE = (48, 36)


def sphere_view():
    scene = pl.Scene()
    scene.add("sphere")
    return scene, pl.Camera.look_at((0, 0.5, 3.0), (0, 0, 0), size=SIZE)


def stage_steps(scene, camera, lod):
    stage = ParametricStage(scene)
    dev = stage.upload(scene, camera)
    _, n, steps, _ = stage.lod.run(dev["inst"], dev["domains"], dev["cam"], lod)
    return n, steps


def made(steps):
    """Patches splitting made: every step's input but the first's."""
    return sum(s["in"] for s in steps[1:])


def test_a_frame_within_its_budget_is_untouched():
    scene, cam = sphere_view()
    n, steps = stage_steps(scene, cam, LodSettings(threshold=(4.0, 4.0)))
    exact = made(steps)
    assert exact > 100
    # exactly at the budget still renders, one patch less is refused
    n2, steps2 = stage_steps(scene, cam, LodSettings(threshold=(4.0, 4.0), patch_budget=exact))
    assert (n2, made(steps2)) == (n, exact)
    with pytest.raises(pl.CapacityError, match=f"patch_budget={exact - 1}"):
        stage_steps(scene, cam, LodSettings(threshold=(4.0, 4.0), patch_budget=exact - 1))


def test_the_numpy_twin_keeps_the_same_budget():
    scene, cam = sphere_view()
    lod = LodSettings(threshold=(8.0, 8.0))
    _, steps = stage_steps(scene, cam, lod)
    exact = made(steps)
    rec = camera_record(cam)
    _, ref_steps = run_lod(scene, rec, LodSettings(threshold=(8.0, 8.0), patch_budget=exact))
    assert made(ref_steps) == exact
    with pytest.raises(pl.CapacityError, match=f"patch_budget={exact - 1}"):
        run_lod(scene, rec, LodSettings(threshold=(8.0, 8.0), patch_budget=exact - 1))


@pytest.mark.parametrize("variant", ["points", "points-ssaa", "tess"])
def test_a_view_where_everything_splits_stops_soon_in_every_variant(variant):
    # a threshold far below a pixel splits every patch at every step, as a degenerate view
    # does: 4^(max_steps-1) patches unbounded; the budget stops it after a few grown stages
    scene, cam = sphere_view()
    rs = pl.RenderSettings()
    rs.lod = LodSettings(threshold=(1e-3, 1e-3), max_steps=12, patch_budget=20000)
    with pytest.raises(pl.CapacityError, match="patch_budget=20000") as exc:
        pl.render(scene, cam, variant=variant, settings=rs)
    assert "raise patch_budget ([render] in a scene file)" in str(exc.value)
    # stopped within a few grown stages of the budget, not after the whole 4^11 split
    made = int(re.search(r"made (\d+) patches", str(exc.value)).group(1))
    assert 20000 < made < 64 * 20000
    # and the state is not poisoned: the next sane frame of the same scene renders
    f = pl.render(scene, cam, variant=variant)
    assert f.stats["pixels_written"] > 0


def test_the_default_budget_is_far_above_a_detailed_frame():
    scene, cam = sphere_view()
    # the default threshold at 1920x1080 with the points-ssaa divisor (the finest a variant measures):
    # a hundred times that (an 8192x8192 frame is 32 times its pixels) is still within the budget
    _, steps = stage_steps(scene, cam.with_size((1920, 1080)), LodSettings(threshold=(21.0, 21.0)))
    assert 100 * made(steps) < LodSettings().patch_budget


@pytest.mark.parametrize("bad", [0, -1, 1.5, True, 1 << 40, "many"])
def test_budget_values_are_checked(bad):
    scene, cam = sphere_view()
    with pytest.raises(pl.SceneError, match="lod patch_budget"):
        stage_steps(scene, cam, LodSettings(patch_budget=bad))
