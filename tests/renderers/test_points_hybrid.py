"""Hybrid anti-aliasing of the direct points (aa = "hybrid"): each render patch is drawn into the
key buffers of its tier (1x, 4xSS, 16xSS), coarsest first, and each finer tier starts from a copy
of the coarser tier's keys in every subsample (kernels/points/subsamples.cl upsample_keys, twin
points_reference.upsample_keys), so the tiers meet per subsample by depth."""
import numpy as np
import pyopencl as cl
import pytest

import paramlod as pl
from paramlod.core.debug_colors import TIER_COLORS
from paramlod.device.context import cl_device
from paramlod.lod.patches import RENDER_DTYPE, TIER_SHIFT
from paramlod.pipeline.driver import scene_state
from paramlod.pipeline.plan import plan
from paramlod.pipeline.settings import RenderSettings
from paramlod.renderers.points_reference import upsample_keys
from paramlod.renderers.sampling import patch_debug_materials
from paramlod.renderers.targets import KeyBuffer, Upsample


def _settings(aa, color_by="material", silhouettes=True):
    rs = RenderSettings()
    rs.lod.threshold = (62.0, 62.0)
    rs.lod.spot_silhouettes = silhouettes
    rs.apply_aa(aa, variant="points")
    rs.points.color_by = color_by
    return rs


SPHERE = pl.translate(0.4, -7.5, 1.0) @ pl.scale(0.7)


def _shells_and_sphere(size=(160, 90)):
    """Seashell 3 far enough for its bumps to be sub-pixel (tiers 1 and 2), and a sphere in front of
    part of it (smooth: tier 0)."""
    scene = pl.Scene()
    scene.add("seashell3", material=pl.Material((0.9, 0.8, 0.7)))
    scene.add("sphere", transform=SPHERE, material=pl.Material((0.2, 0.5, 0.9)))
    cam = pl.Camera.look_at((-0.1, -11.5, 3.0), (-0.1, -3.2, 0.5), (0, 0, 1), size=size)
    return scene, cam


@pytest.mark.parametrize("ratio", [2, 4])
def test_upsample_equals_its_twin(ratio):
    rng = np.random.default_rng(ratio)
    src, dst = KeyBuffer(7, 5, layers=2), KeyBuffer(7 * ratio, 5 * ratio, layers=2)
    color = rng.integers(0, 2**63, (2 * 5, 7), dtype=np.uint64)
    aux = rng.integers(0, 2**63, (2 * 5, 7), dtype=np.uint64)
    q = cl_device().queue
    cl.enqueue_copy(q, src.color, color)
    cl.enqueue_copy(q, src.aux, aux)
    Upsample(ratio).enqueue(src, dst)
    got_c, got_a = dst.read_keys()
    want_c, want_a = upsample_keys(color, aux, ratio)   # layers are rows of one tall image
    np.testing.assert_array_equal(got_c.reshape(want_c.shape), want_c)
    np.testing.assert_array_equal(got_a.reshape(want_a.shape), want_a)
    with pytest.raises(ValueError, match="do not fill"):
        Upsample(ratio).enqueue(src, KeyBuffer(7, 5, layers=2))


def test_smooth_scene_draws_as_plain_points():
    """No patch of a sphere and a torus has sub-pixel detail: without the silhouette rule all of
    them stay in tier 0, and the copies through the 4xSS and 16xSS buffers and the downsample give
    the plain frame's keys. With it, the silhouette patches go to tier 1: the edges get fractional
    coverage, the rest of the frame stays the plain one."""
    scene = pl.Scene()
    scene.add("torus", transform=pl.rotate(50, (1, 0, 0)), material=pl.Material(color=(0.9, 0.3, 0.1)))
    scene.add("sphere", transform=pl.translate(0.4, 0, 0.3) @ pl.scale(0.5))
    cam = pl.Camera.look_at((0, 1, 3), (0, 0, 0), size=(80, 60))
    plain = pl.render(scene, cam, "points", _settings("noAA"))
    plain_keys = scene_state(scene).keys(cam.size, 1).read_keys()
    hybrid = pl.render(scene, cam, "points", _settings("hybrid", silhouettes=False))
    hybrid_keys = scene_state(scene).keys(cam.size, 4).read_keys()
    for got, want in zip(hybrid_keys, plain_keys):
        np.testing.assert_array_equal(got, want)
    st = hybrid.stats
    assert st["aa"] == "hybrid" and st["tiers"] == [1, 4, 16] and st["samples_per_pixel"] == 16
    assert st["tier_patches"] == [st["render_patches"], 0, 0] == [plain.stats["render_patches"], 0, 0]
    np.testing.assert_array_equal(hybrid.color, plain.color)
    edges = pl.render(scene, cam, "points", _settings("hybrid"))
    assert edges.stats["tier_patches"][1] > 0 and edges.stats["tier_patches"][2] == 0
    partial = (edges.color[..., 3] > 0) & (edges.color[..., 3] < 1)
    assert partial.sum() > 50 and not ((plain.color[..., 3] > 0) & (plain.color[..., 3] < 1)).any()

