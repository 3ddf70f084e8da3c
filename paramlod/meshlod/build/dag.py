"""The offline build of a mesh's cluster DAG (Nanite-style level of detail): ``build_dag``.

Driven by paramlod.meshlod.source.load_mesh (cached builds) and ``paramlod mesh build``; the
result is a paramlod.meshlod.format.MeshLod whose invariants the cut (paramlod.meshlod.cut and its
numpy twin) relies on. No twin: tests/meshlod/test_build.py checks the invariants directly.

The build (meshoptimizer through paramlod.meshlod.build.meshopt):
1. level 0: meshlets of at most ``max_triangles`` triangles over the original triangles;
2. the live clusters (those not yet simplified) are grouped: meshopt_partitionClusters joins
   clusters that share vertices into groups of about ``group_size``; groups it leaves small (parts
   that touch nothing) are pooled and joined by proximity, a k-d split of their centres, because
   edge-only grouping never reaches one root on a mesh of thousands of disconnected parts;
3. each group is simplified to about ``ratio`` of its triangles with only the vertices it shares
   with other groups locked (vertices welded by position, so split seams lock too; the mesh's own
   open borders stay free: locking them stalls open scans at dozens of roots). The simplifier only
   drops vertices, so every level indexes the original vertex array and shared borders match.
   Levels above 0 use one vertex per position (the first): meshoptimizer locks any position more
   than two vertices share, so a triangle soup or a flat-shaded mesh would not simplify otherwise;
4. the result is split into new clusters, which are live for the next round. A group whose result
   keeps more than ``stall`` of its triangles is left as it is and its clusters stay live (they may
   group differently next round); the build ends when one cluster is left, when a round (also with
   doubled groups) makes no progress, or after ``max_levels`` rounds: what is live then are roots.

Errors and spheres (object units): a level-0 cluster has error 0 and its own sphere as lod sphere.
A group's error is max(its clusters' errors) + max(the simplifier's absolute error, a floor of 1e-6
of the mesh's radius), rounded in float32 to strictly above the children's (so parent_error >
error exactly, and threshold 0 selects exactly level 0). A group's lod sphere encloses its
clusters' lod spheres, computed in float64 from the stored float32 values and inflated by a
relative 1e-6, so containment holds for the stored numbers.
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np
from tqdm import tqdm

from paramlod.core.layouts import CLUSTER
from paramlod.core.transforms import SQUARE_LIMIT
from paramlod.errors import MeshError
from paramlod.meshlod.build import meshopt
from paramlod.meshlod.format import MeshLod

NEVER_CULL = 2.0       # cone cutoff for clusters whose normal cone is too wide (dot <= 1 < 2)
_INFLATE = 1e-6        # relative slack on every sphere radius (float32 roundoff)
_ERROR_FLOOR = 1e-6    # relative to the mesh's radius: a group's error is at least this above its children's
_QUIET_BELOW = 200_000 # triangles: builds smaller than this show no progress bar by default
CLUSTER_MAX_TRIANGLES = CLUSTER.constant("CLUSTER_MAX_TRIANGLES")


class SettingsRecord:
    """as_dict / from_dict (unknown names refused) for the frozen settings dataclasses of the builds."""
    WHAT = "build"

    def as_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict):
        known = set(cls.__dataclass_fields__)
        unknown = set(d) - known
        if unknown:
            raise MeshError(f"unknown {cls.WHAT} settings {', '.join(sorted(unknown))} "
                            f"(known: {', '.join(sorted(known))})")
        return cls(**d).validate()

    def bad(self, name, rule):
        raise MeshError(f"{self.WHAT} setting {name}={getattr(self, name)!r}: {rule}")

    def check_meshlets_and_levels(self):
        """The fields both builds have: meshlet limits, the reduction per round, the rounds."""
        bad = self.bad
        if not (4 <= self.max_triangles <= CLUSTER_MAX_TRIANGLES and self.max_triangles % 4 == 0):
            bad("max_triangles", f"must be a multiple of 4 in 4..{CLUSTER_MAX_TRIANGLES}")
        if not 3 <= self.max_vertices <= meshopt.MAX_MESHLET_VERTICES:
            bad("max_vertices", f"must be in 3..{meshopt.MAX_MESHLET_VERTICES}")
        if not 0.0 <= self.cone_weight <= 1.0:
            bad("cone_weight", "must be in [0, 1]")
        if not 0.05 <= self.ratio <= 0.9:
            bad("ratio", "must be in [0.05, 0.9]")
        if not self.ratio < self.stall < 1.0:
            bad("stall", "must be above ratio and below 1")
        if not 1 <= self.max_levels <= 64:
            bad("max_levels", "must be in 1..64")


@dataclass(frozen=True)
class BuildSettings(SettingsRecord):
    max_triangles: int = 128    # per cluster (<= CLUSTER_MAX_TRIANGLES, a multiple of 4)
    max_vertices: int = 255     # per cluster (meshoptimizer's limit; the raster reads global indices)
    cone_weight: float = 0.25   # meshlet shape vs backface-cone tightness (meshopt_buildMeshlets)
    group_size: int = 8         # clusters per group (meshopt_partitionClusters' target)
    ratio: float = 0.5          # each group is simplified to about this fraction of its triangles
    stall: float = 0.85         # a group that keeps more than this fraction has not shrunk
    max_levels: int = 32        # rounds of grouping and simplifying at most
    prune: bool = True          # let the simplifier drop whole small parts that touch no locked vertex

    def validate(self) -> "BuildSettings":
        self.check_meshlets_and_levels()
        if not 2 <= self.group_size <= 64:
            self.bad("group_size", "must be in 2..64")
        return self


# --- input ------------------------------------------------------------------------------------------
def check_mesh(vertices, faces, normals=None, what: str = "mesh"):
    """(vertices float32 [V,3], faces uint32 [F,3], normals float32 [V,3] or None), or MeshError
    naming ``what`` and the fix."""
    try:
        v = np.asarray(vertices)
        f = np.asarray(faces)
    except (TypeError, ValueError) as exc:
        raise MeshError(f"{what}: vertices and faces must be arrays ({exc})") from None
    if v.ndim != 2 or v.shape[1] != 3 or v.dtype.kind not in "fiu":
        raise MeshError(f"{what}: vertices must be a number array [V, 3], got {v.dtype} {v.shape}")
    if f.ndim != 2 or f.shape[1] != 3 or f.dtype.kind not in "iu":
        kind = f"{f.shape[1]}-corner faces" if f.ndim == 2 else f"shape {f.shape}"
        raise MeshError(f"{what}: faces must be an integer array [F, 3] of triangles, got {f.dtype} {f.shape} "
                        f"({kind}); triangulate the mesh first (trimesh does it when it loads)")
    if len(v) == 0 or len(f) == 0:
        raise MeshError(f"{what}: the mesh is empty ({len(v)} vertices, {len(f)} faces)")
    v = np.ascontiguousarray(v, np.float32)
    bad = ~np.isfinite(v).all(axis=1)
    if bad.any():
        raise MeshError(f"{what}: {int(bad.sum())} vertices are NaN or infinite (first: vertex {int(np.argmax(bad))}); "
                        "fix or remove them")
    p = v.astype(np.float64)
    far = float(np.sqrt((p ** 2).sum(axis=1).max()))
    span = float(np.linalg.norm(p.max(axis=0) - p.min(axis=0)))
    if max(far, span) > SQUARE_LIMIT:   # meshoptimizer's meshlets come out empty, its spheres infinite
        raise MeshError(f"{what}: vertices reach {far:.3g} from the origin and span {span:.3g}; both must stay below "
                        f"{SQUARE_LIMIT:.3g} (the LOD build squares them in float32); scale the mesh down")
    if f.min() < 0 or f.max() >= len(v):
        raise MeshError(f"{what}: face indices must be in 0..{len(v) - 1}, found {int(f.min())}..{int(f.max())}")
    f = np.ascontiguousarray(f, np.uint32)
    degen = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])
    if degen.any():
        i = int(np.argmax(degen))
        raise MeshError(f"{what}: {int(degen.sum())} faces repeat a vertex (first: face {i} = {f[i].tolist()}); "
                        "remove degenerate faces (trimesh: mesh.update_faces(mesh.nondegenerate_faces()))")
    n = None
    if normals is not None:
        n = np.ascontiguousarray(normals, np.float32)
        if n.shape != v.shape:
            raise MeshError(f"{what}: normals must be [V, 3] like the vertices {v.shape}, got {n.shape}")
        if not np.isfinite(n).all():
            raise MeshError(f"{what}: normals contain NaN or infinite values")
    return v, f, n


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals (+z where no face gives one)."""
    p = vertices.astype(np.float64)
    fn = np.cross(p[faces[:, 1]] - p[faces[:, 0]], p[faces[:, 2]] - p[faces[:, 0]])
    n = np.zeros_like(p)
    for k in range(3):
        np.add.at(n, faces[:, k], fn)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    out = np.where(length > 0, n / np.where(length > 0, length, 1), np.array([0.0, 0.0, 1.0]))
    return out.astype(np.float32)


