"""Direct point renderer: adaptive sampling options (measure, oversampling, step shrink), their
exact sample-count twin, hole statistics, and no holes with the defaults."""
import warnings
from functools import lru_cache

import numpy as np
import pytest

import paramlod as pl
from paramlod.core.frame import Frame
from helpers.holes import count_holes
from paramlod.renderers.points import PointSettings, grid_counts, side_counts
from paramlod.function.registry import get_function
from paramlod.pipeline.driver import RenderSettings

from conftest import record_direct_points

# the shapes of the no-holes tests: (function, transform); the heart is Johi's heart
SHAPES = {
    "sphere": ("sphere", pl.rotate(30, (1, 0, 0))),
    "torus": ("torus", pl.rotate(60, (1, 0, 0))),
    "heart": ("johis_heart", pl.rotate(-20, (0, 1, 0))),
}
DISTANCES = (2.4, 4.0, 9.0)
SIZE = (112, 112)


def camera_at(dist, size=SIZE):
    return pl.Camera.look_at((0.25 * dist, 0.2 * dist, dist), (0, 0, 0), size=size)


@lru_cache(maxsize=None)
def _dense_world(name, n=1400):
    fn, m = SHAPES[name]
    f = get_function(fn)
    u = np.linspace(*f.u_range, n)
    v = np.linspace(*f.v_range, n)
    uu, vv = np.meshgrid(u, v)
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore")
        p = f.evaluate(uu, vv).reshape(-1, 3)
    p = p[np.all(np.isfinite(p), axis=1)]
    return (np.concatenate([p, np.ones((len(p), 1))], axis=1) @ m.T)


def dense_silhouette(name, cam):
    """Silhouette and per-pixel front depth of SHAPES[name] from a dense numpy sampling (about
    10 samples per pixel side at the sizes used here), and the 3x3-neighbourhood maximum of that
    depth (a drawn sample may lie anywhere in its pixel)."""
    w, h = cam.size
    pw = _dense_world(name)
    e = pw @ cam.view.T
    c = e @ cam.projection.T
    x = (c[:, 0] / c[:, 3] * 0.5 + 0.5) * w
    y = (0.5 - c[:, 1] / c[:, 3] * 0.5) * h
    ok = (x >= 0) & (y >= 0) & (x < w) & (y < h) & (-e[:, 2] > cam.near)
    pix = y[ok].astype(np.int64) * w + x[ok].astype(np.int64)
    depth = np.full(w * h, np.inf)
    np.minimum.at(depth, pix, -e[ok, 2])
    depth = depth.reshape(h, w)
    mask = np.isfinite(depth)
    d = np.where(mask, depth, -np.inf)
    p = np.pad(d, 1, constant_values=-np.inf)
    dmax = np.max([p[dy:dy + h, dx:dx + w] for dy in range(3) for dx in range(3)], axis=0)
    return mask, dmax


def shape_scene(name):
    fn, m = SHAPES[name]
    s = pl.Scene()
    s.add(fn, transform=m)
    return s


# ---------------------------------------------------------------- sample counts and the record hook

def test_factor_and_side_counts_twin():
    d = PointSettings()
    assert d.factor() == np.float32(d.density)   # the defaults keep the foundation's counts
    ext = np.array([0, 0.2, 1, 7.5, 40, 1e9, np.inf, np.nan], np.float32)
    n = side_counts(ext, d)
    assert n.tolist() == [2, 2, 3, 13, 61, 1024, 1024, 1024]
    s = PointSettings(sampling="extent", oversample=2.0, epsilon=0.2)
    assert s.factor() == np.float32(1.5 * 2.0 / 0.8)
    assert side_counts(np.float32([10]), s).tolist() == [int(np.ceil(np.float32(10) * s.factor())) + 1]
    # grid_counts picks e (extent), s (segment) or, for the direct variant's segment sampling,
    # w (s raised to the boundary lines, RenderPatch.w) columns
    from paramlod.lod.patches import RENDER_DTYPE
    rl = np.zeros(1, RENDER_DTYPE)
    rl["ext"] = [[10, 20, 30, 40]]
    rl["w"] = np.float32([[35, 41]])
    assert [a.tolist() for a in grid_counts(rl, s)] == [side_counts(np.float32([10]), s).tolist(),
                                                         side_counts(np.float32([20]), s).tolist()]
    assert [a.tolist() for a in grid_counts(rl, d, boundary=False)] == [[46], [61]]
    # the direct variant: uniform for w would be 54 x 63; boundary strips (the outer sevenths stepped
    # for w, the middle for s) give 2 x ceil(35 * 1.5 / 7) + ceil(30 * 1.5 * 5 / 7) + 1 = 50 and
    # 2 x 9 + 43 + 1 = 62
    assert [a.tolist() for a in grid_counts(rl, d)] == [[50], [62]]
    rl["w"] = np.float32([[30, 40]])   # w = s: not raised, uniform as before
    assert [a.tolist() for a in grid_counts(rl, d)] == [[46], [61]]
    assert grid_counts(rl, s, boundary=False)[0].tolist() == grid_counts(rl, s)[0].tolist()  # extent: no w


