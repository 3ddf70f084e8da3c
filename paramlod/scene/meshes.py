"""Triangle meshes from files and arrays: ``read_mesh(source) -> TriangleMesh``, validated.

Driven by ``paramlod.meshlod`` (its "mesh" loader builds a MeshLod from a TriangleMesh; the
scene room only asks the loader registry for one) and usable on its own. No twin: this is
host-only numpy.

Sources: a path that trimesh reads (OBJ, PLY, STL, OFF, GLB/glTF; a file holding a scene of
several meshes gives their concatenation with the node transforms applied), a GIfTI surface
(``.gii``, ``.surf.gii``: its POINTSET and TRIANGLE arrays, read with nibabel), a
``trimesh.Trimesh`` or ``trimesh.Scene``, or a ``(vertices, faces)`` pair (``(vertices, faces,
normals)`` also works).

What is done to the data, and why:
- trimesh loads with ``process=False``: its own processing merges vertices by rounded position
  and drops the normals a file stores. Instead, vertices that are bitwise equal in position (and
  in the normal, when the file gives one) are welded here, keeping first-occurrence order. That
  loses nothing the file says, and it turns the triangle soups of STL (and of files split by
  material) into connected meshes, which the LOD build needs to simplify across triangles.
- Degenerate faces (a repeated vertex, or an area below what float32 positions resolve) are
  dropped with a warning; vertices no face uses are dropped too (order kept), so the mesh's
  bounds are those of what is drawn.
- Normals: the file's (renormalised) where it has them, else area-weighted face normals.
"""
from __future__ import annotations

import hashlib
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from paramlod.errors import MeshError

# Extensions read through trimesh and tested here; trimesh may read more (listed in messages).
TRIMESH_TYPES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")
GIFTI_TYPES = (".gii",)          # also .surf.gii
MESH_TYPES = TRIMESH_TYPES + GIFTI_TYPES
# Areas below this times the squared longest edge are below float32's resolution: "zero area".
ZERO_AREA = float(np.finfo(np.float32).eps) ** 2


@dataclass
class TriangleMesh:
    vertices: np.ndarray     # float32 [V, 3]
    faces: np.ndarray        # uint32 [F, 3]
    normals: np.ndarray      # float32 [V, 3], unit
    name: str = "mesh"       # the file's name, "array" or the trimesh object's name
    normals_from: str = "computed"   # "file", "computed", or "file+computed" (some missing in the file)

    @property
    def bounds(self) -> np.ndarray:
        """float64 [2, 3]: the lower and upper corner of the box around the vertices."""
        return np.stack([self.vertices.min(axis=0), self.vertices.max(axis=0)]).astype(np.float64)

    def content_hash(self) -> str:
        """SHA-256 of the vertices, normals and faces (for caches of builds made from them)."""
        h = hashlib.sha256()
        for a in (self.vertices, self.normals, self.faces):
            h.update(str(a.shape).encode())
            h.update(np.ascontiguousarray(a).tobytes())
        return h.hexdigest()


def source_label(source) -> str:
    """The name messages use for ``source``: the file's name, "array", or the object's type."""
    if isinstance(source, (str, os.PathLike)):
        return Path(source).name
    if isinstance(source, (tuple, list)):
        return "array"
    name = getattr(getattr(source, "metadata", None), "get", lambda k: None)("file_name")
    return str(name) if name else getattr(source, "name", None) or type(source).__name__


def source_key(source):
    """A key under which equal sources load to the same mesh: the resolved path with its size and
    modification time for a file, else the object's identity (callers keep the object alive)."""
    if isinstance(source, (str, os.PathLike)):
        p = Path(source).expanduser().resolve()
        try:
            st = p.stat()
            return ("file", str(p), st.st_size, st.st_mtime_ns)
        except OSError:
            return ("file", str(p), None, None)
    return ("object", id(source))


def read_mesh(source) -> TriangleMesh:
    """The validated triangle mesh of ``source`` (see the module docstring); a MeshError that names
    the file (or "array") and the fix when it cannot be used."""
    if isinstance(source, (str, os.PathLike)):
        path = Path(source)
        where = f"mesh file {path}"
        _check_file(path, where)
        parts = _read_gifti(path, where) if _is_gifti(path) else _read_trimesh_file(path, where)
        return _finish(parts, where, path.name)
    if isinstance(source, (tuple, list)):
        return _finish([_from_arrays(source)], "mesh array", "array")
    module = type(source).__module__ or ""
    if module.startswith("trimesh"):
        label = source_label(source)
        where = f"trimesh {type(source).__name__} '{label}'"
        return _finish(_trimesh_parts(source, where), where, label)
    raise MeshError(f"cannot read a mesh from a {type(source).__name__}: give a file path, a trimesh.Trimesh "
                    "or a (vertices [V, 3], faces [F, 3]) pair of arrays")


