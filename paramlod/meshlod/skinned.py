"""Linear-blend-skinned meshes: the skeleton and its animation clip (``Rig``), the mesh with its
joint weights and meshlets (``SkinnedMesh``), and the glTF/GLB loader (``load_skinned``).

Driven by the scene's "skinned" loader (``Scene.add_skinned_mesh``, ``[[objects]] skinned = ...``
in scene files), the skinning pass (paramlod.meshlod.skin, whose numpy twin skin_reference takes
``Rig.skin_matrices``) and the offline bounds (paramlod.meshlod.build.skin_bounds). No twin (host
only); tests/meshlod/test_skinned.py checks the samplers against hand-computed values.

Building from arrays (tests, generators)::

    rig = Rig(parents=[-1, 0], joint_nodes=[0, 1], inverse_bind=ibm,          # ibm float [J, 4, 4]
              rest=(T, Q, S),                                                  # float [N,3], [N,4] xyzw, [N,3]
              channels=[Channel(node=1, path="rotation", interpolation="LINEAR",
                                times=[0, 1], values=[[0, 0, 0, 1], [0, 0, 0.7071, 0.7071]])],
              root=None)                                                       # None: identity
    mesh = SkinnedMesh.build(vertices, triangles, joints, weights, rig, normals=None, name="arm")

``Channel.values`` is [K, 3] or [K, 4]; for CUBICSPLINE [K, 3, d]: (in-tangent, value, out-tangent)
of each keyframe, as glTF stores them. ``Rig.times`` is the sorted union of the channels' times
([0] for a clip without channels); ``Rig.interpolation`` the clip's ("CUBICSPLINE" if any channel
is, else "LINEAR" if any is, else "STEP"). Times outside the clip are clamped to it.

``SkinnedMesh.build`` normalises the weights (rows sum to 1; a vertex without weight is bound to
joint 0 with weight 1 and counted in ``info["unweighted"]``), drops zero-area triangles (counted in
``info["degenerate_dropped"]``: they draw nothing), computes area-weighted normals when none are
given and cuts the meshlets with the leaf stage of the DAG build (paramlod.meshlod.build.dag,
lod="full": meshoptimizer clusters of at most 128 triangles; the triangles come back reordered so
cluster i is triangles[first:first + count]). There is no DAG for skinned meshes: every meshlet is
drawn at full detail and only culled (paramlod.meshlod.skin_cull).

glTF specifics (``load_skinned``): every node with a skin contributes its mesh (all its
primitives, in mesh space: glTF ignores a skinned node's own transform); the joints of several
skins are concatenated. Mesh nodes without a skin in the same file are drawn rigidly with their
node (a joint of their own with an identity inverse bind matrix), so nothing in the file is left
out. Morph targets and the animation's "weights" channels are not applied (counted in
``info["ignored"]``). Triangle strips and fans are turned into triangles; points and lines refuse.
"""
from __future__ import annotations

import base64
import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from paramlod.errors import MeshError
from paramlod.meshlod.build.dag import BuildSettings, build_dag, vertex_normals

INTERPOLATIONS = ("LINEAR", "STEP", "CUBICSPLINE")
PATHS = {"translation": 3, "rotation": 4, "scale": 3}
MAX_JOINTS = 1 << 16   # JOINTS_0 is at most unsigned short in glTF


# --- quaternions (x, y, z, w) ----------------------------------------------------------------------
def quat_matrix(q: np.ndarray) -> np.ndarray:
    """float64 [..., 3, 3] rotation matrices of unit quaternions [..., 4] (x, y, z, w)."""
    q = np.asarray(q, np.float64)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], -2)


