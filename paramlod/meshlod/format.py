"""A mesh's level of detail as the renderers read it (``MeshLod``), its ``.meshlod`` file and the
cache of builds.

CONTRACT (shared by build, cut, raster and draw; do not change field meanings):

- ``vertices`` float32 [V, 3] and ``normals`` float32 [V, 3] (unit): the original vertices; the
  simplifier only drops vertices, never moves them, so every level indexes this one array.
- ``triangles`` uint32 [T, 3]: the triangles of every cluster of every level, each cluster's
  triangles contiguous (``clusters["first"]``, ``clusters["count"]``), indices into ``vertices``.
- ``clusters``: numpy array of ``paramlod.core.layouts.CLUSTER.dtype`` [C], level 0 first. For
  ``lod="full"`` there is only level 0 and every cluster is a root (parent_error = +inf). For
  ``lod="chain"`` (paramlod.meshlod.build.chain) level k is the whole mesh simplified k times and
  every cluster carries the mesh's one bounding sphere, its level's error and the next level's as
  parent error, so one whole level is drawn per instance.
- A cluster is drawn iff project(error, lod_sphere) <= T < project(parent_error, parent_sphere).
  Invariants: parent_error >= error, parent_sphere contains lod_sphere (both per cluster),
  so on every root-to-leaf path exactly one cluster passes.

The ``.meshlod`` file (written by ``save_meshlod``, read by ``load_meshlod``; driven by
paramlod.meshlod.source and ``paramlod mesh``; no twin):
  magic ``PLMESHLD`` (8 bytes) | version uint32 LE | header length uint32 LE | header: JSON, UTF-8,
  sorted keys, padded with spaces to a multiple of 16 | the arrays (vertices, normals, triangles,
  clusters), little-endian, each at the offset the header gives (16-aligned, zero padding) |
  SHA-256 of every byte before it (32 bytes).
The header holds the counts, the name and lod, the Cluster layout it was written with, ``info``
(build settings, content hash, build seconds) and each array's dtype, shape, offset and size. The
same MeshLod always gives the same bytes; files are written atomically. Version 1. ``lod`` is
"dag", "full" or "chain": a chain is the same records in the same layout, so it is one more value
of the header's ``lod``, not a new version (a reader that does not know a value refuses the file
with a message naming it).

The cache: builds keyed by (content hash of vertices, normals and faces; lod; build settings; file
version) in ``$PARAMLOD_CACHE/meshlod/`` or ``~/.cache/paramlod/meshlod/``, one ``<key>.meshlod``
each. A cache file that cannot be read is rebuilt with a warning; one that cannot be written is
skipped with a warning.
"""
from __future__ import annotations

import hashlib
import json
import os
import struct
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from paramlod.core.files import write_atomically
from paramlod.core.layouts import CLUSTER
from paramlod.errors import MeshError, ParamlodError

FORMAT = "paramlod.meshlod"
MAGIC = b"PLMESHLD"
VERSION = 1
SUFFIX = ".meshlod"
_PREFIX = struct.Struct("<8sII")   # magic, version, header length
_ALIGN = 16
_DIGEST = 32
LODS = ("dag", "full", "chain")


@dataclass
class MeshLod:
    vertices: np.ndarray      # float32 [V, 3]
    normals: np.ndarray       # float32 [V, 3]
    triangles: np.ndarray     # uint32 [T, 3]
    clusters: np.ndarray      # CLUSTER.dtype [C]
    name: str = "mesh"        # the file's name or "array"
    lod: str = "dag"          # "dag", "full" or "chain"
    info: dict = field(default_factory=dict)   # build settings, content hash, build seconds

    @property
    def levels(self) -> int:
        return int(self.clusters["level"].max()) + 1 if len(self.clusters) else 0

    @property
    def roots(self) -> np.ndarray:
        """Indices of the clusters without parents."""
        return np.flatnonzero(np.isinf(self.clusters["parent_error"]))

    @property
    def original_triangles(self) -> int:
        return int(self.clusters["count"][self.clusters["level"] == 0].sum())

    def bounding_sphere(self) -> tuple[np.ndarray, float]:
        """Centre (float64 [3]) and radius of a sphere around every vertex."""
        lo, hi = self.vertices.min(axis=0).astype(np.float64), self.vertices.max(axis=0).astype(np.float64)
        c = (lo + hi) / 2
        return c, float(np.sqrt(((self.vertices - c) ** 2).sum(axis=1).max()))

    @property
    def nbytes(self) -> int:
        return int(self.vertices.nbytes + self.normals.nbytes + self.triangles.nbytes + self.clusters.nbytes)



