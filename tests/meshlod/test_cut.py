"""The per-frame LOD cut (paramlod.meshlod.cut, kernels/meshlod/cut.cl) against its numpy twin
(paramlod.meshlod.cut_reference), and the cut's properties: a valid cut of the DAG (every
level-0 cluster covered exactly once), threshold 0 = the original clusters, nesting in the
threshold and the distance, overflow and growth, frustum and backface culling against float64
brute force, bad input.

Meshes: synthetic DAGs made here from CLUSTER records (random spheres, errors and cones, nested
and monotone by construction, products of one group spread over several next groups), a
clustered icosphere with real bounding spheres and cones (one level), and real DAGs of the
builder (paramlod.meshlod.build.dag) when it is importable.
"""
from __future__ import annotations

import math

import numpy as np
import pyopencl as cl
import pytest

from paramlod.core.camera import Camera
from paramlod.core.layouts import CLUSTER
from paramlod.device.context import cl_device
from paramlod.errors import MeshError
from paramlod.meshlod import buffers
from paramlod.meshlod.buffers import DeviceMeshes, MeshArrays, MeshInstances
from paramlod.meshlod.build.dag import build_dag
from paramlod.meshlod.cut import ClusterCut, Selection
from paramlod.meshlod.cut_reference import COUNTERS, ONE_SIDED, SIMILAR, projected_error, cut_camera, select
from paramlod.meshlod.format import MeshLod
from paramlod.scene.scene import Material, MeshObject
from paramlod.surfels.build.views import OrthoCamera

from helpers import meshes as test_meshes


# --- meshes -------------------------------------------------------------------------------------
def _records(rows) -> np.ndarray:
    c = np.zeros(len(rows), CLUSTER.dtype)
    for i, r in enumerate(rows):
        for k, v in r.items():
            c[i][k] = v
    return c


def _random_cone(rng, centre, radius):
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    cutoff = 1.0 if rng.random() < 0.2 else rng.uniform(-0.4, 0.95)
    apex = centre + rng.normal(size=3) * radius * 0.3
    return np.append(apex, 0.0), np.append(axis, cutoff)


