"""Quad coverage of the direct points (PointSettings.coverage "quad"; kernels/points/points.cl
quad_vertex, cover_triangle): the quads between neighbouring samples of a patch's grid cover the
pixels whose centres they hold, as a rasterizer covers a mesh of the sample grid. The triangle
test against its numpy twin (paramlod.renderers.sampling.cover_triangle), bit for bit, and what it
does to silhouettes (its holes: test_points_coverage.py, with centre coverage's)."""
import numpy as np
import pyopencl as cl
import pytest

import paramlod as pl
from conftest import sphere_disc
from helpers.silhouettes import glyph_case, iou_of, settings_for
from paramlod import kernels
from paramlod.core.layouts import camera_record, cl_prelude
from paramlod.core.shading import LIGHT
from paramlod.device.context import cl_device
from paramlod.device.programs import define_options
from paramlod.function.codegen_cl import cl_dispatch_source
from paramlod.function.registry import get_function
from paramlod.renderers.sampling import cover_triangle, points_cl_defines

PROBE = """
__kernel void probe(__global const float* tri, __global const float* cam, __global const float* light,
                    __global ulong* color, __global ulong* aux, uint pixels) {
    uint i = get_global_id(0);
    __global const float* t = tri + 9 * i;
    QuadVertex q[3];
    for (uint k = 0; k < 3; ++k) {
        q[k].x = t[3 * k]; q[k].y = t[3 * k + 1]; q[k].depth = t[3 * k + 2];
        q[k].e = (float3)(0.0f, 0.0f, -q[k].depth); q[k].n = (float3)(0.0f, 0.0f, 1.0f); q[k].state = SAMPLE_DRAWN;
    }
    cover_triangle(q[0], q[1], q[2], cam, (float4)(0.8f, 0.8f, 0.8f, 0.0f), light, 1u, color + i * pixels,
                   aux + i * pixels);
}
"""
SIZE = (12, 10)


def _device_cover(tris):
    dev = cl_device()
    src = "\n".join([cl_prelude(), kernels.source("common/common.cl"), cl_dispatch_source([get_function("sphere")]),
                     kernels.source("common/keys.cl"), kernels.source("points/points.cl"), PROBE])
    prog = cl.Program(dev.context, src).build(options=list(define_options(points_cl_defines())))
    mf = cl.mem_flags
    cam = pl.Camera.look_at((0, 0, 3), (0, 0, 0), size=SIZE)
    bufs = [cl.Buffer(dev.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(a, np.float32))
            for a in (tris, camera_record(cam), LIGHT)]
    pixels = SIZE[0] * SIZE[1]
    keys = np.full(len(tris) * pixels, np.iinfo(np.uint64).max, np.uint64)
    color = cl.Buffer(dev.context, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=keys)
    aux = cl.Buffer(dev.context, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=keys)
    prog.probe(dev.queue, (len(tris),), None, *bufs, color, aux, np.uint32(pixels))
    cl.enqueue_copy(dev.queue, keys, color)
    return keys.reshape(len(tris), pixels)