def weld_ids(vertices: np.ndarray) -> tuple[np.ndarray, int]:
    """An id per vertex shared by vertices at the same position (as meshoptimizer sees them: equal
    float bits, -0 counted as 0), and how many ids there are."""
    bits = (vertices + np.float32(0.0)).view(np.uint32).reshape(-1, 3)
    order = np.lexsort((bits[:, 2], bits[:, 1], bits[:, 0]))
    s = bits[order]
    new = np.ones(len(s), bool)
    new[1:] = np.any(s[1:] != s[:-1], axis=1)
    ids = np.empty(len(s), np.int64)
    ids[order] = np.cumsum(new) - 1
    return ids, int(new.sum())


# --- spheres ----------------------------------------------------------------------------------------
def round_up32(x: float) -> np.float32:
    y = np.float32(x)
    return y if float(y) >= x else np.nextafter(y, np.float32(np.inf))


def enclosing_sphere(spheres: np.ndarray) -> np.ndarray:
    """float32 [4] sphere that contains every sphere of ``spheres`` (float32 [N, 4]) when checked in
    float64 on the stored values, with a relative slack of 1e-6."""
    s = np.asarray(spheres, np.float64).reshape(-1, 4)
    lo = (s[:, :3] - s[:, 3:]).min(axis=0)
    hi = (s[:, :3] + s[:, 3:]).max(axis=0)
    c = np.float32((lo + hi) / 2).astype(np.float64)
    big = int(np.argmax(s[:, 3]))
    # the box centre, or the largest sphere's centre when that is tighter (one dominant child)
    best = None
    for centre in (c, s[big, :3]):
        r = float(np.max(np.linalg.norm(s[:, :3] - centre, axis=1) + s[:, 3]))
        if best is None or r < best[1]:
            best = (centre, r)
    centre, r = best
    return np.array([*np.float32(centre), round_up32(r * (1 + _INFLATE) + 1e-30)], np.float32)


