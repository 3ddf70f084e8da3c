"""The surfel -> mesh hand-off (issue 15, deliverable 5; paramlod.scene.handoff): the weight against
hand-computed values, the dither on the device, in GLSL and in numpy, the splat, cut and raster
twins bit-exact with dithering, whole frames of the bunny (far: surfels only; close: mesh only;
between: disjoint pixel sets with no hole inside the mesh's silhouette, also with 4xSS and
through OpenGL), the scene API and the scene-file key, and their errors."""
from __future__ import annotations

import math

import numpy as np
import pyopencl as cl
import pytest

import paramlod as pl
from helpers.holes import count_holes
from helpers.meshes import bunny_path, load_bunny, sphere
from paramlod import kernels
from paramlod.app.scenefile import load_scene
from paramlod.core.layouts import camera_record, cl_prelude
from paramlod.device.context import cl_device
from paramlod.core.color import srgb_to_linear
from paramlod.errors import MeshError, SceneError, SurfelError
from paramlod.meshlod import cut_reference, raster_reference
from paramlod.meshlod.buffers import DeviceMeshes, MeshArrays, MeshInstances
from paramlod.meshlod.build.dag import build_dag
from paramlod.meshlod.cut import ClusterCut, Selection
from paramlod.meshlod.draw import MeshDraw
from paramlod.meshlod.raster import MeshRaster
from paramlod.pipeline.driver import render_passes
from paramlod.renderers.shading import LIGHT
from paramlod.renderers.targets import KeyBuffer
from paramlod.core.hashing import dither
from paramlod.scene.handoff import demand, mesh_weight
from paramlod.scene.scene import Material, MeshObject, SurfelObject
from paramlod.surfels import FixedCount, FixedSize, FrameTimeAdaptive, SurfelSet
from paramlod.surfels.build import reference as surfel_ref
from paramlod.surfels.build import sample_mesh
from paramlod.surfels.render import SurfelSplats, _DeviceSurfels, draw_records

ALL = np.uint64(0xFFFFFFFFFFFFFFFF)
FOV = 30.0
DIRECTION = np.array([0.3, 0.25, 1.0]) / np.linalg.norm([0.3, 0.25, 1.0])


@pytest.fixture(scope="module")
def bunny_surfels():
    import trimesh

    v, f = load_bunny()
    return sample_mesh(trimesh.Trimesh(v, f, process=False), 4000, views=8, resolution=128)


@pytest.fixture(scope="module")
def bunny_scene(bunny_surfels):
    """The bunny's surfels with the bunny as their hand-off mesh, and the bunny alone."""
    s = pl.Scene()
    so = s.add_surfels(bunny_surfels, strategy=FixedSize(2.0), mesh=bunny_path(), blend=0.5)
    alone = pl.Scene()
    alone.add_mesh(bunny_path(), material=so.mesh.material)
    return s, so, alone


def distance_for(surfels, want_demand, size=(96, 96), size_px=2.0, fov=FOV):
    """The eye distance from the bounding sphere's centre at which the law asks for ``want_demand``
    times the set, by hand: r = sqrt(packing / (q N)), one pixel at depth d is 2 d tan(fov/2) / H,
    r = size_px * pixel / 2, and the depth is that of the sphere's nearest point (distance - radius)."""
    c, rad = surfels.bounding_sphere()
    r = math.sqrt(surfels.packing / (want_demand * len(surfels)))
    depth = (2 * r / size_px) * size[1] / (2 * math.tan(math.radians(fov) / 2))
    return depth + rad


def bunny_camera(surfels, want_demand, size=(96, 96)):
    c, rad = surfels.bounding_sphere()
    dist = distance_for(surfels, want_demand, size)
    return pl.Camera.look_at(c + DIRECTION * dist, c, (0, 1, 0), FOV, size, near=1.0, far=dist + 2 * rad)


def pixel_dither(w, h):
    ys, xs = np.mgrid[0:h, 0:w]
    return dither(xs, ys)


