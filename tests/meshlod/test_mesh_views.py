"""Multi-view meshes (issue #20): one cut for N views (paramlod.meshlod.cut, kernels/meshlod/cut.cl),
the skinned cull (skin_cull.cl), the OpenCL raster into layered key buffers (raster.cl) and the
layered GL draw (paramlod.meshlod.draw.MeshDraw.draw_views), each kernel against its numpy twin for
2 and 6 views; the rule: never coarser than any view's own cut where that view sees the cluster,
culled only when every view culls it; frames: a view of a multi-view frame equals the single-view
frame of its camera where the cuts agree, on both renderers, with skinned meshes and beyond the 32
views of one GL draw; per-view stats; bad input.

Meshes: the synthetic DAGs and the clustered sphere of test_cut (no geometry needed / real cones),
DAGs the builder makes of a bumpy sphere and a height field, flat clusterings (test_raster), the
rigged sheets of test_skin_bounds and the rigged worm.
"""
from __future__ import annotations

import math

import numpy as np
import pyopencl as cl
import pytest

import paramlod as pl
from paramlod.core.camera import Camera
from paramlod.core.layouts import INSTANCE_F
from paramlod.core.views import Views
from paramlod.device.context import cl_device
from paramlod.errors import MeshError, SceneError
from paramlod.meshlod import buffers
from paramlod.meshlod import raster_reference as rref
from paramlod.meshlod.buffers import DeviceMeshes, MeshArrays, MeshInstances
from paramlod.meshlod.build.dag import build_dag
from paramlod.meshlod.build.skin_bounds import SkinBoundsSettings, skin_bounds
from paramlod.meshlod.build.worm_rig import write_worm
from paramlod.meshlod.cut import ClusterCut, Selection, counters_bytes
from paramlod.meshlod.cut_reference import COUNTERS, select_views
from paramlod.meshlod.draw import VIEWS_PER_DRAW, MeshDraw
from paramlod.meshlod.raster import MeshRaster
from paramlod.meshlod.skin import pose_records
from paramlod.meshlod.skin_cull import SkinCull
from paramlod.meshlod import skin_cull_reference as sref
from paramlod.meshlod.skinned import load_skinned
from paramlod.renderers.targets import KeyBuffer
from paramlod.scene.scene import Material, MeshObject
from paramlod.surfels.build.views import OrthoCamera

from helpers.meshes import grid, sphere
from test_cut import clustered_sphere, collapsed_groups, dag_relations, objects_for, one_sided_first, random_models, \
    scene_of, synthetic_lod
from test_raster import Scene as RasterScene, flat_lod, translate
from test_render import bumpy_sphere
from test_skin_bounds import random_rig_mesh

SIZE = (96, 72)


# --- cameras and helpers ----------------------------------------------------------------------------
def views_of(rng, n, size=SIZE, dist=(3.0, 25.0), ortho_every=0):
    """``n`` random cameras of one size around the origin (every ``ortho_every``-th orthographic)."""
    out = []
    for k in range(n):
        d = rng.normal(size=3)
        eye = d / np.linalg.norm(d) * rng.uniform(*dist)
        view = Camera.look_at(eye, rng.uniform(-1, 1, 3), size=size).view
        near = float(rng.uniform(0.05, 0.5))
        if ortho_every and k % ortho_every == ortho_every - 1:
            out.append(OrthoCamera(view, size, float(rng.uniform(2.0, 10.0)), near, 200.0))
        else:
            out.append(Camera(view, float(rng.uniform(25, 80)), size, near, 200.0))
    return Views(out)


def bit(masks, v):
    return ((np.asarray(masks, np.uint64) >> np.uint64(v)) & np.uint64(1)) != 0


def as_set(pairs):
    return {(int(i), int(c)) for i, c in pairs}


