"""The skinned meshlet cull (paramlod.meshlod.skin_cull, kernels/meshlod/skin_cull.cl) against its
numpy twin (paramlod.meshlod.skin_cull_reference): (c) the same pairs and counters bit for bit on
PoCL for random cameras (perspective and orthographic), poses, instances (non-uniform, mirrored) and
every culling mode; (d) no meshlet with a triangle inside the frustum or facing the eye at the
frame's pose is culled (float64, at times between keyframes); the classes' rules; bad input."""
from __future__ import annotations

import math

import numpy as np
import pyopencl as cl
import pytest

from paramlod.core.camera import Camera
from paramlod.core.layouts import INSTANCE_F
from paramlod.device.context import cl_device
from paramlod.errors import MeshError
from paramlod.meshlod.buffers import DeviceMeshes, MeshArrays, MeshInstances
from paramlod.meshlod.build.skin_bounds import SkinBoundsSettings, skin_bounds
from paramlod.meshlod.cut import Selection
from paramlod.meshlod.cut_reference import COUNTERS, cut_camera
from paramlod.meshlod.skin import pose_records
from paramlod.meshlod.skin_cull import SkinCull
from paramlod.meshlod.skin_cull_reference import rows_point3, scale_bound, select
from paramlod.meshlod.skin_reference import skin, skin_records
from paramlod.scene.scene import Material, MeshObject
from paramlod.surfels.build.views import OrthoCamera

from test_skin_bounds import random_rig_mesh


def _models(rng, n, spread):
    out = np.tile(np.eye(4), (n, 1, 1))
    for i in range(n):
        a = rng.normal(size=3)
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        s = rng.uniform(0.5, 2.0, 3) if i % 2 else np.full(3, rng.uniform(0.5, 2.0))
        if i == 2:
            s[0] = -s[0]   # a mirror
        out[i, :3, :3] = q @ np.diag(s)
        out[i, :3, 3] = a * spread
    return out


@pytest.fixture(scope="module")
def scene():
    gentle = random_rig_mesh(1, bones=4, keys=3, nx=48, ny=8, max_angle=math.radians(10), amp=0.05, name="gentle")
    wild = random_rig_mesh(4, bones=3, keys=3, nx=40, ny=8, max_angle=math.radians(120), amp=0.5, name="wild")
    meshes = [gentle, wild]
    bounds = [skin_bounds(gentle, SkinBoundsSettings(max_radius_scale=50.0, max_cone_angle_deg=89.0), progress=False),
              skin_bounds(wild, SkinBoundsSettings(max_radius_scale=1.45), progress=False)]
    rng = np.random.default_rng(0)
    # a one-sided object (backface tests) and a two-sided one (frustum tests only)
    objs = [MeshObject(gentle, np.eye(4), Material(two_sided=False), 1, count=4, transforms=_models(rng, 4, 3.0)),
            MeshObject(wild, np.eye(4), Material(), 2, count=2, transforms=_models(rng, 2, 3.0))]
    own = {id(o): k for k, o in enumerate(objs)}   # each object its own mesh
    instances = MeshInstances.pack(objs, lambda o: own[id(o)])
    dev = DeviceMeshes(MeshArrays.pack(meshes), instances)
    classes = np.concatenate([b.classes for b in bounds])
    assert set(classes.tolist()) == {0, 1, 2}, "the scene should hold every class"
    return dev, bounds, SkinCull(dev, bounds)


def _camera(rng, ortho=False):
    d = rng.normal(size=3)
    eye = d / np.linalg.norm(d) * rng.uniform(2.0, 12.0)
    size = (int(rng.integers(64, 161)), int(rng.integers(48, 121)))
    view = Camera.look_at(eye, rng.uniform(-2, 2, 3), size=size).view
    near = float(rng.uniform(0.05, 0.5))
    if ortho:
        return OrthoCamera(view, size, float(rng.uniform(1.0, 6.0)), near, 200.0)
    return Camera(view, float(rng.uniform(20, 90)), size, near, 200.0)


def _upload(dev, records):
    cl.enqueue_copy(cl_device().queue, dev.skin_matrices, np.ascontiguousarray(records, np.float32), is_blocking=True)