# --- the weight ---------------------------------------------------------------------------------------
def test_weight_against_hand_computed_values(bunny_surfels, bunny_scene):
    _, so, _ = bunny_scene
    for q, want in [(0.6, 0.0), (1.0, 0.0), (1.1, 0.2), (1.25, 0.5), (1.4, 0.8), (1.5, 1.0), (3.0, 1.0)]:
        cam = bunny_camera(bunny_surfels, q)
        assert demand(cam, so) == pytest.approx(q, rel=1e-9)
        assert mesh_weight(cam, so) == pytest.approx(want, abs=1e-9)
    cam = bunny_camera(bunny_surfels, 1.2)
    # blend: weight = (demand - 1) / blend
    wide = SurfelObject(bunny_surfels, np.eye(4), FixedSize(2.0), 1, mesh=so.mesh, blend=2.0)
    assert mesh_weight(cam, wide) == pytest.approx(0.1)
    # surfels of 4 px: a quarter of the demand
    big = SurfelObject(bunny_surfels, np.eye(4), FixedSize(4.0), 1, mesh=so.mesh, blend=0.5)
    assert demand(cam, big) == pytest.approx(0.3) and mesh_weight(cam, big) == 0.0
    # the default strategy is FixedSize(2); FrameTimeAdaptive uses its current size
    assert mesh_weight(cam, SurfelObject(bunny_surfels, np.eye(4), None, 1, mesh=so.mesh)) == pytest.approx(0.4)
    ada = FrameTimeAdaptive(size_px=2.0)
    assert mesh_weight(cam, SurfelObject(bunny_surfels, np.eye(4), ada, 1, mesh=so.mesh)) == pytest.approx(0.4)
    # a fixed count never runs out by the law; without a mesh there is nothing to hand over to
    assert mesh_weight(cam, SurfelObject(bunny_surfels, np.eye(4), FixedCount(10), 1, mesh=so.mesh)) == 0.0
    assert mesh_weight(bunny_camera(bunny_surfels, 5.0), SurfelObject(bunny_surfels, np.eye(4), None, 1)) == 0.0
    # an object scaled by 2 seen from twice as far asks for what the original asks from here
    c, _ = bunny_surfels.bounding_sphere()
    dist = distance_for(bunny_surfels, 1.2)
    rad = bunny_surfels.bounding_sphere()[1]
    scaled = SurfelObject(bunny_surfels, np.diag([2.0, 2.0, 2.0, 1.0]), FixedSize(2.0), 1, mesh=so.mesh)
    far = pl.Camera.look_at(2 * c + DIRECTION * 2 * dist, 2 * c, (0, 1, 0), FOV, (96, 96), near=1.0,
                            far=2 * (dist + 2 * rad))
    assert mesh_weight(far, scaled) == pytest.approx(0.4)


def test_weight_meets_the_prefix_law(bunny_surfels, bunny_scene):
    """The weight starts where choose_prefix saturates: the same radius, from the same code."""
    from paramlod.surfels import choose_prefix

    _, so, _ = bunny_scene
    for q in (0.9, 0.999, 1.001, 1.3):
        cam = bunny_camera(bunny_surfels, q)
        ch = choose_prefix(bunny_surfels, cam, FixedSize(2.0))
        assert ch["saturated"] == (mesh_weight(cam, so) > 0)


# --- the dither --------------------------------------------------------------------------------------
def test_dither_on_the_device_equals_the_twin():
    src = "\n".join([cl_prelude(), kernels.source("common/common.cl"), kernels.source("common/keys.cl"), """
__kernel void dither_grid(uint w, uint x0, uint y0, __global float* out) {
    uint i = get_global_id(0);
    out[i] = pl_dither(x0 + i % w, y0 + i / w);
}"""])
    k = cl.Kernel(cl.Program(cl_device().context, src).build(), "dither_grid")
    q = cl_device().queue
    w, h, x0, y0 = 256, 128, 0, 16000   # rows near the 16384 limit too
    for oy in (0, y0):
        out = np.empty(w * h, np.float32)
        buf = cl.Buffer(cl_device().context, cl.mem_flags.WRITE_ONLY, out.nbytes)
        k(q, (w * h,), None, np.uint32(w), np.uint32(x0), np.uint32(oy), buf)
        cl.enqueue_copy(q, out, buf)
        ys, xs = np.mgrid[oy:oy + h, x0:x0 + w]
        np.testing.assert_array_equal(out.reshape(h, w), dither(xs, ys))
    d = dither(*np.mgrid[0:256, 0:256][::-1])
    assert d.dtype == np.float32 and d.min() >= 0 and d.max() < 1
    # even: every tenth of [0, 1) holds a tenth of the pixels, and neighbours are unrelated
    counts = np.histogram(d, bins=10, range=(0, 1))[0] / d.size
    assert np.all(np.abs(counts - 0.1) < 0.01)
    assert abs(np.corrcoef(d[:, :-1].ravel(), d[:, 1:].ravel())[0, 1]) < 0.02
    assert abs(np.corrcoef(d[:-1].ravel(), d[1:].ravel())[0, 1]) < 0.02


