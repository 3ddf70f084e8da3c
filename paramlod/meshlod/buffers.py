"""The meshes and mesh instances of a scene packed for the device: what the cut, the raster and
the OpenGL draw read.

``MeshArrays`` concatenates the MeshLods of a scene (each once, however many objects use it):
  vertices  float32 [V, 4]   xyz, w = 1
  normals   float32 [V, 4]   xyz, w = 0
  triangles uint32  [T, 3]   indices into the concatenated vertices
  clusters  CLUSTER [C]      ``first`` into the concatenated triangles
  ranges    uint32  [M, 2]   mesh m's clusters are [ranges[m, 0], ranges[m, 0] + ranges[m, 1])
``MeshInstances`` holds one record per drawn copy, in the instance layouts of the parametric
objects (paramlod.core.layouts INSTANCE_F: model, normal matrix, domain unused; INSTANCE_U: func =
the mesh's index in MeshArrays, params = 0, object id, flags: SIMILAR when the model's 3x3 part is
a rotation times a uniform scale, so that backface cones stay valid, MIRRORED when its determinant
is negative, ONE_SIDED when its object's material has ``two_sided`` False: only such instances may
lose clusters to the backface cone), its material (MATERIAL), and
for each instance the largest scale of its model matrix (``scales``: errors and spheres grow by it).
``batches`` lists (mesh index, first instance, instance count): instances of one mesh are
contiguous, so the cut runs once per batch over (its mesh's clusters) x (its instances).
``handoffs`` lists (instance index, SurfelObject) for the meshes that take over from a surfel
object (paramlod.scene.handoff); ``weights(camera)`` gives every instance's share of its pixels
for a frame (1 without a hand-off), which ``DeviceMeshes.set_weights`` sends to the device.

Skinned meshes (paramlod.meshlod.skinned.SkinnedMesh) are packed like the others, their bind pose
as the vertices; ``SkinArrays`` adds what the skinning kernel (paramlod.meshlod.skin) reads: the
bind pose again (the vertex buffers are overwritten by each frame's pose), joints offset into the
scene's concatenated skin matrices, weights, and one ``SkinSlot`` per skinned mesh. The device's
vertex and normal buffers are then writable.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field, replace

import numpy as np

import pyopencl as cl

from paramlod.core.layouts import CLUSTER, INSTANCE_F, INSTANCE_U, MATERIAL
from paramlod.device.context import cl_device
from paramlod.errors import MeshError, SceneError
from paramlod.meshlod.skinned import SkinnedMesh
from paramlod.scene.handoff import mesh_weight

SIMILAR, MIRRORED, ONE_SIDED = 1, 2, 4   # MeshInstances.inst_u flags


@dataclass
class MeshArrays:
    vertices: np.ndarray
    normals: np.ndarray
    triangles: np.ndarray
    clusters: np.ndarray
    ranges: np.ndarray
    meshes: list            # the MeshLods, in index order

    @classmethod
    def pack(cls, meshes) -> "MeshArrays":
        meshes = list(meshes)
        vb = tb = cb = 0
        vs, ns, ts, cs, ranges = [], [], [], [], []
        for m in meshes:
            v = np.ones((len(m.vertices), 4), np.float32)
            v[:, :3] = m.vertices
            n = np.zeros((len(m.normals), 4), np.float32)
            n[:, :3] = m.normals
            c = m.clusters.copy()
            c["first"] += tb
            vs.append(v)
            ns.append(n)
            ts.append(m.triangles.astype(np.uint32) + np.uint32(vb))
            cs.append(c)
            ranges.append((cb, len(c)))
            vb += len(v)
            tb += len(m.triangles)
            cb += len(c)
        if vb >= 2 ** 32 or tb >= 2 ** 32 // 3:
            raise SceneError(f"the scene's meshes hold {vb} vertices and {tb} triangles; at most 2^32 vertex "
                             "indices fit the device's index buffer")
        empty = [np.zeros((0, 4), np.float32)]
        return cls(np.concatenate(vs or empty), np.concatenate(ns or empty),
                   np.concatenate(ts or [np.zeros((0, 3), np.uint32)]),
                   np.concatenate(cs or [np.zeros(0, CLUSTER.dtype)]),
                   np.asarray(ranges, np.uint32).reshape(-1, 2), meshes)

    @property
    def nbytes(self) -> int:
        return int(self.vertices.nbytes + self.normals.nbytes + self.triangles.nbytes + self.clusters.nbytes)


@dataclass
class MeshInstances:
    inst_f: np.ndarray      # float32 [n, INSTANCE_F.length]
    inst_u: np.ndarray      # uint32 [n, INSTANCE_U.length]
    materials: np.ndarray   # float32 [n, MATERIAL.length]
    scales: np.ndarray      # float32 [n]: largest singular value of each model's 3x3 part
    batches: list           # (mesh index, first instance, count)
    handoffs: list = field(default_factory=list)   # (instance, SurfelObject) of hand-off meshes

    @classmethod
    def pack(cls, objects, mesh_index) -> "MeshInstances":
        """``objects``: MeshObjects (paramlod.scene.scene); ``mesh_index(object) -> int``: the index in
        MeshArrays of the object's mesh (a skinned object's is its own copy, not its mesh's)."""
        fs, us, ms, ss, batches, handoffs, at = [], [], [], [], [], [], 0
        for o in objects:
            mi = mesh_index(o)
            if getattr(o, "handoff", None) is not None:
                handoffs.append((at, o.handoff))
            models = np.broadcast_to(o.transform, (o.count, 4, 4)) if o.transforms is None else o.transform @ o.transforms
            models = np.asarray(models, np.float64)
            lin = models[:, :3, :3]
            if np.any(np.abs(np.linalg.det(lin)) < 1e-20):
                raise SceneError(f"mesh '{o.mesh.name}': an instance transform is singular")
            n = len(models)
            f = np.zeros((n, INSTANCE_F.length), np.float32)
            f[:, INSTANCE_F.slice("model")] = models.reshape(n, 16)
            nrm = np.transpose(np.linalg.inv(lin), (0, 2, 1))
            f[:, INSTANCE_F.slice("normal")] = np.concatenate([nrm, np.zeros((n, 3, 1))], axis=2).reshape(n, 12)
            u = np.zeros((n, INSTANCE_U.length), np.uint32)
            u[:, INSTANCE_U.offset("func")] = mi
            u[:, INSTANCE_U.offset("object")] = o.object_id
            sv = np.linalg.svd(lin, compute_uv=False)
            u[:, INSTANCE_U.offset("flags")] = (np.where(sv[:, 2] >= sv[:, 0] * (1 - 1e-4), SIMILAR, 0)
                                                | np.where(np.linalg.det(lin) < 0, MIRRORED, 0)
                                                | (0 if o.material.two_sided else ONE_SIDED))
            mat = np.tile(np.array([*o.material.color, o.material.specular], np.float32), (n, 1))
            if o.colors is not None:
                mat[:, :3] = o.colors
            fs.append(f)
            us.append(u)
            ms.append(mat)
            ss.append(sv[:, 0].astype(np.float32))
            batches.append((mi, at, n))
            at += n
        return cls(np.concatenate(fs or [np.zeros((0, INSTANCE_F.length), np.float32)]),
                   np.concatenate(us or [np.zeros((0, INSTANCE_U.length), np.uint32)]),
                   np.concatenate(ms or [np.zeros((0, MATERIAL.length), np.float32)]),
                   np.concatenate(ss or [np.zeros(0, np.float32)]), batches, handoffs)

    def __len__(self) -> int:
        return len(self.inst_f)

    def weights(self, camera) -> np.ndarray:
        """float32 [n]: each instance's share of its pixels for ``camera`` (the camera of the pass
        it is drawn in): paramlod.scene.handoff.mesh_weight of its surfel object, 1 without one."""
        w = np.ones(len(self), np.float32)
        for i, so in self.handoffs:
            w[i] = mesh_weight(camera, so)
        return w