def synthetic_lod(seed: int, leaves: int = 48, group_size: int = 4, name: str = "synthetic") -> MeshLod:
    """A DAG of CLUSTER records with no geometry behind it: level-0 spheres at random, groups of
    ``group_size`` clusters taken along a random direction (so one group's products land in
    different next groups), each group's sphere enclosing its members' with a margin, its error
    the members' largest plus a random step, half as many products as members."""
    rng = np.random.default_rng(seed)
    rows = []
    for _ in range(leaves):
        c, r = rng.uniform(-1, 1, 3), rng.uniform(0.05, 0.2)
        apex, cone = _random_cone(rng, c, r)
        rows.append(dict(sphere=np.append(c + rng.normal(size=3) * 0.01, r * 0.9), lod_sphere=np.append(c, r),
                         cone_apex=apex, cone=cone, error=0.0, count=int(rng.integers(1, 129)), level=0,
                         group=len(rows)))
    gid, level, current = leaves, 0, list(range(leaves))
    while len(current) > 1:
        d = rng.normal(size=3)
        current.sort(key=lambda i: float(np.dot(rows[i]["lod_sphere"][:3], d)))
        chunks = [current[k:k + group_size] for k in range(0, len(current), group_size)]
        if len(chunks) > 1 and len(chunks[-1]) == 1:
            last = chunks.pop()
            chunks[-1] += last
        nxt = []
        for members in chunks:
            s = np.array([rows[m]["lod_sphere"] for m in members])
            centre = s[:, :3].mean(axis=0)
            radius = float((np.linalg.norm(s[:, :3] - centre, axis=1) + s[:, 3]).max()) * 1.01 + 1e-3
            err = max(rows[m]["error"] for m in members) + rng.uniform(0.002, 0.05) * 2.0 ** level
            for m in members:
                rows[m]["parent_sphere"] = np.append(centre, radius)
                rows[m]["parent_error"] = err
            for _ in range(max(1, len(members) // 2)):
                c = centre + rng.normal(size=3) * radius * 0.2
                apex, cone = _random_cone(rng, c, radius * 0.5)
                nxt.append(len(rows))
                rows.append(dict(sphere=np.append(c, radius * 0.5), lod_sphere=np.append(centre, radius),
                                 cone_apex=apex, cone=cone, error=err, count=int(rng.integers(1, 129)),
                                 level=level + 1, group=gid))
            gid += 1
        current, level = nxt, level + 1
    for r in rows:
        if "parent_error" not in r:
            r["parent_error"], r["parent_sphere"] = np.inf, r["lod_sphere"]
    clusters = _records(rows)
    clusters["first"] = np.concatenate([[0], np.cumsum(clusters["count"])[:-1]])
    tris = np.zeros((int(clusters["count"].sum()), 3), np.uint32)
    return MeshLod(np.zeros((1, 3), np.float32), np.array([[0, 0, 1]], np.float32), tris, clusters, name=name)


def _cone(vertices, tris, centre):
    """A backface cone of triangles (meshoptimizer's construction, float64): the axis is the mean
    normal; the cutoff sin(widest normal angle); the apex moved back along the axis until it lies
    behind every triangle's plane. No cone (cutoff 1) when some normal is 90 degrees off."""
    p = vertices[tris].astype(np.float64)
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    axis = n.sum(axis=0)
    axis /= np.linalg.norm(axis)
    mindp = float((n @ axis).min())
    if mindp <= 0.1:
        return np.append(centre, 0.0), np.array([*axis, 1.0])
    t = float((np.einsum("ij,ij->i", centre - p[:, 0], n) / (n @ axis)).max())
    cutoff = np.nextafter(np.float32(math.sqrt(1 - mindp * mindp)), np.float32(2))
    return np.append(centre - axis * t, 0.0), np.array([*axis, cutoff])


def clustered_sphere(subdiv: int = 3, patches: int = 40) -> MeshLod:
    """An icosphere cut into ``patches`` clusters (faces by nearest Fibonacci direction) with real
    bounding spheres and cones; one level, every cluster a root (the lod="full" shape)."""
    v, f = test_meshes.sphere(subdiv)
    k = np.arange(patches) + 0.5
    z = 1 - 2 * k / patches
    phi = k * math.pi * (3 - math.sqrt(5))
    dirs = np.stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z], axis=1)
    cent = v[f].mean(axis=1)
    owner = np.argmax(cent @ dirs.T, axis=1)
    order = np.argsort(owner, kind="stable")
    f, owner = f[order], owner[order]
    rows, first = [], 0
    for g in range(patches):
        tris = f[owner == g]
        if not len(tris):
            continue
        pts = v[np.unique(tris)].astype(np.float64)
        c = pts.mean(axis=0)
        r = np.nextafter(np.float32(np.linalg.norm(pts - c, axis=1).max() * (1 + 1e-6)), np.float32(np.inf))
        apex, cone = _cone(v, tris, c)
        rows.append(dict(sphere=np.append(c, r), lod_sphere=np.append(c, r), parent_sphere=np.append(c, r),
                         cone_apex=apex, cone=cone, error=0.0, parent_error=np.inf, first=first,
                         count=len(tris), level=0, group=g))
        first += len(tris)
        assert len(tris) <= CLUSTER.constant("CLUSTER_MAX_TRIANGLES")
    normals = v / np.linalg.norm(v, axis=1, keepdims=True)
    return MeshLod(v, normals.astype(np.float32), f.astype(np.uint32), _records(rows), name="sphere", lod="full")


# --- instances and cameras ----------------------------------------------------------------------
def _rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def random_models(rng, n, spread=4.0):
    """Models that cycle through: rotation x uniform scale, non-uniform scale, a mirror with a
    uniform scale, a mirror with a non-uniform scale; random translations."""
    out = np.zeros((n, 4, 4))
    for i in range(n):
        kind = i % 4
        s = rng.uniform(0.4, 2.0)
        d = np.full(3, s) if kind in (0, 2) else rng.uniform(0.3, 2.0, 3)
        if kind >= 2:
            d[rng.integers(3)] *= -1
        out[i, :3, :3] = _rotation(rng) @ np.diag(d)
        out[i, :3, 3] = rng.uniform(-spread, spread, 3)
        out[i, 3, 3] = 1
    return out


