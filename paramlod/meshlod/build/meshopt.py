"""A small ctypes layer over the compiled meshoptimizer library that the PyPI package
``meshoptimizer==0.2.30a0`` ships (its C sources are meshoptimizer 0.22, header version 220).

Driven by paramlod.meshlod.build.dag (the offline cluster-DAG build); it has no twin (it is the
reference the DAG's tests check against: invariants, not bytes).

The package wraps simplify but not the cluster functions, and its simplify_with_attributes has no
argument types; so the functions the build needs are declared here against the 0.22 header
(src/meshoptimizer.h of the sdist), on a CDLL handle of our own (argtypes set on the package's handle
would change the package's functions). The library is built with assertions on: a bad argument
aborts the process, so every wrapper checks its inputs first and raises MeshError instead.

ABI trap: meshoptimizer 0.24 inserted vertex positions and a stride into meshopt_partitionClusters;
calling the 0.22 signature on a newer library corrupts memory. Newer libraries also export
meshopt_computeSphereBounds (0.24+), so its presence refuses the library.
"""
from __future__ import annotations

import ctypes
import glob
import importlib.util
import os

import numpy as np

from paramlod.errors import MeshError

# meshopt_Simplify* options (meshoptimizer.h, enum after meshopt_encodeFilterExp)
SIMPLIFY_LOCK_BORDER = 1 << 0
SIMPLIFY_SPARSE = 1 << 1
SIMPLIFY_ERROR_ABSOLUTE = 1 << 2
SIMPLIFY_PRUNE = 1 << 3

MAX_MESHLET_VERTICES = 255    # kMeshletMaxVertices ("255 - not 256!")
MAX_MESHLET_TRIANGLES = 512   # kMeshletMaxTriangles; computeClusterBounds takes at most this many

_REQUIRED = ("meshopt_buildMeshlets", "meshopt_buildMeshletsBound", "meshopt_computeClusterBounds",
             "meshopt_partitionClusters", "meshopt_simplifyWithAttributes")
_NEWER_ABI = ("meshopt_computeSphereBounds",)   # 0.24+: partitionClusters has another signature

_P = ctypes.c_void_p
_S = ctypes.c_size_t


class Bounds(ctypes.Structure):
    """struct meshopt_Bounds (48 bytes)."""
    _fields_ = [("center", ctypes.c_float * 3), ("radius", ctypes.c_float),
                ("cone_apex", ctypes.c_float * 3), ("cone_axis", ctypes.c_float * 3),
                ("cone_cutoff", ctypes.c_float),
                ("cone_axis_s8", ctypes.c_byte * 3), ("cone_cutoff_s8", ctypes.c_byte)]


_LIB = None


def library_path() -> str:
    """The package's compiled library (``meshoptimizer/_meshoptimizer*.so``)."""
    spec = importlib.util.find_spec("meshoptimizer")
    if spec is None or not spec.submodule_search_locations:
        raise MeshError("the mesh LOD build needs meshoptimizer: pip install meshoptimizer==0.2.30a0")
    for folder in spec.submodule_search_locations:
        found = sorted(glob.glob(os.path.join(folder, "_meshoptimizer*.so")) +
                       glob.glob(os.path.join(folder, "_meshoptimizer*.pyd")))
        if found:
            return found[0]
    raise MeshError(f"meshoptimizer is installed in {list(spec.submodule_search_locations)} without its compiled "
                    "library (_meshoptimizer*.so); reinstall it: pip install --force-reinstall meshoptimizer==0.2.30a0")