def _edge_distance(t, pix):
    """Pixels' centres' distance (float64 pixels) to the nearest edge of triangle t (rows x, y, depth)."""
    q = np.stack([pix % SIZE[0] + 0.5, pix // SIZE[0] + 0.5], 1)
    p = t[:, :2].astype(np.float64)
    out = np.full(len(pix), np.inf)
    for a, b in ((0, 1), (1, 2), (2, 0)):
        e = p[b] - p[a]
        cross = e[0] * (q[:, 1] - p[a, 1]) - e[1] * (q[:, 0] - p[a, 0])
        out = np.minimum(out, np.abs(cross) / max(np.hypot(*e), 1e-30))
    return out


def test_triangle_cover_equals_its_twin():
    rng = np.random.default_rng(5)
    n = 6000
    w, h = SIZE
    centre = rng.uniform(-2, 14, (n, 1, 2))
    spread = 10.0 ** rng.uniform(-1.5, 1.2, (n, 1, 1))      # from a tenth of a pixel to a screen
    xy = centre + rng.normal(0, 1, (n, 3, 2)) * spread
    xy[: n // 20, 2] = xy[: n // 20, 0] + (xy[: n // 20, 1] - xy[: n // 20, 0]) * 0.5   # no area
    xy[n // 20: n // 10] = np.round(xy[n // 20: n // 10] * 2) / 2                         # corners on centres
    depth = rng.uniform(1, 5, (n, 3, 1))
    tris = np.concatenate([xy, depth], axis=2).astype(np.float32).reshape(n, 9)
    keys = _device_cover(tris)
    # NVIDIA's compiler fuses the edge functions' multiply-adds whatever FP_CONTRACT says: a centre
    # within float rounding of an edge may fall either side there, and depths differ in the last bits
    exact = not cl_device().is_gpu
    sizes = []
    for i in range(n):
        t = tris[i].reshape(3, 3)
        pix, d = cover_triangle(t[0], t[1], t[2], SIZE)
        got = np.flatnonzero(keys[i] != np.iinfo(np.uint64).max)
        depth = (keys[i][got] >> np.uint64(32)).astype(np.uint32).view(np.float32)
        if exact:
            np.testing.assert_array_equal(got, pix, err_msg=f"triangle {i}: {t.tolist()}")
            np.testing.assert_array_equal(depth.view(np.uint32), d.view(np.uint32))
        else:
            differ = np.setxor1d(got, pix)
            assert _edge_distance(t, differ).max(initial=0) < 1e-4, f"triangle {i}: {t.tolist()}"
            both, a, b = np.intersect1d(got, pix, return_indices=True)
            np.testing.assert_allclose(depth[a], d[b], rtol=1e-5)
        sizes.append(len(pix))
    sizes = np.array(sizes)
    # none, a few and many centres, and triangles that cover the whole image
    assert (sizes == 0).mean() > 0.2 and ((sizes > 0) & (sizes < 5)).mean() > 0.1 and (sizes == w * h).any()


def test_quads_draw_the_sphere_disc_exactly():
    scene = pl.Scene()
    scene.add("sphere", transform=pl.rotate(30, (1, 0.3, 0)))
    cam = pl.Camera.look_at((0.4, 0.5, 3.0), (0, 0, 0), size=(48, 48))
    rs = pl.RenderSettings(lod=pl.LodSettings(threshold=(4.0, 4.0)))
    rs.points.coverage = "quad"
    frame = pl.render(scene, cam, "points", rs)
    assert np.array_equal(frame.coverage > 0, sphere_disc(cam)[0])


@pytest.mark.parametrize("order", [4, 8, 12])
def test_small_glyph_quads_stay_inside_the_silhouette(order):
    """Glyphs of 20 pixels: the samples' cells reach past the tips of thin lobes (measured: 3, 24
    and 27 pixels outside at orders 4, 8, 12), the quads between the samples do not (0), and they
    miss what a mesh of the grid misses, the chords' sag at the tips (IoU 0.86-0.98 measured)."""
    scene, cam, ref = glyph_case(order, 20)
    outside, iou = {}, {}
    for coverage in ("centre", "quad"):
        rs = settings_for("points", "noAA")
        rs.points.coverage = coverage
        frame = pl.render(scene, cam, "points", rs)
        outside[coverage] = int((np.asarray(frame.coverage > 0) & ~ref).sum())
        iou[coverage] = iou_of(frame, ref)
    assert outside["quad"] <= 1 and outside["quad"] < outside["centre"], outside
    assert iou["quad"] >= 0.85, iou


def test_quads_of_several_views_are_the_single_view_frames():
    """A frame of several views with quad coverage: each view that sees a patch draws its quads
    into its own layer, so a view that no other asks more detail of is the single-view frame of its
    camera, bit for bit (keys, depth, ids), and a view that sees nothing stays empty."""
    scene = pl.Scene()
    scene.add("sphere", transform=pl.translate((4, 0, 0)), material=pl.Material((0.8, 0.3, 0.2)))
    scene.add("torus", transform=pl.translate((-4, 0, 0)) @ pl.rotate(60, (1, 0, 0)))
    cams = [pl.Camera.look_at((0, 0, 0), d, size=(64, 48), near=0.05, far=50) for d in ((1, 0, 0), (-1, 0, 0), (0, 0, 1))]
    rs = pl.RenderSettings()
    rs.points.coverage = "quad"
    frames = pl.render_views(scene, cams, "points", rs)
    for cam, frame in zip(cams[:2], frames):
        single = pl.render(scene, cam, "points", rs)
        assert frame.stats["pixels_written"] > 200
        np.testing.assert_array_equal(frame.rgb8(), single.rgb8())
        np.testing.assert_array_equal(frame.depth, single.depth)
        np.testing.assert_array_equal(frame.object_id, single.object_id)
    assert frames[2].stats["pixels_written"] == 0