def scene_of(objects):
    meshes = []
    for o in objects:
        if all(o.mesh is not m for m in meshes):
            meshes.append(o.mesh)
    index = {id(m): k for k, m in enumerate(meshes)}
    arrays = MeshArrays.pack(meshes)
    instances = MeshInstances.pack(objects, lambda o: index[id(o.mesh)])
    return arrays, instances


def one_sided_first(k) -> Material:
    """Object k's material: the even ones one-sided (backface cones apply), the odd ones two-sided."""
    return Material(two_sided=k % 2 == 1)


def objects_for(rng, mesh_counts, spread=4.0):
    objs = []
    for k, (mesh, n) in enumerate(mesh_counts):
        objs.append(MeshObject(mesh, np.eye(4), one_sided_first(k), k + 1, count=n,
                               transforms=random_models(rng, n, spread)))
    return objs


def random_camera(rng, ortho=False, dist=(3.0, 30.0)):
    d = rng.normal(size=3)
    eye = d / np.linalg.norm(d) * rng.uniform(*dist)
    size = (int(rng.integers(64, 161)), int(rng.integers(48, 121)))
    view = Camera.look_at(eye, rng.uniform(-1, 1, 3), size=size).view
    near = float(rng.uniform(0.05, 0.5))
    if ortho:
        return OrthoCamera(view, size, float(rng.uniform(1.0, 10.0)), near, 200.0)
    return Camera(view, float(rng.uniform(20, 90)), size, near, 200.0)


@pytest.fixture(scope="module")
def cut():
    return ClusterCut()


def device_select(cut, arrays, instances, camera, t, **cull):
    return cut.select(DeviceMeshes(arrays, instances), camera, t, **cull)


# --- the DAG relations the checks use ------------------------------------------------------------
def dag_relations(clusters):
    """(parent group of every cluster, -1 for a root; {group: its products}). A group is the set
    of clusters made in it (``group`` of level >= 1); a cluster's parent group is the one whose
    (error, lod_sphere) its (parent_error, parent_sphere) names (the builder's implicit link)."""
    key_of, products = {}, {}
    for i, c in enumerate(clusters):
        if c["level"] == 0:
            continue
        key = (np.float32(c["error"]).tobytes(), c["lod_sphere"].tobytes())
        g = int(c["group"])
        assert key_of.setdefault(g, key) == key, f"cluster {i}: group {g}'s clusters differ in error or sphere"
        products.setdefault(g, []).append(i)
    by_key = {}
    for g, key in key_of.items():
        assert key not in by_key, f"groups {by_key.get(key)} and {g} have the same error and sphere"
        by_key[key] = g
    parent = np.full(len(clusters), -1)
    for i, c in enumerate(clusters):
        if np.isinf(c["parent_error"]):
            continue
        key = (np.float32(c["parent_error"]).tobytes(), c["parent_sphere"].tobytes())
        assert key in by_key, f"cluster {i}: no group has its parent error and sphere"
        parent[i] = by_key[key]
    return parent, products


def collapsed_groups(clusters, selected, relations):
    """Check that ``selected`` (bool per cluster of one mesh, one instance) is a valid cut: every
    level-0 cluster is covered exactly once by selected clusters or by a collapsed group above it.
    Returns {group: collapsed}. A group is collapsed when its products, each selected or itself
    replaced by its collapsed parent group, stand in for its members; partly is an error."""
    parent, products = relations
    memo = {}

    def cover(i):   # 0 or 1: how often cluster i's area is drawn at or above i
        n = int(selected[i]) + (collapsed(parent[i]) if parent[i] >= 0 else 0)
        assert n <= 1, f"cluster {i} is drawn and replaced by its parents too"
        return n

    def collapsed(g):
        if g not in memo:
            ys = {cover(p) for p in products[g]}
            assert len(ys) == 1, f"group {g}: some of its products stand in for it and some do not"
            memo[g] = ys.pop()
        return memo[g]

    for i in np.flatnonzero(clusters["level"] == 0):
        assert cover(i) == 1, f"level-0 cluster {i} is not drawn and no group above it is"
    for g in products:
        collapsed(g)
    return memo