# --- readers: each returns parts (vertices float64 [V,3], faces int64 [F,3], normals [V,3] or None) ---
def _is_gifti(path: Path) -> bool:
    return path.name.lower().endswith(".gii")


def _known(path: Path) -> bool:
    name = path.name.lower()
    if name.endswith(MESH_TYPES):
        return True
    import trimesh

    return any(name.endswith("." + f) for f in trimesh.available_formats())


def _check_file(path: Path, where: str) -> None:
    if not path.exists():
        raise MeshError(f"{where} does not exist (paths in scene files are relative to the scene file)")
    if path.is_dir():
        raise MeshError(f"{where} is a folder, not a mesh file")
    if not _known(path):
        raise MeshError(f"{where}: unknown type '{path.suffix}' (known: {', '.join(MESH_TYPES)}, .surf.gii; "
                        "convert it to PLY or OBJ)")
    try:
        size = os.path.getsize(path)
        with open(path, "rb"):
            pass
    except OSError as exc:
        raise MeshError(f"cannot read {where}: {exc.strerror or exc}") from None
    if size == 0:
        raise MeshError(f"{where} is empty (0 bytes)")


def _read_trimesh_file(path: Path, where: str):
    import trimesh

    try:
        loaded = trimesh.load(str(path), process=False)
    except Exception as exc:   # trimesh's loaders raise anything from ValueError to struct.error
        raise MeshError(f"cannot read {where}: it is corrupt or not a {path.suffix[1:].upper()} file "
                        f"({type(exc).__name__}: {exc})") from None
    return _trimesh_parts(loaded, where)


def _trimesh_parts(obj, where: str):
    import trimesh

    if isinstance(obj, trimesh.Scene):
        parts = []
        for node in obj.graph.nodes_geometry:
            transform, geom_name = obj.graph[node]
            g = obj.geometry.get(geom_name)
            if isinstance(g, trimesh.Trimesh) and len(g.faces):
                parts.append(_transformed(*_trimesh_arrays(g), np.asarray(transform, np.float64)))
    elif isinstance(obj, trimesh.Trimesh) and len(obj.faces):
        parts = [_trimesh_arrays(obj)]
    else:
        parts = []
    if not parts:
        what = type(obj).__name__
        raise MeshError(f"{where} is not a triangle mesh (it holds a {what} without faces: a point cloud, "
                        "lines or nothing); give a file with faces")
    return parts


def _trimesh_arrays(g):
    v = np.asarray(g.vertices, np.float64)
    f = np.asarray(g.faces, np.int64)
    # Normals the file stored sit in trimesh's cache (asking for g.vertex_normals would compute
    # them when it has none); ``in`` drops stale entries first. If that private cache moves,
    # normals are computed here instead.
    n = None
    try:
        if "vertex_normals" in g._cache:
            n = np.asarray(g._cache.cache["vertex_normals"], np.float64)
    except (AttributeError, KeyError, TypeError):
        n = None
    return v, f, (n if n is not None and n.shape == v.shape else None)


def _transformed(v, f, n, m):
    if np.allclose(m, np.eye(4)):
        return v, f, n
    v = v @ m[:3, :3].T + m[:3, 3]
    if n is not None:
        n = n @ np.linalg.inv(m[:3, :3])   # rows times the inverse transpose
    if np.linalg.det(m[:3, :3]) < 0:
        f = f[:, ::-1]   # a mirroring node keeps the faces' outward winding
    return v, f, n