@dataclass
class SkinSlot:
    """One skinned mesh of a MeshArrays: mesh ``index``, its vertices [dst_first, dst_first + count)
    of the packed vertices, its bind pose at src_first in SkinArrays, its joints at joint_first."""
    mesh: SkinnedMesh
    index: int
    dst_first: int
    src_first: int
    count: int
    joint_first: int
    n_joints: int


@dataclass
class SkinArrays:
    bind_v: np.ndarray    # float32 [Vs, 4] bind-pose positions (w = 1)
    bind_n: np.ndarray    # float32 [Vs, 4] bind-pose normals (w = 0)
    joints: np.ndarray    # uint32 [Vs, 4] into the concatenated skin matrices
    weights: np.ndarray   # float32 [Vs, 4]
    slots: list           # SkinSlot per skinned mesh, in mesh order
    n_joints: int

    @classmethod
    def pack(cls, arrays: MeshArrays) -> "SkinArrays":
        vs, ns, js, ws, slots = [], [], [], [], []
        dst = src = jb = 0
        for i, m in enumerate(arrays.meshes):
            if isinstance(m, SkinnedMesh):
                n = len(m.vertices)
                vs.append(arrays.vertices[dst:dst + n])
                ns.append(arrays.normals[dst:dst + n])
                js.append(m.joints.astype(np.uint32) + np.uint32(jb))
                ws.append(m.weights.astype(np.float32))
                nj = len(m.rig.joint_nodes)
                slots.append(SkinSlot(m, i, dst, src, n, jb, nj))
                src += n
                jb += nj
            dst += len(m.vertices)
        if not slots:
            z4 = np.zeros((0, 4), np.float32)
            return cls(z4, z4, np.zeros((0, 4), np.uint32), z4, [], 0)
        return cls(np.concatenate(vs), np.concatenate(ns), np.concatenate(js), np.concatenate(ws), slots, jb)

    @property
    def mesh_indices(self) -> set:
        return {s.index for s in self.slots}

    @property
    def nbytes(self) -> int:
        return int(self.bind_v.nbytes + self.bind_n.nbytes + self.joints.nbytes + self.weights.nbytes
                   + self.n_joints * 64)