def per_instance(pairs, arrays, instances):
    """{instance: bool mask over its mesh's clusters} of sorted (instance, cluster) pairs."""
    out = {}
    for mesh, i0, ni in instances.batches:
        c0, nc = (int(x) for x in arrays.ranges[mesh])
        for i in range(i0, i0 + ni):
            out[i] = np.zeros(nc, bool)
    for i, c in pairs:
        mesh = next(m for m, i0, ni in instances.batches if i0 <= i < i0 + ni)
        out[int(i)][int(c) - int(arrays.ranges[mesh][0])] = True
    return out


# --- device == twin -----------------------------------------------------------------------------
def test_twin_flag_matches_the_instance_flag():
    assert (SIMILAR, ONE_SIDED) == (buffers.SIMILAR, buffers.ONE_SIDED)


@pytest.mark.parametrize("seed", range(6))
def test_device_matches_twin_exactly(cut, seed):
    rng = np.random.default_rng(seed)
    a, b = synthetic_lod(seed, leaves=60), synthetic_lod(100 + seed, leaves=25, group_size=3)
    arrays, instances = scene_of(objects_for(rng, [(a, 9), (b, 5), (a, 3)]))
    dev = DeviceMeshes(arrays, instances)
    compared = 0
    for ortho in (False, True):
        cam = random_camera(rng, ortho=ortho)
        for t in (0.0, 0.3, 1.0, 4.0, 60.0):
            for cull in ((True, True), (True, False), (False, True), (False, False)):
                kw = dict(cull_frustum=cull[0], cull_backface=cull[1])
                got, gc = cut.select(dev, cam, t, **kw)
                want, wc = select(arrays, instances, cam, t, **kw)
                np.testing.assert_array_equal(got, want)
                assert gc == wc
                compared += len(want)
    assert compared > 1000


def test_device_matches_twin_on_the_edges_of_the_rule(cut):
    """Thresholds equal to projected errors themselves (the comparisons' ties, taken from the
    twin's arithmetic) and one float below them, a camera whose near plane cuts the spheres: the twin and the device agree
    exactly, and the cut stays valid at the ties."""
    rng = np.random.default_rng(7)
    lod = synthetic_lod(7, leaves=40)
    arrays, instances = scene_of(objects_for(rng, [(lod, 6)], spread=1.0))
    dev = DeviceMeshes(arrays, instances)
    cam = Camera.look_at((0.3, 0.2, 1.5), (0, 0, 0), fov_y=70, size=(96, 64), near=0.8, far=50)
    c = lod.clusters[lod.clusters["level"] > 0]
    v = projected_error(c["error"], c["lod_sphere"], np.ascontiguousarray(instances.inst_f[:, :16]), instances.scales,
              cut_camera(cam, 0.0))
    ties = np.unique(v)
    assert len(ties) > 100
    # at each value and one float below it: a device off by one rounding in either direction differs
    for k, t in enumerate(np.concatenate([ties, np.nextafter(ties, np.float32(0))])):
        got, gc = cut.select(dev, cam, float(t))
        want, wc = select(arrays, instances, cam, float(t))
        np.testing.assert_array_equal(got, want)
        assert gc == wc
        if k % 10 == 0:
            pairs, _ = cut.select(dev, cam, float(t), cull_frustum=False, cull_backface=False)
            _check_all(arrays, instances, pairs)


# --- properties of the cut ----------------------------------------------------------------------
def _check_all(arrays, instances, pairs):
    out = []
    masks = per_instance(pairs, arrays, instances)
    rel = {}
    for mesh, i0, ni in instances.batches:
        c0, nc = (int(x) for x in arrays.ranges[mesh])
        cl = arrays.clusters[c0:c0 + nc]
        rel.setdefault(mesh, dag_relations(cl))
        for i in range(i0, i0 + ni):
            out.append((i, collapsed_groups(cl, masks[i], rel[mesh])))
    return dict(out)