def cluster_clip(arrays, instances, i, c, camera):
    """Clip coordinates (float64 [3 * triangles, 4]) of cluster c's vertices for instance i."""
    model = instances.inst_f[i, INSTANCE_F.slice("model")].astype(np.float64).reshape(4, 4)
    cl_ = arrays.clusters[c]
    tri = arrays.triangles[cl_["first"]:cl_["first"] + cl_["count"]].ravel()
    p = arrays.vertices[tri, :3].astype(np.float64) @ model[:3, :3].T + model[:3, 3]
    return np.c_[p, np.ones(len(p))] @ (camera.projection @ camera.view).T, p.reshape(-1, 3, 3), model


def shows_in(arrays, instances, i, c, camera, margin=1e-3):
    """Some vertex of the cluster lies inside the camera's frustum by a margin (float64)."""
    clip, _, _ = cluster_clip(arrays, instances, i, c, camera)
    w = clip[:, 3:]
    return bool(np.any(np.all(np.abs(clip[:, :3]) < w * (1 - margin), axis=1) & (w[:, 0] > 0)))


def culled_in(arrays, instances, i, c, camera):
    """The cluster shows nothing in the camera's view (float64 brute force, as test_cut checks):
    every vertex outside one clip plane, or (SIMILAR, ONE_SIDED instances) every triangle facing away."""
    clip, p, model = cluster_clip(arrays, instances, i, c, camera)
    w = clip[:, 3]
    tol = 1e-6 * np.abs(clip).max()
    if any((clip[:, a] * s < -w + tol).all() for a in range(3) for s in (1, -1)):
        return True
    if not (instances.inst_u[i, 3] & buffers.SIMILAR and instances.inst_u[i, 3] & buffers.ONE_SIDED):
        return False
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]) * np.sign(np.linalg.det(model[:3, :3]))
    ray = np.broadcast_to(-camera.view[2, :3], p[:, 0].shape) if isinstance(camera, OrthoCamera) else p[:, 0] - camera.eye
    ok = np.linalg.norm(n, axis=1) > 0
    cos = np.einsum("ij,ij->i", n[ok], ray[ok]) / np.linalg.norm(n[ok], axis=1) / np.linalg.norm(ray[ok], axis=1)
    return bool((cos >= -1e-4).all())


@pytest.fixture(scope="module")
def cut():
    return ClusterCut()


@pytest.fixture(scope="module")
def dags():
    """DAGs the builder makes of a closed bumpy sphere and an open height field."""
    return {"sphere": build_dag(*bumpy_sphere(4), progress=False, name="bumpy"),
            "grid": build_dag(*grid(40), progress=False, name="grid")}


def dag_scene(dags, rng, n=4, spread=3.0):
    objs = []
    for k, (name, lod) in enumerate(sorted(dags.items())):
        c, r = lod.bounding_sphere()
        to_unit = np.diag([1 / r, 1 / r, 1 / r, 1.0])
        to_unit[:3, 3] = -c / r
        objs.append(MeshObject(lod, np.eye(4), one_sided_first(k), k + 1, count=n,
                               transforms=random_models(rng, n, spread) @ to_unit))
    return scene_of(objs)


# --- the cut: kernel == twin ------------------------------------------------------------------------
@pytest.mark.parametrize("n_views", [2, 6])
def test_cut_kernel_matches_twin_for_several_views(cut, n_views):
    rng = np.random.default_rng(n_views)
    a, b = synthetic_lod(n_views, leaves=60), synthetic_lod(200 + n_views, leaves=25, group_size=3)
    arrays, instances = scene_of(objects_for(rng, [(a, 8), (b, 5)]))
    dev = DeviceMeshes(arrays, instances)
    sel = Selection(capacity=16)   # grows along the way
    partial = dropped = 0
    for trial in range(4):
        views = views_of(rng, n_views, ortho_every=3)
        for t in (0.0, 0.5, 2.0, 30.0):
            for fr, bf in ((True, True), (True, False), (False, True), (False, False)):
                got = cut.select_views(dev, views, t, sel, cull_frustum=fr, cull_backface=bf)
                want = select_views(arrays, instances, views, t, fr, bf)
                np.testing.assert_array_equal(got[0], want[0])
                np.testing.assert_array_equal(got[1], want[1])
                assert got[2] == want[2]
                full = np.uint64((1 << n_views) - 1)
                partial += int(np.sum(want[1] != full))
                dropped += want[2]["culled_frustum"] + want[2]["culled_backface"]
                assert all(m != 0 for m in want[1])
                assert [v["clusters"] for v in want[2]["views"]] == [int(bit(want[1], v).sum()) for v in range(n_views)]
    assert partial > 100 and dropped > 20   # views that drop some clusters and clusters every view drops


