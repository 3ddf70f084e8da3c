"""The discrete LOD chain (paramlod.meshlod.build.chain): its levels are proper (level 0 is the
original triangles, each level has at most the triangles of the one above, errors grow strictly,
every level indexes the original vertices), the device cut draws exactly one level per instance
and the same level as the numpy twin ``select_levels``, files and the cache keep it, the command
builds it, a scene draws it, bad settings are errors.

Meshes: tests/helpers/meshes (a closed icosphere, an open bumpy grid, scattered parts).
"""
from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from paramlod.app.cli import main
from paramlod.core.camera import Camera
from paramlod.core.layouts import INSTANCE_F
from paramlod.errors import MeshError
from paramlod.meshlod import source
from paramlod.meshlod.buffers import DeviceMeshes, MeshArrays, MeshInstances
from paramlod.meshlod.build.chain import ChainSettings, build_chain, chain_errors, select_levels
from paramlod.meshlod.build.dag import BuildSettings, build_dag, dag_parents
from paramlod.meshlod.cut import ClusterCut
from paramlod.meshlod.cut_reference import select
from paramlod.meshlod.format import check_meshlod, load_meshlod, mesh_info, save_meshlod
from paramlod.meshlod.source import build_settings, load_mesh
from paramlod.pipeline.driver import render
from paramlod.pipeline.settings import RenderSettings
from paramlod.scene.scene import Material, MeshObject, Scene

from helpers import meshes as test_meshes

MESHES = {
    "sphere": lambda: test_meshes.sphere(4),                         # 5,120 triangles, closed
    "grid": lambda: test_meshes.grid(40),                            # 3,200 triangles, open border
    "parts": lambda: test_meshes.scattered_parts(60, seed=3, subdiv=1),   # 4,800 triangles in 60 parts
}


@pytest.fixture(scope="module")
def chains():
    return {name: (make(), build_chain(*make(), name=name)) for name, make in MESHES.items()}


def canonical(tris) -> np.ndarray:
    """Triangles as rows rotated to start at their smallest index (winding kept), sorted."""
    t = np.asarray(tris, np.int64)
    k = np.argmin(t, axis=1)
    rolled = np.stack([t[np.arange(len(t)), (k + j) % 3] for j in range(3)], axis=1)
    return rolled[np.lexsort(rolled.T[::-1])]


def level_triangles(lod, k) -> np.ndarray:
    c = lod.clusters[lod.clusters["level"] == k]
    return np.concatenate([lod.triangles[f:f + n] for f, n in zip(c["first"], c["count"])])


# --- the levels ---------------------------------------------------------------------------------
@pytest.mark.parametrize("name", list(MESHES))
def test_levels_are_proper(chains, name):
    (v, f), lod = chains[name]
    check_meshlod(lod, name)
    assert lod.lod == "chain" and lod.levels >= 5
    assert np.array_equal(lod.vertices, v)           # the chain adds no vertex and moves none
    # level 0 is exactly the original triangles, winding kept
    assert np.array_equal(canonical(level_triangles(lod, 0)), canonical(f))
    counts = [len(level_triangles(lod, k)) for k in range(lod.levels)]
    assert counts == lod.info["level_triangles"] == mesh_info(lod)["triangles_per_level"]
    assert all(b <= a for a, b in zip(counts, counts[1:]))
    assert all(b <= 0.85 * a for a, b in zip(counts, counts[1:]))   # each level really is coarser
    assert lod.info["stopped"] == "min_triangles" and counts[-1] <= 100 < counts[-2]
    for k in range(1, lod.levels):
        t = level_triangles(lod, k)
        assert t.max() < len(v)
        assert np.all((t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 0] != t[:, 2]))
    e = chain_errors(lod)
    assert e[0] == 0 and np.all(np.diff(e) > 0)
    c = lod.clusters
    assert c["count"].max() <= 128 and np.all(c["group"] == c["level"])
    assert np.array_equal(c["error"], e[c["level"]])
    assert np.array_equal(c["parent_error"], np.append(e[1:], np.inf)[c["level"]])
    # the one sphere contains every vertex
    s = c["lod_sphere"][0].astype(np.float64)
    assert np.all(np.linalg.norm(v - s[:3], axis=1) <= s[3])
    assert np.all(c["parent_sphere"] == c["lod_sphere"][0])
    # every cluster's own bounds hold its triangles (frustum culling stays exact)
    for i in range(0, len(c), 7):
        pts = v[lod.triangles[c["first"][i]:c["first"][i] + c["count"][i]].reshape(-1)].astype(np.float64)
        assert np.all(np.linalg.norm(pts - c["sphere"][i, :3], axis=1) <= c["sphere"][i, 3] * (1 + 1e-5))
    # the DAG's reading of the records sees a chain: each level's parent is the next level
    level = c["level"].astype(np.int64)
    assert np.array_equal(dag_parents(c), np.where(level + 1 < lod.levels, level + 1, -1))
    roots = lod.roots
    assert np.all(c["level"][roots] == lod.levels - 1) and len(roots) == np.sum(c["level"] == lod.levels - 1)


