"""Silhouettes against the true shape (issue #21): each variant's coverage (alpha >= 1/2 where a
pixel has several samples) against a dense analytic silhouette (the surface tessellated far below
a pixel and rasterized at pixel centres, paramlod.app.bench.peers), as 1 - IoU. SH glyph fields of
orders 4 to 12, seashell 3 and a yarn curve, at 60 and 200 pixels a glyph / object; and the detail
levels that give thin lobes of 20-pixel glyphs the tessellation they need."""
import numpy as np
import pytest

import paramlod as pl
from helpers.silhouettes import glyph_case, iou_of, settings_for
from paramlod.app.bench import peers
from paramlod.renderers.aa import POINT_TIERS, parse_aa
from paramlod.scene.framing import framing_camera

VARIANTS = (("tess", "noAA"), ("tess", "hybrid"), ("points", "noAA"), ("points", "hybrid"))


def _analytic(scene, cam, n=900):
    """Pixel-centre coverage of every instance tessellated n x n over its domain."""
    inst_f, inst_u, params = scene.instance_buffers()
    fns = scene.functions()
    mask = np.zeros(cam.size[::-1], bool)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    for i in range(len(inst_f)):
        fn = fns[inst_u[i, 0]]
        uu, vv = np.meshgrid(np.linspace(*inst_f[i, 28:30], n), np.linspace(*inst_f[i, 30:32], n))
        p = fn.evaluate(uu.ravel(), vv.ravel(), params[inst_u[i, 1]: inst_u[i, 1] + fn.param_count])
        M = inst_f[i, :16].reshape(4, 4)
        xy, w = peers.project(cam, np.asarray(p, np.float64).reshape(-1, 3) @ M[:3, :3].T + M[:3, 3])
        mask |= peers.coverage_mask(xy, faces, cam.size, w, cam.near)
    return mask


@pytest.mark.parametrize("order", [4, 8, 12])
@pytest.mark.parametrize("px", [60, 200])
def test_glyph_fields(order, px):
    scene, cam, ref = glyph_case(order, px)
    iou = {f"{v}-{aa}": iou_of(pl.render(scene, cam, v, settings_for(v, aa)), ref) for v, aa in VARIANTS}
    assert min(iou.values()) >= 0.8, iou
    # a point covers the (sub)pixel it lands in: the points' silhouette is the true one grown by up
    # to a (sub)pixel, so they trail tess (by up to 0.06 here); with quad coverage in their tiers the
    # points draw the sampled polygon's silhouette and agree with tess within the 0.03
    # (measured: at most 0.006)
    assert abs(iou["tess-hybrid"] - iou["points-hybrid"]) <= 0.1, iou
    rs = settings_for("points", "hybrid")
    rs.points.coverage = "quad"
    assert abs(iou["tess-hybrid"] - iou_of(pl.render(scene, cam, "points", rs), ref)) <= 0.03, iou


@pytest.mark.parametrize("order", [4, 8, 12])
def test_hybrid_keeps_the_lobes_of_20_pixel_glyphs(order):
    """Glyphs of 20 pixels: the hybrid's finer tiers draw the thin lobes that noAA cuts short. The
    spot check's cells spread over each patch find the lobes' sub-pixel detail wherever it is
    (measured: points hybrid 0.91 / 0.93 / 0.91, plain points 0.75 / 0.74 / 0.69; with the
    thesis's cells in the patch's middle 0.83 / 0.83 / 0.85, most glyphs stayed in tier 1). Tess
    hybrid with the thesis's inner levels in every tier (TessSettings.inner_measure "extent")
    improves on noAA (0.86 / 0.50 / 0.46); with the default, the longest segment's levels in the
    tiers the spot check sent patches to ("detail"), it reaches 0.97 / 0.97 / 0.96, and the points
    hybrid with quad coverage agrees with it within 0.03 (0.98 / 0.96 / 0.95). That holds where
    both hybrids take the same samples per pixel in each tier, as where the device's multisampling
    stops at 4 (llvmpipe: tess's tiers are 4xMS and 4xSS+4xMS, the points' 4xSS and 16xSS). With
    8xMS (an H100) the tess tiers take twice the points' samples, whose 2 x 2 subsamples put a
    pixel at alpha 1/2 wherever an edge passes within a quarter pixel of its centre (there the
    points with quads trailed tess by 0.065 at order 8 with the middle cells, by 0.021 now); the
    test then asserts only that tess scores at least the points' IoU less 0.03."""
    scene, cam, ref = glyph_case(order, 20)
    points = iou_of(pl.render(scene, cam, "points", settings_for("points", "hybrid")), ref)
    assert points >= 0.88
    noaa = iou_of(pl.render(scene, cam, "tess", settings_for("tess", "noAA")), ref)
    rs = settings_for("tess", "hybrid")
    rs.tess.inner_measure = "extent"
    extent = iou_of(pl.render(scene, cam, "tess", rs), ref)
    tess_frame = pl.render(scene, cam, "tess", settings_for("tess", "hybrid"))
    tess = iou_of(tess_frame, ref)
    assert extent >= noaa + (0.05 if order == 4 else 0.2) and tess >= 0.94, (noaa, extent, tess)
    rs = settings_for("points", "hybrid")
    rs.points.coverage = "quad"
    quads = iou_of(pl.render(scene, cam, "points", rs), ref)
    assert quads >= 0.94
    tess_samples = [parse_aa(t["aa"]).samples_per_pixel for t in tess_frame.stats["tiers"]]
    point_samples = [t.samples_per_pixel for t in POINT_TIERS]
    if tess_samples == point_samples:
        assert abs(quads - tess) <= 0.03, (quads, tess)
    else:   # more multisamples than the points' subsamples: tess may be the more exact
        assert all(t >= p for t, p in zip(tess_samples, point_samples)), tess_samples
        assert tess >= quads - 0.03, (tess_samples, quads, tess)