def cluster_bounds(tris: np.ndarray, positions: np.ndarray):
    """(sphere [4], apex [3], cone [4]) of one cluster, its sphere made to contain its vertices."""
    b = meshopt.cluster_bounds(tris, positions)
    pts = positions[tris.reshape(-1)].astype(np.float64)
    c = np.array(b.center, np.float64)
    cutoff = float(b.cone_cutoff)
    axis = np.array(b.cone_axis, np.float32)
    if b.radius == 0.0 and cutoff == 0.0:   # every triangle has zero area: meshopt returns zeros
        c = np.float32((pts.min(axis=0) + pts.max(axis=0)) / 2).astype(np.float64)
        cutoff = NEVER_CULL
    r = max(float(b.radius), float(np.max(np.linalg.norm(pts - c, axis=1))))
    sphere = np.array([*np.float32(c), round_up32(r * (1 + _INFLATE) + 1e-30)], np.float32)
    if cutoff >= 1.0 or not np.any(axis):
        cutoff, apex = NEVER_CULL, sphere[:3].copy()
        axis = np.zeros(3, np.float32)
    else:
        apex = np.array(b.cone_apex, np.float32)
    return sphere, apex, np.array([*axis, cutoff], np.float32)


# --- grouping ---------------------------------------------------------------------------------------
def _kd_groups(units: list, centres: np.ndarray, weights: np.ndarray, max_size: int) -> list:
    """Join units (lists of cluster ids) into groups of at most ``max_size`` clusters by splitting
    their centres at the weighted median of the longest axis, recursively."""
    out = []
    stack = [np.arange(len(units))]
    while stack:
        sel = stack.pop()
        if weights[sel].sum() <= max_size or len(sel) == 1:
            out.append(np.concatenate([units[i] for i in sel]))
            continue
        pts = centres[sel]
        axis = int(np.argmax(pts.max(axis=0) - pts.min(axis=0)))
        order = sel[np.argsort(pts[:, axis], kind="stable")]
        cum = np.cumsum(weights[order])
        cut = int(np.searchsorted(cum, cum[-1] / 2))
        cut = min(max(cut, 1), len(order) - 1)
        stack.extend([order[cut:], order[:cut]])
    return out