def matrix_quat(m: np.ndarray) -> np.ndarray:
    """The unit quaternion (x, y, z, w; w >= 0) of a rotation matrix [3, 3] (Shepperd's method)."""
    m = np.asarray(m, np.float64)
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = 2 * np.sqrt(tr + 1)
        q = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, s / 4]
    else:
        i = int(np.argmax(np.diag(m)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2 * np.sqrt(max(1 + m[i, i] - m[j, j] - m[k, k], 1e-300))
        q = [0.0, 0.0, 0.0, (m[k, j] - m[j, k]) / s]
        q[i] = s / 4
        q[j] = (m[j, i] + m[i, j]) / s
        q[k] = (m[k, i] + m[i, k]) / s
    q = np.asarray(q)
    q /= np.linalg.norm(q)
    return -q if q[3] < 0 else q


def slerp(a: np.ndarray, b: np.ndarray, s: float) -> np.ndarray:
    """Spherical interpolation of unit quaternions along the shorter arc (b's sign flipped when the
    dot product is negative), normalised; a lerp where they are almost equal."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    d = float(np.dot(a, b))
    if d < 0:
        b, d = -b, -d
    if d > 1 - 1e-9:
        q = a + s * (b - a)
    else:
        th = np.arccos(min(d, 1.0))
        q = (np.sin((1 - s) * th) * a + np.sin(s * th) * b) / np.sin(th)
    return q / np.linalg.norm(q)


def trs_matrix(t, q, s) -> np.ndarray:
    """float64 [..., 4, 4] = T @ R @ S."""
    t, s = np.asarray(t, np.float64), np.asarray(s, np.float64)
    m = np.zeros(t.shape[:-1] + (4, 4))
    m[..., :3, :3] = quat_matrix(q) * s[..., None, :]
    m[..., :3, 3] = t
    m[..., 3, 3] = 1.0
    return m


# --- the clip ------------------------------------------------------------------------------------
@dataclass
class Channel:
    """One animated property of one node: its keyframe ``times`` float [K] (increasing) and
    ``values`` [K, d] (LINEAR, STEP) or [K, 3, d] (CUBICSPLINE: in-tangent, value, out-tangent)."""
    node: int
    path: str            # "translation" | "rotation" | "scale"
    interpolation: str   # "LINEAR" | "STEP" | "CUBICSPLINE"
    times: np.ndarray
    values: np.ndarray

    def __post_init__(self):
        what = f"animation channel (node {self.node}, {self.path})"
        if self.path not in PATHS:
            raise MeshError(f"{what}: path must be one of {', '.join(PATHS)}")
        if self.interpolation not in INTERPOLATIONS:
            raise MeshError(f"{what}: interpolation must be one of {', '.join(INTERPOLATIONS)}, "
                            f"got {self.interpolation!r}")
        d = PATHS[self.path]
        self.times = np.asarray(self.times, np.float64).reshape(-1)
        v = np.asarray(self.values, np.float64)
        k = len(self.times)
        want = (k, 3, d) if self.interpolation == "CUBICSPLINE" else (k, d)
        if k == 0 or v.size != int(np.prod(want)):
            raise MeshError(f"{what}: {k} keyframe times need values of shape {want}, got {v.shape}")
        self.values = v.reshape(want)
        if not (np.isfinite(self.times).all() and np.isfinite(self.values).all()):
            raise MeshError(f"{what}: times and values must be finite")
        if np.any(np.diff(self.times) <= 0):
            raise MeshError(f"{what}: keyframe times must be strictly increasing")

    def sample(self, t: float) -> np.ndarray:
        """The value at time ``t`` (float64 [d]); clamped to the first and last keyframe."""
        ts, v, cubic = self.times, self.values, self.interpolation == "CUBICSPLINE"
        if t <= ts[0] or len(ts) == 1:
            out = v[0, 1] if cubic else v[0]
        elif t >= ts[-1]:
            out = v[-1, 1] if cubic else v[-1]
        else:
            k = int(np.searchsorted(ts, t, side="right")) - 1
            td = ts[k + 1] - ts[k]
            s = (t - ts[k]) / td
            if self.interpolation == "STEP":
                out = v[k]
            elif self.interpolation == "LINEAR":
                if self.path == "rotation":
                    return slerp(v[k], v[k + 1], s)
                out = v[k] + s * (v[k + 1] - v[k])
            else:   # Hermite between value k (out-tangent b_k) and value k+1 (in-tangent a_k+1)
                s2, s3 = s * s, s * s * s
                out = ((2 * s3 - 3 * s2 + 1) * v[k, 1] + td * (s3 - 2 * s2 + s) * v[k, 2]
                       + (-2 * s3 + 3 * s2) * v[k + 1, 1] + td * (s3 - s2) * v[k + 1, 0])
        out = np.array(out, np.float64)
        if self.path == "rotation":
            n = np.linalg.norm(out)
            out = out / n if n > 0 else np.array([0.0, 0.0, 0.0, 1.0])
        return out


class Rig:
    """A skeleton and one animation clip. Nodes are the joints and their ancestors (index order:
    parents before children). See the module docstring for the constructor."""

    def __init__(self, parents, joint_nodes, inverse_bind, rest, channels=(), root=None, name: str = "rig",
                 node_names=None, animation: str = ""):
        self.name, self.animation = name, animation
        self.parents = np.asarray(parents, np.int64).astype(np.int32).reshape(-1)
        n = len(self.parents)
        if n == 0:
            raise MeshError(f"{name}: a rig needs at least one node")
        if np.any(self.parents >= np.arange(n)) or np.any(self.parents < -1):
            raise MeshError(f"{name}: parents must come before their children (parents[i] < i, -1 for a root)")
        self.joint_nodes = np.asarray(joint_nodes, np.int64).astype(np.int32).reshape(-1)
        if len(self.joint_nodes) == 0 or len(self.joint_nodes) > MAX_JOINTS:
            raise MeshError(f"{name}: a rig needs 1..{MAX_JOINTS} joints, got {len(self.joint_nodes)}")
        if self.joint_nodes.min() < 0 or self.joint_nodes.max() >= n:
            raise MeshError(f"{name}: joint nodes must be in 0..{n - 1}")
        ib = np.asarray(inverse_bind, np.float64)
        if ib.shape != (len(self.joint_nodes), 4, 4) or not np.isfinite(ib).all():
            raise MeshError(f"{name}: inverse_bind must be a finite [{len(self.joint_nodes)}, 4, 4] array, got {ib.shape}")
        self.inverse_bind = ib
        self.root = np.eye(4) if root is None else np.asarray(root, np.float64).reshape(4, 4)
        t, q, s = (np.asarray(a, np.float64) for a in rest)
        if t.shape != (n, 3) or q.shape != (n, 4) or s.shape != (n, 3):
            raise MeshError(f"{name}: rest (T, Q, S) must be [{n}, 3], [{n}, 4], [{n}, 3]")
        qn = np.linalg.norm(q, axis=1, keepdims=True)
        if np.any(qn == 0) or not (np.isfinite(t).all() and np.isfinite(q).all() and np.isfinite(s).all()):
            raise MeshError(f"{name}: rest transforms must be finite with non-zero rotations")
        self.rest = (t, q / qn, s)
        self.channels = list(channels)
        for c in self.channels:
            if not 0 <= c.node < n:
                raise MeshError(f"{name}: an animation channel targets node {c.node}; the rig has {n}")
        self.node_names = list(node_names) if node_names is not None else [f"node{i}" for i in range(n)]
        self.times = (np.unique(np.concatenate([c.times for c in self.channels])) if self.channels
                      else np.zeros(1))
        kinds = {c.interpolation for c in self.channels}
        self.interpolation = next((k for k in ("CUBICSPLINE", "LINEAR", "STEP") if k in kinds), "LINEAR")

    @property
    def start(self) -> float:
        return float(self.times[0])

    @property
    def end(self) -> float:
        return float(self.times[-1])

    def clamp(self, t: float) -> float:
        return float(min(max(float(t), self.start), self.end))

    def local_trs(self, t: float):
        """Each node's local translation float64 [N, 3], rotation quaternion [N, 4] (x, y, z, w,
        unit) and scale [N, 3] at time ``t`` (clamped to the clip)."""
        t = self.clamp(t)
        tr, q, s = (a.copy() for a in self.rest)
        for c in self.channels:
            {"translation": tr, "rotation": q, "scale": s}[c.path][c.node] = c.sample(t)
        return tr, q, s

    def node_matrices(self, t: float) -> np.ndarray:
        """float64 [N, 4, 4]: each node's global transform root @ ... @ parent @ T R S at ``t``."""
        local = trs_matrix(*self.local_trs(t))
        out = np.empty_like(local)
        for i, p in enumerate(self.parents):
            out[i] = (self.root if p < 0 else out[p]) @ local[i]
        return out

    def skin_matrices(self, t: float) -> np.ndarray:
        """float64 [J, 4, 4]: node_matrices(t)[joint_nodes] @ inverse_bind."""
        return self.node_matrices(t)[self.joint_nodes] @ self.inverse_bind


# --- the mesh ------------------------------------------------------------------------------------
@dataclass
class SkinnedMesh:
    name: str                 # file name or given name, used in messages
    vertices: np.ndarray      # float32 [V, 3] bind pose, mesh space
    normals: np.ndarray       # float32 [V, 3]
    triangles: np.ndarray     # uint32 [T, 3], in cluster order
    joints: np.ndarray        # uint32 [V, 4] joint indices
    weights: np.ndarray       # float32 [V, 4], rows sum to 1, unused slots weight 0
    rig: Rig
    clusters: np.ndarray      # CLUSTER [C]: the meshlets (level 0, every one a root)
    info: dict = field(default_factory=dict)
    lod: str = "skinned"
    # the meshlets' conservative bounds over the clip (paramlod.meshlod.build.skin_bounds.SkinBounds),
    # made by the mesh renderers the first time they cull this mesh (or set beforehand), then reused
    bounds: object = field(default=None, repr=False, compare=False)

    @classmethod
    def build(cls, vertices, triangles, joints, weights, rig: Rig, normals=None, name: str = "skinned",
              info: dict | None = None) -> "SkinnedMesh":
        """A SkinnedMesh from arrays (see the module docstring): checked, weights normalised,
        meshlets cut. MeshError naming ``name`` for bad input."""
        v = np.asarray(vertices, np.float32)
        f = np.asarray(triangles)
        if v.ndim != 2 or v.shape[1] != 3 or len(v) == 0:
            raise MeshError(f"{name}: vertices must be a non-empty [V, 3] array, got {v.shape}")
        if f.ndim != 2 or f.shape[1] != 3 or f.dtype.kind not in "iu" or len(f) == 0:
            raise MeshError(f"{name}: triangles must be a non-empty integer [T, 3] array, got {f.dtype} {f.shape}")
        if f.min() < 0 or f.max() >= len(v):
            raise MeshError(f"{name}: triangle indices must be in 0..{len(v) - 1}")
        j = np.asarray(joints)
        w = np.asarray(weights, np.float64)
        if j.shape != (len(v), 4) or w.shape != (len(v), 4) or j.dtype.kind not in "iu":
            raise MeshError(f"{name}: joints (integer) and weights must be [{len(v)}, 4] like the vertices, "
                            f"got {j.dtype} {j.shape} and {w.shape}")
        if not np.isfinite(w).all() or np.any(w < 0):
            raise MeshError(f"{name}: weights must be finite and >= 0")
        n_j = len(rig.joint_nodes)
        if np.any((j >= n_j) & (w > 0)) or np.any(j < 0):
            bad = int(np.argmax(np.any((j >= n_j) & (w > 0), axis=1) | np.any(j < 0, axis=1)))
            raise MeshError(f"{name}: vertex {bad} is weighted to joint {j[bad].tolist()}; the rig has {n_j} joints")
        info = dict(info or {})
        j = np.where(w > 0, j, 0).astype(np.uint32)
        total = w.sum(axis=1)
        none = total <= 0
        info["unweighted"] = int(none.sum())
        w = np.where(none[:, None], np.array([1.0, 0, 0, 0]), w / np.where(none, 1, total)[:, None])
        f = f.astype(np.uint32)
        p = v.astype(np.float64)
        area2 = np.linalg.norm(np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]]), axis=1)
        keep = (area2 > 0) & (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])
        info["degenerate_dropped"] = int((~keep).sum())
        if not keep.any():
            raise MeshError(f"{name}: every triangle has zero area")
        f = f[keep]
        n = vertex_normals(v, f) if normals is None else np.asarray(normals, np.float32)
        if n.shape != v.shape or not np.isfinite(n).all():
            raise MeshError(f"{name}: normals must be a finite [V, 3] array like the vertices")
        ln = np.linalg.norm(n, axis=1, keepdims=True)
        n = np.where(ln > 0, n / np.where(ln > 0, ln, 1), vertex_normals(v, f)).astype(np.float32)
        built = build_dag(v, f, n, settings=BuildSettings(), lod="full", progress=False, name=name)
        info["build_seconds"] = built.info.get("build_seconds")
        return cls(name, built.vertices, built.normals, built.triangles, j, w.astype(np.float32), rig,
                   built.clusters, info)

    @property
    def levels(self) -> int:
        return 1

    @property
    def roots(self) -> np.ndarray:
        return np.arange(len(self.clusters))

    @property
    def original_triangles(self) -> int:
        return len(self.triangles)

    def bounding_sphere(self, samples: int = 9) -> tuple[np.ndarray, float]:
        """Centre and radius of a sphere around the posed vertices at ``samples`` times of the clip
        (for framing a camera; the bind pose can be far from every pose, e.g. FBX units)."""
        ts = np.unique(np.concatenate([np.linspace(self.rig.start, self.rig.end, samples), self.rig.times]))
        if len(ts) > samples:
            ts = ts[np.linspace(0, len(ts) - 1, samples).round().astype(int)]
        pts = np.concatenate([self.posed(float(t))[0] for t in ts])
        c = (pts.min(axis=0) + pts.max(axis=0)) / 2
        return c, float(np.sqrt(((pts - c) ** 2).sum(axis=1).max()))

    def posed(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(positions, normals) float64 [V, 3] at time ``t``, in float64 on the host (for framing and
        checks; the frame's pose is skinned on the device by paramlod.meshlod.skin)."""
        m = self.rig.skin_matrices(t)
        blend = np.einsum("vk,vkij->vij", self.weights.astype(np.float64), m[self.joints])
        p = np.einsum("vij,vj->vi", blend[:, :3, :3], self.vertices.astype(np.float64)) + blend[:, :3, 3]
        n = np.einsum("vij,vj->vi", blend[:, :3, :3], self.normals.astype(np.float64))
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
        return p, n

    @property
    def nbytes(self) -> int:
        return int(self.vertices.nbytes + self.normals.nbytes + self.triangles.nbytes + self.clusters.nbytes
                   + self.joints.nbytes + self.weights.nbytes)

    def content_hash(self) -> str:
        h = hashlib.sha256()
        for a in (self.vertices, self.triangles, self.joints, self.weights, self.rig.inverse_bind):
            h.update(np.ascontiguousarray(a).tobytes())
        return h.hexdigest()[:32]


# --- glTF ----------------------------------------------------------------------------------------
_COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}


class _Gltf:
    """A parsed glTF/GLB file and its decoded buffers; errors name the file."""

    def __init__(self, path: Path):
        import pygltflib   # optional at import time: only skinned files need it

        self.path, self.where = path, f"skinned mesh '{path.name}'"
        if not path.is_file():
            raise MeshError(f"{self.where}: {path} is not a file" if path.exists() else f"{self.where}: no such file {path}")
        with open(path, "rb") as fh:
            head = fh.read(4)
        suffix = path.suffix.lower()
        if suffix not in (".glb", ".gltf"):
            raise MeshError(f"{self.where}: skinned meshes are read from glTF files (.glb, .gltf); convert "
                            f"{suffix or 'this file'} with: assimp export {path.name} {path.stem}.glb -fglb2")
        if suffix == ".glb" and head != b"glTF":
            raise MeshError(f"{self.where}: not a GLB file (it does not start with 'glTF')")
        try:
            self.g = pygltflib.GLTF2().load(str(path))
        except Exception as exc:   # pygltflib raises json, struct and dataclass errors for bad files
            raise MeshError(f"{self.where}: not a readable glTF file ({type(exc).__name__}: {exc})") from None
        if self.g is None:
            raise MeshError(f"{self.where}: not a readable glTF file")
        self._buffers = {}

    def bad(self, msg: str):
        raise MeshError(f"{self.where}: {msg}")

    def buffer(self, i: int) -> bytes:
        if i in self._buffers:
            return self._buffers[i]
        if not 0 <= i < len(self.g.buffers):
            self.bad(f"buffer {i} does not exist")
        b = self.g.buffers[i]
        if b.uri is None:
            data = self.g.binary_blob()
            if data is None:
                self.bad(f"buffer {i} has no uri and the file has no binary chunk")
        elif b.uri.startswith("data:"):
            try:
                data = base64.b64decode(b.uri.split(",", 1)[1])
            except (IndexError, ValueError):
                self.bad(f"buffer {i}: bad data URI")
        else:
            f = self.path.parent / b.uri
            if not f.is_file():
                self.bad(f"buffer {i}: its file {b.uri} is missing next to the glTF file")
            data = f.read_bytes()
        if len(data) < (b.byteLength or 0):
            self.bad(f"buffer {i} holds {len(data)} bytes, {b.byteLength} declared")
        self._buffers[i] = data
        return data

    def accessor(self, i, what: str) -> np.ndarray:
        """Accessor ``i`` decoded to a numpy array [count, width] (float64 for normalised integers)."""
        if i is None or not 0 <= i < len(self.g.accessors):
            self.bad(f"{what}: accessor {i} does not exist")
        a = self.g.accessors[i]
        dt = _COMPONENTS.get(a.componentType)
        width = _WIDTH.get(a.type)
        if dt is None or width is None:
            self.bad(f"{what}: accessor {i} has an unknown component type {a.componentType} or type {a.type!r}")
        dt = np.dtype(dt).newbyteorder("<")
        count = int(a.count)
        out = np.zeros((count, width), dt)
        if a.bufferView is not None:
            if not 0 <= a.bufferView < len(self.g.bufferViews):
                self.bad(f"{what}: accessor {i} names buffer view {a.bufferView}, which does not exist")
            bv = self.g.bufferViews[a.bufferView]
            data = self.buffer(bv.buffer)
            start = (bv.byteOffset or 0) + (a.byteOffset or 0)
            elem = dt.itemsize * width
            stride = bv.byteStride or elem
            end = start + (count - 1) * stride + elem if count else start
            if end > (bv.byteOffset or 0) + bv.byteLength or end > len(data):
                self.bad(f"{what}: accessor {i} reads past the end of its buffer view")
            if count:
                raw = np.frombuffer(data, np.uint8, end - start, start)
                if stride == elem:
                    out = raw.view(dt).reshape(count, width).copy()
                else:
                    out = np.lib.stride_tricks.as_strided(raw, (count, elem), (stride, 1)).copy().view(dt).reshape(count, width)
        if a.sparse is not None and a.sparse.count:
            sp = a.sparse
            idt = _COMPONENTS.get(sp.indices.componentType)
            if idt is None:
                self.bad(f"{what}: accessor {i} has sparse indices of unknown type")
            idx = self._view(sp.indices.bufferView, sp.indices.byteOffset, np.dtype(idt), sp.count, 1, what).reshape(-1)
            vals = self._view(sp.values.bufferView, sp.values.byteOffset, dt, sp.count, width, what)
            if idx.size and idx.max() >= count:
                self.bad(f"{what}: accessor {i} has sparse indices past its count")
            out = out.copy()
            out[idx.astype(np.int64)] = vals
        if a.normalized and dt.kind in "iu":
            m = float(np.iinfo(dt).max)
            out = np.maximum(out.astype(np.float64) / m, -1.0)
        if out.dtype.kind == "f" and not np.isfinite(out).all():
            self.bad(f"{what}: accessor {i} holds NaN or infinite values")
        return out

    def _view(self, view, offset, dt, count, width, what):
        if view is None or not 0 <= view < len(self.g.bufferViews):
            self.bad(f"{what}: sparse data names buffer view {view}, which does not exist")
        bv = self.g.bufferViews[view]
        data = self.buffer(bv.buffer)
        start = (bv.byteOffset or 0) + (offset or 0)
        n = dt.itemsize * width * count
        if start + n > len(data):
            self.bad(f"{what}: sparse data reads past the end of its buffer")
        return np.frombuffer(data, dt.newbyteorder("<"), width * count, start).reshape(count, width).copy()


def _node_trs(g: _Gltf, i: int):
    n = g.g.nodes[i]
    if n.matrix is not None and len(n.matrix) == 16 and not np.allclose(n.matrix, np.eye(4).reshape(-1)):
        m = np.asarray(n.matrix, np.float64).reshape(4, 4).T   # glTF matrices are column-major
        lin = m[:3, :3]
        s = np.linalg.norm(lin, axis=0)
        if np.any(s == 0):
            g.bad(f"node {i} ({n.name or 'unnamed'}) has a singular matrix")
        r = lin / s
        if np.linalg.det(r) < 0:
            s[0], r[:, 0] = -s[0], -r[:, 0]
        q = matrix_quat(r)
        if not np.allclose(quat_matrix(q) * s, lin, atol=1e-5 * max(1.0, float(np.abs(lin).max()))):
            g.bad(f"node {i} ({n.name or 'unnamed'}) has a sheared matrix, which a joint's translation, "
                  "rotation and scale cannot hold")
        return m[:3, 3], q, s
    t = np.asarray(n.translation if n.translation is not None else [0, 0, 0], np.float64)
    q = np.asarray(n.rotation if n.rotation is not None else [0, 0, 0, 1], np.float64)
    s = np.asarray(n.scale if n.scale is not None else [1, 1, 1], np.float64)
    if t.shape != (3,) or q.shape != (4,) or s.shape != (3,) or not np.linalg.norm(q) > 0:
        g.bad(f"node {i} ({n.name or 'unnamed'}) has a malformed translation, rotation or scale")
    return t, q, s


def _triangles(g: _Gltf, prim, count: int, what: str) -> np.ndarray:
    mode = 4 if prim.mode is None else prim.mode
    if prim.indices is None:
        idx = np.arange(count, dtype=np.int64)
    else:
        idx = g.accessor(prim.indices, f"{what} indices").reshape(-1).astype(np.int64)
    if mode == 4:
        if len(idx) % 3:
            g.bad(f"{what}: {len(idx)} triangle indices is not a multiple of 3")
        f = idx.reshape(-1, 3)
    elif mode == 5:   # strip: alternate the winding so every triangle faces the same way
        k = np.arange(max(len(idx) - 2, 0))
        f = np.stack([idx[k], np.where(k % 2, idx[k + 2], idx[k + 1]), np.where(k % 2, idx[k + 1], idx[k + 2])], 1)
    elif mode == 6:
        k = np.arange(1, max(len(idx) - 1, 1))
        f = np.stack([np.full(len(k), idx[0]), idx[k], idx[k + 1]], 1) if len(idx) >= 3 else np.zeros((0, 3), np.int64)
    else:
        g.bad(f"{what} draws points or lines (mode {mode}); only triangles can be skinned and drawn")
    if len(f) and (f.min() < 0 or f.max() >= count):
        g.bad(f"{what}: indices must be in 0..{count - 1}")
    return f


def animation_names(path) -> list[str]:
    """The names of the animations of a glTF/GLB file ("#i" for an unnamed one)."""
    g = _Gltf(Path(path))
    return [a.name or f"#{i}" for i, a in enumerate(g.g.animations or [])]


def load_skinned(path, animation=None, name: str | None = None) -> SkinnedMesh:
    """The SkinnedMesh of a glTF/GLB file with a skin. ``animation``: a name, an index, or None
    (the first; a file without animations then stays in its rest pose). MeshError naming the file
    for a file that is not glTF, no skin, no animation when one is asked for, an unknown name (the
    names are listed) and bad accessors."""
    path = Path(path)
    g = _Gltf(path)
    try:
        return _load(g, path, animation, name)
    except (TypeError, ValueError, AttributeError, IndexError, KeyError, OverflowError) as exc:
        # fields of the wrong type or missing (pygltflib does not check them): the file is malformed
        raise MeshError(f"{g.where}: malformed glTF data ({type(exc).__name__}: {exc})") from None


def _load(g: "_Gltf", path: Path, animation, name) -> SkinnedMesh:
    gl = g.g
    nodes = gl.nodes or []
    if not gl.skins:
        g.bad("the file has no skin (no skinned mesh); load it with add_mesh instead")
    parent = np.full(len(nodes), -1, np.int64)
    for i, n in enumerate(nodes):
        for c in n.children or []:
            if not 0 <= c < len(nodes) or parent[c] >= 0 or c == i:
                g.bad(f"node {i} has a bad child {c} (missing, or a node with two parents)")
            parent[c] = i

    # joints: those of every skin, concatenated; rigid mesh nodes get a joint of their own
    joint_nodes, ibms, skin_base = [], [], {}
    for si, sk in enumerate(gl.skins):
        if not sk.joints:
            g.bad(f"skin {si} has no joints")
        if any(not 0 <= j < len(nodes) for j in sk.joints):
            g.bad(f"skin {si} names a joint node that does not exist")
        skin_base[si] = len(joint_nodes)
        joint_nodes.extend(sk.joints)
        if sk.inverseBindMatrices is None:
            ibms.append(np.tile(np.eye(4), (len(sk.joints), 1, 1)))
        else:
            m = g.accessor(sk.inverseBindMatrices, f"skin {si} inverse bind matrices")
            if m.shape != (len(sk.joints), 16):
                g.bad(f"skin {si}: {len(m)} inverse bind matrices for {len(sk.joints)} joints")
            ibms.append(m.astype(np.float64).reshape(-1, 4, 4).transpose(0, 2, 1))
    mesh_nodes = [i for i, n in enumerate(nodes) if n.mesh is not None]
    if not any(nodes[i].skin is not None for i in mesh_nodes):
        g.bad("no node draws a mesh with its skin")
    rigid_base = {}
    for i in mesh_nodes:
        if nodes[i].skin is None:
            rigid_base[i] = len(joint_nodes)
            joint_nodes.append(i)
            ibms.append(np.eye(4)[None])

    # the nodes kept: joints and their ancestors, parents before children
    keep = set()
    for j in joint_nodes:
        while j >= 0 and j not in keep:
            keep.add(j)
            j = int(parent[j])
    depth = {}
    for i in keep:
        d, p = 0, int(parent[i])
        while p >= 0:
            d, p = d + 1, int(parent[p])
        depth[i] = d
    order = sorted(keep, key=lambda i: (depth[i], i))
    new = {old: k for k, old in enumerate(order)}
    parents = [new[int(parent[i])] if parent[i] >= 0 else -1 for i in order]
    rest = [np.stack(a) for a in zip(*(_node_trs(g, i) for i in order))]

    # the clip
    anims = gl.animations or []
    names = [a.name or f"#{i}" for i, a in enumerate(anims)]
    info = {"file": path.name, "animations": names, "ignored": {}}
    channels, chosen = [], ""
    if animation is not None and not anims:
        g.bad(f"animation {animation!r} was asked for but the file has no animations")
    if anims:
        if animation is None:
            ai = 0
        elif isinstance(animation, (int, np.integer)) and not isinstance(animation, bool):
            if not 0 <= animation < len(anims):
                g.bad(f"animation index {animation} is out of range: the file has {len(anims)} "
                      f"({', '.join(map(repr, names))})")
            ai = int(animation)
        elif isinstance(animation, str) and animation in names:
            ai = names.index(animation)
        else:
            g.bad(f"no animation named {animation!r}; the file has {', '.join(map(repr, names))}")
        chosen = names[ai]
        an = anims[ai]
        for ci, ch in enumerate(an.channels or []):
            what = f"animation {chosen!r} channel {ci}"
            path_ = ch.target.path if ch.target is not None else None
            if path_ == "weights":
                info["ignored"]["morph weight channels"] = info["ignored"].get("morph weight channels", 0) + 1
                continue
            if path_ not in PATHS or ch.target.node is None:
                g.bad(f"{what}: target path {path_!r} is not translation, rotation, scale or weights")
            if ch.target.node not in new:
                continue   # it moves a node that neither a joint nor its ancestors is: it cannot move the mesh
            if not 0 <= ch.sampler < len(an.samplers or []):
                g.bad(f"{what}: sampler {ch.sampler} does not exist")
            smp = an.samplers[ch.sampler]
            interp = smp.interpolation or "LINEAR"
            if interp not in INTERPOLATIONS:
                g.bad(f"{what}: unknown interpolation {interp!r}")
            times = g.accessor(smp.input, f"{what} times").reshape(-1).astype(np.float64)
            vals = g.accessor(smp.output, f"{what} values").astype(np.float64)
            try:
                channels.append(Channel(new[ch.target.node], path_, interp, times, vals))
            except MeshError as exc:
                g.bad(f"{what}: {str(exc).split(': ', 1)[-1]}")
    rig = Rig(parents, [new[j] for j in joint_nodes], np.concatenate(ibms), rest, channels,
              name=path.name, node_names=[nodes[i].name or f"node{i}" for i in order], animation=chosen)

    # the geometry: every mesh node's primitives
    vs, ns, fs, js, ws, base = [], [], [], [], [], 0
    has_normals = True
    for ni in mesh_nodes:
        node = nodes[ni]
        if not 0 <= node.mesh < len(gl.meshes or []):
            g.bad(f"node {ni} names mesh {node.mesh}, which does not exist")
        for pi, prim in enumerate(gl.meshes[node.mesh].primitives):
            what = f"mesh {node.mesh} primitive {pi}"
            at = prim.attributes
            if at.POSITION is None:
                g.bad(f"{what} has no POSITION")
            p = g.accessor(at.POSITION, f"{what} POSITION")
            if p.shape[1] != 3:
                g.bad(f"{what} POSITION must be VEC3")
            count = len(p)
            if at.NORMAL is not None:
                n = g.accessor(at.NORMAL, f"{what} NORMAL")
                if n.shape != p.shape:
                    g.bad(f"{what} NORMAL must be VEC3 like POSITION")
            else:
                has_normals, n = False, np.zeros_like(p, np.float64)
            if prim.targets:
                info["ignored"]["morph targets"] = info["ignored"].get("morph targets", 0) + len(prim.targets)
            if node.skin is not None:
                if not 0 <= node.skin < len(gl.skins):
                    g.bad(f"node {ni} names skin {node.skin}, which does not exist")
                if at.JOINTS_0 is None or at.WEIGHTS_0 is None:
                    g.bad(f"{what} is skinned but has no JOINTS_0/WEIGHTS_0")
                j = g.accessor(at.JOINTS_0, f"{what} JOINTS_0")
                w = g.accessor(at.WEIGHTS_0, f"{what} WEIGHTS_0").astype(np.float64)
                if j.shape != (count, 4) or w.shape != (count, 4) or j.dtype.kind not in "iu":
                    g.bad(f"{what}: JOINTS_0 (integer VEC4) and WEIGHTS_0 (VEC4) must have one row per vertex")
                if getattr(at, "JOINTS_1", None) is not None:
                    info["ignored"]["JOINTS_1/WEIGHTS_1 sets"] = info["ignored"].get("JOINTS_1/WEIGHTS_1 sets", 0) + 1
                n_sj = len(gl.skins[node.skin].joints)
                if np.any((j >= n_sj) & (w > 0)):
                    g.bad(f"{what}: JOINTS_0 names joints past the {n_sj} of skin {node.skin}")
                j = np.where(w > 0, j.astype(np.int64) + skin_base[node.skin], 0)
            else:
                j = np.zeros((count, 4), np.int64)
                j[:, 0] = rigid_base[ni]
                w = np.zeros((count, 4))
                w[:, 0] = 1
            fs.append(_triangles(g, prim, count, what) + base)
            vs.append(p)
            ns.append(n)
            js.append(j)
            ws.append(w)
            base += count
    if not fs or not sum(len(f) for f in fs):
        g.bad("the skinned meshes have no triangles")
    v = np.concatenate(vs).astype(np.float32)
    if not np.isfinite(v).all():
        g.bad("POSITION holds NaN or infinite values")
    f = np.concatenate(fs)
    normals = np.concatenate(ns).astype(np.float32) if has_normals else None
    info["ignored"] = {k: v_ for k, v_ in info["ignored"].items() if v_}
    try:
        return SkinnedMesh.build(v, f, np.concatenate(js), np.concatenate(ws), rig, normals=normals,
                                 name=name or path.name, info=info)
    except MeshError as exc:
        msg = str(exc)
        raise MeshError(msg if path.name in msg else f"{g.where}: {msg}") from None


def skinned_source(source, animation=None) -> SkinnedMesh:
    """The scene's "skinned" loader: a SkinnedMesh is returned as it is; a path is loaded."""
    if isinstance(source, SkinnedMesh):
        if animation is not None:
            raise MeshError(f"skinned mesh '{source.name}': animation is chosen when the file is loaded")
        return source
    if isinstance(source, (str, Path)):
        return load_skinned(source, animation=animation)
    raise MeshError(f"a skinned mesh is a path to a glTF/GLB file or a SkinnedMesh, got {type(source).__name__}")