# --- twins with dithering ------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def ball():
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    m.visual.vertex_colors = np.column_stack([(m.vertices * 0.5 + 0.5) * 255,
                                              np.full(len(m.vertices), 255)]).astype(np.uint8)
    return sample_mesh(m, 1500, views=8, resolution=64)


@pytest.mark.parametrize("w", [0.3, 0.75, 1.0])
def test_splat_twin_with_dithering(ball, w):
    cam = pl.Camera.look_at((1.5, 1.0, 3.2), (0, 0, 0), fov_y=40, size=(64, 48), near=0.5, far=20)
    xform = pl.translate(0.1, -0.2, 0.0) @ pl.scale(1.1)
    keys = KeyBuffer(*cam.size)
    keys.clear()
    r = SurfelSplats()
    sp = r.splat(keys, cam, ball, FixedCount(1500), xform, 9, 0.3, mesh_weight=w)
    r._splats = [sp]
    r.collect()
    cl_device().queue.finish()
    st = sp.stats()
    ck, ak = keys.read_keys()
    xf, ip = draw_records(cam, xform)
    n = 0 if w >= 1 else 1500
    rck, rak = surfel_ref.splat_discs(*_DeviceSurfels(ball).host, n, np.float32(st["radius_view"]), xf,
                                      camera_record(cam), ip, LIGHT, 0.3, 9, mesh_weight=w)
    covered = ck != ALL
    np.testing.assert_array_equal(covered, rck != ALL)
    np.testing.assert_array_equal(ck >> np.uint64(32), rck >> np.uint64(32))
    np.testing.assert_array_equal(ak & np.uint64(0xFFF), rak & np.uint64(0xFFF))
    assert st["mesh_weight"] == w
    if w >= 1:
        assert st["surfels_drawn"] == 0 and st["pixels_covered"] == 0 and not covered.any()
        return
    # only the surfels' pixels, and (the discs overlap) about 1 - w of the disc-covered ones
    assert not np.any(covered & (pixel_dither(*cam.size) < w))
    full = surfel_ref.splat_discs(*_DeviceSurfels(ball).host, 1500, np.float32(st["radius_view"]), xf,
                                  camera_record(cam), ip, LIGHT, 0.3, 9)[0] != ALL
    assert covered.sum() == pytest.approx((1 - w) * full.sum(), rel=0.15)
    assert np.array_equal(covered, full & (pixel_dither(*cam.size) >= w))


@pytest.fixture(scope="module")
def three_balls():
    """Three instances of one DAG sphere with hand-off weights 1, 0.45 and 0 (the last one's
    surfels would draw it all), packed, uploaded and cut at 1 px."""
    lod = build_dag(*sphere(3), name="ball")
    objects = [MeshObject(lod, pl.translate(x, 0, 0) @ pl.scale(0.7), Material((0.8, 0.4, 0.2)), k + 1)
               for k, x in enumerate((-1.6, 0.0, 1.6))]   # apart on screen too
    arrays = MeshArrays.pack([lod])
    instances = MeshInstances.pack(objects, lambda m: 0)
    return arrays, instances, DeviceMeshes(arrays, instances), np.array([1.0, 0.45, 0.0], np.float32)