# --- the build --------------------------------------------------------------------------------------
class _Clusters:
    """Cluster records as the build appends them (struct-of-lists, turned into CLUSTER at the end)."""

    def __init__(self):
        self.tris, self.sphere, self.apex, self.cone = [], [], [], []
        self.lod_sphere, self.error, self.level, self.group = [], [], [], []
        self.parent_error, self.parent_sphere = [], []

    def add(self, tris, bounds, lod_sphere, error, level, group) -> int:
        sphere, apex, cone = bounds
        self.tris.append(tris)
        self.sphere.append(sphere)
        self.apex.append(apex)
        self.cone.append(cone)
        self.lod_sphere.append(np.asarray(lod_sphere, np.float32))
        self.error.append(np.float32(error))
        self.level.append(int(level))
        self.group.append(int(group))
        self.parent_error.append(np.float32(np.inf))
        self.parent_sphere.append(None)
        return len(self.tris) - 1

    def __len__(self):
        return len(self.tris)

    def records(self) -> tuple[np.ndarray, np.ndarray]:
        """(CLUSTER [C] sorted by level, stable; triangles [T, 3] in that cluster order)."""
        order = np.argsort(np.asarray(self.level), kind="stable")
        c = np.zeros(len(order), CLUSTER.dtype)
        counts = np.array([len(self.tris[i]) for i in order], np.uint32)
        c["first"] = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.uint32)
        c["count"] = counts
        c["sphere"] = np.stack([self.sphere[i] for i in order])
        c["cone_apex"][:, :3] = np.stack([self.apex[i] for i in order])
        c["cone"] = np.stack([self.cone[i] for i in order])
        c["lod_sphere"] = np.stack([self.lod_sphere[i] for i in order])
        c["parent_sphere"] = np.stack([self.lod_sphere[i] if self.parent_sphere[i] is None else self.parent_sphere[i]
                                       for i in order])
        c["error"] = [self.error[i] for i in order]
        c["parent_error"] = [self.parent_error[i] for i in order]
        c["level"] = [self.level[i] for i in order]
        c["group"] = [self.group[i] for i in order]
        tris = np.concatenate([self.tris[i] for i in order]).astype(np.uint32)
        return c, tris


class Progress:
    def __init__(self, progress, total: int, triangles: int):
        self.done, self.total, self.call, self.bar = 0, max(total, 1), None, None
        if callable(progress):
            self.call = progress
        elif progress is True or (progress is None and triangles >= _QUIET_BELOW):
            # disable=None: tqdm shows nothing when stderr is not a terminal
            self.bar = tqdm(total=self.total, unit="tri", unit_scale=True, desc="mesh LOD",
                            disable=None if progress is None else False, leave=False)

    def step(self, n: int, level: int):
        self.done = min(self.total, self.done + int(n))
        if self.call is not None:
            self.call(self.done, self.total)
        elif self.bar is not None:
            self.bar.set_postfix_str(f"level {level}", refresh=False)
            self.bar.update(int(n))

    def close(self):
        if self.bar is not None:
            self.bar.close()


