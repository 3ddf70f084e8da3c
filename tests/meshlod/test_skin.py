"""Linear blend skinning on the device (paramlod.meshlod.skin, kernels/meshlod/skin.cl) against its
numpy twin (paramlod.meshlod.skin_reference): bit for bit on random rigs (non-uniform scales,
shears and mirrors included), the twin against a float64 reference, the cofactor normals against
the inverse transpose, several skinned slots in one scene, and bad input."""
from __future__ import annotations

import numpy as np
import pytest

from paramlod.core.layouts import CLUSTER
from paramlod.errors import MeshError
from paramlod.meshlod.buffers import DeviceMeshes, MeshArrays, MeshInstances, SkinArrays
from paramlod.meshlod.format import MeshLod
from paramlod.meshlod.skin import Skinning, pose_records, read_vertices
from paramlod.meshlod.skin_reference import skin, skin_records
from paramlod.meshlod.skinned import Channel, Rig, SkinnedMesh
from paramlod.scene.scene import Material, MeshObject

from helpers.meshes import sphere


def random_inputs(seed, n=3000, joints=7, shear=True):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n, 3)).astype(np.float32) * 3
    nn = rng.normal(size=(n, 3))
    nn = (nn / np.linalg.norm(nn, axis=1, keepdims=True)).astype(np.float32)
    j = rng.integers(0, joints, size=(n, 4)).astype(np.uint32)
    w = rng.random((n, 4))
    w[rng.random((n, 4)) < 0.3] = 0
    w[:, 0] += 1e-3
    w = (w / w.sum(axis=1, keepdims=True)).astype(np.float32)
    m = np.tile(np.eye(4), (joints, 1, 1))
    m[:, :3, :3] = rng.normal(size=(joints, 3, 3)) if shear else np.eye(3)
    m[:, :3, 3] = rng.normal(size=(joints, 3)) * 5
    m[0, :3, :3] = np.diag([1.0, -2.0, 0.5])   # a mirror with non-uniform scale
    return v, nn, j, w, m


def _single_slot_mesh(v, nn, j, w, m):
    """A SkinnedMesh around the arrays (its rig's skin matrices are ``m`` at every time)."""
    n_j = len(m)
    rig = Rig(parents=np.arange(n_j) * 0 - 1, joint_nodes=np.arange(n_j), inverse_bind=np.tile(np.eye(4), (n_j, 1, 1)),
              rest=(m[:, :3, 3], np.tile([0, 0, 0, 1.0], (n_j, 1)), np.ones((n_j, 3))), root=None)
    f = np.arange(len(v) - len(v) % 3, dtype=np.uint32).reshape(-1, 3)
    mesh = SkinnedMesh.build(v, f, j, w, rig, normals=nn, name="random")
    return mesh


def _device(meshes):
    arrays = MeshArrays.pack(meshes)
    objs = [MeshObject(mm, np.eye(4), Material(), k + 1) for k, mm in enumerate(meshes)]
    own = {id(o): k for k, o in enumerate(objs)}   # each object its own mesh
    instances = MeshInstances.pack(objs, lambda o: own[id(o)])
    return DeviceMeshes(arrays, instances)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_kernel_matches_twin_bit_for_bit(seed):
    v, nn, j, w, m = random_inputs(seed)
    mesh = _single_slot_mesh(v, nn, j, w, np.tile(np.eye(4), (len(m), 1, 1)))
    dev = _device([mesh])
    rec = skin_records(m)
    out_v, out_n = Skinning().pose(dev, rec)
    ref_v, ref_n = skin(mesh.vertices, mesh.normals, mesh.joints, mesh.weights, rec)
    assert out_v.view(np.uint32).tolist() == ref_v.view(np.uint32).tolist()
    assert np.array_equal(out_n.view(np.uint32), ref_n.view(np.uint32))
    # and the twin is the float64 formula to float32 accuracy
    blend = np.einsum("vk,vkij->vij", mesh.weights.astype(np.float64), m[mesh.joints])
    p64 = np.einsum("vij,vj->vi", blend[:, :3, :3], mesh.vertices.astype(np.float64)) + blend[:, :3, 3]
    scale = np.abs(blend[:, :3, :]).max(axis=(1, 2)) * (np.abs(mesh.vertices).max(axis=1) + 1)
    assert np.all(np.abs(ref_v[:, :3] - p64).max(axis=1) <= 1e-5 * scale + 1e-6)
    n64 = np.einsum("vij,vj->vi", np.transpose(np.linalg.inv(blend[:, :3, :3]), (0, 2, 1)), mesh.normals.astype(np.float64))
    n64 /= np.linalg.norm(n64, axis=1, keepdims=True)
    cond = np.linalg.cond(blend[:, :3, :3])
    ok = cond < 1e3   # a nearly singular blend loses the normal in float32, as any method would
    assert ok.mean() > 0.9
    assert np.all(np.abs(ref_n[ok, :3] - n64[ok]).max(axis=1) < 1e-3)
    assert np.all(ref_v[:, 3] == 1) and np.all(ref_n[:, 3] == 0)