def test_cut_kernel_matches_twin_on_real_dags(cut, dags):
    rng = np.random.default_rng(9)
    arrays, instances = dag_scene(dags, rng)
    dev = DeviceMeshes(arrays, instances)
    for n_views in (2, 6):
        views = views_of(rng, n_views, dist=(2.0, 12.0))
        for t in (1.0, 4.0):
            got = cut.select_views(dev, views, t)
            want = select_views(arrays, instances, views, t)
            np.testing.assert_array_equal(got[0], want[0])
            np.testing.assert_array_equal(got[1], want[1])
            assert got[2] == want[2]


def test_one_view_of_views_is_the_camera_cut(cut):
    rng = np.random.default_rng(3)
    lod = synthetic_lod(3, leaves=50)
    arrays, instances = scene_of(objects_for(rng, [(lod, 6)]))
    dev = DeviceMeshes(arrays, instances)
    cam = views_of(rng, 1)[0]
    pairs, masks, counts = cut.select_views(dev, Views([cam]), 1.0)
    want, wc = cut.select(dev, cam, 1.0)
    np.testing.assert_array_equal(pairs, want)
    assert (masks == 1).all() and {k: counts[k] for k in COUNTERS} == wc
    assert counts["views"] == [{"clusters": wc["selected"], "triangles": wc["triangles"]}]


# --- the cut: the rule ----------------------------------------------------------------------------------
def test_multi_view_cut_is_never_coarser_than_any_view_needs(cut, dags):
    """For each view v, every cluster v's own cut draws where v sees it is drawn by the multi-view
    cut (into view v) or replaced there by finer clusters; the multi-view cut stays a valid cut."""
    rng = np.random.default_rng(17)
    arrays, instances = dag_scene(dags, rng, n=3, spread=2.5)
    dev = DeviceMeshes(arrays, instances)
    rel = {m: dag_relations(arrays.clusters[int(arrays.ranges[m][0]):int(arrays.ranges[m][0] + arrays.ranges[m][1])])
           for m, _, _ in instances.batches}
    checked = finer = 0
    for n_views, t in ((2, 0.5), (6, 1.0)):
        views = views_of(rng, n_views, dist=(1.5, 8.0))
        pairs, masks, _ = cut.select_views(dev, views, t)
        full, _, _ = cut.select_views(dev, views, t, cull_frustum=False, cull_backface=False)
        kept = dict(zip(map(tuple, pairs.tolist()), masks.tolist()))
        collapsed = {}
        for mesh, i0, ni in instances.batches:
            c0, nc = (int(x) for x in arrays.ranges[mesh])
            for i in range(i0, i0 + ni):
                mine = np.zeros(nc, bool)
                mine[full[full[:, 0] == i][:, 1] - c0] = True
                collapsed[i] = (c0, rel[mesh][0], collapsed_groups(arrays.clusters[c0:c0 + nc], mine, rel[mesh]))
        for v, cam in enumerate(views):
            single, _ = cut.select(dev, cam, t)
            for i, c in single.tolist():
                if not shows_in(arrays, instances, i, c, cam):
                    continue
                checked += 1
                if (i, c) in kept:
                    assert kept[(i, c)] >> v & 1, f"view {v}: cluster {c} of instance {i} drawn but not into view {v}"
                    continue
                c0, parent, groups = collapsed[i]
                g = parent[c - c0]
                assert g < 0 or not groups[g], f"view {v}: cluster {c} of instance {i} is drawn coarser"
                finer += 1
    assert checked > 150 and finer > 50   # the views disagree: some clusters are refined for another view