@pytest.mark.parametrize("settings", [
    PointSettings(sampling="extent", coverage="pixel"),
    PointSettings(sampling="extent", oversample=2.0, epsilon=0.25, coverage="pixel"),
    PointSettings(oversample=1.5, density=1.0, coverage="pixel"),
], ids=["extent", "extent-os2-eps", "segment-os1.5"])
def test_key_buffer_equals_minimum_at_with_adaptive_options(settings):
    stats, color, pix, key, total = record_direct_points(settings, (80, 64))
    assert stats["samples"] == total
    kept = pix != 0xFFFFFFFF
    expect = np.full(color.size, np.iinfo(np.uint64).max, np.uint64)
    np.minimum.at(expect, pix[kept], key[kept])
    np.testing.assert_array_equal(color, expect)
    assert 0 < stats["atomics"] <= kept.sum()


# ---------------------------------------------------------------- the trade-off, measured

def _render(scene, cam, **opts):
    return pl.render(scene, cam, settings=RenderSettings(points=PointSettings(**opts)))


def test_adaptive_sampling_trades_samples_for_holes():
    scene = shape_scene("torus")
    cam = camera_at(2.4)
    mask, dmax = dense_silhouette("torus", cam)
    tol = 0.02 * 2.4
    base = _render(scene, cam)
    ext = _render(scene, cam, sampling="extent", density=1.0)
    ext_fixed = _render(scene, cam, sampling="extent", density=1.0, oversample=2.0)
    shrink = _render(scene, cam, sampling="extent", density=1.0, epsilon=0.5)
    s = {k: f.stats["samples"] for k, f in
         (("base", base), ("ext", ext), ("ext_fixed", ext_fixed), ("shrink", shrink))}
    holes = {k: count_holes(f, mask, dmax, tol) for k, f in
             (("base", base), ("ext", ext), ("ext_fixed", ext_fixed), ("shrink", shrink))}
    # extents (sum of a line's segments) <= 7 x the longest segment: fewer samples
    assert s["ext"] < 0.6 * s["base"]
    # the fixed factor and the step shrink multiply samples per side by about 2
    assert 3.0 < s["ext_fixed"] / s["ext"] < 4.6
    assert 3.0 < s["shrink"] / s["ext"] < 4.6
    # one sample per measured pixel leaves many 1-pixel holes; either remedy removes most
    assert holes["base"] == 0
    assert holes["ext"] > 100
    assert holes["ext_fixed"] < holes["ext"] / 10 and holes["shrink"] < holes["ext"] / 10
    # overdraw: atomics per written pixel, higher with more samples
    assert ext_fixed.stats["overdraw"] > ext.stats["overdraw"] >= 1.0


def test_count_holes_counts_gaps_inside_the_eroded_silhouette():
    h, w = 20, 30
    depth = np.full((h, w), np.inf, np.float32)
    depth[4:16, 5:25] = 2.0
    frame = Frame(color=np.zeros((h, w, 4), np.float32), depth=depth.copy(),
                  normal=np.zeros((h, w, 3), np.float32), object_id=np.zeros((h, w), np.uint32))
    mask = np.isfinite(depth)
    assert count_holes(frame, mask) == 0
    frame.depth[8, 10] = np.inf            # a 1-pixel hole inside
    frame.depth[4, 12] = np.inf            # on the silhouette's edge row: not a hole after erosion
    assert count_holes(frame, mask) == 1
    assert count_holes(frame, mask, erode=0) == 2
    frame.depth[9, 11] = 3.0                # a surface behind shows through
    assert count_holes(frame, mask) == 1
    assert count_holes(frame, mask, depth=np.full((h, w), 2.0), tol=0.5) == 2
    with pytest.raises(pl.SceneError, match="mask shape"):
        count_holes(frame, mask[:5])


@pytest.mark.parametrize("bad, match", [
    ({"sampling": "threshold"}, "sampling"),
    ({"oversample": 0.5}, "oversample"),
    ({"epsilon": 1.0}, "epsilon"),
    ({"density": 0.0}, "density"),
])
def test_bad_point_settings_name_the_option(bad, match):
    scene = shape_scene("sphere")
    with pytest.raises(pl.SceneError, match=match):
        _render(scene, camera_at(4.0, size=(32, 32)), **bad)


# ---------------------------------------------------------------- no holes with the defaults

@pytest.mark.parametrize("dist", DISTANCES)
@pytest.mark.parametrize("name", list(SHAPES))
def test_direct_defaults_leave_no_holes(name, dist):
    cam = camera_at(dist)
    frame = pl.render(shape_scene(name), cam)
    mask, dmax = dense_silhouette(name, cam)
    assert mask.sum() > 150
    holes = count_holes(frame, mask, dmax, tol=0.02 * dist)
    assert holes == 0, f"{holes} holes in {name} at distance {dist}"
    # the drawn silhouette matches the dense one (only edge pixels may differ)
    assert np.count_nonzero(frame.coverage & ~mask) <= 0.08 * mask.sum()