def test_the_chain_shares_the_dags_simplifier_and_size(chains):
    (v, f), chain = chains["sphere"]
    dag = build_dag(v, f, name="sphere")
    # the same triangle count at level 0 and the same halving; the chain stores about twice the mesh
    assert chain.original_triangles == dag.original_triangles == len(f)
    assert 1.6 < len(chain.triangles) / len(f) < 2.1
    assert ChainSettings.like(BuildSettings(max_triangles=64, ratio=0.4)).max_triangles == 64
    small = build_chain(v, f, settings=ChainSettings(max_triangles=64, ratio=0.25, min_triangles=400))
    counts = small.info["level_triangles"]
    assert small.clusters["count"].max() <= 64 and counts[-1] <= 400 and len(counts) < chain.levels
    assert all(b <= 0.3 * a for a, b in zip(counts, counts[1:]))


def test_max_levels_and_the_stall_end_the_chain():
    v, f = MESHES["sphere"]()
    lod = build_chain(v, f, settings=ChainSettings(max_levels=2))
    assert lod.levels == 3 and lod.info["stopped"] == "max_levels"
    chain_errors(lod)
    # a tetrahedron folds to two triangles and no further: the stall ends the chain there
    v4 = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float32)
    f4 = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], np.uint32)
    tet = build_chain(v4, f4, settings=ChainSettings(min_triangles=1))
    assert tet.info["stopped"] == "stall" and tet.info["level_triangles"] == [4, 2]
    assert chain_errors(tet)[1] > 0 and np.all(tet.clusters["level"][tet.roots] == 1)


# --- level selection: the device cut against the numpy twin -------------------------------------
def chain_objects(rng, lod, n):
    """``n`` instances of ``lod`` along a line away from the origin (0.5 .. 300 mesh radii), each
    under a random rotation and scale (uniform and not, mirrors), so that every level is chosen."""
    r = float(lod.clusters["lod_sphere"][0, 3])
    models = np.zeros((n, 4, 4))
    for i in range(n):
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        d = np.full(3, rng.uniform(0.5, 2.0)) if i % 3 else rng.uniform(0.3, 2.0, 3) * rng.choice([-1, 1], 3)
        models[i, :3, :3] = q @ np.diag(d / r)
        models[i, :3, 3] = [rng.uniform(-1, 1), rng.uniform(-1, 1), -np.exp(rng.uniform(np.log(0.5), np.log(300)))]
        models[i, 3, 3] = 1
    return [MeshObject(lod, np.eye(4), Material(), 1, count=n, transforms=models)]


@pytest.mark.parametrize("name", ["sphere", "parts"])
def test_device_cut_draws_one_level_per_instance_as_the_twin(chains, name):
    _, lod = chains[name]
    rng = np.random.default_rng(7)
    objects = chain_objects(rng, lod, 40)
    arrays = MeshArrays.pack([lod])
    instances = MeshInstances.pack(objects, lambda m: 0)
    dev = DeviceMeshes(arrays, instances)
    cut = ClusterCut()
    level_of = lod.clusters["level"]
    per_level = [np.flatnonzero(level_of == k) for k in range(lod.levels)]
    seen = set()
    for trial in range(6):
        cam = Camera(Camera.look_at((rng.uniform(-1, 1), rng.uniform(-1, 1), 2.0), (0, 0, -20)).view,
                     float(rng.uniform(30, 70)), (int(rng.integers(64, 161)), int(rng.integers(48, 121))),
                     0.05, 1000.0)
        for t in (0.0, 0.5, 1.0, 4.0):
            want = select_levels(lod, instances.inst_f[:, INSTANCE_F.slice("model")], instances.scales, cam, t)
            assert np.all(want >= 0)
            if t == 0:
                assert np.all(want == 0)
            pairs, counts = cut.select(dev, cam, t, cull_frustum=False, cull_backface=False)
            for i in range(len(instances)):
                drawn = pairs[pairs[:, 0] == i, 1]
                # every cluster of one level, nothing else: the level the twin chose
                assert np.array_equal(drawn, per_level[want[i]]), (trial, t, i)
            assert counts["triangles"] == sum(int(lod.clusters["count"][per_level[k]].sum()) for k in want)
            seen.update(want.tolist())
            # with culling: the cut twin's pairs exactly, a subset of the chosen level's clusters
            pairs_c, counts_c = cut.select(dev, cam, t)
            ref_pairs, ref_counts = select(arrays, instances, cam, t)
            assert np.array_equal(pairs_c, ref_pairs) and counts_c == ref_counts
            assert np.all(level_of[pairs_c[:, 1]] == want[pairs_c[:, 0]])
    assert len(seen) >= lod.levels - 2   # the placements reach (nearly) every level