def test_clusters_are_culled_only_when_every_view_culls_them(cut):
    rng = np.random.default_rng(23)
    lod = clustered_sphere()
    arrays, instances = scene_of(objects_for(rng, [(lod, 16)], spread=4.0))
    dev = DeviceMeshes(arrays, instances)
    dropped_total = partial_total = 0
    for n_views in (2, 6):
        views = views_of(rng, n_views, dist=(3.0, 10.0), ortho_every=4)
        pairs, masks, counts = cut.select_views(dev, views, 0.0)
        every, _, _ = cut.select_views(dev, views, 0.0, cull_frustum=False, cull_backface=False)
        kept = dict(zip(map(tuple, pairs.tolist()), masks.tolist()))
        assert set(kept) <= as_set(every)
        dropped = as_set(every) - set(kept)
        assert counts["culled_frustum"] + counts["culled_backface"] == len(dropped)
        for i, c in dropped:
            for v, cam in enumerate(views):
                assert culled_in(arrays, instances, i, c, cam), f"cluster {c} of instance {i} shows in view {v}"
        for (i, c), m in kept.items():
            for v, cam in enumerate(views):
                if not m >> v & 1:
                    assert culled_in(arrays, instances, i, c, cam), f"cluster {c} of instance {i} shows in view {v}"
                    partial_total += 1
        dropped_total += len(dropped)
    assert dropped_total > 20 and partial_total > 50


# --- the skinned cull ----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def skinned():
    gentle = random_rig_mesh(1, bones=4, keys=3, nx=48, ny=8, max_angle=math.radians(10), amp=0.05, name="gentle")
    wild = random_rig_mesh(4, bones=3, keys=3, nx=40, ny=8, max_angle=math.radians(120), amp=0.5, name="wild")
    bounds = [skin_bounds(gentle, SkinBoundsSettings(max_radius_scale=50.0, max_cone_angle_deg=89.0), progress=False),
              skin_bounds(wild, SkinBoundsSettings(max_radius_scale=1.45), progress=False)]
    rng = np.random.default_rng(0)
    # a one-sided object (backface tests) and a two-sided one (frustum tests only)
    objs = [MeshObject(gentle, np.eye(4), Material(two_sided=False), 1, count=4, transforms=random_models(rng, 4, 3.0)),
            MeshObject(wild, np.eye(4), Material(), 2, count=2, transforms=random_models(rng, 2, 3.0))]
    own = {id(o): k for k, o in enumerate(objs)}
    instances = MeshInstances.pack(objs, lambda o: own[id(o)])
    dev = DeviceMeshes(MeshArrays.pack([gentle, wild]), instances)
    return dev, bounds, SkinCull(dev, bounds)