@pytest.mark.parametrize("seed", range(4))
def test_cut_is_valid_for_random_cameras(cut, seed):
    rng = np.random.default_rng(50 + seed)
    lod = synthetic_lod(50 + seed, leaves=80)
    arrays, instances = scene_of(objects_for(rng, [(lod, 8)]))
    dev = DeviceMeshes(arrays, instances)
    levels_drawn = set()
    for k in range(6):
        cam = random_camera(rng, ortho=k == 5)
        for t in (0.5, 2.0, 8.0):
            pairs, counts = cut.select(dev, cam, t, cull_frustum=False, cull_backface=False)
            _check_all(arrays, instances, pairs)
            levels_drawn |= set(arrays.clusters["level"][pairs[:, 1]].tolist())
            assert counts["tests"] == len(instances) * len(lod.clusters)
            assert counts["culled_frustum"] == counts["culled_backface"] == 0
    assert len(levels_drawn) >= 3   # the cameras reach several levels: the check saw mixed cuts


def test_threshold_zero_draws_exactly_the_original_clusters(cut):
    rng = np.random.default_rng(3)
    lod = synthetic_lod(3, leaves=50)
    arrays, instances = scene_of(objects_for(rng, [(lod, 7)]))
    dev = DeviceMeshes(arrays, instances)
    leaves = np.flatnonzero(arrays.clusters["level"] == 0)
    want = np.array([(i, c) for i in range(len(instances)) for c in leaves], np.uint32)
    for cam in (random_camera(rng), random_camera(rng, dist=(100.0, 150.0)), random_camera(rng, ortho=True)):
        pairs, counts = cut.select(dev, cam, 0.0, cull_frustum=False, cull_backface=False)
        np.testing.assert_array_equal(pairs, want)
        assert counts["triangles"] == len(instances) * lod.original_triangles


def test_larger_thresholds_and_distances_collapse_more(cut):
    """Collapsed groups are nested: for a larger threshold, and for the camera moved straight
    back along its view axis (every depth grows, so every projected error shrinks). The drawn
    triangles then change by exactly the collapsed groups' products minus members."""
    rng = np.random.default_rng(11)
    lod = synthetic_lod(11, leaves=80)
    arrays, instances = scene_of(objects_for(rng, [(lod, 4)], spread=2.0))
    dev = DeviceMeshes(arrays, instances)
    parent, products = dag_relations(arrays.clusters)
    count = arrays.clusters["count"].astype(np.int64)
    delta = {g: int(count[products[g]].sum()) - int(count[parent == g].sum()) for g in products}
    leaf_tris = len(instances) * lod.original_triangles
    eye, target = np.array([1.0, 2.0, 6.0]), np.zeros(3)
    ahead = (target - eye) / np.linalg.norm(target - eye)
    runs = []
    for back, t in [(0, 0.5), (0, 1.0), (0, 3.0), (2, 3.0), (6, 3.0), (20, 3.0), (20, 30.0)]:
        cam = Camera.look_at(eye - back * ahead, target, size=(120, 90), far=500)
        pairs, counts = cut.select(dev, cam, t, cull_frustum=False, cull_backface=False)
        col = _check_all(arrays, instances, pairs)
        tris = leaf_tris + sum(delta[g] for c in col.values() for g, on in c.items() if on)
        assert counts["triangles"] == tris
        runs.append(col)
    for a, b in zip(runs, runs[1:]):
        for i in a:
            assert all(b[i][g] for g, on in a[i].items() if on)
    assert sum(map(sum, (c.values() for c in runs[0].values()))) < sum(map(sum, (c.values() for c in runs[-1].values())))


