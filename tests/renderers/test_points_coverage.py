"""Pixel-centre coverage of the direct points (PointSettings.coverage "centre";
kernels/points/points.cl cover_cells): a sample covers the pixels whose centres its grid cell
holds, so silhouettes are the surface's instead of the surface grown by up to a pixel. The cell
test against its numpy twin (paramlod.renderers.sampling.cover_cells), bit for bit, and what it
does to silhouettes and holes."""
import numpy as np
import pyopencl as cl
import pytest

import paramlod as pl
from conftest import sphere_disc
from helpers.holes import count_holes, dense_silhouette
from helpers.silhouettes import glyph_case, iou_of, settings_for
from paramlod import kernels
from paramlod.core.layouts import cl_prelude
from paramlod.device.context import cl_device
from paramlod.device.programs import define_options
from paramlod.function.codegen_cl import cl_dispatch_source
from paramlod.function.registry import get_function
from paramlod.renderers.sampling import COVER_OWN, COVER_REACH, cover_cells, points_cl_defines

PROBE = """
__kernel void probe(__global const float* in, uint n, uint W, uint H, __global uint* out) {
    uint i = get_global_id(0);
    if (i >= n) return;
    __global const float* r = in + 10 * i;
    Placed p;
    p.x = r[0]; p.y = r[1];
    out[i] = cover_cells(p, (float2)(r[2], r[3]), (float2)(r[4], r[5]), (float2)(r[6], r[7]),
                         (float2)(r[8], r[9]), W, H);
}
"""


def _device_cover(rows, size):
    dev = cl_device()
    src = "\n".join([cl_prelude(), kernels.source("common/common.cl"), cl_dispatch_source([get_function("sphere")]),
                     kernels.source("common/keys.cl"), kernels.source("points/points.cl"), PROBE])
    prog = cl.Program(dev.context, src).build(options=list(define_options(points_cl_defines())))
    mf = cl.mem_flags
    inp = cl.Buffer(dev.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(rows, np.float32))
    out = np.zeros(len(rows), np.uint32)
    ob = cl.Buffer(dev.context, mf.WRITE_ONLY, out.nbytes)
    prog.probe(dev.queue, (len(rows),), None, inp, np.uint32(len(rows)), np.uint32(size[0]), np.uint32(size[1]), ob)
    cl.enqueue_copy(dev.queue, out, ob)
    return out