def test_tiers_meet_per_subsample_and_approach_the_reference():
    """The sphere (tier 0) hides seashell 3's finer tiers per subsample: where it covers whole
    pixels the frame is the sphere alone, exactly. Elsewhere the shell's supersampled tiers bring
    it closer to a uniform 16xSS frame than plain points are, with fewer samples than it."""
    scene, cam = _shells_and_sphere()
    hybrid = pl.render(scene, cam, "points", _settings("hybrid"))
    st = hybrid.stats
    assert st["tier_patches"][1] > 0 and st["tier_patches"][2] > 0 and sum(st["tier_patches"]) == st["render_patches"]
    assert sum(sum(s["tiers"]) for s in st["lod_steps"]) == st["render_patches"]
    plain = pl.render(scene, cam, "points", _settings("noAA"))
    uniform = pl.render(scene, cam, "points", _settings("16xSS"))
    alone = pl.Scene()
    alone.add("sphere", transform=SPHERE, material=pl.Material((0.2, 0.5, 0.9)))
    sphere = pl.render(alone, cam, "points", _settings("hybrid"))
    inside = (sphere.color[..., 3] == 1) & (hybrid.object_id == 2)
    assert inside.sum() > 200
    np.testing.assert_array_equal(hybrid.color[inside], sphere.color[inside])
    shell = (uniform.color[..., 3] == 1) & (uniform.object_id == 1)
    err = {name: np.abs(f.color[..., :3] - uniform.color[..., :3])[shell].mean()
           for name, f in (("hybrid", hybrid), ("plain", plain))}
    assert err["hybrid"] < 0.5 * err["plain"], err
    assert st["samples"] < uniform.stats["samples"]   # here most of the shell needs the finest tier


def test_debug_view_colours_patches_by_tier():
    scene, cam = _shells_and_sphere((96, 54))
    frame = pl.render(scene, cam, "points", _settings("hybrid", color_by="tier", silhouettes=False))
    rgb = frame.color[..., :3][frame.coverage]
    dominant = np.argmax(rgb, axis=1)   # tier 0 blue, 1 green, 2 red
    assert (dominant == 2).sum() > 0 and (dominant == 0).sum() > 0
    rl = np.zeros(3, RENDER_DTYPE)
    rl["flags"] = np.arange(3, dtype=np.uint32) << np.uint32(TIER_SHIFT)
    np.testing.assert_array_equal(patch_debug_materials(rl, np.ones((1, 4), np.float32), "tier")[:, :3], TIER_COLORS)


def test_plan_and_per_object_modes():
    scene, cam = _shells_and_sphere((64, 36))
    passes = plan(scene, "points", _settings("hybrid"))
    assert [(p.ss, p.tiers) for p in passes] == [(4, (1, 2, 4))]
    scene.objects[0].aa = "hybrid"   # the shell hybrid, the sphere plain: two passes, composited
    scene._version += 1
    passes = plan(scene, "points", _settings("noAA"))
    assert sorted((p.ss, p.tiers) for p in passes) == [(1, ()), (4, (1, 2, 4))]
    frame = pl.render(scene, cam, "points", _settings("noAA"))
    assert frame.stats["variant"] == "composite" and frame.coverage.any()
    with pytest.raises(pl.SceneError, match="supersamples only"):
        RenderSettings().apply_aa("8xMS", variant="points")


def test_hybrid_in_several_views():
    scene, cam = _shells_and_sphere((64, 36))
    cams = [cam, pl.Camera.look_at((2.0, -11.5, 3.0), (-0.1, -3.2, 0.5), (0, 0, 1), size=(64, 36))]
    frames = pl.render_views(scene, cams, "points", _settings("hybrid"))
    assert len(frames) == 2 and all(f.coverage.sum() > 100 for f in frames)
    assert frames[0].stats["tier_patches"][1:] != [0, 0]