# --- capacity -------------------------------------------------------------------------------------
def test_overflow_reports_the_true_count_and_growing_redoes_the_cut(cut):
    rng = np.random.default_rng(5)
    lod = synthetic_lod(5, leaves=40)
    arrays, instances = scene_of(objects_for(rng, [(lod, 6)]))
    dev = DeviceMeshes(arrays, instances)
    cam = random_camera(rng)
    want, wc = select(arrays, instances, cam, 0.0)
    assert wc["selected"] > 20
    sel = Selection(capacity=7)
    cut.enqueue(dev, cam, 0.0, sel)
    counts = sel.read_counters()
    assert counts == wc                                  # the true count, not the capacity
    part = sel.read_pairs(7)
    assert len({tuple(p) for p in part} - {tuple(p) for p in want}) == 0   # the first 7 are real ones
    with pytest.raises(MeshError, match="grow"):
        sel.read_pairs()
    assert sel.grow() and sel.capacity >= wc["selected"]
    assert not sel.grow()
    cut.enqueue(dev, cam, 0.0, sel)
    got = sel.read_pairs()
    np.testing.assert_array_equal(got[np.lexsort((got[:, 1], got[:, 0]))], want)
    # the buffer form of the contract, with counters added to (reset=False) for a second view
    ctx = cl_device().context
    buf = cl.Buffer(ctx, cl.mem_flags.READ_WRITE, 8 * 2 * len(want))
    counters = cl.Buffer(ctx, cl.mem_flags.READ_WRITE, 64)
    cut.enqueue(dev, cam, 0.0, buf, 2 * len(want), counters)
    cut.enqueue(dev, cam, 0.0, buf, 2 * len(want), counters, reset=False)
    raw = np.zeros(8, np.uint64)
    cl.enqueue_copy(cl_device().queue, raw, counters)
    assert raw[:5].tolist() == [2 * wc[k] for k in COUNTERS] and raw[5:].tolist() == [0, 0, 0]
    out = np.zeros((2 * len(want), 2), np.uint32)
    cl.enqueue_copy(cl_device().queue, out, buf)
    np.testing.assert_array_equal(np.unique(out, axis=0), want)


# --- culling against float64 brute force --------------------------------------------------------
def world_positions(model, pts):
    return pts @ model[:3, :3].T + model[:3, 3]


def _culled(cut, dev, cam, **cull):
    """Pairs drawn without the given culling but not with it."""
    base, _ = cut.select(dev, cam, 0.0, cull_frustum=False, cull_backface=False)
    kept, counts = cut.select(dev, cam, 0.0, **cull)
    b, k = {tuple(p) for p in base}, {tuple(p) for p in kept}
    assert k <= b
    return sorted(b - k), counts


def test_frustum_culling_drops_only_clusters_outside():
    cut_ = ClusterCut()
    rng = np.random.default_rng(21)
    lod = clustered_sphere()
    arrays, instances = scene_of(objects_for(rng, [(lod, 24)], spread=6.0))
    dev = DeviceMeshes(arrays, instances)
    total = 0
    for k in range(5):
        cam = random_camera(rng, ortho=k == 4, dist=(4.0, 12.0))
        culled, counts = _culled(cut_, dev, cam, cull_frustum=True, cull_backface=False)
        assert counts["culled_frustum"] == len(culled)
        pv = cam.projection @ cam.view
        for i, c in culled:
            model = instances.inst_f[i, :16].reshape(4, 4).astype(np.float64)
            cl = arrays.clusters[c]
            tri = arrays.triangles[cl["first"]:cl["first"] + cl["count"]]
            clip = np.c_[world_positions(model, arrays.vertices[tri.ravel(), :3].astype(np.float64)), np.ones(tri.size)] @ pv.T
            w = clip[:, 3]
            tol = 1e-6 * np.abs(clip).max()
            outside = [(clip[:, a] * s < -w + tol).all() for a in range(3) for s in (1, -1)]
            assert any(outside), f"instance {i} cluster {c} was culled with a vertex inside the frustum"
        total += len(culled)
    assert total > 50