def test_cell_cover_equals_its_twin():
    rng = np.random.default_rng(3)
    n, size = 200_000, (40, 30)
    xy = rng.uniform(0, 1, (n, 2)) * size
    # Jacobian columns from sub-pixel to several pixels a step, some nearly parallel (silhouettes)
    step = rng.uniform(0.05, 1.2, (n, 2)) * 10.0 ** rng.uniform(-1, 3, (n, 1))
    ang = rng.uniform(0, 2 * np.pi, (n, 2))
    ang[: n // 10, 1] = ang[: n // 10, 0] + rng.normal(0, 1e-3, n // 10)
    ju = np.stack([np.cos(ang[:, 0]), np.sin(ang[:, 0])], 1) * (rng.uniform(0.3, 1.0, (n, 1)) / step[:, :1])
    jv = np.stack([np.cos(ang[:, 1]), np.sin(ang[:, 1])], 1) * (rng.uniform(0.3, 1.0, (n, 1)) / step[:, 1:])
    lo = step * rng.uniform(0.3, 0.7, (n, 2))
    hi = step * rng.uniform(0.3, 0.7, (n, 2))
    rows = np.concatenate([xy, ju, jv, lo, hi], 1).astype(np.float32)
    rows[:50, 2:4] = [np.inf, 0.0]   # not finite: the own pixel
    rows[50:100, 4:6] = np.nan
    rows[100:5000, 4:6] = rows[100:5000, 2:4]   # parallel columns: degenerate, the own pixel
    rows[-10000:, 2:6] *= 8.0                    # cells of several pixels: the centres within the reach
    got = _device_cover(rows, size)
    want = cover_cells(rows[:, 0], rows[:, 1], rows[:, 2:4], rows[:, 4:6], rows[:, 6:8], rows[:, 8:10], size)
    np.testing.assert_array_equal(got, want)
    # every kind of answer occurs: none, one or several centres, and the own-pixel fallback
    counts = np.array([bin(b).count("1") for b in want[want != COVER_OWN]])
    assert (counts == 0).any() and (counts == 1).any() and (counts >= 2).any()
    assert (want[:5000] == COVER_OWN).all() and (want[5000:] != COVER_OWN).mean() > 0.95
    big = np.array([bin(b).count("1") for b in want[-10000:] if b != COVER_OWN])
    assert np.median(big) >= 9 and big.max() <= (2 * COVER_REACH + 1) ** 2
    # a centre only within COVER_REACH pixels of the sample's own, never outside the image
    assert not (want[want != COVER_OWN] >> np.uint32((2 * COVER_REACH + 1) ** 2)).any()


@pytest.mark.parametrize("order", [4, 8, 12])
def test_small_glyph_silhouettes_are_the_surfaces(order):
    """Glyphs of 20 pixels: with pixel coverage a point covers the whole pixel it lands in and the
    silhouette is the true one grown by up to a pixel (IoU 0.69-0.75); with centre coverage it
    is the surface's (0.86-0.99 measured)."""
    scene, cam, ref = glyph_case(order, 20)
    iou = {}
    for coverage in ("pixel", "centre"):
        rs = settings_for("points", "noAA")
        rs.points.coverage = coverage
        iou[coverage] = iou_of(pl.render(scene, cam, "points", rs), ref)
    assert iou["centre"] >= 0.85 and iou["centre"] >= iou["pixel"] + 0.1, iou


@pytest.mark.parametrize("name,eye", [("torus", (0.3, 1.9, 1.4)), ("sphere", (0.0, 0.4, 2.4)),
                                      ("torus", (1.2, 0.6, 0.9))])
@pytest.mark.parametrize("coverage", ["centre", "quad"])   # quad: tests/renderers/test_points_quads.py
def test_centre_and_quad_coverage_leave_no_holes(name, eye, coverage):
    scene = pl.Scene()
    scene.add(name)
    cam = pl.Camera.look_at(eye, (0, 0, 0), size=(128, 112))
    rs = pl.RenderSettings()
    rs.points.coverage = coverage
    frame = pl.render(scene, cam, "points", rs)
    mask, dmax, _, _ = dense_silhouette(get_function(name), cam)
    assert mask.sum() > 2000
    assert count_holes(frame, mask, dmax, tol=0.02 * float(np.linalg.norm(eye))) == 0


def test_back_face_culling_leaves_the_limb_whole():
    """A sphere seen with back-face culling on and off: the same pixels. Near the limb the
    projection bends within a step; with cells widened by 1.2 a limb pixel inside the true disc
    was covered only by a back-facing patch's cell, so culling that patch left it empty."""
    scene = pl.Scene()
    scene.add("sphere", transform=pl.rotate(30, (1, 0.3, 0)), material=pl.Material(two_sided=False))
    cam = pl.Camera.look_at((0.4, 0.5, 3.0), (0, 0, 0), size=(48, 48))
    frames = []
    for cull in (True, False):
        rs = pl.RenderSettings(lod=pl.LodSettings(threshold=(4.0, 4.0), backface_cull=cull))
        rs.points.coverage = "centre"
        frames.append(pl.render(scene, cam, "points", rs))
    assert frames[0].stats["render_patches"] < frames[1].stats["render_patches"]
    np.testing.assert_array_equal(frames[0].coverage, frames[1].coverage)
    assert np.array_equal(frames[0].coverage, sphere_disc(cam)[0])   # and it is the true disc