def _slots(dev):
    return [(s.index, int(dev.arrays.ranges[s.index][0]), s.joint_first) for s in dev.skin.slots]


def _times(rng, dev):
    return [float(rng.uniform(s.mesh.rig.start - 0.2, s.mesh.rig.end + 0.2)) for s in dev.skin.slots]


# --- (c) kernel = twin ---------------------------------------------------------------------------
def test_kernel_matches_twin_bit_for_bit(scene):
    dev, bounds, cull = scene
    rng = np.random.default_rng(1)
    sel = Selection(capacity=8)   # grows along the way
    totals = dict.fromkeys(COUNTERS, 0)
    for trial in range(24):
        cam = _camera(rng, ortho=trial % 4 == 3)
        rec = pose_records(dev, _times(rng, dev))
        _upload(dev, rec)
        fr, bf = [(True, True), (True, False), (False, True), (False, False)][trial % 4 if trial < 8 else 0]
        pairs, counts = cull.select(dev.skin_matrices, cam, sel, cull_frustum=fr, cull_backface=bf)
        rp, rc = select(bounds, _slots(dev), dev.instances, rec, cam, cull_frustum=fr, cull_backface=bf)
        assert counts == rc, (trial, counts, rc)
        assert np.array_equal(pairs, rp), trial
        for k in COUNTERS:
            totals[k] += counts[k]
    n_pairs = sum(len(b.classes) * n for b, (_m, _i, n) in zip(bounds, dev.instances.batches))
    assert totals["tests"] == 24 * n_pairs
    assert totals["culled_frustum"] > 0 and totals["culled_backface"] > 0 and totals["selected"] > 0, totals


def test_hand_off_weight_zero_selects_nothing(scene):
    dev, bounds, cull = scene
    rec = pose_records(dev, [0.0, 0.0])
    _upload(dev, rec)
    w = np.ones(len(dev.instances), np.float32)
    w[0] = 0
    dev.set_weights(w)
    try:
        cam = Camera.look_at((0, 0, 8), (1, 0, 0), size=(64, 48))
        pairs, counts = cull.select(dev.skin_matrices, cam)
        rp, rc = select(bounds, _slots(dev), dev.instances, rec, cam, weights=w)
        assert counts == rc and np.array_equal(pairs, rp)
        assert not np.any(pairs[:, 0] == 0)
    finally:
        dev.set_weights(np.ones(len(dev.instances), np.float32))


# --- (d) never culls what shows --------------------------------------------------------------------
def test_culled_meshlets_show_nothing(scene):
    dev, bounds, cull = scene
    rng = np.random.default_rng(2)
    inst = dev.instances
    models = inst.inst_f[:, INSTANCE_F.slice("model")].astype(np.float64).reshape(-1, 4, 4)
    checked = {"frustum": 0, "backface": 0}
    for trial in range(30):
        cam = _camera(rng, ortho=trial % 3 == 2)
        times = _times(rng, dev)
        rec = pose_records(dev, times)
        # what the full selection (no culling) draws, less what the cull keeps = what it culled
        allp, _ = select(bounds, _slots(dev), inst, rec, cam, cull_frustum=False, cull_backface=False)
        keep, _ = select(bounds, _slots(dev), inst, rec, cam)
        kept = {tuple(p) for p in keep.tolist()}
        culled = [tuple(p) for p in allp.tolist() if tuple(p) not in kept]
        cc = cut_camera(cam, 0.0).astype(np.float64)
        planes = cc[:24].reshape(6, 4)
        eye = cc[28:32]
        posed = {s.index: s.mesh.posed(t)[0] for s, t in zip(dev.skin.slots, times)}
        for i, c in culled:
            mesh_i = next(m for m, i0, n in inst.batches if i0 <= i < i0 + n)
            slot = next(s for s in dev.skin.slots if s.index == mesh_i)
            c_local = c - int(dev.arrays.ranges[mesh_i][0])
            cl_ = slot.mesh.clusters[c_local]
            tri = slot.mesh.triangles[cl_["first"]:cl_["first"] + cl_["count"]].astype(int)
            p = posed[mesh_i][tri]                                            # [t, 3, 3] mesh space
            M = models[i]
            w = p @ M[:3, :3].T + M[:3, 3]
            dist = w @ planes[:, :3].T + planes[:, 3]                         # [t, 3, 6]
            outside_one = np.any(np.all(dist < 0, axis=(0, 1)))
            if outside_one:
                checked["frustum"] += 1
                continue
            # else the backface test culled it: every triangle faces away (mesh space, as the cut)
            Minv = np.linalg.inv(M)
            e = Minv @ eye
            n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 1])
            to_eye = (e[:3] - p[:, 0] * e[3])
            facing = (n * to_eye).sum(axis=1)
            assert np.all(facing < 0), f"trial {trial}: instance {i} meshlet {c} culled with a front-facing triangle"
            checked["backface"] += 1
    assert checked["frustum"] > 0 and checked["backface"] > 0, checked