# --- the file -----------------------------------------------------------------------------------------
def _arrays(lod: MeshLod) -> dict:
    return {"vertices": np.ascontiguousarray(lod.vertices, "<f4"), "normals": np.ascontiguousarray(lod.normals, "<f4"),
            "triangles": np.ascontiguousarray(lod.triangles, "<u4"), "clusters": np.ascontiguousarray(lod.clusters)}


def _layout() -> list:
    """The Cluster record's fields as [name, dtype, offset]: a file written with another layout is refused."""
    return [[name, CLUSTER.dtype.fields[name][0].str, CLUSTER.dtype.fields[name][1]] for name in CLUSTER.dtype.names]


def _json_default(x):
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, Path):
        return str(x)
    raise TypeError(f"cannot store {type(x).__name__} in a .meshlod header")


def _pad(n: int) -> int:
    return (-n) % _ALIGN


def check_meshlod(lod: MeshLod, what: str) -> None:
    """MeshError naming ``what`` unless ``lod`` holds arrays of the contract's types and shapes whose
    clusters and triangles point inside the arrays they index."""
    if not isinstance(lod, MeshLod):
        raise MeshError(f"{what}: expected a MeshLod, got {type(lod).__name__}")
    v, n, t, c = lod.vertices, lod.normals, lod.triangles, lod.clusters
    for name, a, dtype in (("vertices", v, np.float32), ("normals", n, np.float32), ("triangles", t, np.uint32)):
        if not isinstance(a, np.ndarray) or a.dtype != dtype or a.ndim != 2 or a.shape[1] != 3:
            got = f"{a.dtype} {a.shape}" if isinstance(a, np.ndarray) else type(a).__name__
            raise MeshError(f"{what}: '{name}' must be {np.dtype(dtype).name} [N, 3], got {got}")
    if not isinstance(c, np.ndarray) or c.dtype != CLUSTER.dtype or c.ndim != 1:
        raise MeshError(f"{what}: 'clusters' must be a 1-d array of the Cluster record")
    if n.shape != v.shape:
        raise MeshError(f"{what}: {len(n)} normals for {len(v)} vertices")
    if len(v) == 0 or len(t) == 0 or len(c) == 0:
        raise MeshError(f"{what}: the mesh is empty ({len(v)} vertices, {len(t)} triangles, {len(c)} clusters)")
    if not (np.isfinite(v).all() and np.isfinite(n).all()):
        raise MeshError(f"{what}: vertices or normals are NaN or infinite")
    if int(t.max()) >= len(v):
        raise MeshError(f"{what}: triangle index {int(t.max())} is out of range for {len(v)} vertices")
    end = c["first"].astype(np.int64) + c["count"]
    if int(end.max()) > len(t) or int(c["count"].min()) == 0 or int(c["count"].max()) > CLUSTER.constant("CLUSTER_MAX_TRIANGLES"):
        raise MeshError(f"{what}: a cluster's triangle range is empty, longer than "
                        f"{CLUSTER.constant('CLUSTER_MAX_TRIANGLES')} or outside the {len(t)} triangles")
    if lod.lod not in LODS:
        raise MeshError(f"{what}: lod must be one of {', '.join(LODS)}, got {lod.lod!r}")