@pytest.mark.parametrize("n_views", [2, 6])
def test_skin_cull_kernel_matches_twin_for_several_views(skinned, n_views):
    dev, bounds, cull = skinned
    slots = [(s.index, int(dev.arrays.ranges[s.index][0]), s.joint_first) for s in dev.skin.slots]
    rng = np.random.default_rng(40 + n_views)
    sel = Selection(capacity=8)
    partial = dropped = 0
    for trial in range(8):
        views = views_of(rng, n_views, dist=(2.0, 10.0), ortho_every=3)
        rec = pose_records(dev, [float(rng.uniform(s.mesh.rig.start, s.mesh.rig.end)) for s in dev.skin.slots])
        cl.enqueue_copy(cl_device().queue, dev.skin_matrices, np.ascontiguousarray(rec, np.float32), is_blocking=True)
        fr, bf = [(True, True), (True, False), (False, True), (True, True)][trial % 4]
        got = cull.select_views(dev.skin_matrices, views, sel, cull_frustum=fr, cull_backface=bf)
        want = sref.select_views(bounds, slots, dev.instances, rec, views, fr, bf)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])
        assert got[2] == want[2]
        partial += int(np.sum(want[1] != np.uint64((1 << n_views) - 1)))
        dropped += want[2]["culled_frustum"] + want[2]["culled_backface"]
        # one view of the multi-view cull is that view's own cull, pair for pair
        v = trial % n_views
        own, _ = sref.select(bounds, slots, dev.instances, rec, views[v], fr, bf)
        assert as_set(own) == as_set(want[0][bit(want[1], v)])
    assert partial > 20 and dropped >= (5 if n_views == 2 else 1)   # six views rarely all cull a meshlet


# --- the raster: kernel == twin ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def raster_scene():
    s, g = flat_lod(*sphere(3)), flat_lod(*grid(24), run=100)
    return RasterScene([MeshObject(s, translate(-0.5, 0, 0), Material((0.8, 0.3, 0.2), specular=0.4), 1),
                        MeshObject(g, translate(0.6, 0.2, -0.5), Material((0.2, 0.6, 0.9)), 2,
                                   count=2, transforms=np.stack([translate(0.6, 0.2, -0.5), translate(-0.4, -0.6, -1.0)]))])


@pytest.mark.parametrize("n_views", [2, 6])
def test_raster_kernel_matches_twin_for_several_views(raster_scene, n_views):
    """Random view masks, views from far to inside the near plane (clipping, the large list): each
    layer equals the twin's one-view raster of its pairs, key for key."""
    sc = raster_scene
    rng = np.random.default_rng(60 + n_views)
    eyes = [(0.3, 0.2, 3.0), (0.2, -0.1, 0.9), (-1.0, 0.8, 2.0), (2.5, 1.0, 2.5), (-0.5, 0.1, 1.2), (0.0, 3.0, 0.5)]
    views = Views([Camera.look_at(eyes[k], (0, 0, 0), fov_y=50, size=SIZE, near=0.3, far=20) for k in range(n_views)])
    masks = rng.integers(1, 1 << n_views, len(sc.pairs)).astype(np.uint64)
    buf, cap, cnt = sc.selection()
    mb = cl.Buffer(cl_device().context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=masks)
    keys = KeyBuffer(*SIZE, layers=n_views)
    keys.clear()
    raster = MeshRaster(large_pixels=64, large_capacity=4)   # grows
    for _ in range(3):
        keys.clear()
        raster.enqueue(keys, views, sc.dev, buf, cap, cnt, masks=mb)
        raster.collect()
        cl_device().queue.finish()
        if not raster.grow():
            break
    color, aux = keys.read_keys()
    # on this device, layer v is the one-view raster of view v's pairs (whatever its built-ins round)
    ctx, q = cl_device().context, cl_device().queue
    for v, cam in enumerate(views):
        mine = sc.pairs[bit(masks, v)]
        sel = cl.Buffer(ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(mine))
        count = cl.Buffer(ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                          hostbuf=np.array([len(mine)] + [0] * 7, np.uint64))
        one = KeyBuffer(*SIZE)
        one.clear()
        MeshRaster(large_pixels=64, large_capacity=raster.large_capacity).enqueue(one, cam, sc.dev, sel, len(mine), count)
        q.finish()
        c1, a1 = one.read_keys()
        assert np.array_equal(c1, color[v]) and np.array_equal(a1, aux[v]), f"layer {v} is not view {v}'s raster"
    # and the twin's, key for key
    want = rref.rasterize_views(*SIZE, views, sc.arrays, sc.instances, sc.pairs, masks, large_pixels=64)
    np.testing.assert_array_equal(color, want["color"])
    np.testing.assert_array_equal(aux, want["aux"])
    got = raster.stats()
    for k in ("triangles", "near_clipped", "culled", "large", "pixels"):
        assert got[k] == want["counters"][k], k
    assert got["large"] > 0 and got["near_clipped"] > 0
    # layer v is view v: each holds pixels, and two views never draw the same image
    drawn = [(color[v] != rref.ALL_ONES).sum() for v in range(n_views)]
    assert min(drawn) > 100 and len({color[v].tobytes() for v in range(n_views)}) == n_views