def test_classes_decide_the_tests(scene):
    """Class 2 is never culled, class 1 never by the cone; with both tests off all are drawn."""
    dev, bounds, cull = scene
    rng = np.random.default_rng(3)
    classes = np.concatenate([b.classes for b in bounds])
    c0 = np.concatenate([[int(dev.arrays.ranges[s.index][0])] * len(b.classes) for s, b in zip(dev.skin.slots, bounds)])
    for trial in range(10):
        cam = _camera(rng)
        rec = pose_records(dev, _times(rng, dev))
        allp, ca = select(bounds, _slots(dev), dev.instances, rec, cam, cull_frustum=False, cull_backface=False)
        assert ca["culled_frustum"] == ca["culled_backface"] == 0 and ca["selected"] == ca["tests"]
        bfp, _ = select(bounds, _slots(dev), dev.instances, rec, cam, cull_frustum=False)
        keep = {tuple(p) for p in bfp.tolist()}
        for i, c in allp.tolist():
            k = np.searchsorted(np.unique(c0), c, side="right") - 1
            local = c - np.unique(c0)[k]
            cls = bounds[k].classes[local]
            if cls != 0:
                assert (i, c) in keep
    # the full classes vector is what the records carry
    assert len(classes) == len(dev.arrays.clusters)


# --- bad input -----------------------------------------------------------------------------------
def test_bad_input(scene):
    dev, bounds, cull = scene
    with pytest.raises(MeshError, match="2 skinned meshes"):
        SkinCull(dev, bounds[:1])
    with pytest.raises(MeshError, match="meshlets but its bounds"):
        SkinCull(dev, bounds[::-1])
    with pytest.raises(MeshError, match="device buffer"):
        cull.enqueue(np.zeros((4, 4, 4), np.float32), Camera.look_at((0, 0, 5), (0, 0, 0)), Selection())
    with pytest.raises(MeshError, match="capacity"):
        cull.enqueue(dev.skin_matrices, Camera.look_at((0, 0, 5), (0, 0, 0)), Selection().pairs)


def test_float32_skinning_stays_in_the_float32_spheres(scene):
    """The device's float32 skinning (its twin, paramlod.meshlod.skin_reference) against the cull's
    float32 sphere (centre J c, radius (r s_r) ||J||), at many times: the float32 slack of the
    bounds covers both roundings."""
    dev, bounds, _ = scene
    rng = np.random.default_rng(5)
    for s, b in zip(dev.skin.slots, bounds):
        mesh = s.mesh
        first, count = mesh.clusters["first"].astype(int), mesh.clusters["count"].astype(int)
        verts = [np.unique(mesh.triangles[f:f + c]) for f, c in zip(first, count)]
        for t in rng.uniform(mesh.rig.start, mesh.rig.end, 25):
            rec = skin_records(mesh.rig.skin_matrices(float(t)))
            pos, _ = skin(mesh.vertices, mesh.normals, mesh.joints, mesh.weights, rec)
            J = rec.reshape(-1, 16)[b.principal.astype(int)]
            S = b.sphere
            c = np.stack(rows_point3(J, [S[:, 0], S[:, 1], S[:, 2]]), 1)
            R = (S[:, 3] * np.float32(b.radius_scale)) * scale_bound(J)
            for m in np.nonzero(b.classes < 2)[0]:
                d = np.linalg.norm(pos[verts[m], :3].astype(np.float64) - c[m].astype(np.float64), axis=1)
                assert d.max() <= float(R[m]), (mesh.name, t, m, d.max(), R[m])