def meshlod_bytes(lod: MeshLod) -> bytes:
    """The ``.meshlod`` file of ``lod`` (the same bytes every time for the same MeshLod)."""
    check_meshlod(lod, f"mesh LOD '{lod.name}'")
    arrays = _arrays(lod)
    table, at = [], 0
    for name, a in arrays.items():
        table.append({"name": name, "dtype": a.dtype.str if a.dtype.names is None else "Cluster",
                      "shape": list(a.shape), "offset": at, "nbytes": int(a.nbytes)})
        at += a.nbytes + _pad(a.nbytes)
    header = {"format": FORMAT, "name": lod.name, "lod": lod.lod,
              "counts": {"vertices": len(lod.vertices), "triangles": len(lod.triangles), "clusters": len(lod.clusters),
                         "levels": lod.levels, "roots": len(lod.roots)},
              "cluster_layout": _layout(), "cluster_bytes": CLUSTER.dtype.itemsize,
              "info": lod.info, "arrays": table}
    try:
        text = json.dumps(header, sort_keys=True, separators=(",", ":"), default=_json_default,
                          allow_nan=False).encode()
    except (TypeError, ValueError) as exc:
        raise MeshError(f"mesh LOD '{lod.name}': its info cannot be stored ({exc})") from None
    base = _PREFIX.size + len(text)
    text += b" " * _pad(base)
    parts = [_PREFIX.pack(MAGIC, VERSION, len(text)), text]
    for a in arrays.values():
        parts.append(a.tobytes())
        parts.append(b"\0" * _pad(a.nbytes))
    body = b"".join(parts)
    return body + hashlib.sha256(body).digest()


def save_meshlod(lod: MeshLod, path) -> Path:
    """Write ``lod`` to ``path`` (atomically: a temporary file renamed into place)."""
    data = meshlod_bytes(lod)
    try:
        return write_atomically(path, lambda tmp: Path(tmp).write_bytes(data))
    except ParamlodError as exc:
        raise MeshError(str(exc)) from None


def load_meshlod(path) -> MeshLod:
    """Read a ``.meshlod`` file; MeshError naming the file and what is wrong with it."""
    path = Path(path)
    where = f"mesh LOD file {path}"
    if not path.exists():
        raise MeshError(f"{where} does not exist")
    if path.is_dir():
        raise MeshError(f"{where} is a folder")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise MeshError(f"cannot read {where}: {exc.strerror or exc}") from None
    return parse_meshlod(data, where)


def parse_meshlod(data: bytes, where: str = "mesh LOD data") -> MeshLod:
    rebuild = "rebuild it with: paramlod mesh build <mesh file> -o <file>.meshlod"
    if len(data) < _PREFIX.size or data[:len(MAGIC)] != MAGIC:
        raise MeshError(f"{where} is not a .meshlod file (no {MAGIC.decode()} signature at its start)")
    _, version, header_len = _PREFIX.unpack_from(data)
    if version != VERSION:
        raise MeshError(f"{where} is .meshlod version {version}; this paramlod reads version {VERSION}: {rebuild}")
    if len(data) < _PREFIX.size + header_len + _DIGEST:
        raise MeshError(f"{where} is truncated ({len(data)} bytes, shorter than its header says): {rebuild}")
    try:
        header = json.loads(data[_PREFIX.size:_PREFIX.size + header_len].decode())
        start = _PREFIX.size + header_len
        table = header["arrays"]
        expected = start + sum(a["nbytes"] + _pad(a["nbytes"]) for a in table) + _DIGEST
    except (UnicodeDecodeError, json.JSONDecodeError, KeyError, TypeError) as exc:
        raise MeshError(f"{where} is corrupt (its header cannot be read: {type(exc).__name__}): {rebuild}") from None
    if len(data) < expected:
        raise MeshError(f"{where} is truncated ({len(data)} of {expected} bytes): {rebuild}")
    if len(data) > expected:
        raise MeshError(f"{where} is corrupt ({len(data) - expected} bytes after its end): {rebuild}")
    if hashlib.sha256(data[:-_DIGEST]).digest() != data[-_DIGEST:]:
        raise MeshError(f"{where} is corrupt (its checksum does not match its contents): {rebuild}")
    if header.get("format") != FORMAT:
        raise MeshError(f"{where} is not a .meshlod file (format {header.get('format')!r})")
    if header.get("cluster_layout") != _layout():
        raise MeshError(f"{where} was written with another Cluster record layout than this paramlod's: {rebuild}")
    arrays = {}
    try:
        for a in table:
            dtype = CLUSTER.dtype if a["dtype"] == "Cluster" else np.dtype(a["dtype"])
            count = int(np.prod(a["shape"]))
            if count * dtype.itemsize != a["nbytes"]:
                raise ValueError(f"array {a['name']}: {a['nbytes']} bytes for shape {a['shape']}")
            arr = np.frombuffer(data, dtype, count, start + a["offset"]).reshape(a["shape"])
            arrays[a["name"]] = arr.astype(arr.dtype.newbyteorder("=")) if dtype.names is None else arr.copy()
        lod = MeshLod(vertices=arrays["vertices"], normals=arrays["normals"], triangles=arrays["triangles"],
                      clusters=arrays["clusters"], name=str(header["name"]), lod=str(header["lod"]),
                      info=dict(header["info"]))
    except (KeyError, TypeError, ValueError) as exc:
        raise MeshError(f"{where} is corrupt ({exc}): {rebuild}") from None
    check_meshlod(lod, where)
    return lod