# --- frames ------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def lod():
    return build_dag(*bumpy_sphere(4), progress=False, name="bumpy sphere")


def _apart_scene(lod, variant):
    """Two copies far apart, and two cameras at the same distance, each seeing one of them."""
    s = pl.Scene()
    s.add_mesh(lod, transform=pl.translate(-8, 0, 0), material=pl.Material((0.9, 0.4, 0.2)), variant=variant)
    s.add_mesh(lod, transform=pl.translate(8, 0, 0) @ pl.rotate(40, (0, 1, 0)), variant=variant)
    cams = [pl.Camera.look_at((-8 + 0.6, 0.5, 3.5), (-8, 0, 0), (0, 1, 0), 40.0, SIZE, near=0.05, far=30),
            pl.Camera.look_at((8 - 1.0, -0.8, 3.4), (8, 0, 0), (0, 1, 0), 40.0, SIZE, near=0.05, far=30)]
    return s, cams


def test_views_of_disjoint_instances_equal_their_single_view_frames(lod):
    s, cams = _apart_scene(lod, "meshlets")
    frames = pl.render_views(s, cams)
    assert len(frames) == 2
    for v, (frame, cam) in enumerate(zip(frames, cams)):
        single = pl.render(s, cam)
        assert set(np.unique(frame.object_id)) == {0, v + 1}
        np.testing.assert_array_equal(frame.object_id, single.object_id)
        np.testing.assert_array_equal(frame.depth, single.depth)
        np.testing.assert_array_equal(frame.color, single.color)
        assert frame.stats["view"] == v and frame.stats["views"] == 2
        vc = frame.stats["view_counts"]
        assert (vc["clusters_drawn"], vc["triangles_drawn"]) == (single.stats["clusters_drawn"],
                                                                 single.stats["triangles_drawn"])
    # one cut for both: the pairs are the union of the views'
    assert frames[0].stats["clusters_drawn"] == sum(f.stats["view_counts"]["clusters_drawn"] for f in frames)


@pytest.mark.parametrize("aa", [None, "4xMS"])
def test_meshlets_gl_views_match_single_view_frames(lod, aa):
    s, cams = _apart_scene(lod, "meshlets-gl")
    rs = pl.RenderSettings()
    if aa:
        rs.apply_aa(aa)
    frames = pl.render_views(s, cams, settings=rs)
    cl_frames = pl.render_views(s, cams, "meshlets", rs)
    for v, (frame, cam) in enumerate(zip(frames, cams)):
        single = pl.render(s, cam, settings=rs)
        assert frame.stats["variant"] == "meshlets-gl" and frame.stats["view"] == v
        assert frame.stats["view_counts"] == cl_frames[v].stats["view_counts"]
        assert frame.stats["view_counts"]["triangles_drawn"] == single.stats["triangles_drawn"]
        a, b = frame.object_id > 0, single.object_id > 0
        assert a.sum() > 500 and (a & b).sum() / (a | b).sum() > 0.999
        both = a & b   # the geometry stage rounds its own way (edge samples of MSAA most)
        np.testing.assert_allclose(frame.depth[both], single.depth[both], rtol=1e-4)
        np.testing.assert_allclose(frame.color[both], single.color[both], atol=2e-3)
        c = cl_frames[v].object_id > 0   # and the OpenCL raster's view covers the same pixels
        assert (a & c).sum() / (a | c).sum() > 0.98
        if aa:
            alpha = frame.color[..., 3]
            assert np.any((alpha > 0.05) & (alpha < 0.95)), "4xMS edges have partial coverage"