def library() -> ctypes.CDLL:
    """The library with this module's signatures, checked once per process."""
    global _LIB
    if _LIB is not None:
        return _LIB
    path = library_path()
    try:
        lib = ctypes.CDLL(path)
    except OSError as exc:
        raise MeshError(f"cannot load meshoptimizer's library {path}: {exc}") from None
    missing = [s for s in _REQUIRED if not hasattr(lib, s)]
    if missing:
        raise MeshError(f"meshoptimizer's library {path} lacks {', '.join(missing)} (older than 0.22); "
                        "install the version paramlod is written for: pip install meshoptimizer==0.2.30a0")
    newer = [s for s in _NEWER_ABI if hasattr(lib, s)]
    if newer:
        raise MeshError(f"meshoptimizer's library {path} exports {', '.join(newer)}: it is meshoptimizer 0.24 or "
                        "newer, whose meshopt_partitionClusters takes other arguments than the 0.22 one paramlod "
                        "calls; install the version paramlod is written for: pip install meshoptimizer==0.2.30a0")
    # signatures of src/meshoptimizer.h (0.22); pointers as c_void_p so numpy addresses pass as ints
    lib.meshopt_buildMeshletsBound.argtypes = [_S, _S, _S]
    lib.meshopt_buildMeshletsBound.restype = _S
    lib.meshopt_buildMeshlets.argtypes = [_P, _P, _P, _P, _S, _P, _S, _S, _S, _S, ctypes.c_float]
    lib.meshopt_buildMeshlets.restype = _S
    lib.meshopt_computeClusterBounds.argtypes = [_P, _S, _P, _S, _S]
    lib.meshopt_computeClusterBounds.restype = Bounds
    lib.meshopt_partitionClusters.argtypes = [_P, _P, _S, _P, _S, _S, _S]
    lib.meshopt_partitionClusters.restype = _S
    lib.meshopt_simplifyWithAttributes.argtypes = [_P, _P, _S, _P, _S, _S, _P, _S, _P, _S, _P, _S,
                                                   ctypes.c_float, ctypes.c_uint, ctypes.POINTER(ctypes.c_float)]
    lib.meshopt_simplifyWithAttributes.restype = _S
    _LIB = lib
    return lib


def _positions(positions) -> np.ndarray:
    p = np.ascontiguousarray(positions, np.float32)
    if p.ndim != 2 or p.shape[1] != 3:
        raise MeshError(f"meshopt: vertex positions must be float32 [V, 3], got shape {p.shape}")
    return p


def _indices(indices, vertex_count: int, what: str) -> np.ndarray:
    i = np.ascontiguousarray(indices, np.uint32).reshape(-1)
    if len(i) % 3:
        raise MeshError(f"meshopt.{what}: {len(i)} indices is not a whole number of triangles")
    if len(i) and int(i.max()) >= vertex_count:
        raise MeshError(f"meshopt.{what}: index {int(i.max())} is out of range for {vertex_count} vertices")
    return i


def build_meshlets(indices, positions, max_vertices: int = 255, max_triangles: int = 128,
                   cone_weight: float = 0.25) -> tuple[np.ndarray, np.ndarray]:
    """meshopt_buildMeshlets over a triangle list. Returns (triangles uint32 [T, 3] in meshlet order,
    indices into ``positions``; counts uint32 [M]: triangles per meshlet). Every input triangle comes
    out once, its corners in their cyclic order (winding kept)."""
    lib = library()
    p = _positions(positions)
    idx = _indices(indices, len(p), "build_meshlets")
    if not 3 <= max_vertices <= MAX_MESHLET_VERTICES:
        raise MeshError(f"meshopt.build_meshlets: max_vertices must be 3..{MAX_MESHLET_VERTICES}, got {max_vertices}")
    if not (4 <= max_triangles <= MAX_MESHLET_TRIANGLES and max_triangles % 4 == 0):
        raise MeshError(f"meshopt.build_meshlets: max_triangles must be a multiple of 4 in 4..{MAX_MESHLET_TRIANGLES}, "
                        f"got {max_triangles}")
    if not 0.0 <= cone_weight <= 1.0:
        raise MeshError(f"meshopt.build_meshlets: cone_weight must be in [0, 1], got {cone_weight}")
    if len(idx) == 0:
        return np.zeros((0, 3), np.uint32), np.zeros(0, np.uint32)
    bound = lib.meshopt_buildMeshletsBound(len(idx), max_vertices, max_triangles)
    meshlets = np.empty((bound, 4), np.uint32)   # vertex_offset, triangle_offset, vertex_count, triangle_count
    mverts = np.empty(bound * max_vertices, np.uint32)
    mtris = np.empty(bound * max_triangles * 3, np.uint8)
    n = lib.meshopt_buildMeshlets(meshlets.ctypes.data, mverts.ctypes.data, mtris.ctypes.data, idx.ctypes.data,
                                  len(idx), p.ctypes.data, len(p), 12, max_vertices, max_triangles,
                                  float(cone_weight))
    m = meshlets[:n].astype(np.int64)
    counts = m[:, 3]
    total = int(counts.sum())
    # corner k of the meshlet's triangle list, gathered through its local vertex table
    corner_meshlet = np.repeat(np.arange(n), counts * 3)
    starts = np.cumsum(counts * 3) - counts * 3
    within = np.arange(total * 3) - np.repeat(starts, counts * 3)
    local = mtris[m[corner_meshlet, 1] + within].astype(np.int64)
    tris = mverts[m[corner_meshlet, 0] + local].reshape(-1, 3)
    return np.ascontiguousarray(tris, np.uint32), counts.astype(np.uint32)


