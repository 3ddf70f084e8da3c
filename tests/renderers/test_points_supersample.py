"""Supersampled direct points (PointSettings.supersample, the bench's points-4xSS): the downsample
against its numpy twin bit for bit, coverage against the analytic silhouette, settings errors."""
import numpy as np
import pytest

import paramlod as pl
from paramlod.renderers.points_reference import resolve_blocks
from paramlod.pipeline.driver import scene_state
from paramlod.pipeline.settings import RenderSettings

from conftest import sphere_disc


def _settings(ss):
    rs = RenderSettings()
    rs.points.supersample = ss
    return rs


@pytest.mark.parametrize("ss", [2, 3])
def test_downsample_equals_numpy_resolve_of_the_subsample_keys(ss):
    scene = pl.Scene()
    scene.add("torus", transform=pl.rotate(50, (1, 0, 0)), material=pl.Material(color=(0.9, 0.3, 0.1)))
    scene.add("sphere", transform=pl.translate(0.4, 0, 0.3) @ pl.scale(0.5))
    cam = pl.Camera.look_at((0, 1, 3), (0, 0, 0), size=(80, 60))
    frame = pl.render(scene, cam, settings=_settings(ss))
    state = scene_state(scene)
    color_ss, aux_ss = state.subsample_keys(cam.size, ss).read_keys()
    assert color_ss.shape == (60 * ss, 80 * ss)
    color, aux = state.keys(cam.size, ss).read_keys()
    expect_c, expect_a, covered = resolve_blocks(color_ss, aux_ss, 80, 60, ss)
    np.testing.assert_array_equal(color, expect_c)
    np.testing.assert_array_equal(aux, expect_a)
    st = frame.stats
    assert st["supersample"] == ss and st["covered_subsamples"] == int(covered.sum()) > 3000
    assert st["pixels_written"] == int(np.count_nonzero(covered))
    assert st["overdraw"] == pytest.approx(st["atomics"] / st["covered_subsamples"])
    assert set(np.unique(frame.object_id[frame.coverage])) == {1, 2}


def test_alpha_follows_the_true_coverage_of_the_silhouette():
    """A sphere's edge pixels get fractional alpha, closer to the area the disc covers (an 8x8
    analytic reference per pixel) than the all-or-nothing pixels of the plain variant, and closer
    still with 3x3. What remains is a bias: points cover a subsample when any sample lands in
    it, so the silhouette grows by up to one subsample. Inside, alpha is 1 and the colour
    matches the plain render."""
    scene = pl.Scene()
    scene.add("sphere")
    cam = pl.Camera.look_at((0.4, 0.3, 3.2), (0, 0, 0), size=(96, 96))
    fine, fine_depth = sphere_disc(cam.with_size((96 * 8, 96 * 8)))
    truth = fine.reshape(96, 8, 96, 8).mean(axis=(1, 3))
    edge = (truth > 0) & (truth < 1)
    assert edge.sum() > 100
    plain = pl.render(scene, cam)
    err = {1: np.abs(plain.coverage.astype(float) - truth)[edge].mean()}
    for ss in (2, 3):
        frame = pl.render(scene, cam, settings=_settings(ss))
        alpha = frame.color[..., 3]
        err[ss] = np.abs(alpha - truth)[edge].mean()
        assert np.all(np.isin(np.round(alpha * ss * ss), np.arange(ss * ss + 1)))   # k / ss^2
    assert err[3] < err[2] < 0.6 * err[1], err
    inner = truth == 1
    aa = pl.render(scene, cam, settings=_settings(2))
    assert np.all(aa.color[inner, 3] == 1)
    assert np.abs(aa.color[inner, :3] - plain.color[inner, :3]).mean() < 0.01
    # depth is the nearest sample's: between the analytic sphere's nearest point in the pixel
    # and its depth at the pixel centre (to 0.2 %)
    _, depth = sphere_disc(cam)
    nearest = fine_depth.reshape(96, 8, 96, 8).min(axis=(1, 3))
    assert np.all(aa.depth[inner] >= nearest[inner] * 0.998)
    assert np.all(aa.depth[inner] <= depth[inner] * 1.002)


def test_supersample_settings_are_checked(tmp_path, capsys):
    scene = pl.Scene()
    scene.add("sphere")
    cam = pl.Camera.look_at((0, 0, 3), (0, 0, 0), size=(32, 32))
    with pytest.raises(pl.SceneError, match="supersample must be 1"):
        pl.render(scene, cam, settings=_settings(5))
    with pytest.raises(pl.SceneError, match="16384 a side"):
        pl.render(scene, cam.with_size((9000, 16)), settings=_settings(2))
    from paramlod.app.cli import main

    path = tmp_path / "s.toml"
    path.write_text('[camera]\neye = [0, 0, 3]\nsize = [32, 32]\n[render]\naa = "8xMS"\n'
                    '[[objects]]\nfunction = "sphere"\n')
    assert main(["render", str(path), "-o", str(tmp_path / "s.png")]) == 2
    assert "render.aa" in capsys.readouterr().err
    path.write_text(path.read_text().replace('"8xMS"', '"4xSS"'))
    assert main(["render", str(path), "-o", str(tmp_path / "s.png"), "--stats", str(tmp_path / "s.json")]) == 0
    import json

    assert json.loads((tmp_path / "s.json").read_text())["supersample"] == 2