def test_a_far_view_is_refined_for_a_near_one(lod):
    """Two views of one mesh, near and far: the far view's share of the one cut is finer than its
    own cut (never coarser), and it still covers the same silhouette."""
    s = pl.Scene()
    s.add_mesh(lod)
    near = pl.Camera.look_at((0.3, 0.4, 2.2), (0, 0, 0), (0, 1, 0), 40.0, SIZE, near=0.05, far=30)
    far = pl.Camera.look_at((-0.5, 0.2, 9.0), (0, 0, 0), (0, 1, 0), 40.0, SIZE, near=0.05, far=30)
    for variant in ("meshlets", "meshlets-gl"):
        frames = pl.render_views(s, [near, far], variant)
        alone = pl.render(s, far, variant)
        assert frames[1].stats["view_counts"]["triangles_drawn"] > alone.stats["triangles_drawn"]
        a, b = frames[1].object_id > 0, alone.object_id > 0
        assert (a & b).sum() / (a | b).sum() > 0.97


def test_more_views_than_one_gl_draw_takes(lod):
    """Beyond VIEWS_PER_DRAW views the GL draw is chunked: views on either side of the chunk
    boundary equal their single-view frames."""
    n = VIEWS_PER_DRAW + 2
    size = (40, 30)
    s = pl.Scene()
    s.add_mesh(lod, variant="meshlets-gl")
    cams = [pl.Camera.look_at((3.0 * math.sin(a), 0.4, 3.0 * math.cos(a)), (0, 0, 0), (0, 1, 0), 45.0, size,
                              near=0.05, far=20) for a in np.linspace(0, 2 * math.pi, n, endpoint=False)]
    frames = pl.render_views(s, cams)
    assert len(frames) == n
    for v in (0, VIEWS_PER_DRAW - 1, VIEWS_PER_DRAW, n - 1):
        single = pl.render(s, cams[v])
        a, b = frames[v].object_id > 0, single.object_id > 0
        assert a.sum() > 100 and (a & b).sum() / (a | b).sum() > 0.99, v


@pytest.fixture(scope="module")
def worm(tmp_path_factory):
    path = tmp_path_factory.mktemp("worm") / "worm.glb"
    write_worm(path, {"nu": 40, "nv": 64, "bones": 12})   # fine enough for backface cones
    return load_skinned(path)


@pytest.mark.parametrize("variant", ["meshlets", "meshlets-gl"])
def test_skinned_mesh_in_two_views(worm, variant):
    """A skinned mesh seen from two sides: one skinned cull for both (each meshlet dropped only
    when both views cull it), each view the frame of its own camera."""
    c, r = worm.bounding_sphere()
    cams = [pl.Camera.look_at(c + np.array([0.3, 0.2, 1.0]) * r * 0.9, c + [0, r * 0.3, 0], (0, 1, 0), 40.0, SIZE,
                              near=r * 0.02, far=r * 8),
            pl.Camera.look_at(c + np.array([1.0, -0.3, 0.2]) * r * 1.6, c, (0, 1, 0), 40.0, SIZE, near=r * 0.02,
                              far=r * 8)]
    s = pl.Scene()
    s.add_skinned_mesh(worm, variant=variant, material=pl.Material(two_sided=False))
    frames = pl.render_views(s, cams, time=0.3)
    per_view = [f.stats["view_counts"]["clusters_drawn"] for f in frames]
    n = len(worm.clusters)
    assert frames[0].stats["skin_cull"] == "skin_cull"
    assert frames[0].stats["clusters_drawn"] + frames[0].stats["clusters_culled_frustum"] + \
        frames[0].stats["clusters_culled_backface"] == n
    assert max(per_view) < n and frames[0].stats["clusters_drawn"] > max(per_view)   # each view culls others
    for frame, cam, drawn in zip(frames, cams, per_view):
        single = pl.render(s, cam, time=0.3)
        assert single.stats["clusters_drawn"] == drawn
        if variant == "meshlets":
            np.testing.assert_array_equal(frame.object_id, single.object_id)
            np.testing.assert_array_equal(frame.depth, single.depth)
            np.testing.assert_array_equal(frame.color, single.color)
        else:
            a, b = frame.object_id > 0, single.object_id > 0
            assert a.sum() > 500 and (a & b).sum() / (a | b).sum() > 0.999


