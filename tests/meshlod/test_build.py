"""The cluster-DAG build (paramlod.meshlod.build): the meshoptimizer layer and the DAG's invariants
(monotone errors, nested spheres, consistent levels, level 0 = the original triangles, one cluster
per root-to-leaf path for any threshold, crack-free cuts of a closed mesh)."""
import numpy as np
import pytest

from helpers.meshes import grid, load_bunny, scattered_parts, sphere
from paramlod.errors import MeshError
from paramlod.meshlod.build import meshopt
from paramlod.meshlod.build.dag import BuildSettings, build_dag, dag_parents, enclosing_sphere, weld_ids

MESHES = {
    "grid": lambda: grid(24),
    "sphere": lambda: sphere(4),
    "parts": lambda: scattered_parts(2000, seed=3),
    "bunny": load_bunny,
}
_BUILT = {}


def built(name):
    if name not in _BUILT:
        v, f = MESHES[name]()
        _BUILT[name] = (v, f, build_dag(v, f, None, progress=False, name=name))
    return _BUILT[name]


def canonical(tris) -> np.ndarray:
    """Triangles rotated so that the smallest index comes first (winding kept), sorted."""
    t = np.asarray(tris, np.int64)
    k = np.argmin(t, axis=1)
    rot = np.stack([t[np.arange(len(t)), (k + j) % 3] for j in range(3)], axis=1)
    return rot[np.lexsort(rot.T[::-1])]


def cluster_tris(lod, i):
    c = lod.clusters[i]
    return lod.triangles[c["first"]:c["first"] + c["count"]]


# --- the meshoptimizer layer --------------------------------------------------------------------
def test_meshlets_keep_every_triangle_with_its_winding():
    v, f = sphere(3)
    tris, counts = meshopt.build_meshlets(f, v, 255, 128, 0.25)
    assert counts.sum() == len(f) and counts.max() <= 128 and len(counts) >= len(f) // 128
    np.testing.assert_array_equal(canonical(tris), canonical(f))


def test_cluster_bounds_partition_and_simplify():
    v, f = sphere(3)
    tris, counts = meshopt.build_meshlets(f, v, 255, 64, 0.0)
    b = meshopt.cluster_bounds(tris[:counts[0]], v)
    pts = v[tris[:counts[0]].ravel()]
    assert np.linalg.norm(pts - np.array(b.center), axis=1).max() <= b.radius * (1 + 1e-5)
    assert 0 < b.cone_cutoff < 1 and abs(np.linalg.norm(b.cone_axis) - 1) < 1e-5
    part, n = meshopt.partition_clusters(tris.ravel(), counts * 3, len(v), 4)
    assert 2 <= n < len(counts) and part.max() == n - 1
    half, err = meshopt.simplify(f, v, None, len(f) * 3 // 2, 1e3, meshopt.SIMPLIFY_ERROR_ABSOLUTE)
    assert len(half) == len(f) * 3 // 2 and 0 < err < 0.1
    same, err = meshopt.simplify(f, v, np.ones(len(v), np.uint8), len(f) * 3 // 2, 1e3,
                                 meshopt.SIMPLIFY_ERROR_ABSOLUTE)
    assert len(same) == len(f) * 3 and err == 0   # every vertex locked: nothing can collapse


def test_wrappers_refuse_arguments_that_would_abort_the_library():
    v, f = sphere(1)
    with pytest.raises(MeshError, match="multiple of 4"):
        meshopt.build_meshlets(f, v, 255, 126)
    with pytest.raises(MeshError, match="max_vertices"):
        meshopt.build_meshlets(f, v, 256, 128)
    with pytest.raises(MeshError, match="out of range"):
        meshopt.simplify(f + len(v), v, None, 3)
    with pytest.raises(MeshError, match="lock array"):
        meshopt.simplify(f, v, np.zeros(3, np.uint8), 3)
    with pytest.raises(MeshError, match="at most 512"):
        meshopt.cluster_bounds(np.zeros((513, 3), np.uint32), v)
    with pytest.raises(MeshError, match="add up"):
        meshopt.partition_clusters(f.ravel(), [3, 3], len(v), 4)


def test_a_newer_library_abi_is_refused(monkeypatch):
    # meshopt_simplify exists in every version: posing as the 0.24+ marker must refuse the library
    monkeypatch.setattr(meshopt, "_LIB", None)
    monkeypatch.setattr(meshopt, "_NEWER_ABI", ("meshopt_simplify",))
    with pytest.raises(MeshError, match="0.24 or newer.*partitionClusters"):
        meshopt.library()
    monkeypatch.setattr(meshopt, "_NEWER_ABI", ())
    monkeypatch.setattr(meshopt, "_REQUIRED", meshopt._REQUIRED + ("meshopt_noSuchFunction",))
    with pytest.raises(MeshError, match="lacks meshopt_noSuchFunction"):
        meshopt.library()


# --- helpers of the build -------------------------------------------------------------------------
def test_weld_ids_join_equal_positions_only():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 0], [-0.0, 0, 0], [1, 0, 1e-7]], np.float32)
    ids, n = weld_ids(v)
    assert n == 3 and ids[0] == ids[2] == ids[3] and len({ids[0], ids[1], ids[4]}) == 3