def _read_gifti(path: Path, where: str):
    try:
        import nibabel as nib
    except ImportError:
        raise MeshError(f"{where}: reading GIfTI surfaces needs nibabel (pip install nibabel)") from None
    try:
        img = nib.load(str(path))
    except Exception as exc:   # nibabel raises parser errors of several kinds
        raise MeshError(f"cannot read {where}: it is corrupt or not a GIfTI file ({type(exc).__name__}: {exc})") from None
    if not isinstance(img, nib.gifti.GiftiImage):
        raise MeshError(f"{where} is not a GIfTI file (nibabel read a {type(img).__name__})")
    points = img.get_arrays_from_intent("NIFTI_INTENT_POINTSET")
    tris = img.get_arrays_from_intent("NIFTI_INTENT_TRIANGLE")
    if not points or not tris:
        raise MeshError(f"{where} holds no surface (it needs a POINTSET and a TRIANGLE array; a .func.gii, "
                        ".shape.gii or .label.gii holds values on a surface: give its .surf.gii)")
    v, f = np.asarray(points[0].data, np.float64), np.asarray(tris[0].data)
    if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3:
        raise MeshError(f"{where}: its POINTSET must be [V, 3] and its TRIANGLE array [F, 3], "
                        f"got {v.shape} and {f.shape}")
    return [(v, f.astype(np.int64), None)]


def _from_arrays(source):
    where = "mesh array"
    if len(source) not in (2, 3):
        raise MeshError(f"{where}: give (vertices, faces) or (vertices, faces, normals), got {len(source)} items")
    try:
        v = np.asarray(source[0], np.float64)
    except (TypeError, ValueError):
        raise MeshError(f"{where}: vertices must be a [V, 3] array of numbers") from None
    if v.ndim != 2 or v.shape[1] != 3:
        raise MeshError(f"{where}: vertices must have shape (V, 3), got {v.shape}")
    f = np.asarray(source[1])
    if f.ndim == 2 and f.shape[1] == 4:
        raise MeshError(f"{where}: faces must be triangles, got shape {f.shape} (quads): split each into two, "
                        "e.g. np.concatenate([f[:, [0, 1, 2]], f[:, [0, 2, 3]]])")
    if f.ndim != 2 or (f.shape[1] != 3 and len(f)):
        raise MeshError(f"{where}: faces must have shape (F, 3) (triangles), got {f.shape}")
    if f.dtype == bool or not (np.issubdtype(f.dtype, np.integer) or np.issubdtype(f.dtype, np.floating)):
        raise MeshError(f"{where}: faces must be integer vertex indices, got dtype {f.dtype}")
    if np.issubdtype(f.dtype, np.floating):
        if not np.all(np.isfinite(f)) or np.any(f != np.round(f)):
            raise MeshError(f"{where}: faces must be integer vertex indices, got non-integer values")
    n = None
    if len(source) == 3 and source[2] is not None:
        n = np.asarray(source[2], np.float64)
        if n.shape != v.shape:
            raise MeshError(f"{where}: normals must have the vertices' shape {v.shape}, got {n.shape}")
    return v, f.reshape(-1, 3).astype(np.int64), n


# --- the checks and the clean-up every source goes through -------------------------------------
def _finish(parts, where: str, name: str) -> TriangleMesh:
    counts = np.cumsum([0] + [len(p[0]) for p in parts])
    v = np.concatenate([p[0] for p in parts])
    f = np.concatenate([p[1] + counts[k] for k, p in enumerate(parts)])
    has_n = any(p[2] is not None for p in parts)
    n = np.concatenate([p[2] if p[2] is not None else np.full((len(p[0]), 3), np.nan) for p in parts]) if has_n else None
    if len(v) == 0 or len(f) == 0:
        raise MeshError(f"{where} is empty ({len(v)} vertices, {len(f)} faces); give a mesh with triangles")
    bad = ~np.all(np.isfinite(v), axis=1)
    if bad.any():
        raise MeshError(f"{where} has {int(bad.sum())} vertices with NaN or infinite coordinates "
                        f"(first: vertex {int(np.argmax(bad))}); repair or remove them")
    if f.min() < 0 or f.max() >= len(v):
        k = int(np.argmax(np.any((f < 0) | (f >= len(v)), axis=1)))
        raise MeshError(f"{where}: face {k} {f[k].tolist()} refers to a vertex out of range 0..{len(v) - 1}; "
                        "faces index the vertex array from 0")
    if len(v) >= 2 ** 32:
        raise MeshError(f"{where} has {len(v)} vertices; at most 2^32 - 1 can be indexed")
    with np.errstate(over="ignore"):   # the overflow is reported below, by name
        v32 = v.astype(np.float32)
    if not np.all(np.isfinite(v32)):
        raise MeshError(f"{where}: vertex coordinates overflow float32 (|x| > 3.4e38); scale the mesh down")
    v32, f, n = _weld(v32, f, n)
    f, cross = _drop_degenerate(v32, f, where)
    v32, f, n = _compact(v32, f, n)
    normals, source = _normals(v32, f, cross, n)
    return TriangleMesh(np.ascontiguousarray(v32), np.ascontiguousarray(f.astype(np.uint32)),
                        normals, name, source)