def test_backface_culling_drops_only_clusters_facing_away():
    """Every triangle of a culled cluster faces away from the eye (its outward normal in world
    space, flipped under a mirror, against the view ray); only SIMILAR, ONE_SIDED instances are culled."""
    cut_ = ClusterCut()
    rng = np.random.default_rng(31)
    lod = clustered_sphere()
    arrays, instances = scene_of(objects_for(rng, [(lod, 16)], spread=3.0))
    dev = DeviceMeshes(arrays, instances)
    flags = instances.inst_u[:, 3]
    total, mirrored = 0, 0
    for k in range(6):
        cam = random_camera(rng, ortho=k >= 4, dist=(2.0, 12.0))
        culled, counts = _culled(cut_, dev, cam, cull_frustum=False, cull_backface=True)
        assert counts["culled_backface"] == len(culled)
        ahead = -cam.view[2, :3]
        for i, c in culled:
            assert flags[i] & SIMILAR and flags[i] & ONE_SIDED
            model = instances.inst_f[i, :16].reshape(4, 4).astype(np.float64)
            cl = arrays.clusters[c]
            tri = arrays.triangles[cl["first"]:cl["first"] + cl["count"]]
            p = world_positions(model, arrays.vertices[tri.ravel(), :3].astype(np.float64)).reshape(-1, 3, 3)
            n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]) * np.sign(np.linalg.det(model[:3, :3]))
            ray = np.broadcast_to(ahead, p[:, 0].shape) if isinstance(cam, OrthoCamera) else p[:, 0] - cam.eye
            cos = np.einsum("ij,ij->i", n, ray) / np.linalg.norm(n, axis=1) / np.linalg.norm(ray, axis=1)
            assert (cos >= -1e-5).all(), f"instance {i} cluster {c}: a culled triangle faces the eye"
            mirrored += bool(flags[i] & buffers.MIRRORED)
        total += len(culled)
    assert total > 30 and mirrored > 5


# --- bad input ------------------------------------------------------------------------------------
@pytest.mark.parametrize("t", [-0.5, float("nan"), "1", None, True])
def test_bad_threshold_is_a_mesh_error(cut, t):
    lod = synthetic_lod(1, leaves=8)
    arrays, instances = scene_of(objects_for(np.random.default_rng(1), [(lod, 1)]))
    cam = Camera.look_at((0, 0, 5), (0, 0, 0), size=(64, 48))
    with pytest.raises(MeshError, match="threshold_px"):
        cut.enqueue(DeviceMeshes(arrays, instances), cam, t, Selection())
    with pytest.raises(MeshError, match="threshold_px"):
        select(arrays, instances, cam, t)


def test_bad_camera_and_selection_are_mesh_errors(cut):
    lod = synthetic_lod(2, leaves=8)
    arrays, instances = scene_of(objects_for(np.random.default_rng(2), [(lod, 1)]))
    dev = DeviceMeshes(arrays, instances)
    cam = Camera.look_at((0, 0, 5), (0, 0, 0), size=(64, 48))

    class Skewed(Camera):
        @property
        def projection(self):
            p = Camera.projection.fget(self)
            p[3, 0] = 0.1
            return p

    with pytest.raises(MeshError, match="last row"):
        cut.enqueue(dev, Skewed(cam.view, 45.0, (64, 48)), 1.0, Selection())
    sel = Selection(capacity=4)
    with pytest.raises(MeshError, match="capacity and counters"):
        cut.enqueue(dev, cam, 1.0, sel.pairs)
    with pytest.raises(MeshError, match="does not fit"):
        cut.enqueue(dev, cam, 1.0, sel.pairs, 5, sel.counters)


def test_infinite_threshold_draws_the_roots_and_empty_scenes_draw_nothing(cut):
    lod = synthetic_lod(4, leaves=30)
    arrays, instances = scene_of(objects_for(np.random.default_rng(4), [(lod, 3)]))
    cam = Camera.look_at((0, 0, 5), (0, 0, 0), size=(64, 48))
    pairs, counts = device_select(cut, arrays, instances, cam, np.inf, cull_frustum=False, cull_backface=False)
    assert counts["selected"] == 3 * len(lod.roots)
    assert set(pairs[:, 1].tolist()) == set(lod.roots.tolist())
    empty = MeshInstances.pack([], lambda m: 0)
    pairs, counts = device_select(cut, arrays, empty, cam, 1.0)
    assert len(pairs) == 0 and counts == dict.fromkeys(COUNTERS, 0)