def test_enclosing_sphere_contains_its_spheres():
    rng = np.random.default_rng(1)
    for _ in range(50):
        s = np.concatenate([rng.normal(size=(6, 3)) * 10 ** rng.uniform(-3, 3), rng.uniform(0, 2, (6, 1))], axis=1)
        s = s.astype(np.float32)
        e = enclosing_sphere(s).astype(np.float64)
        d = np.linalg.norm(s[:, :3].astype(np.float64) - e[:3], axis=1) + s[:, 3]
        assert np.all(d <= e[3])


# --- the DAG's invariants --------------------------------------------------------------------------
@pytest.mark.parametrize("name", list(MESHES))
def test_dag_invariants(name):
    v, f, lod = built(name)
    c = lod.clusters
    assert c.dtype.itemsize == 112 and len(lod.roots) >= 1
    assert np.all(c["count"] >= 1) and np.all(c["count"] <= 128)
    assert np.all(np.diff(c["level"].astype(np.int64)) >= 0)          # level 0 first (sorted)
    np.testing.assert_array_equal(c["first"][1:], np.cumsum(c["count"])[:-1])
    # errors monotone, strictly above the children's (so a threshold of 0 selects only level 0)
    assert np.all(c["parent_error"] > c["error"])
    level0 = c["level"] == 0
    assert np.all(c["error"][level0] == 0) and np.all(c["error"][~level0] > 0)
    np.testing.assert_array_equal(c["lod_sphere"][level0], c["sphere"][level0])
    # spheres nested, checked in float64 on the stored float32 numbers
    d = np.linalg.norm(c["parent_sphere"][:, :3].astype(np.float64) - c["lod_sphere"][:, :3], axis=1)
    assert np.all(d + c["lod_sphere"][:, 3] <= c["parent_sphere"][:, 3])
    # every cluster's sphere holds its triangles
    for i in range(len(c)):
        p = lod.vertices[cluster_tris(lod, i).ravel()].astype(np.float64)
        assert np.linalg.norm(p - c["sphere"][i, :3], axis=1).max() <= c["sphere"][i, 3]
    # cones: a real cutoff in [0, 1) with a unit axis, or "never cull" (> 1)
    cut = c["cone"][:, 3]
    real = cut < 1
    assert np.all(cut[real] >= 0) and np.all(cut[~real] > 1)   # 0: a flat cluster, culled by its plane
    np.testing.assert_allclose(np.linalg.norm(c["cone"][real, :3], axis=1), 1, atol=1e-5)
    # level 0 holds exactly the original triangles
    np.testing.assert_array_equal(canonical(lod.triangles[:lod.original_triangles]), canonical(f))
    assert lod.original_triangles == len(f)
    np.testing.assert_array_equal(lod.vertices, v)
    # the groups: one error, lod sphere and level each; parents above their children
    parent = dag_parents(c)
    assert np.all((parent >= 0) == np.isfinite(c["parent_error"]))
    for g in np.unique(c["group"]):
        members = c[c["group"] == g]
        assert len(np.unique(members["error"])) == 1 and len(np.unique(members["level"])) == 1
        assert len(np.unique(members["lod_sphere"], axis=0)) == 1
        children = c[parent == g]
        if len(children):
            assert members["level"][0] == children["level"].max() + 1
            assert members["error"][0] > children["error"].max()
            # the group's triangles are about half of what it was made from
            assert members["count"].sum() <= 0.85 * children["count"].sum()


@pytest.mark.parametrize("name", list(MESHES))
def test_build_reaches_few_roots_by_halving(name):
    v, f, lod = built(name)
    c = lod.clusters
    per_level = [int(c["count"][c["level"] == k].sum()) for k in range(lod.levels)]
    assert len(lod.roots) <= 4, (name, len(lod.roots))
    assert per_level[1] <= 0.6 * per_level[0]
    assert lod.levels >= 4
    assert c["count"][lod.roots].sum() <= 4 * 128


