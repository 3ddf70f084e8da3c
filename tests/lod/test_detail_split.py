"""The LOD stage's detail split (LodSettings.detail_angle; kernels/lod/lod.cl line_turns, twin
paramlod.lod.reference.line_turns): a patch splits across a measured line whose world-space
segments turn by more than the angle, so thin SH lobes get the patches they need at any size.
Kernel against twin on glyph fields, and silhouettes against the dense analytic one: the lobes are
no longer drawn short by tess, and the point grid has no holes in them."""
import numpy as np
import pytest
from scipy import ndimage

import paramlod as pl
from paramlod.app.bench import peers
from paramlod.core.layouts import camera_record
from paramlod.lod.reference import line_turns, run_lod
from paramlod.lod.patches import sort_key
from helpers.stages import ParametricStage


def _field(grid, size):
    spec = peers.scene_spec("glyphs8", size, grid=grid)
    field = peers.glyph_field(8, grid)
    return spec, field, peers.paramlod_scene(spec, field), peers.camera_of(spec)


def _settings(angle):
    rs = pl.RenderSettings()
    rs.lod.threshold = (84.0, 84.0)
    rs.lod.detail_angle = angle
    rs.tess.l_max, rs.tess.l_min = 64.0, 8.0
    return rs


def test_line_turns_twin():
    t = np.linspace(0, 1, 8, dtype=np.float32)
    straight = np.stack([t, 2 * t, 0 * t], -1)
    zigzag = straight.copy()
    zigzag[3, 1] += 1.0   # a spike: the segments into and out of it turn back
    w = np.stack([straight, zigzag])
    bad = np.zeros((2, 8), bool)
    cos90 = pl.LodSettings().curve_cos()
    assert line_turns(w, bad, cos90).tolist() == [False, True]
    bad[1, 3] = True   # a bad sample takes its turns out
    assert line_turns(w, bad, cos90).tolist() == [False, False]
    assert not line_turns(w[1:], np.zeros((1, 8), bool), pl.LodSettings(detail_angle=180).curve_cos()).any()


@pytest.mark.parametrize("angle", [90.0, 120.0])
def test_kernel_matches_twin_on_a_glyph_field(angle):
    _, _, scene, cam = _field(4, (160, 160))
    lod = _settings(angle).lod
    got, steps = ParametricStage(scene).render_list(scene, cam, lod)
    ref, ref_steps = run_lod(scene, camera_record(cam), lod)
    assert steps == ref_steps
    assert len(got) > 2 * 16   # the 16 glyphs split for their lobes (one patch each without)
    for g, r in ((got[sort_key(got)], ref[sort_key(ref)]),):
        np.testing.assert_array_equal(g["inst"], r["inst"])
        np.testing.assert_array_equal(g["range"], r["range"])


def test_lobes_are_drawn_whole():
    """A 4 x 4 field of order-8 glyphs at 160 px (about 30 px a glyph): against the dense analytic
    silhouette, tess with the detail split loses at most 2 % (without it: the lobes cut short),
    and the points cover every pixel centre the glyphs cover (without it: holes in the lobes) and
    nothing farther than a pixel from them (a point lands in the pixel it falls in, so the points'
    silhouette is the true one grown by up to a pixel: docs/lod.md)."""
    spec, field, scene, cam = _field(4, (160, 160))
    ref, _ = peers.reference_silhouette(spec, field)
    err, holes, masks = {}, {}, {}
    for angle in (90.0, 180.0):
        for variant in ("tess", "points"):
            mask = masks[variant, angle] = pl.render(scene, cam, variant, _settings(angle)).coverage
            err[variant, angle] = peers.silhouette_error(mask, ref)
            holes[variant, angle] = int((ref & ~mask).sum())
    assert err["tess", 90.0] < 0.02 < err["tess", 180.0], err
    assert holes["points", 90.0] == 0 < holes["points", 180.0], holes
    grown = ndimage.binary_dilation(ref, np.ones((3, 3), bool))
    assert not (masks["points", 90.0] & ~grown).any()


def test_detail_angle_is_checked():
    for bad in (0, -5, 181, "90", True):
        with pytest.raises(pl.SceneError, match="detail_angle must be in"):
            pl.LodSettings(detail_angle=bad).validate()