def test_cut_skips_instances_of_weight_zero(three_balls):
    arrays, instances, dev, weights = three_balls
    cam = pl.Camera.look_at((0.0, 0.8, 4.5), (0.0, 0, 0), fov_y=45, size=(96, 64), near=0.1, far=20)
    cut = ClusterCut()
    dev.set_weights(np.ones(3, np.float32))
    every, every_c = cut.select(dev, cam, 1.0, Selection())
    dev.set_weights(weights)
    got, gc = cut.select(dev, cam, 1.0, Selection())
    want, wc = cut_reference.select(arrays, instances, cam, 1.0, weights=weights)
    np.testing.assert_array_equal(got, want)
    assert gc == wc
    assert set(np.unique(got[:, 0])) == {0, 1} and set(np.unique(every[:, 0])) == {0, 1, 2}
    np.testing.assert_array_equal(got, every[every[:, 0] != 2])
    assert gc["tests"] == every_c["tests"] * 2 // 3


@pytest.mark.parametrize("large_pixels", [256, 8])
def test_raster_twin_with_dithering(three_balls, large_pixels):
    """Keys equal the twin's bit for bit with per-instance weights, on both raster paths (8: most
    triangles go through raster_large); the weight-0.45 ball draws only pixels of dither < 0.45."""
    arrays, instances, dev, weights = three_balls
    cam = pl.Camera.look_at((0.0, 0.8, 4.5), (0.0, 0, 0), fov_y=45, size=(96, 64), near=0.1, far=20)
    pairs = cut_reference.select(arrays, instances, cam, 1.0, weights=np.ones(3, np.float32))[0]   # all three
    dev.set_weights(weights)
    ctx = cl_device().context
    mf = cl.mem_flags
    counters = np.zeros(8, np.uint64)
    counters[0] = len(pairs)
    sel = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(pairs))
    cbuf = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=counters)
    keys = KeyBuffer(*cam.size)
    keys.clear()
    raster = MeshRaster(large_pixels=large_pixels)
    raster.enqueue(keys, cam, dev, sel, len(pairs), cbuf)
    raster.collect()
    cl_device().queue.finish()
    c, a = keys.read_keys()
    st = raster.stats()
    d = raster_reference.rasterize_detail(*cam.size, cam, arrays, instances, pairs, large_pixels=large_pixels,
                                          weights=weights)
    np.testing.assert_array_equal(c, d["color"])
    np.testing.assert_array_equal(a, d["aux"])
    assert st["pixels"] == d["counters"]["pixels"] and st["large_overflow"] == 0
    if large_pixels == 8:
        assert st["large"] > 100
    ids = (a & np.uint64(0xFFF)).astype(int)
    ids[a == ALL] = 0
    full = raster_reference.rasterize(*cam.size, cam, arrays, instances, pairs)[1]
    full_ids = np.where(full == ALL, 0, (full & np.uint64(0xFFF)).astype(int))
    dm = pixel_dither(*cam.size)
    assert (ids == 1).sum() == (full_ids == 1).sum() > 300          # weight 1: all of it
    assert (ids == 3).sum() == 0 and (full_ids == 3).sum() > 300     # weight 0: nothing
    half = full_ids == 2
    assert np.array_equal(ids == 2, half & (dm < 0.45))               # where 2 is the front surface


# --- whole frames of the bunny ---------------------------------------------------------------------------
def _parts(scene, so, cam, settings=None, variant=None):
    """Coverage of the surfels alone and of the hand-off mesh alone (each keeps its weight)."""
    s = pl.render(scene.subscene(surfels=[so]), cam, variant, settings)
    m = pl.render(scene.subscene(meshes=[so.mesh]), cam, variant, settings)
    return s, m


def test_far_camera_draws_only_surfels(bunny_scene, bunny_surfels):
    scene, so, _ = bunny_scene
    cam = bunny_camera(bunny_surfels, 0.7)
    f = pl.render(scene, cam)
    st = f.stats
    assert st["handoff_weights"] == [0.0]
    assert st["surfels"][0]["mesh_weight"] == 0.0 and st["surfels"][0]["pixels_covered"] > 500
    assert st["clusters_drawn"] == 0 and st["triangles_drawn"] == 0 and st["raster_pixels"] == 0
    assert st["cluster_tests"] == 0                       # the cut skipped the instance whole
    assert set(np.unique(f.object_id)) == {0, so.object_id}