def _one_cluster_per_path(lod, selected) -> bool:
    """Along every root-to-leaf path of the DAG, exactly one cluster is selected (min = max = 1 of
    the selected count over the paths below each root)."""
    c = lod.clusters
    parent = dag_parents(c)
    lo = np.zeros(len(c), np.int64)
    hi = np.zeros(len(c), np.int64)
    children_of = {}
    for i, p in enumerate(parent):
        if p >= 0:
            children_of.setdefault(int(p), []).append(i)
    for i in np.argsort(c["level"], kind="stable"):   # children before parents
        kids = children_of.get(int(c["group"][i]), [])
        lo[i] = int(selected[i]) + (min(lo[k] for k in kids) if kids else 0)
        hi[i] = int(selected[i]) + (max(hi[k] for k in kids) if kids else 0)
    roots = lod.roots
    return bool(np.all(lo[roots] == 1) and np.all(hi[roots] == 1))


def _select(lod, eye, threshold):
    """A conservative projection as the cut makes it: error / (distance to the sphere), monotone in
    the error and in sphere containment."""
    c = lod.clusters

    def proj(err, s):
        d = np.linalg.norm(s[:, :3].astype(np.float64) - eye, axis=1) - s[:, 3]
        return np.where(np.isinf(err), np.inf, err / np.maximum(d, 1e-6))

    return (proj(c["error"], c["lod_sphere"]) <= threshold) & (threshold < proj(c["parent_error"], c["parent_sphere"]))


@pytest.mark.parametrize("name", ["sphere", "parts", "bunny"])
def test_any_threshold_draws_one_cluster_per_path(name):
    v, f, lod = built(name)
    rng = np.random.default_rng(7)
    centre, radius = lod.bounding_sphere()
    errors = lod.clusters["error"][lod.clusters["error"] > 0]
    for k in range(6):
        eye = centre + rng.normal(size=3) * radius * rng.uniform(0.5, 6)
        t = 0.0 if k == 0 else float(np.quantile(errors, rng.uniform())) / (radius * rng.uniform(0.5, 4))
        sel = _select(lod, eye, t)
        assert _one_cluster_per_path(lod, sel)
        if t == 0.0:
            assert np.array_equal(sel, lod.clusters["level"] == 0)   # threshold 0: the original triangles


def _edges_twice_opposite(tris, weld) -> bool:
    w = weld[np.asarray(tris, np.int64)]
    directed = np.concatenate([w[:, [0, 1]], w[:, [1, 2]], w[:, [2, 0]]])
    fwd = {tuple(e) for e in directed.tolist()}
    return len(fwd) == len(directed) and all((b, a) in fwd for a, b in fwd)


@pytest.mark.parametrize("soup", [False, True])
def test_cuts_of_a_closed_mesh_are_watertight(soup):
    """Every edge of the selected triangles is shared by exactly two of them, in opposite
    directions, at every cut: no cracks between clusters of different levels. The soup variant
    (every triangle with its own three vertices) checks that locking goes by position."""
    v, f = sphere(4)
    if soup:
        v, f = v[f.ravel()], np.arange(3 * len(f), dtype=np.uint32).reshape(-1, 3)
    lod = build_dag(v, f, None, progress=False)
    weld, _ = weld_ids(lod.vertices)
    rng = np.random.default_rng(5)
    centre, radius = lod.bounding_sphere()
    for k in range(5):
        eye = centre + rng.normal(size=3) * radius * 2.5
        t = [0.0, 0.002, 0.01, 0.03, 1.0][k]
        sel = np.flatnonzero(_select(lod, eye, t))
        tris = np.concatenate([cluster_tris(lod, i) for i in sel])
        assert _edges_twice_opposite(tris, weld), (soup, t)
    assert lod.levels >= 5 and len(lod.roots) == 1


def test_open_borders_stay_free():
    # only the vertices shared between groups are locked: an open grid still ends in one root
    v, f, lod = built("grid")
    assert len(lod.roots) == 1


def test_full_lod_is_level_zero_only():
    v, f = sphere(3)
    lod = build_dag(v, f, None, lod="full", progress=False)
    c = lod.clusters
    assert lod.lod == "full" and lod.levels == 1 and len(lod.roots) == len(c)
    assert np.all(np.isinf(c["parent_error"])) and np.all(c["error"] == 0)
    np.testing.assert_array_equal(canonical(lod.triangles), canonical(f))