# --- real DAGs (paramlod.meshlod.build.dag) -------------------------------------------------------
@pytest.fixture(scope="module")
def real_dags():
    """DAGs the builder makes of a closed sphere, an open height field, 120 disconnected parts and
    the Stanford bunny scan (99,785 triangles, 67 parts)."""
    srcs = {"sphere": test_meshes.sphere(4), "grid": test_meshes.grid(48),
            "parts": test_meshes.scattered_parts(120, subdiv=2), "bunny": test_meshes.load_bunny()}
    return {k: build_dag(v, f, progress=False, name=k) for k, (v, f) in srcs.items()}


def unit_objects(rng, lods_counts, spread=4.0):
    """Mesh objects whose transform brings each mesh to the unit sphere, then random models."""
    objs = []
    for k, (lod, n) in enumerate(lods_counts):
        c, r = lod.bounding_sphere()
        to_unit = np.diag([1 / r, 1 / r, 1 / r, 1.0])
        to_unit[:3, 3] = -c / r
        objs.append(MeshObject(lod, np.eye(4), one_sided_first(k), k + 1, count=n,
                               transforms=random_models(rng, n, spread) @ to_unit))
    return objs


def test_real_dags_device_matches_twin_and_cuts_are_valid(cut, real_dags):
    rng = np.random.default_rng(41)
    arrays, instances = scene_of(unit_objects(rng, [(real_dags[k], 4) for k in ("sphere", "grid", "parts", "bunny")]))
    dev = DeviceMeshes(arrays, instances)
    levels = set()
    for k in range(5):
        cam = random_camera(rng, ortho=k == 4, dist=(2.0, 25.0))
        for t in (0.0, 1.0, 4.0, 16.0):
            for cull in (True, False):
                got, gc = cut.select(dev, cam, t, cull_frustum=cull, cull_backface=cull)
                want, wc = select(arrays, instances, cam, t, cull_frustum=cull, cull_backface=cull)
                np.testing.assert_array_equal(got, want)
                assert gc == wc
            _check_all(arrays, instances, got)   # the last one: culling off
            levels |= set(arrays.clusters["level"][got[:, 1]].tolist())
            if t == 0:
                assert (arrays.clusters["level"][got[:, 1]] == 0).all()
                assert gc["triangles"] == 4 * sum(real_dags[k].original_triangles for k in real_dags)
    assert len(levels) >= 4


def test_real_cones_cull_only_triangles_facing_away(real_dags):
    """The builder's meshoptimizer cones, under rotations, uniform scales and mirrors."""
    cut_ = ClusterCut()
    rng = np.random.default_rng(43)
    arrays, instances = scene_of(unit_objects(rng, [(real_dags["bunny"], 6), (real_dags["sphere"], 6)], spread=2.5))
    dev = DeviceMeshes(arrays, instances)
    flags = instances.inst_u[:, 3]
    total = mirrored = 0
    for k in range(4):
        cam = random_camera(rng, ortho=k == 3, dist=(2.0, 8.0))
        culled, counts = _culled(cut_, dev, cam, cull_frustum=False, cull_backface=True)
        assert counts["culled_backface"] == len(culled)
        for i, c in culled:
            assert flags[i] & SIMILAR and flags[i] & ONE_SIDED
            model = instances.inst_f[i, :16].reshape(4, 4).astype(np.float64)
            cl = arrays.clusters[c]
            tri = arrays.triangles[cl["first"]:cl["first"] + cl["count"]]
            p = world_positions(model, arrays.vertices[tri.ravel(), :3].astype(np.float64)).reshape(-1, 3, 3)
            n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]) * np.sign(np.linalg.det(model[:3, :3]))
            ray = np.broadcast_to(-cam.view[2, :3], p[:, 0].shape) if isinstance(cam, OrthoCamera) else p[:, 0] - cam.eye
            ok = np.linalg.norm(n, axis=1) > 0   # the scan has a few zero-area triangles
            cos = np.einsum("ij,ij->i", n[ok], ray[ok]) / np.linalg.norm(n[ok], axis=1) / np.linalg.norm(ray[ok], axis=1)
            assert (cos >= -1e-4).all(), f"instance {i} cluster {c}: a culled triangle faces the eye ({cos.min()})"
            mirrored += bool(flags[i] & buffers.MIRRORED)
        total += len(culled)
    assert total > 100 and mirrored > 10