def cluster_bounds(indices, positions) -> Bounds:
    """meshopt_computeClusterBounds of at most 512 triangles: bounding sphere and normal cone
    (cone_cutoff = 1 means "do not cull"; all zeros when every triangle has zero area)."""
    lib = library()
    p = _positions(positions)
    idx = _indices(indices, len(p), "cluster_bounds")
    if len(idx) // 3 > MAX_MESHLET_TRIANGLES:
        raise MeshError(f"meshopt.cluster_bounds: {len(idx) // 3} triangles, at most {MAX_MESHLET_TRIANGLES}")
    return lib.meshopt_computeClusterBounds(idx.ctypes.data, len(idx), p.ctypes.data, len(p), 12)


def partition_clusters(cluster_indices, index_counts, vertex_count: int, target_size: int) -> tuple[np.ndarray, int]:
    """meshopt_partitionClusters (0.22 signature: no positions): groups of about ``target_size``
    clusters that share vertices. ``cluster_indices`` is every cluster's vertex indices one after the
    other, ``index_counts`` how many belong to each. Returns (partition id per cluster, partitions)."""
    lib = library()
    idx = np.ascontiguousarray(cluster_indices, np.uint32).reshape(-1)
    counts = np.ascontiguousarray(index_counts, np.uint32).reshape(-1)
    if len(counts) == 0:
        return np.zeros(0, np.uint32), 0
    if np.any(counts == 0):
        raise MeshError("meshopt.partition_clusters: every cluster needs at least one index")
    if int(counts.sum(dtype=np.int64)) != len(idx):
        raise MeshError(f"meshopt.partition_clusters: index counts add up to {int(counts.sum())}, "
                        f"but {len(idx)} indices were given")
    if int(idx.max()) >= vertex_count:
        raise MeshError(f"meshopt.partition_clusters: index {int(idx.max())} is out of range for {vertex_count} vertices")
    if target_size < 1:
        raise MeshError(f"meshopt.partition_clusters: target size must be >= 1, got {target_size}")
    dest = np.empty(len(counts), np.uint32)
    n = lib.meshopt_partitionClusters(dest.ctypes.data, idx.ctypes.data, len(idx), counts.ctypes.data, len(counts),
                                      int(vertex_count), int(target_size))
    return dest, int(n)


def simplify(indices, positions, lock=None, target_index_count: int = 0, target_error: float = 1e30,
             options: int = SIMPLIFY_ERROR_ABSOLUTE) -> tuple[np.ndarray, float]:
    """meshopt_simplifyWithAttributes without attributes, with a per-vertex lock array (uint8 [V],
    1 = the vertex must stay). Returns (indices uint32 [K], the error it reached: absolute in object
    units with SIMPLIFY_ERROR_ABSOLUTE, else relative to the extent). Vertices are never moved: the
    result indexes ``positions``."""
    lib = library()
    p = _positions(positions)
    idx = _indices(indices, len(p), "simplify")
    target = int(target_index_count)
    if not 0 <= target <= len(idx):
        raise MeshError(f"meshopt.simplify: target index count {target} is outside 0..{len(idx)}")
    if not (np.isfinite(target_error) and target_error >= 0):
        raise MeshError(f"meshopt.simplify: target error must be finite and >= 0, got {target_error}")
    if options & ~(SIMPLIFY_LOCK_BORDER | SIMPLIFY_SPARSE | SIMPLIFY_ERROR_ABSOLUTE | SIMPLIFY_PRUNE):
        raise MeshError(f"meshopt.simplify: unknown option bits in {options:#x}")
    lock_ptr = None
    if lock is not None:
        lk = np.ascontiguousarray(lock, np.uint8).reshape(-1)
        if len(lk) != len(p):
            raise MeshError(f"meshopt.simplify: the lock array has {len(lk)} entries for {len(p)} vertices")
        lock_ptr = lk.ctypes.data   # a bare address: lk stays referenced until the function returns
    dest = np.empty(max(len(idx), 3), np.uint32)
    err = ctypes.c_float(0.0)
    n = lib.meshopt_simplifyWithAttributes(dest.ctypes.data, idx.ctypes.data, len(idx), p.ctypes.data, len(p), 12,
                                           None, 0, None, 0, lock_ptr, target, float(target_error), int(options),
                                           ctypes.byref(err))
    return dest[:n].copy(), float(err.value)