def test_select_levels_refuses_what_is_not_a_chain(chains):
    (v, f), lod = chains["grid"]
    dag = build_dag(v, f, name="grid")
    with pytest.raises(MeshError, match="not a chain"):
        chain_errors(dag)
    cam = Camera.look_at((0, 0, 3), (0, 0, 0), size=(64, 48))
    with pytest.raises(MeshError, match="2 models but 1 scales"):
        select_levels(lod, np.eye(4)[None].repeat(2, 0), [1.0], cam, 1.0)
    assert load_mesh(lod, lod="full") is lod   # a MeshLod comes back as it is (scenes take a chain so)
    bad = build_chain(v, f, name="grid")
    bad.clusters["error"][bad.clusters["level"] == 2] = bad.clusters["error"][bad.clusters["level"] == 1][0]
    with pytest.raises(MeshError, match="parent error|grow strictly"):
        chain_errors(bad)


# --- files, cache, command, scene ---------------------------------------------------------------
def test_file_round_trip_and_cache(chains, tmp_path, monkeypatch):
    (v, f), lod = chains["grid"]
    path = save_meshlod(lod, tmp_path / "grid.meshlod")
    back = load_meshlod(path)
    assert back.lod == "chain" and np.array_equal(back.clusters, lod.clusters)
    assert np.array_equal(back.triangles, lod.triangles) and back.info["level_triangles"] == lod.info["level_triangles"]
    monkeypatch.setenv("PARAMLOD_CACHE", str(tmp_path / "cache"))
    a = load_mesh((v, f), lod="chain")
    assert a.lod == "chain" and a.levels == lod.levels
    calls = []
    monkeypatch.setattr(source, "build_chain", lambda *x, **k: calls.append(1))
    b = load_mesh((v, f), lod="chain")           # from the cache, not built again
    assert calls == [] and np.array_equal(b.clusters, a.clusters)
    # the DAG of the same content is another cache entry
    assert load_mesh((v, f), lod="dag").lod == "dag" and len(list((tmp_path / "cache" / "meshlod").iterdir())) == 2
    # settings: the chain's own, a dict of them, or the DAG's shared fields
    assert build_settings({"min_triangles": 500}, "chain").min_triangles == 500
    assert build_settings(BuildSettings(max_triangles=64), "chain") == ChainSettings(max_triangles=64)
    with pytest.raises(MeshError, match="unknown chain build settings group_size"):
        build_settings({"group_size": 8}, "chain")
    with pytest.raises(MeshError, match="must be a BuildSettings"):
        build_settings(ChainSettings(), "dag")


@pytest.mark.parametrize("bad, match", [
    (dict(ratio=0.95), "ratio"), (dict(stall=0.4), "stall"), (dict(min_triangles=0), "min_triangles"),
    (dict(max_triangles=130), "max_triangles"), (dict(max_levels=0), "max_levels"), (dict(max_vertices=1.5), "integer"),
])
def test_bad_settings_name_the_setting(bad, match):
    v, f = MESHES["grid"]()
    with pytest.raises(MeshError, match=f"chain build setting {match}|{match}"):
        build_chain(v, f, settings=ChainSettings(**bad))


def test_command_builds_a_chain(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("PARAMLOD_CACHE", str(tmp_path / "cache"))
    v, f = MESHES["sphere"]()
    ply = tmp_path / "ball.ply"
    trimesh.Trimesh(v, f, process=False).export(ply)
    out = tmp_path / "ball.meshlod"
    assert main(["mesh", "build", str(ply), "--lod", "chain", "-o", str(out), "-q"]) == 0
    assert "ball.ply: lod chain, 5,120 triangles" in capsys.readouterr().out
    assert load_meshlod(out).lod == "chain"
    assert main(["mesh", "info", str(ply), "--chain", "--json"]) == 0   # the cached build
    info = json.loads(capsys.readouterr().out)
    assert info["lod"] == "chain" and info["triangles_per_level"][0] == 5120 and info["roots"] == info["clusters_per_level"][-1]
    assert main(["mesh", "build", str(ply), "--full", "--chain", "-q"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "--lod chain / --lod full contradict" in err


def test_a_scene_draws_the_chosen_level(chains):
    _, lod = chains["sphere"]
    scene = Scene()
    r = float(lod.clusters["lod_sphere"][0, 3])
    far = np.diag([1 / r, 1 / r, 1 / r, 1.0])
    far[:3, 3] = (0.0, 0.0, -12.0)
    obj = scene.add_mesh(lod, transform=far)
    assert obj.mesh is lod
    cam = Camera.look_at((0, 0, 0), (0, 0, -1), size=(96, 72), near=0.05, far=100.0)
    rs = RenderSettings()
    rs.mesh.cull_frustum = rs.mesh.cull_backface = False
    for t in (0.0, 2.0):
        rs.mesh.threshold_px = t
        k = select_levels(lod, far.reshape(1, 16), [1 / r], cam, t)[0]
        if t:
            assert k >= 2   # far away: a coarse level
        masks = []
        for variant in ("meshlets", "meshlets-gl"):   # the same cut, both renderers
            frame = render(scene, cam, variant, rs)
            assert frame.stats["triangles_drawn"] == len(level_triangles(lod, k)), variant
            masks.append(frame.coverage)
            assert masks[-1].sum() > 50
        assert (masks[0] & masks[1]).sum() / (masks[0] | masks[1]).sum() > 0.9