def test_normals_are_kept_or_computed():
    v, f = sphere(2)
    n = np.tile(np.float32([0, 0, 1]), (len(v), 1))
    assert np.array_equal(build_dag(v, f, n, progress=False).normals, n)
    computed = build_dag(v, f, None, progress=False).normals
    np.testing.assert_allclose(np.sum(computed * v, axis=1), 1, atol=0.02)   # outward on a unit sphere


def test_progress_callback_and_build_info():
    calls = []
    v, f = sphere(4)
    lod = build_dag(v, f, None, progress=lambda done, total: calls.append((done, total)))
    assert calls and all(a[0] <= b[0] for a, b in zip(calls, calls[1:]))
    assert all(done <= total for done, total in calls)
    assert lod.info["settings"] == BuildSettings().as_dict() and lod.info["build_seconds"] > 0


def test_a_disconnected_mesh_with_pruning_off_still_terminates():
    v, f = scattered_parts(300, seed=1)
    lod = build_dag(v, f, None, settings=BuildSettings(prune=False), progress=False)
    assert lod.levels >= 2 and lod.original_triangles == len(f)
    assert np.all(lod.clusters["parent_error"] > lod.clusters["error"])


@pytest.mark.parametrize("vertices, faces, message", [
    (np.zeros((0, 3)), np.zeros((0, 3), int), "empty"),
    ([[0, 0, 0], [1, 0, 0], [np.nan, 1, 0]], [[0, 1, 2]], "NaN"),
    ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 3]], "0..2"),
    ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 1]], "repeat a vertex"),
    ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], [[0, 1, 2, 3]], "triangles"),
    ([[0, 0], [1, 0], [0, 1]], [[0, 1, 2]], r"\[V, 3\]"),
    # float32 holds 1e20, but not its square: meshoptimizer's meshlets came out empty (a numpy traceback)
    ([[0, 0, 0], [1e20, 0, 0], [0, 1e20, 0]], [[0, 1, 2]], r"reach 1e\+20 .* below 1.84e\+19"),
    ([[1.5e19, 1.5e19, 1.5e19], [1.6e19, 1.5e19, 1.5e19], [1.5e19, 1.6e19, 1.5e19]], [[0, 1, 2]],
     r"reach 2.66e\+19 from the origin"),
])
def test_bad_input_is_a_mesh_error_naming_it(vertices, faces, message):
    with pytest.raises(MeshError, match=message) as exc:
        build_dag(np.asarray(vertices, float), np.asarray(faces), None, progress=False, name="bad.ply")
    assert "bad.ply" in str(exc.value)


def test_a_mesh_just_within_the_float32_square_limit_builds():
    lod = build_dag(np.array([[0, 0, 0], [1e19, 0, 0], [0, 1e19, 0]]), np.array([[0, 1, 2]]), None, progress=False)
    assert all(np.isfinite(lod.clusters[k]).all() for k in ("sphere", "lod_sphere", "cone"))


def test_bad_settings_and_lod():
    v, f = sphere(1)
    with pytest.raises(MeshError, match="max_triangles"):
        build_dag(v, f, None, settings=BuildSettings(max_triangles=130))
    with pytest.raises(MeshError, match="stall"):
        build_dag(v, f, None, settings=BuildSettings(ratio=0.5, stall=0.4))
    with pytest.raises(MeshError, match="'dag' or 'full'"):
        build_dag(v, f, None, lod="coarse")
    with pytest.raises(MeshError, match="unknown build settings colour"):
        BuildSettings.from_dict({"colour": 1})


def test_groups_that_do_not_shrink_end_the_build(monkeypatch):
    """A simplifier that removes nothing: every group stalls, the build tries larger groups, then
    stops with the level-0 clusters as roots instead of looping."""
    from paramlod.meshlod.build import dag

    calls = []

    def stuck(indices, positions, lock=None, target_index_count=0, target_error=0.0, options=0):
        calls.append(len(indices))
        return np.asarray(indices, np.uint32).copy(), 0.0

    monkeypatch.setattr(dag.meshopt, "simplify", stuck)
    v, f = sphere(4)
    lod = build_dag(v, f, None, progress=False)
    assert lod.levels == 1 and len(lod.roots) == len(lod.clusters) and lod.info["stalled_groups"] > 0
    assert lod.info["rounds"] == 3 and max(calls) > 8 * 128 * 3   # groups doubled twice before stopping


def test_builds_are_deterministic():
    v, f = scattered_parts(300, seed=4)
    a = build_dag(v, f, None, progress=False)
    b = build_dag(v, f, None, progress=False)
    for name in ("vertices", "normals", "triangles", "clusters"):
        assert getattr(a, name).tobytes() == getattr(b, name).tobytes()