def build_dag(vertices, faces, normals=None, *, settings: BuildSettings = BuildSettings(), lod: str = "dag",
              progress=None, name: str = "array") -> MeshLod:
    """The cluster DAG of a triangle mesh (``lod="dag"``), or only its level-0 clusters, every one a
    root (``lod="full"``).

    ``normals`` float32 [V, 3] or None (area-weighted vertex normals are computed). ``progress``:
    None shows a tqdm bar for builds of 200k triangles or more (on a terminal), True always, False
    never, or a callable ``progress(done, total)`` (in triangles simplified). MeshError for bad input.
    """
    t0 = time.perf_counter()
    if lod not in ("dag", "full"):
        raise MeshError(f"{name}: lod must be 'dag' or 'full', got {lod!r}")
    settings = settings.validate()
    v, f, n = check_mesh(vertices, faces, normals, what=name)
    if n is None:
        n = vertex_normals(v, f)
    centre = (v.min(axis=0).astype(np.float64) + v.max(axis=0)) / 2
    radius = float(np.sqrt(((v - centre) ** 2).sum(axis=1).max()))
    err_floor = max(radius, 1e-30) * _ERROR_FLOOR
    weld, n_weld = weld_ids(v)
    s = settings

    out = _Clusters()
    tris0, counts0 = meshopt.build_meshlets(f, v, s.max_vertices, s.max_triangles, s.cone_weight)
    starts = np.concatenate([[0], np.cumsum(counts0)]).astype(np.int64)
    for i in range(len(counts0)):
        t = tris0[starts[i]:starts[i + 1]]
        b = cluster_bounds(t, v)
        out.add(t, b, b[0], 0.0, 0, i)   # a level-0 cluster: its own group, its own sphere
    next_group = len(out)
    stats = {"stalled_groups": 0, "rounds": 0}

    if lod == "dag":
        bar = Progress(progress, 2 * len(f), len(f))
        try:
            next_group = _simplify_rounds(out, v, weld, n_weld, s, err_floor, radius, next_group, bar, stats)
        finally:
            bar.close()

    clusters, tris = out.records()
    lod_out = MeshLod(vertices=v, normals=n, triangles=tris, clusters=clusters, name=name, lod=lod)
    lod_out.info.update({
        "settings": s.as_dict(), "build_seconds": round(time.perf_counter() - t0, 4),
        "stalled_groups": stats["stalled_groups"], "rounds": stats["rounds"],
    })
    return lod_out


def _simplify_rounds(out: _Clusters, v, weld, n_weld, s: BuildSettings, err_floor, radius, next_group,
                     bar: Progress, stats) -> int:
    first = np.full(n_weld, len(v), np.int64)
    np.minimum.at(first, weld, np.arange(len(v)))
    rep = first[weld]   # each vertex's representative: the first vertex at its position
    live = np.arange(len(out))
    group_size = s.group_size
    target_error = max(4.0 * radius, 1e-30)   # absolute: never move a vertex farther than the mesh is big
    for level in range(1, s.max_levels + 1):
        if len(live) <= 1:
            break
        stats["rounds"] = level
        groups = _groups(out, live, weld, n_weld, group_size)
        # welded vertices referenced by more than one group: they stay where they are
        gid = np.concatenate([np.full(3 * len(out.tris[c]), g, np.int64) for g, grp in enumerate(groups) for c in grp])
        wid = weld[np.concatenate([out.tris[c].reshape(-1) for grp in groups for c in grp])]
        lo = np.full(n_weld, np.iinfo(np.int64).max)
        hi = np.full(n_weld, -1, np.int64)
        np.minimum.at(lo, wid, gid)
        np.maximum.at(hi, wid, gid)
        locked_weld = (hi >= 0) & (lo != hi)

        next_live, progressed = [], False
        for grp in groups:
            made = _simplify_group(out, grp, v, weld, rep, locked_weld, s, err_floor, target_error, next_group)
            bar.step(sum(len(out.tris[c]) for c in grp), level)
            if made is None:
                stats["stalled_groups"] += 1
                next_live.extend(int(c) for c in grp)
            else:
                next_group += 1
                progressed = True
                next_live.extend(made)
        live = np.asarray(next_live, np.int64)
        if progressed:
            group_size = s.group_size
        elif group_size < 4 * s.group_size:
            group_size *= 2   # nothing shrank: try larger groups before giving up
        else:
            break
    return next_group