@pytest.mark.parametrize("name,direction,up", [("seashell3", (0.0, -1.0, 0.35), (0, 0, 1)),
                                                ("yarn", (0.15, 0.1, 1.0), (0, 1, 0))])
@pytest.mark.parametrize("px", [80, 200])
def test_seashell_and_yarn(name, direction, up, px):
    scene = pl.Scene()
    scene.add(name)
    cam = framing_camera(scene, direction, up, 40.0, (px, px), margin=1.0)
    ref = _analytic(scene, cam)
    iou = {f"{v}-{aa}": iou_of(pl.render(scene, cam, v, settings_for(v, aa, 62.0)), ref) for v, aa in VARIANTS}
    assert min(iou.values()) >= 0.8, iou


@pytest.mark.parametrize("order,before,after", [(4, 0.9, 0.97), (8, 0.55, 0.95), (12, 0.5, 0.93)])
def test_detail_levels_draw_the_lobes_of_smallglyph_case(order, before, after):
    """Glyphs of 20 pixels: a patch's 8-sample lines cut across thin lobes, so the tessellation
    level taken from them draws the lobes short. With TessSettings.detail_levels the spot check
    finds the sub-pixel detail and the patch is tessellated for a finer threshold, with inner
    levels from its longest segment (inner_measure "detail"). (Measured here: 0.86 -> 1.00,
    0.50 -> 0.97, 0.46 -> 0.95 for orders 4, 8, 12; with the spot check's cells in the middle of
    the patch, as the thesis has them, 0.95 / 0.95 / 0.94.)"""
    scene, cam, ref = glyph_case(order, 20)
    plain = pl.render(scene, cam, "tess", settings_for("tess", "noAA"))
    detailed = pl.render(scene, cam, "tess", settings_for("tess", "noAA", detail_levels=True))
    iou = iou_of(plain, ref), iou_of(detailed, ref)
    assert iou[0] < before and iou[1] > after, iou
    assert sum(detailed.stats["detail_patches"][1:]) > 0 and plain.stats["detail_patches"][1:] == [0, 0]


@pytest.mark.parametrize("tessellator", ["hardware", "grid"])
@pytest.mark.parametrize("order", [8, 12])
def test_segment_inner_levels_keep_thin_lobes(order, tessellator):
    """Inner levels from the longest LOD segment (TessSettings.inner_measure "segment") instead of
    the polylines' lengths give the fastest part of a patch pixel-long segments: the lobes of
    60-pixel glyphs come out whole, as the points with pixel-centre coverage draw them (measured:
    0.91 / 0.89 -> 0.97 / 0.96-0.97, points 0.98); with the detail levels too, 20-pixel glyphs
    (0.50 / 0.46 -> 0.95 / 0.94)."""
    scene, cam, ref = glyph_case(order, 60)
    rs = settings_for("points", "noAA")
    rs.points.coverage = "centre"
    points = iou_of(pl.render(scene, cam, "points", rs), ref)
    iou = {}
    for measure in ("extent", "segment"):
        rs = settings_for("tess", "noAA")
        rs.tess.tessellator, rs.tess.inner_measure = tessellator, measure
        iou[measure] = iou_of(pl.render(scene, cam, "tess", rs), ref)
    assert iou["segment"] >= 0.95 and iou["segment"] >= iou["extent"] + 0.04, iou
    assert abs(iou["segment"] - points) <= 0.03, (iou, points)
    scene, cam, ref = glyph_case(order, 20)
    rs = settings_for("tess", "noAA", detail_levels=True)
    rs.tess.tessellator, rs.tess.inner_measure = tessellator, "segment"
    assert iou_of(pl.render(scene, cam, "tess", rs), ref) >= 0.9


def test_detail_levels_leave_smooth_shapes_alone():
    scene = pl.Scene()
    scene.add("torus", transform=pl.rotate(50, (1, 0, 0)))
    cam = pl.Camera.look_at((0, 1, 3), (0, 0, 0), size=(64, 48))
    plain = pl.render(scene, cam, "tess", settings_for("tess", "noAA"))
    detailed = pl.render(scene, cam, "tess", settings_for("tess", "noAA", detail_levels=True))
    assert detailed.stats["detail_patches"] == [plain.stats["render_patches"], 0, 0]
    np.testing.assert_array_equal(detailed.color, plain.color)
    with pytest.raises(pl.SceneError, match="detail_levels must be true or false"):
        pl.renderers.tess.TessSettings(detail_levels="yes").validate()
