"""Thin tubes (``PointSettings.thin_tubes``): a patch whose surface closes around an axis in a loop
of at most 5.35 target pixels is drawn by the direct variant as a curve, with one line around (2 on
opposite sides over 2 pixels, 3 over 3, 5 over 4) (kernels/points/points.cl patch_axes; twin
paramlod.renderers.sampling.grid_counts)."""
import numpy as np
import pytest
from scipy import ndimage

import paramlod as pl
from paramlod.errors import SceneError
from paramlod.lod.patches import RENDER_DTYPE
from paramlod.renderers.points import grid_counts, patch_wraps

from conftest import check_every_sample_once, record_direct_points
from helpers.stages import ParametricStage

CAM = pl.Camera.look_at((0.0, 0.4, 3.0), (0.0, 0.0, 0.0), size=(200, 140))
# rings whose tubes are about 0.2, 0.4, 0.6, 2.7, 0.8, 1.1 and 1.5 pixels across: loops under 1
# pixel, of 1 to 2, one that is no thin tube, and loops of 2 to 3, 3 to 4 and 4 to 5.35
MINOR = (0.0015, 0.003, 0.0045, 0.02, 0.006, 0.0095, 0.0135)
WIDE = 3   # the ring that is no thin tube
NARROW, WIDER = (0, 1, 2, 4), (5, 6)   # the thin rings under a pixel across, and of 1.1 and 1.5


def _rings():
    scene = pl.Scene()
    for k, minor in enumerate(MINOR):
        x, y = (0.75 * k - 1.1, 0.1 * k - 0.15) if k < 4 else (0.75 * k - 3.75, -0.6)
        scene.add("torus", params={"major": 0.3, "minor": minor},
                  transform=pl.translate(x, y, 0.0) @ pl.rotate(25 + 20 * k, (1, 0.2, 0)),
                  material=pl.Material(color=(0.9, 0.6 - 0.08 * k, 0.2 + 0.12 * k)))
    return scene


def _render_list(scene, rs):
    stage = ParametricStage(scene)
    dev = stage.upload(scene, CAM)
    _, n, _, _ = stage.lod.run(dev["inst"], dev["domains"], dev["cam"], rs.lod)
    rl = stage.lod.read_render_list(n)
    return rl, patch_wraps(rl, dev["flags"], dev["domains"])


def test_the_rings_have_loops_of_every_kind():
    rl, wraps = _render_list(_rings(), pl.RenderSettings())
    loop = rl["w"][:, 1][wraps[:, 1]]   # v, the way around the tube: all patches span it whole
    assert wraps[:, 1].all()
    for low, high in ((0, 1), (1, 2), (2, 3), (3, 4), (4, 5.35), (5.35, np.inf)):
        assert ((loop > low) & (loop <= high)).any(), (low, high)


def test_the_kernel_samples_the_curves_the_twin_counts():
    # every sample of the thin tubes' grids visited once, as many as the twin counts, and the keys
    # np.minimum.at over them
    recorded = record_direct_points(pl.PointSettings(), CAM.size, _rings(), CAM)
    check_every_sample_once(*recorded)
    total = recorded[-1]
    off = pl.PointSettings(thin_tubes=False)
    rl, wraps = _render_list(_rings(), pl.RenderSettings())
    nu, nv = grid_counts(rl, off, wraps=wraps)
    assert total < int((nu * nv).sum())


def test_thin_tubes_keep_their_pixels_with_fewer_samples():
    rs_on, rs_off = pl.RenderSettings(), pl.RenderSettings()
    rs_off.points.thin_tubes = False
    on, off = (pl.render(_rings(), CAM, "points", rs) for rs in (rs_on, rs_off))
    # the frames took the samples the twin counts; the rings under a pixel across under half of
    # them (one or 2 lines around instead of 2-5), the wider thin ones under 3/4 (3 or 5 lines
    # around instead of 6-9)
    rl, wraps = _render_list(_rings(), rs_on)
    narrow, wider = np.isin(rl["inst"], NARROW), np.isin(rl["inst"], WIDER)
    counts = []
    for frame, rs in ((on, rs_on), (off, rs_off)):
        nu, nv = grid_counts(rl, rs.points, wraps=wraps)
        assert frame.stats["samples"] == int((nu * nv).sum())
        counts.append([int((nu * nv)[m].sum()) for m in (narrow, wider)])
    assert counts[0][0] < 0.5 * counts[1][0] and counts[0][1] < 0.75 * counts[1][1]
    # each ring drawn as a curve stays one 8-connected ring, covers no more pixels than drawn as a
    # surface (the pixel rule's widening shrinks) and at least its true area (16xSS coverage)
    rs_ref = pl.RenderSettings()
    rs_ref.points.supersample, rs_ref.points.thin_tubes = 4, False
    ref = pl.render(_rings(), CAM, "points", rs_ref)
    for k in range(len(MINOR)):
        mine_on, mine_off = on.object_id == k + 1, off.object_id == k + 1
        area = ref.color[..., 3][ref.object_id == k + 1].sum()
        assert 40 < area <= mine_on.sum() <= mine_off.sum(), k
        assert ndimage.label(mine_on, structure=np.ones((3, 3)))[1] == 1, k
    # the ring that is no thin tube is drawn as before, bit for bit
    wide = off.object_id == WIDE + 1
    np.testing.assert_array_equal(on.rgb8()[wide], off.rgb8()[wide])


