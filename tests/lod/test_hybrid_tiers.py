"""The hybrid tiers in the LOD stage (kernels/lod/spot.cl and lod.cl, twin paramlod.lod.reference):
before a patch is rendered at a tier that has a finer one, the spot check compares normals at
sub-pixel offsets with the bilinear blend of their cell's corner normals; a patch with sub-pixel
detail is measured again at the next tier's threshold. Kernel against twin, exactly; smooth
shapes never leave tier 0; seashell 3's bumps go to the finer tiers the farther it is."""
import numpy as np
import pytest
from sympy import exp, sin

import paramlod as pl
from paramlod.app.bench.run import _orbit
from paramlod.app.bench.scenes import SCENARIOS
from paramlod.core.layouts import camera_record
from paramlod.lod.patches import initial_patches, render_tiers, sort_key
from paramlod.lod.reference import camera_rows, grid_silhouettes, run_lod, spot_counts
from paramlod.lod.stage import tier_values
from paramlod.renderers.aa import POINT_TIERS, TESS_TIERS, AAMode, hybrid_tiers, parse_aa, tier_divisors
from paramlod.scene.framing import framing_camera, scene_box
from helpers.stages import ParametricStage

TESS_DIV = tier_divisors(TESS_TIERS, msaa_lod=True)   # thresholds and scales / sqrt(8), sqrt(32)


def _scenario(name, size, dist):
    build, direction, up, threshold, _, _ = SCENARIOS[name]
    scene = build()
    base = framing_camera(scene, direction, up, 40.0, size, margin=1.0)
    lo, hi = scene_box(scene)
    return scene, _orbit(base, (lo + hi) / 2, dist, 0, 1, size), pl.LodSettings(threshold=(threshold, threshold))


def _tiers_by_instance(render_list, n_inst):
    t = render_tiers(render_list)
    return np.array([np.bincount(t[render_list["inst"] == i], minlength=3) for i in range(n_inst)])


@pytest.mark.parametrize("dist,tiers", [(0.6, TESS_DIV), (2.0, tier_divisors(TESS_TIERS)),
                                        (1.0, tier_divisors(POINT_TIERS))])
def test_kernel_matches_twin(dist, tiers):
    scene, cam, lod = _scenario("seashells", (160, 90), dist)
    got, steps = ParametricStage(scene).render_list(scene, cam, lod, tiers=tiers)
    ref, ref_steps = run_lod(scene, camera_record(cam), lod, tiers=tiers)
    assert steps == ref_steps   # per step: promoted patches and patches rendered per tier
    assert sum(s["promoted"] for s in steps) > 0
    g, r = got[sort_key(got)], ref[sort_key(ref)]
    for field in ("inst", "range", "flags"):
        np.testing.assert_array_equal(g[field], r[field])


def test_smooth_shapes_need_no_supersampling():
    """A sphere and a torus have no sub-pixel detail: no patch reaches tier 2. Their silhouette
    patches go to tier 1 (edge anti-aliasing); without the silhouette rule every patch stays in
    tier 0."""
    for name in ("sphere", "torus"):
        for dist in (0.35, 1.0, 4.0):
            scene, cam, lod = _scenario(name, (160, 90), dist)
            stage = ParametricStage(scene)
            got, steps = stage.render_list(scene, cam, lod, tiers=TESS_DIV)
            tiers = np.bincount(render_tiers(got), minlength=3)
            assert tiers[1] > 0 and tiers[2] == 0, (name, dist, tiers)
            lod.spot_silhouettes = False
            got, steps = stage.render_list(scene, cam, lod, tiers=TESS_DIV)
            assert len(got) and not render_tiers(got).any(), (name, dist)
            assert sum(s["promoted"] for s in steps) == 0


def test_silhouette_twin_on_a_sphere():
    """Facing of the 5 x 5 grid: a patch of the sphere's visible middle faces the camera
    everywhere, one across its rim faces both ways, in every view that sees it."""
    s = pl.Scene()
    s.add("sphere")
    inst = s.instance_buffers()
    cam = camera_rows(camera_record(pl.Camera.look_at((0, -4, 0), (0, 0, 0), (0, 0, 1), size=(64, 64))))
    fn = s.functions()[0]
    (u0, u1), (v0, v1) = fn.u_range, fn.v_range
    patches = initial_patches(np.array([[u0, u1, v0, v1]], np.float32), (8, 8))
    sil = grid_silhouettes(patches, inst, s.functions(), cam, np.ones((1, len(patches)), bool))
    assert 0 < sil.sum() < len(patches)
    assert not grid_silhouettes(patches, inst, s.functions(), cam, np.zeros((1, len(patches)), bool)).any()