def test_per_view_stats_of_the_keys_renderer(lod):
    s = pl.Scene()
    tr = np.repeat(np.eye(4)[None], 6, axis=0)
    tr[:, 0, 3] = np.arange(6) * 3.0 - 7.5
    s.add_mesh_instances(lod, 6, transforms=tr)
    cams = [pl.Camera.look_at((x, 0.5, 5.0), (x, 0, 0), (0, 1, 0), 50.0, SIZE, near=0.05, far=40) for x in (-6, 0, 6)]
    frames = pl.render_views(s, cams)
    counts = [f.stats["view_counts"] for f in frames]
    total = frames[0].stats["clusters_drawn"]
    assert all(0 < c["clusters_drawn"] < total for c in counts)
    assert sum(c["clusters_drawn"] for c in counts) >= total        # shared clusters count in each view
    for f, cam in zip(frames, cams):
        assert f.stats["pixels_written"] == int(np.isfinite(f.depth).sum()) > 0


# --- bad input ------------------------------------------------------------------------------------------
def test_bad_multi_view_input_is_named(cut, raster_scene):
    sc = raster_scene
    views = Views([Camera.look_at((0, 0, 3), (0, 0, 0), size=SIZE), Camera.look_at((1, 0, 3), (0, 0, 0), size=SIZE)])
    buf, cap, cnt = sc.selection()
    keys = KeyBuffer(*SIZE, layers=2)
    with pytest.raises(MeshError, match="view masks"):
        MeshRaster().enqueue(keys, views, sc.dev, buf, cap, cnt)
    with pytest.raises(MeshError, match="2 layer"):
        MeshRaster().enqueue(keys, views[0], sc.dev, buf, cap, cnt, masks=buf)
    sel = Selection(capacity=4)
    with pytest.raises(MeshError, match="masks buffer"):
        cut.enqueue(sc.dev, views, 1.0, sel.pairs, 4, cl.Buffer(cl_device().context, cl.mem_flags.READ_WRITE,
                                                                 counters_bytes(2)))
    with pytest.raises(MeshError, match="counters buffer needs"):
        cut.enqueue(sc.dev, views, 1.0, sel.pairs, 4, sel.counters, masks=sel.pairs)
    with pytest.raises(SceneError, match="same size"):
        pl.render_views(pl.Scene(), [Camera.look_at((0, 0, 3), (0, 0, 0), size=(64, 48)),
                                     Camera.look_at((0, 0, 3), (0, 0, 0), size=(32, 24))])


def test_bad_gl_view_masks_are_named(lod):
    arrays = MeshArrays.pack([lod])
    instances = MeshInstances.pack([MeshObject(lod, np.eye(4), Material(), 1)], lambda o: 0)
    draw = MeshDraw()
    draw.upload(arrays, instances)
    sel = np.array([[0, 0], [0, 1]], np.uint32)
    views = Views([Camera.look_at((0, 0, 3), (0, 0, 0), size=SIZE)] * 2)
    with pytest.raises(MeshError, match="one unsigned view mask per selected pair"):
        draw.draw_views(sel, np.ones(3, np.uint64), views)
    with pytest.raises(MeshError, match="needs a paramlod.core.views.Views"):
        draw.draw_views(sel, np.ones(2, np.uint64), views[0])
    draw.release()