class DeviceMeshes:
    """Device copies of a MeshArrays and a MeshInstances (OpenCL buffers, read-only)."""

    def __init__(self, arrays: MeshArrays, instances: MeshInstances):
        ctx = cl_device().context
        mf = cl.mem_flags

        def up(a):
            a = np.ascontiguousarray(a)
            return cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=a if a.nbytes else np.zeros(4, np.uint32))

        self.arrays, self.instances = arrays, instances
        self.skin = SkinArrays.pack(arrays)
        if self.skin.slots:   # the skinning kernel writes each frame's pose into them
            self.vertices = cl.Buffer(ctx, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(arrays.vertices))
            self.normals = cl.Buffer(ctx, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(arrays.normals))
        else:
            self.vertices, self.normals = up(arrays.vertices), up(arrays.normals)
        sk = self.skin
        self.bind_v, self.bind_n = up(sk.bind_v), up(sk.bind_n)
        self.joints, self.joint_weights = up(sk.joints), up(sk.weights)
        self.skin_matrices = cl.Buffer(ctx, mf.READ_ONLY, max(sk.n_joints, 1) * 64)
        self.triangles, self.clusters = up(arrays.triangles), up(arrays.clusters)
        self.inst_f, self.inst_u = up(instances.inst_f), up(instances.inst_u)
        self.materials, self.scales = up(instances.materials), up(instances.scales)
        # per-instance hand-off weights (all 1 until set_weights; only scenes with hand-offs change them)
        self._weights_host = np.ones(max(len(instances), 1), np.float32)
        self.weights = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=self._weights_host)

    def set_weights(self, weights) -> None:
        """Enqueue the upload of the instances' hand-off weights (float [n] in [0, 1]) without
        waiting: the queue is in order, so this frame's cut and raster read them. Nothing is sent
        when they equal the last ones sent."""
        w = np.ascontiguousarray(weights, np.float32).reshape(-1)
        if len(w) != len(self.instances):
            raise MeshError(f"hand-off weights: {len(w)} given for {len(self.instances)} mesh instances")
        if not np.all((w >= 0) & (w <= 1)):
            raise MeshError("hand-off weights must be in [0, 1] (the mesh's share of its pixels)")
        if not len(w) or np.array_equal(w, self._weights_host[:len(w)]):
            return
        # a new host array each time: the previous one may still be in flight
        self._weights_host = w.copy()
        cl.enqueue_copy(cl_device().queue, self.weights, self._weights_host, is_blocking=False)

    def only(self, skinned: bool) -> "DeviceMeshes":
        """A view of these buffers whose instances keep only the batches of skinned meshes
        (``skinned``) or of the others, for the cut that suits them (no copy of device data)."""
        idx = self.skin.mesh_indices
        view = copy.copy(self)
        view.instances = replace(self.instances, batches=[b for b in self.instances.batches
                                                          if (b[0] in idx) == bool(skinned)])
        return view

    @property
    def nbytes(self) -> int:
        i = self.instances
        return self.arrays.nbytes + self.skin.nbytes + int(i.inst_f.nbytes + i.inst_u.nbytes + i.materials.nbytes + i.scales.nbytes
                                        + self._weights_host.nbytes)