def test_sub_pixel_bumps_go_to_finer_tiers_with_distance():
    """Seashell 3 (instance 2) has bumps that become sub-pixel as it recedes: its share of patches
    in tiers 1 and 2 grows with distance, and seashell 1, mostly smooth, keeps more of tier 0."""
    finer = []
    for dist in (0.35, 1.0, 2.0):
        scene, cam, lod = _scenario("seashells", (320, 180), dist)
        got, steps = ParametricStage(scene).render_list(scene, cam, lod, tiers=TESS_DIV)
        per = _tiers_by_instance(got, 3)
        assert per.sum() == len(got) == sum(sum(s["tiers"]) for s in steps)
        finer.append(per[2, 1:].sum() / per[2].sum())
        assert per[2, 0] / per[2].sum() <= per[0, 0] / per[0].sum()
    assert finer[0] < finer[1] <= finer[2] and finer[2] > 0.9, finer


def test_without_tiers_nothing_is_checked():
    scene, cam, lod = _scenario("seashells", (160, 90), 2.0)
    got, steps = ParametricStage(scene).render_list(scene, cam, lod)
    assert not render_tiers(got).any() and sum(s["promoted"] for s in steps) == 0


def test_spot_counts_twin():
    """A plane has no detail at any cell size; a seashell 3 patch seen small has a lot."""
    s = pl.Scene()
    s.add("plane")
    s.add("seashell3")
    inst = s.instance_buffers()
    patches = initial_patches(inst[0][:, 28:32])
    n = len(patches)
    small = spot_counts(patches, inst, s.functions(), np.full(n, 20, np.float32), np.full(n, 20, np.float32),
                        np.ones(n, np.float32), np.float32(np.cos(np.radians(20))))
    assert small[0] == 0 and small[1] > 0.5 * 189, small


@pl.parametric(u=(0, 1), v=(0, 1))
def corner_ripples(u, v):
    """A flat sheet with fine ripples near one corner, far from the middle of the domain."""
    return u, v, 0.004 * exp(-((u - 0.86) ** 2 + (v - 0.83) ** 2) / 0.01) * sin(300 * u)


def test_the_spot_check_finds_detail_anywhere_in_a_patch():
    """The cells are spread over the patch: ripples of 0.02 in u (under a pixel when the patch is
    40 pixels wide) near one corner are found, by the twin and by the kernel, and the patch goes
    to a finer tier. (The thesis's cells, side by side over the patch's middle, saw flat sheet
    there: count 0, the patch stayed in tier 0.)"""
    s = pl.Scene()
    s.add(corner_ripples)
    inst = s.instance_buffers()
    patch = initial_patches(inst[0][:, 28:32])
    spot_cos, spot_min = pl.LodSettings().spot()
    count = spot_counts(patch, inst, s.functions(), np.float32([40]), np.float32([40]), np.ones(1, np.float32),
                        spot_cos)
    assert count[0] >= spot_min, count
    # seen 2,000 pixels wide, a ripple spans 40 pixels: no sub-pixel detail
    near = spot_counts(patch, inst, s.functions(), np.float32([2000]), np.float32([2000]), np.ones(1, np.float32),
                       spot_cos)
    assert near[0] == 0, near

    cam = pl.Camera.look_at((0.5, 0.5, 1.6), (0.5, 0.5, 0), size=(48, 48))   # the sheet about 40 px wide
    lod = pl.LodSettings(threshold=(84.0, 84.0), spot_silhouettes=False)
    got, steps = ParametricStage(s).render_list(s, cam, lod, tiers=tier_divisors(POINT_TIERS))
    ref, ref_steps = run_lod(s, camera_record(cam), lod, tiers=tier_divisors(POINT_TIERS))
    assert steps == ref_steps and steps[0]["promoted"] == 1, steps
    g, r = got[sort_key(got)], ref[sort_key(ref)]
    np.testing.assert_array_equal(g["range"], r["range"])
    np.testing.assert_array_equal(g["flags"], r["flags"])
    assert render_tiers(got).min() >= 1


def test_settings_and_modes_are_checked():
    assert parse_aa("hybrid").hybrid and parse_aa(" Hybrid ").name == "hybrid"
    assert hybrid_tiers("tess", 4)[1:] == (AAMode(1, 4), AAMode(2, 4))
    assert tier_divisors(POINT_TIERS) == ((2.0, 2.0), (4.0, 4.0))
    assert tier_divisors(TESS_TIERS) == ((1.0, 8 ** 0.5), (2.0, 32 ** 0.5))   # thresholds as uniform 8xMS, 4xSS+8xMS
    max_tier, tier_t, scale = tier_values(pl.LodSettings(threshold=(84.0, 42.0)), ((2.0, 3.0), (4.0, 5.0)))
    assert max_tier == 2 and tier_t.tolist() == [42.0, 21.0, 21.0, 10.5] and scale.tolist() == [3.0, 5.0]
    with pytest.raises(pl.SceneError, match="tier divisors and scales must grow"):
        tier_values(pl.LodSettings(), ((4.0, 4.0), (2.0, 2.0)))
    with pytest.raises(pl.SceneError, match="must be"):
        tier_values(pl.LodSettings(), (2.0, 4.0))
    for bad in (0, 180, "20", True):
        with pytest.raises(pl.SceneError, match="spot_angle must be in"):
            pl.LodSettings(spot_angle=bad).validate()
    for bad in (0, 1.5, None):
        with pytest.raises(pl.SceneError, match="spot_share must be a share"):
            pl.LodSettings(spot_share=bad).validate()