def _groups(out: _Clusters, live: np.ndarray, weld, n_weld, group_size: int) -> list:
    """Groups (arrays of cluster ids) of the live clusters: by shared vertices, then the small ones
    by proximity."""
    max_size = group_size + group_size * 3 // 8   # partitionClusters' own upper bound
    if len(live) <= max_size:
        return [live]
    idx = np.concatenate([weld[out.tris[c].reshape(-1)] for c in live]).astype(np.uint32)
    counts = np.array([3 * len(out.tris[c]) for c in live], np.uint32)
    part, count = meshopt.partition_clusters(idx, counts, n_weld, group_size)
    order = np.argsort(part, kind="stable")
    bounds = np.searchsorted(part[order], np.arange(count + 1))
    groups = [live[order[bounds[i]:bounds[i + 1]]] for i in range(count) if bounds[i + 1] > bounds[i]]
    small = [g for g in groups if len(g) <= group_size // 2]
    if len(small) < 2:
        return groups
    big = [g for g in groups if len(g) > group_size // 2]
    centres = np.array([np.mean([out.lod_sphere[c][:3] for c in g], axis=0) for g in small], np.float64)
    weights = np.array([len(g) for g in small], np.int64)
    return big + _kd_groups(small, centres, weights, max_size)


def _simplify_group(out: _Clusters, grp, v, weld, rep, locked_weld, s: BuildSettings, err_floor, target_error,
                    group_id: int) -> list | None:
    """Simplify one group into new clusters (their ids), or None when it did not shrink."""
    # one vertex per position: meshoptimizer locks a position that more than two vertices share
    # (a triangle soup, flat-shaded normals), so it simplifies the welded triangles
    tris = rep[np.concatenate([out.tris[c] for c in grp])]
    uniq, inv = np.unique(tris.reshape(-1), return_inverse=True)
    local = inv.astype(np.uint32)
    pos = np.ascontiguousarray(v[uniq])
    lock = locked_weld[weld[uniq]].astype(np.uint8)
    target = int(len(tris) * s.ratio) * 3
    options = meshopt.SIMPLIFY_ERROR_ABSOLUTE
    res, err = None, 0.0
    if s.prune:
        res, err = meshopt.simplify(local, pos, lock, target, target_error, options | meshopt.SIMPLIFY_PRUNE)
        # pruning removes whole parts; a part that touches a locked vertex must stay (a hole at the
        # group's border otherwise), which is exactly: every locked vertex is still used
        kept = np.zeros(len(pos), bool)
        kept[res] = True
        if len(res) == 0 or not np.all(kept[lock.astype(bool)]):
            res = None
    if res is None:
        res, err = meshopt.simplify(local, pos, lock, target, target_error, options)
    if len(res) == 0 or len(res) > s.stall * len(tris) * 3:
        return None
    new_tris, counts = meshopt.build_meshlets(res, pos, s.max_vertices, s.max_triangles, s.cone_weight)
    child_err = max(float(out.error[c]) for c in grp)
    e = np.float32(child_err + max(float(err), err_floor))
    if not e > np.float32(child_err):
        e = np.nextafter(np.float32(child_err), np.float32(np.inf))
    sphere = enclosing_sphere(np.stack([out.lod_sphere[c] for c in grp]))
    level = max(out.level[c] for c in grp) + 1
    for c in grp:
        out.parent_error[c] = e
        out.parent_sphere[c] = sphere
    made = []
    start = 0
    for k in counts:
        t_local = new_tris[start:start + int(k)]
        start += int(k)
        made.append(out.add(uniq[t_local].astype(np.uint32), cluster_bounds(t_local, pos), sphere, e, level, group_id))
    return made


# --- reading the DAG back ---------------------------------------------------------------------------
def dag_parents(clusters: np.ndarray) -> np.ndarray:
    """For each cluster, the group its triangles were simplified into (-1 for a root), found by
    matching its (parent_error, parent_sphere) to the (error, lod_sphere) every cluster of that group
    carries. MeshError when two groups carry the same pair (the match would be ambiguous)."""
    key_of = {}
    for g, e, s in zip(clusters["group"].tolist(), clusters["error"], clusters["lod_sphere"]):
        k = (np.float32(e).tobytes(), np.asarray(s, np.float32).tobytes())
        if key_of.setdefault(k, g) != g:
            raise MeshError(f"groups {key_of[k]} and {g} carry the same error and lod sphere")
    out = np.full(len(clusters), -1, np.int64)
    for i, (pe, ps) in enumerate(zip(clusters["parent_error"], clusters["parent_sphere"])):
        if np.isinf(pe):
            continue
        k = (np.float32(pe).tobytes(), np.asarray(ps, np.float32).tobytes())
        if k not in key_of:
            raise MeshError(f"cluster {i}: no group carries its parent error {float(pe)} and parent sphere")
        out[i] = key_of[k]
    return out