def _weld(v, f, n):
    """Merge vertices with bitwise-equal positions (and equal file normals), first occurrence first."""
    key = v + np.float32(0.0)   # -0.0 and 0.0 are one position
    if n is not None:
        nn = np.where(np.isfinite(n), n, np.nan).astype(np.float32) + np.float32(0.0)
        key = np.concatenate([key, nn], axis=1)
    rows = np.ascontiguousarray(key).view(np.dtype((np.void, key.dtype.itemsize * key.shape[1]))).ravel()
    _, first, inverse = np.unique(rows, return_index=True, return_inverse=True)
    if len(first) == len(v):
        return v, f, n
    order = np.argsort(first)              # unique rows in first-occurrence order
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    keep = first[order]
    return v[keep], rank[inverse.reshape(-1)][f], (n[keep] if n is not None else None)


def _face_cross(v, f):
    """Per face, float64 [F, 3]: the cross product of two edges (2 * area * unit normal), and the
    squared length of the longest edge."""
    p0, p1, p2 = (v[f[:, k]].astype(np.float64) for k in range(3))
    a, b, c = p1 - p0, p2 - p0, p2 - p1
    longest2 = np.maximum(np.maximum(np.einsum("ij,ij->i", a, a), np.einsum("ij,ij->i", b, b)),
                          np.einsum("ij,ij->i", c, c))
    return np.cross(a, b), longest2


def _drop_degenerate(v, f, where):
    """The faces without a repeated vertex and with an area float32 resolves, and their cross products."""
    cross, longest2 = _face_cross(v, f)
    repeated = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])
    bad = repeated | (np.einsum("ij,ij->i", cross, cross) <= ZERO_AREA * longest2 ** 2)
    if bad.all():
        raise MeshError(f"{where}: all {len(f)} faces are degenerate (a repeated vertex or zero area); "
                        "nothing is left to draw")
    if bad.any():
        warnings.warn(f"{where}: dropped {int(bad.sum())} of {len(f)} faces that are degenerate "
                      "(a repeated vertex or zero area)", stacklevel=4)
        return f[~bad], cross[~bad]
    return f, cross


def _compact(v, f, n):
    used = np.zeros(len(v), bool)
    used[f.reshape(-1)] = True
    if used.all():
        return v, f, n
    new = np.cumsum(used) - 1
    return v[used], new[f], (n[used] if n is not None else None)


def _per_vertex(f, values, count):
    """Sum over each vertex's faces of ``values`` [F] or [F, 3] (bincount: much faster than add.at)."""
    idx = f.reshape(-1)
    if values.ndim == 1:
        return np.bincount(idx, np.repeat(values, 3), minlength=count)
    rep = np.repeat(values, 3, axis=0)
    return np.stack([np.bincount(idx, rep[:, k], minlength=count) for k in range(3)], axis=1)


def _normals(v, f, cross, n):
    """Unit normals: the file's where valid, else the area-weighted sum of the faces' normals
    (``cross``: 2 * area * unit normal per face)."""
    acc = _per_vertex(f, cross, len(v))
    length = np.linalg.norm(acc, axis=1)
    size = _per_vertex(f, np.linalg.norm(cross, axis=1), len(v))
    # Where the faces around a vertex cancel (a fin, a sheet folded back), its largest face decides.
    flat = ~(length > 1e-6 * size)
    if flat.any():
        area2 = np.einsum("ij,ij->i", cross, cross)
        best, winner = np.full(len(v), -1.0), np.full(len(v), len(f))
        for k in range(3):
            np.maximum.at(best, f[:, k], area2)
        for k in range(3):   # ties: the first such face
            m = area2 == best[f[:, k]]
            np.minimum.at(winner, f[m, k], np.flatnonzero(m))
        acc[flat] = cross[winner[flat]]
        length = np.linalg.norm(acc, axis=1)
    computed = acc / length[:, None]
    if n is None:
        return computed.astype(np.float32), "computed"
    nl = np.linalg.norm(n, axis=1)
    valid = np.isfinite(nl) & (nl > 1e-12)
    out = np.where(valid[:, None], n / np.where(valid, nl, 1.0)[:, None], computed)
    return out.astype(np.float32), ("file" if valid.all() else "file+computed")