def test_normals_stay_perpendicular_to_posed_surface_under_nonuniform_scale():
    """The cofactor normal is the posed surface's normal: perpendicular to the posed triangles."""
    v, f = sphere(2)
    v = v.astype(np.float32)
    m = np.eye(4)[None].copy()
    m[0, :3, :3] = [[3.0, 0.5, 0], [0, 0.4, 0], [0, 0, 1.2]]
    j = np.zeros((len(v), 4), np.uint32)
    w = np.zeros((len(v), 4), np.float32)
    w[:, 0] = 1
    nn = (v / np.linalg.norm(v, axis=1, keepdims=True)).astype(np.float32)
    pv, pn = skin(v, nn, j, w, skin_records(m))
    # exact normal of the posed ellipsoid: A^-T n
    a = m[0, :3, :3]
    want = nn @ np.linalg.inv(a)
    want /= np.linalg.norm(want, axis=1, keepdims=True)
    assert np.abs(pn[:, :3] - want).max() < 1e-5
    # the blended-matrix-only normal (no inverse transpose) is visibly wrong here
    naive = nn @ a.T
    naive /= np.linalg.norm(naive, axis=1, keepdims=True)
    assert np.abs(naive - want).max() > 0.2


def test_several_slots_and_a_static_mesh_in_one_scene():
    v, nn, j, w, m = random_inputs(5, n=600, joints=3)
    a = _single_slot_mesh(v, nn, j, w, np.tile(np.eye(4), (3, 1, 1)))
    static = MeshLod(vertices=np.ones((3, 3), np.float32), normals=np.ones((3, 3), np.float32),
                     triangles=np.array([[0, 1, 2]], np.uint32), clusters=a.clusters[:1].copy(), name="static", lod="full")
    static.clusters["first"], static.clusters["count"] = 0, 1
    dev = _device([a, static, a])   # the same skinned mesh twice: two slots with their own poses
    assert [s.index for s in dev.skin.slots] == [0, 2] and dev.skin.n_joints == 6
    m2 = m.copy()
    m2[:, :3, 3] += 10
    rec = np.concatenate([skin_records(m), skin_records(m2)])
    out_v, out_n = Skinning().pose(dev, rec)
    r1 = skin(a.vertices, a.normals, a.joints, a.weights, skin_records(m))
    r2 = skin(a.vertices, a.normals, a.joints, a.weights, skin_records(m2))
    n = len(a.vertices)
    assert np.array_equal(out_v[:n], r1[0]) and np.array_equal(out_n[:n], r1[1])
    assert np.array_equal(out_v[n + 3:], r2[0]) and np.array_equal(out_n[n + 3:], r2[1])
    # the static mesh's vertices are left as they were packed
    assert np.array_equal(out_v[n:n + 3], dev.arrays.vertices[n:n + 3])
    sub_v, _ = read_vertices(dev, n + 3, n)
    assert np.array_equal(sub_v, r2[0])


def test_pose_records_follow_each_slots_time():
    rig = Rig(parents=[-1], joint_nodes=[0], inverse_bind=np.eye(4)[None], rest=([[0, 0, 0]], [[0, 0, 0, 1]], [[1, 1, 1]]),
              channels=[Channel(0, "translation", "LINEAR", [0, 1], [[0, 0, 0], [2, 0, 0]])])
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    mesh = SkinnedMesh.build(v, [[0, 1, 2]], np.zeros((3, 4), np.uint32), np.tile([1, 0, 0, 0.0], (3, 1)), rig)
    dev = _device([mesh, mesh])
    rec = pose_records(dev, [0.25, 1.0])
    assert rec.shape == (2, 4, 4) and rec[0, 0, 3] == np.float32(0.5) and rec[1, 0, 3] == 2
    with pytest.raises(MeshError, match="1 times given for 2 skinned objects"):
        pose_records(dev, [0.0])


def test_bad_records():
    with pytest.raises(MeshError, match="within float32"):
        skin_records(np.full((1, 4, 4), 1e39))
    with pytest.raises(MeshError, match=r"\[J, 4, 4\]"):
        skin_records(np.zeros((2, 3, 4)))
    v, nn, j, w, m = random_inputs(7, n=30, joints=2)
    dev = _device([_single_slot_mesh(v, nn, j, w, m)])
    with pytest.raises(MeshError, match="for the scene's 2 joints"):
        Skinning().enqueue(dev, np.zeros((3, 4, 4), np.float32))


def test_no_skinned_mesh_means_no_skin_arrays():
    static = MeshLod(vertices=np.eye(3, dtype=np.float32), normals=np.eye(3, dtype=np.float32),
                     triangles=np.array([[0, 1, 2]], np.uint32), clusters=np.zeros(1, CLUSTER.dtype), lod="full")
    sk = SkinArrays.pack(MeshArrays.pack([static]))
    assert sk.slots == [] and sk.n_joints == 0 and sk.nbytes == 0