# --- the summary ``paramlod mesh info`` prints --------------------------------------------------------
def mesh_info(lod: MeshLod) -> dict:
    """Levels, clusters, roots, triangles and clusters per level, bytes, error range, build time."""
    c = lod.clusters
    levels = lod.levels
    per_level = [int(c["count"][c["level"] == k].sum()) for k in range(levels)]
    clusters_per_level = [int(np.count_nonzero(c["level"] == k)) for k in range(levels)]
    errors = c["error"][c["error"] > 0]
    return {
        "name": lod.name, "lod": lod.lod, "vertices": len(lod.vertices), "triangles": lod.original_triangles,
        "triangles_stored": len(lod.triangles), "levels": levels, "clusters": len(c), "roots": len(lod.roots),
        "triangles_per_level": per_level, "clusters_per_level": clusters_per_level,
        "root_triangles": int(c["count"][lod.roots].sum()),
        "bytes": lod.nbytes,
        "error_range": [float(errors.min()), float(errors.max())] if len(errors) else [0.0, 0.0],
        "build_seconds": lod.info.get("build_seconds"),
        "settings": lod.info.get("settings"), "content_hash": lod.info.get("content_hash"),
    }


# --- the cache of builds ------------------------------------------------------------------------------
def cache_dir() -> Path:
    """``$PARAMLOD_CACHE/meshlod`` or ``~/.cache/paramlod/meshlod``."""
    root = os.environ.get("PARAMLOD_CACHE")
    return (Path(root).expanduser() if root else Path.home() / ".cache" / "paramlod") / "meshlod"


def cache_key(content_hash: str, lod: str, settings: dict) -> str:
    """The cache's name for a build: the mesh's content hash, lod, settings and the file version."""
    text = json.dumps({"content": content_hash, "lod": lod, "settings": settings, "version": VERSION},
                      sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:40]


def cache_load(key: str) -> MeshLod | None:
    """The cached build of ``key``, or None (also, with a warning, when its file is unreadable)."""
    path = cache_dir() / f"{key}{SUFFIX}"
    if not path.is_file():
        return None
    try:
        return load_meshlod(path)
    except MeshError as exc:
        warnings.warn(f"mesh LOD cache: {exc}; building it again", RuntimeWarning, stacklevel=3)
        return None


def cache_store(lod: MeshLod, key: str) -> Path | None:
    """Write ``lod`` to the cache (a warning, not an error, when the cache cannot be written)."""
    folder = cache_dir()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        return save_meshlod(lod, folder / f"{key}{SUFFIX}")
    except (OSError, MeshError) as exc:
        warnings.warn(f"mesh LOD cache: cannot write to {folder} ({exc}); the build is not cached",
                      RuntimeWarning, stacklevel=3)
        return None