@pytest.mark.parametrize("minor, angle, axis", [(0.003, 75, (1, 0.25, 0.05)), (0.0045, 75, (1, 0.25, 0.05)),
                                               (0.0045, 85, (1, 0.2, 0))])
def test_thin_rings_seen_near_edge_on_stay_connected(minor, angle, axis):
    # the measure sums the LOD segments' chords, which fall short of the fastest part of a ring
    # seen near edge on: at one sample a measured pixel along, these rings (drawn with one line
    # around) had a 1-pixel gap; THIN_ALONG samples a pixel close it
    scene = pl.Scene()
    scene.add("torus", params={"major": 0.3, "minor": minor},
              transform=pl.translate(0.3, -0.1, 0.0) @ pl.rotate(angle, axis))
    frame = pl.render(scene, CAM, "points")
    rl, wraps = _render_list(scene, pl.RenderSettings())
    assert wraps[:, 1].all() and (rl["w"][:, 1] <= 2).all()   # one line around
    ring = frame.object_id == 1
    assert ring.sum() > 50
    assert ndimage.label(ring, structure=np.ones((3, 3)))[1] == 1


def test_grid_counts_by_hand():
    # one patch wrapping v, 40 px long along u; loops of 0.8, 1.5, 2.5, 3.5, 5 and 6 px around
    rl = np.zeros(6, RENDER_DTYPE)
    rl["ext"][:, 2] = rl["w"][:, 0] = 40.0
    rl["w"][:, 1] = rl["ext"][:, 3] = (0.8, 1.5, 2.5, 3.5, 5.0, 6.0)
    wraps = np.array([[False, True]] * 6)
    on = pl.PointSettings()
    nu, nv = grid_counts(rl, on, wraps=wraps)
    # 0.8: 3 lines (ceil(1.2) + 1) capped at 2, less the wrap; along at density: ceil(40 * 1.5) + 1
    # 1.5: 4 lines (ceil(2.25) + 1) capped at 2, less the wrap; along 1.2 a pixel: ceil(40 * 1.2) + 1
    # 2.5: 5 lines capped at 3, less the wrap: 2 on opposite sides; along 1.2 a pixel
    # 3.5: 7 lines capped at 4, less the wrap: 3 around; along at density
    # 5: 9 lines capped at 6, less the wrap: 5 around; along at density
    # 6: a surface, 10 lines less the wrap
    assert nv.tolist() == [1, 1, 2, 3, 5, 9] and nu.tolist() == [61, 49, 49, 61, 61, 61]
    off = grid_counts(rl, pl.PointSettings(thin_tubes=False), wraps=wraps)
    assert [x.tolist() for x in off] == [[61] * 6, [2, 3, 4, 6, 8, 9]]
    # pixel-centre and quad coverage rasterize cells, which a one-line tube would lack: no curves;
    # quads take 3 lines around a tube at least
    centre, quad = pl.PointSettings(coverage="centre"), pl.PointSettings(coverage="quad")
    assert centre.curve_factor() == quad.curve_factor() == 0
    assert [x.tolist() for x in grid_counts(rl, centre, wraps=wraps)] == [x.tolist() for x in off]
    assert [x.tolist() for x in grid_counts(rl, quad, wraps=wraps)] == [[61] * 6, [3, 3, 4, 6, 8, 9]]
    # a hybrid tier's target is `scale` times the measured pixels: the loop is measured in it
    assert on.curve_factor(2) == 2 * on.curve_factor() == 2


@pytest.mark.parametrize("density", [0.75, 1.5])
def test_quads_draw_every_tube_with_3_lines_around(density):
    # quad coverage keeps the surface grid, but a tube's grid of 1 or 2 lines around gave quads
    # without area (a line and its wrapped copy) or a flat ribbon: the rings under a pixel across
    # drew no pixel at all. With 3 lines around each ring is drawn
    rs = pl.RenderSettings()
    rs.points.coverage, rs.points.density = "quad", density
    frame = pl.render(_rings(), CAM, "points", rs)
    rl, wraps = _render_list(_rings(), rs)
    _, nv = grid_counts(rl, rs.points, wraps=wraps)
    assert wraps[:, 1].all() and nv.min() == 3
    for k in range(len(MINOR)):
        assert (frame.object_id == k + 1).sum() >= 8, k


def test_thin_tubes_must_be_a_bool():
    with pytest.raises(SceneError, match="thin_tubes must be true or false"):
        pl.PointSettings(thin_tubes="yes").validate()
