"""The offline build of a mesh's discrete LOD chain (``lod="chain"``), the baseline most engines
use: ``build_chain``; and the chain's level selection in numpy, ``select_levels``.

Driven by paramlod.meshlod.source.load_mesh (cached builds), ``paramlod mesh build --lod chain``
and the mesh-LOD evaluation (paramlod.app.bench.mesh_eval). The chain is written in the same
Cluster records as the DAG, so the same cut kernel, rasterizer and OpenGL draw serve it; the DAG's
cut twin (paramlod.meshlod.cut_reference) is its twin, and ``select_levels`` is the same rule in
terms of levels (tests/meshlod/test_chain.py checks it against the device cut).

The levels: level 0 is the original triangles; level k is the whole of level k-1 simplified to
about ``ratio`` of its triangles by the DAG's simplifier (paramlod.meshlod.build.meshopt.simplify,
absolute error, no locked vertex, pruning of small parts as the DAG's default), down to
``min_triangles``; the chain stops early when a level keeps more than ``stall`` of the one above.
Every level is split into clusters of at most ``max_triangles`` (meshopt_buildMeshlets) that keep
their own bounds and backface cones (so the frustum and cone culling still work per cluster).
The simplifier never moves a vertex: every level indexes the original vertex array, so the chain
adds only indices and cluster records to the mesh.

Errors and spheres: every cluster of every level has the mesh's bounding sphere (inflated by a
relative 1e-6, rounded up in float32, like the DAG's spheres) as lod_sphere and parent_sphere;
level k's error is e_k = e_{k-1} + max(the simplifier's absolute error, 1e-6 of the mesh's radius)
(cumulative: each level is simplified from the one above, not from the original), rounded in
float32 to strictly above e_{k-1}, with e_0 = 0; its parent_error is e_{k+1}, +inf on the coarsest
level. So every cluster of one level makes the same decision and exactly one level is drawn per
instance: the level k with proj(e_k) <= T < proj(e_{k+1}), projected from the bounding sphere.
A cluster's ``group`` is its level.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from paramlod.core.layouts import CLUSTER
from paramlod.errors import MeshError
from paramlod.meshlod import cut_reference
from paramlod.meshlod.build import meshopt
from paramlod.meshlod.build.dag import (BuildSettings, Progress, SettingsRecord, check_mesh, cluster_bounds,
                                        round_up32, vertex_normals, weld_ids)
from paramlod.meshlod.format import MeshLod

_INFLATE = 1e-6        # relative slack on the sphere's radius (the DAG's)
_ERROR_FLOOR = 1e-6    # relative to the mesh's radius: a level's error is at least this above the one above
CLUSTER_MAX_TRIANGLES = CLUSTER.constant("CLUSTER_MAX_TRIANGLES")


@dataclass(frozen=True)
class ChainSettings(SettingsRecord):
    WHAT = "chain build"
    max_triangles: int = 128    # per cluster (<= CLUSTER_MAX_TRIANGLES, a multiple of 4)
    max_vertices: int = 255     # per cluster (meshoptimizer's limit)
    cone_weight: float = 0.25   # meshlet shape vs backface-cone tightness (meshopt_buildMeshlets)
    ratio: float = 0.5          # each level is simplified to about this fraction of the one above
    stall: float = 0.85         # a level that keeps more than this fraction ends the chain (not kept)
    min_triangles: int = 100    # the chain ends once a level has at most this many triangles
    max_levels: int = 32        # levels above 0 at most
    prune: bool = True          # let the simplifier drop whole small parts (the DAG's default)

    def validate(self) -> "ChainSettings":
        for name in ("max_triangles", "max_vertices", "min_triangles", "max_levels"):
            if isinstance(getattr(self, name), bool) or not isinstance(getattr(self, name), (int, np.integer)):
                self.bad(name, "must be an integer")
        self.check_meshlets_and_levels()
        if not self.min_triangles >= 1:
            self.bad("min_triangles", "must be >= 1")
        return self

    @classmethod
    def like(cls, dag: BuildSettings) -> "ChainSettings":
        """The chain settings that share a DAG build's cluster size, cone weight, ratio, stall and
        pruning (so a comparison isolates the structure)."""
        return cls(max_triangles=dag.max_triangles, max_vertices=dag.max_vertices, cone_weight=dag.cone_weight,
                   ratio=dag.ratio, stall=dag.stall, prune=dag.prune).validate()


def bounding_sphere(vertices: np.ndarray) -> np.ndarray:
    """float32 [4]: a sphere around every vertex (box centre, the farthest vertex checked in
    float64 from the stored float32 centre), inflated by a relative 1e-6 and rounded up."""
    v = np.asarray(vertices, np.float64)
    centre = np.float32((v.min(axis=0) + v.max(axis=0)) / 2)
    r = float(np.sqrt(((v - centre.astype(np.float64)) ** 2).sum(axis=1).max()))
    return np.array([*centre, round_up32(r * (1 + _INFLATE) + 1e-30)], np.float32)


def build_chain(vertices, faces, normals=None, *, settings: ChainSettings = ChainSettings(), progress=None,
                name: str = "array") -> MeshLod:
    """The discrete LOD chain of a triangle mesh (see the module docstring), as a MeshLod of lod
    "chain". ``normals`` float32 [V, 3] or None (area-weighted vertex normals are computed).
    ``progress``: as build_dag's (None: a bar from 200k triangles on a terminal, True, False, or a
    callable ``progress(done, total)`` in triangles simplified). MeshError for bad input."""
    t0 = time.perf_counter()
    if not isinstance(settings, ChainSettings):
        raise MeshError(f"{name}: chain settings must be a ChainSettings, got {type(settings).__name__}")
    s = settings.validate()
    v, f, n = check_mesh(vertices, faces, normals, what=name)
    if n is None:
        n = vertex_normals(v, f)
    sphere = bounding_sphere(v)
    err_floor = max(float(sphere[3]), 1e-30) * _ERROR_FLOOR
    target_error = max(4.0 * float(sphere[3]), 1e-30)   # absolute: never farther than the mesh is big
    # levels above 0 simplify one vertex per position (the first), as the DAG's do: meshoptimizer
    # locks a position more than two vertices share (seams, flat shading, triangle soups)
    weld, n_weld = weld_ids(v)
    first = np.full(n_weld, len(v), np.int64)
    np.minimum.at(first, weld, np.arange(len(v)))
    rep = first[weld]

    levels = [(f, 0.0, 0.0)]     # (triangles, cumulative error, the simplifier's own error)
    stopped = "min_triangles"
    bar = Progress(progress, 2 * len(f), len(f))   # the levels add up to about twice the mesh
    try:
        current, error = f, 0.0
        while len(current) > s.min_triangles:
            if len(levels) > s.max_levels:
                stopped = "max_levels"
                break
            welded = rep[current]
            uniq, inv = np.unique(welded.reshape(-1), return_inverse=True)
            pos = np.ascontiguousarray(v[uniq])
            local = inv.astype(np.uint32)
            target = int(len(current) * s.ratio) * 3
            options = meshopt.SIMPLIFY_ERROR_ABSOLUTE | (meshopt.SIMPLIFY_PRUNE if s.prune else 0)
            res, err = meshopt.simplify(local, pos, None, target, target_error, options)
            bar.step(len(current), len(levels))
            if len(res) == 0 or len(res) > s.stall * len(current) * 3:
                stopped = "stall"
                break
            e = np.float32(error + max(float(err), err_floor))
            if not e > np.float32(error):
                e = np.nextafter(np.float32(error), np.float32(np.inf))
            current, error = uniq[res.reshape(-1, 3)].astype(np.uint32), float(e)
            levels.append((current, error, float(err)))
    finally:
        bar.close()

    rows, tris_out, first_tri = [], [], 0
    errors = [lv[1] for lv in levels] + [np.inf]
    for k, (tris, e, _) in enumerate(levels):
        mt, counts = meshopt.build_meshlets(tris, v, s.max_vertices, s.max_triangles, s.cone_weight)
        starts = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        for i in range(len(counts)):
            t = mt[starts[i]:starts[i + 1]]
            rows.append((k, first_tri, len(t), cluster_bounds(t, v), e, errors[k + 1]))
            first_tri += len(t)
        tris_out.append(mt)
    c = np.zeros(len(rows), CLUSTER.dtype)
    c["first"] = [r[1] for r in rows]
    c["count"] = [r[2] for r in rows]
    c["sphere"] = np.stack([r[3][0] for r in rows])
    c["cone_apex"][:, :3] = np.stack([r[3][1] for r in rows])
    c["cone"] = np.stack([r[3][2] for r in rows])
    c["lod_sphere"] = sphere
    c["parent_sphere"] = sphere
    c["error"] = [r[4] for r in rows]
    c["parent_error"] = [r[5] for r in rows]
    c["level"] = [r[0] for r in rows]
    c["group"] = [r[0] for r in rows]
    lod = MeshLod(vertices=v, normals=n, triangles=np.concatenate(tris_out).astype(np.uint32), clusters=c,
                  name=name, lod="chain")
    lod.info.update({
        "settings": s.as_dict(), "build_seconds": round(time.perf_counter() - t0, 4), "stopped": stopped,
        "level_triangles": [len(lv[0]) for lv in levels],
        "simplifier_errors": [lv[2] for lv in levels],
    })
    return lod


# --- reading a chain back ---------------------------------------------------------------------------
def chain_errors(lod: MeshLod) -> np.ndarray:
    """float32 [levels]: each level's error (e_0 = 0), checked to be the chain's structure: every
    cluster of a level carries its level's error, the next level's as parent error (+inf on the
    last), and the one sphere; errors strictly increasing. MeshError naming the mesh otherwise."""
    c = lod.clusters
    where = f"mesh '{lod.name}'"
    if lod.lod != "chain":
        raise MeshError(f"{where} is lod {lod.lod!r}, not a chain (build it with lod='chain')")
    levels = lod.levels
    if not np.array_equal(np.unique(c["level"]), np.arange(levels)):
        raise MeshError(f"{where}: chain levels are not 0..{levels - 1}")
    if not (np.all(c["lod_sphere"] == c["lod_sphere"][0]) and np.all(c["parent_sphere"] == c["lod_sphere"][0])):
        raise MeshError(f"{where}: a chain's clusters must all carry the mesh's one bounding sphere")
    errors = np.empty(levels, np.float32)
    for k in range(levels):
        sel = c["level"] == k
        e, pe = np.unique(c["error"][sel]), np.unique(c["parent_error"][sel])
        if len(e) != 1 or len(pe) != 1:
            raise MeshError(f"{where}: the clusters of chain level {k} carry different errors")
        errors[k] = e[0]
        if k + 1 < levels and pe[0] != np.unique(c["error"][c["level"] == k + 1])[0]:
            raise MeshError(f"{where}: level {k}'s parent error is not level {k + 1}'s error")
        if k + 1 == levels and not np.isinf(pe[0]):
            raise MeshError(f"{where}: the coarsest chain level must have parent error +inf")
    if errors[0] != 0 or not np.all(np.diff(errors) > 0):
        raise MeshError(f"{where}: chain errors must start at 0 and grow strictly, got {errors.tolist()}")
    return errors


def select_levels(lod: MeshLod, models, scales, camera, threshold_px) -> np.ndarray:
    """numpy twin of the cut in terms of levels: int64 [n], the chain level drawn for each of the
    n instances of models ``models`` (float [n, 4, 4] or [n, 16], row-major) with largest scales
    ``scales`` [n], for ``camera`` and ``threshold_px``: the k with proj(e_k) <= T < proj(e_{k+1})
    in the cut's own float32 arithmetic (paramlod.meshlod.cut_reference.projected_error)."""
    errors = chain_errors(lod)
    cc = cut_reference.cut_camera(camera, threshold_px)
    m = np.ascontiguousarray(np.asarray(models, np.float32).reshape(-1, 16))
    s = np.asarray(scales, np.float32).reshape(-1)
    if len(s) != len(m):
        raise MeshError(f"select_levels: {len(m)} models but {len(s)} scales")
    spheres = np.repeat(lod.clusters["lod_sphere"][:1], len(errors), axis=0)
    p = cut_reference.projected_error(errors, spheres, m, s, cc)         # [n, levels]
    T = cc[cut_reference.CC_T]
    # the cut's rule per level: its own error within T, the next level's (+inf past the last) beyond
    above = np.concatenate([p[:, 1:] > T, np.ones((len(m), 1), bool)], axis=1)
    hit = (p <= T) & above
    # exactly one level passes (the projection is monotone in the error); -1 marks a broken chain
    return np.where(hit.sum(axis=1) == 1, np.argmax(hit, axis=1), -1).astype(np.int64)