def test_close_camera_draws_only_the_mesh(bunny_scene, bunny_surfels):
    scene, so, alone = bunny_scene
    cam = bunny_camera(bunny_surfels, 1.8)
    f = pl.render(scene, cam)
    st = f.stats
    assert st["handoff_weights"] == [1.0]
    assert st["surfels"][0]["surfels_drawn"] == 0 and st["surfels"][0]["pixels_covered"] == 0
    ref = pl.render(alone, cam)
    # exactly the mesh alone (same LOD, same keys), under the surfel object's id
    assert st["triangles_drawn"] == ref.stats["triangles_drawn"] > 0
    np.testing.assert_array_equal(f.depth, ref.depth)
    np.testing.assert_array_equal(f.color, ref.color)
    assert set(np.unique(f.object_id)) == {0, so.object_id}


@pytest.mark.parametrize("q", [1.1, 1.25, 1.4])
def test_in_between_both_draw_disjoint_pixels_without_holes(bunny_scene, bunny_surfels, q):
    scene, so, alone = bunny_scene
    cam = bunny_camera(bunny_surfels, q)
    w = mesh_weight(cam, so)
    assert 0.1 < w < 0.9
    f = pl.render(scene, cam)
    s, m = _parts(scene, so, cam)
    S, M = np.isfinite(s.depth), np.isfinite(m.depth)
    dm = pixel_dither(*cam.size)
    assert not np.any(S & (dm < w)) and not np.any(M & (dm >= w))    # disjoint by the dither
    ref = pl.render(alone, cam)
    mask = np.isfinite(ref.depth)
    assert M.sum() == pytest.approx(w * mask.sum(), rel=0.2)
    assert S.sum() == pytest.approx((1 - w) * mask.sum(), rel=0.2)
    assert np.array_equal(np.isfinite(f.depth), S | M)
    assert count_holes(f, mask) == 0
    # no hole shows a surface behind the front one either (the bunny is ~50 units across), but for
    # a pixel at a silhouette where a surfel disc lets the body behind an ear through (seen once
    # in 9,216 pixels on an H200)
    assert count_holes(f, mask, ref.depth, tol=2.0) <= max(1, int(mask.sum()) // 1000)
    st = f.stats
    assert st["handoff_weights"] == [pytest.approx(w)] and st["surfels"][0]["mesh_weight"] == pytest.approx(w)


def test_supersampled_blend(bunny_scene, bunny_surfels):
    """With 4xSS the dither runs per subsample and averages into fractional shares per pixel."""
    scene, so, alone = bunny_scene
    rs = pl.RenderSettings()
    rs.apply_aa("4xSS", points_only=True)
    cam = bunny_camera(bunny_surfels, 1.25)
    sub = cam.with_size((cam.width * 2, cam.height * 2))
    w = mesh_weight(sub, so)          # the pass's camera: subsamples
    assert w == 1.0 and mesh_weight(cam, so) == pytest.approx(0.5)
    # back off so that the subsample camera is in the blend
    cam = bunny_camera(bunny_surfels, 1.25 / 4, size=(128, 128))
    w = mesh_weight(cam.with_size((cam.width * 2, cam.height * 2)), so)
    assert w == pytest.approx(0.5)
    f = pl.render(scene, cam, settings=rs)
    assert f.stats["handoff_weights"] == [pytest.approx(w)]
    mask = np.isfinite(pl.render(alone, cam, settings=rs).depth)
    assert count_holes(f, mask) == 0
    s, m = _parts(scene, so, cam, rs)
    a_s, a_m = s.color[..., 3], m.color[..., 3]
    inside = np.zeros_like(mask)   # the silhouette less its border pixels
    inside[1:-1, 1:-1] = mask[1:-1, 1:-1] & mask[:-2, 1:-1] & mask[2:, 1:-1] & mask[1:-1, :-2] & mask[1:-1, 2:]
    assert inside.sum() > 150
    # interior pixels: the two shares add up to the whole pixel, and many are mixed
    np.testing.assert_allclose((a_s + a_m)[inside], 1.0, atol=1.5 / 255)   # alpha is 8-bit
    mixed = inside & (a_m > 0.2) & (a_m < 0.8)
    assert mixed.sum() > 0.4 * inside.sum()
    assert a_m[inside].mean() == pytest.approx(w, abs=0.05)


def test_gl_draw_dithers_like_the_keys(bunny_scene, bunny_surfels):
    """meshlets-gl: the GLSL copy of the dither keeps exactly the pixels of dither < w (no AA: the
    surfels' keys and the GL target share the pixel grid), and the composite has no hole."""
    scene, so, alone = bunny_scene
    cam = bunny_camera(bunny_surfels, 1.25)
    w = mesh_weight(cam, so)
    passes = render_passes(scene, cam, "tess")
    by = {p.stats["variant"]: p for p in passes}
    assert set(by) == {"surfels", "meshlets-gl"}
    G = np.isfinite(by["meshlets-gl"].depth)
    S = np.isfinite(by["surfels"].depth)
    dm = pixel_dither(*cam.size)
    assert not np.any(G & (dm >= w)) and not np.any(S & (dm < w))
    gl_alone = pl.render(alone, cam, "tess")
    mask = np.isfinite(gl_alone.depth)
    assert np.array_equal(G, mask & (dm < w))
    assert count_holes(pl.render(scene, cam, "tess"), mask) == 0
    assert by["meshlets-gl"].stats["handoff_weights"] == [pytest.approx(w)]


def test_gl_draw_rejects_bad_weights(three_balls):
    arrays, instances, _, _ = three_balls
    d = MeshDraw()
    d.upload(arrays, instances)
    cam = pl.Camera.look_at((0, 0, 4), (0, 0, 0), size=(32, 32))
    sel = np.array([[0, 0]], np.uint32)
    with pytest.raises(MeshError, match="3 numbers in"):
        d.draw(sel, cam, weights=[1.0, 0.5])
    with pytest.raises(MeshError, match="in \\[0, 1\\]"):
        d.draw(sel, cam, weights=[1.0, 0.5, 1.5])


# --- the scene API and the scene file -------------------------------------------------------------------
def test_scene_holds_the_mesh_with_the_surfel_object(bunny_surfels):
    s = pl.Scene()
    s.add("sphere")
    so = s.add_surfels(bunny_surfels, transform=pl.translate(1, 2, 3), mesh=bunny_path(), blend=0.25)
    mo = so.mesh
    assert s.meshes == [mo] and mo.handoff is so and so.blend == 0.25
    assert mo.object_id == so.object_id == 2 and mo.count == 1
    np.testing.assert_array_equal(mo.transform, so.transform)
    assert s.object_count == 2 and s.add("sphere").object_id == 3
    # the material: the surfels' mean colour (linear), their specular
    lin = srgb_to_linear(bunny_surfels.colors[:, :3] / 255.0).mean(axis=0)
    np.testing.assert_allclose(mo.material.color, lin, atol=1e-6)
    own = s.add_surfels(bunny_surfels, mesh=bunny_path(), material=Material((0.1, 0.2, 0.3), 0.5))
    assert own.mesh.material.color == (0.1, 0.2, 0.3) and own.mesh.mesh is mo.mesh   # loaded once
    assert "SurfelObject" in repr(so) and "MeshObject" in repr(mo)   # they point at each other: no recursion
    # a subscene of the mesh alone still counts as one object
    assert s.subscene(meshes=[mo]).object_count == 1
    # without a mesh nothing changes
    plain = s.add_surfels(bunny_surfels)
    assert plain.mesh is None and len(s.meshes) == 2


@pytest.mark.parametrize("blend, why", [(0, "> 0"), (-1.0, "> 0"), (float("nan"), "> 0"), (float("inf"), "> 0"),
                                        ("wide", "number"), (True, "number")])
def test_bad_blend(bunny_surfels, blend, why):
    s = pl.Scene()
    with pytest.raises(SceneError, match=f"blend must be .*{why}"):
        s.add_surfels(bunny_surfels, mesh=bunny_path(), blend=blend)
    assert not s.surfels and not s.meshes


def test_other_bad_input(bunny_surfels, tmp_path):
    s = pl.Scene()
    with pytest.raises(SceneError, match="material colours the hand-off mesh; give mesh="):
        s.add_surfels(bunny_surfels, material=Material())
    with pytest.raises(MeshError, match="nothing.ply"):
        s.add_surfels(bunny_surfels, mesh=tmp_path / "nothing.ply")
    assert not s.surfels and not s.meshes
    r = SurfelSplats()
    keys = KeyBuffer(16, 16)
    cam = pl.Camera.look_at((0, 0, 200), (0, 0, 0), size=(16, 16))
    for bad in (-0.1, 1.5, float("nan")):
        with pytest.raises(SurfelError, match="mesh_weight must be in"):
            r.splat(keys, cam, bunny_surfels, FixedSize(2.0), None, 1, 0.25, mesh_weight=bad)


def _write_scene(tmp_path, surfels_line, extra=""):
    path = tmp_path / "handoff.toml"
    path.write_text(f"""[camera]
eye = [0, 0, 200]
target = [0, 0, 25]
size = [48, 48]

[[objects]]
{extra}surfels = {surfels_line}
""")
    return path


def test_scene_file_key(bunny_surfels, tmp_path):
    import shutil

    bunny_surfels.save(tmp_path / "bunny.surfels")
    shutil.copy(bunny_path(), tmp_path / "bunny.ply")
    sf = load_scene(_write_scene(tmp_path, '{ path = "bunny.surfels", px = 3, mesh = "bunny.ply", blend = 0.75 }'))
    so = sf.scene.surfels[0]
    assert so.blend == 0.75 and so.strategy.size_px == 3 and so.mesh.handoff is so
    assert len(sf.scene.meshes) == 1 and sf.scene.object_count == 1
    assert so.mesh.material.color != (0.8, 0.8, 0.8)          # the mean colour, not the default
    sf = load_scene(_write_scene(tmp_path, '{ path = "bunny.surfels", mesh = "bunny.ply" }', 'color = [0.9, 0.1, 0.1]\n'))
    assert sf.scene.surfels[0].blend == 0.5 and sf.scene.meshes[0].material.color == (0.9, 0.1, 0.1)
    pl.render(sf.scene, sf.camera)                              # it draws


@pytest.mark.parametrize("line, where, what", [
    ('{ path = "bunny.surfels", mesh = "bunny.ply", blend = 0 }', "surfels.blend", "must be a number > 0"),
    ('{ path = "bunny.surfels", mesh = "bunny.ply", blend = -2 }', "surfels.blend", "must be a number > 0"),
    ('{ path = "bunny.surfels", mesh = "bunny.ply", blend = "x" }', "surfels.blend", "must be a number > 0"),
    ('{ path = "bunny.surfels", blend = 0.5 }', "surfels.blend", 'give mesh = "x.ply" too'),
    ('{ path = "bunny.surfels", mesh = 3 }', "surfels.mesh", "must be a file name"),
    ('{ path = "bunny.surfels", mesh = "missing.ply" }', "surfels.mesh", "missing.ply"),
    ('{ path = "bunny.surfels", mesh = "bunny.ply", lod = "full" }', "surfels", "optionally with mesh"),
])
def test_scene_file_errors(bunny_surfels, tmp_path, line, where, what):
    import shutil

    bunny_surfels.save(tmp_path / "bunny.surfels")
    shutil.copy(bunny_path(), tmp_path / "bunny.ply")
    path = _write_scene(tmp_path, line)
    with pytest.raises(SceneError) as exc:
        load_scene(path)
    msg = str(exc.value)
    assert f"{path}:7: objects[0].{where}" in msg and what in msg


def test_surfel_sets_keep_their_object_space(bunny_surfels):
    """The hand-off assumes the set lies in its mesh's object space (sample_mesh keeps it)."""
    v, _ = load_bunny()
    assert isinstance(bunny_surfels, SurfelSet)
    np.testing.assert_allclose(bunny_surfels.bounds, [v.min(axis=0), v.max(axis=0)], atol=1.0)
