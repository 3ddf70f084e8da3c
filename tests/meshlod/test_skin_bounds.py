"""The offline bounds of skinned meshlets (paramlod.meshlod.build.skin_bounds) against posed meshes:
(a) conservativeness on random small rigs (chains of 2-5 bones, LINEAR/STEP keyframes with large
rotations, scales and translations, random weights; CUBICSPLINE clips too): at sampled times of
every interval every skinned vertex is in its meshlet's box and in the sphere moved by the principal
joint and scaled by s_r, and every triangle normal of a class-0 meshlet is within alpha_max of the
reference normal (in the principal joint's space, where the cull tests it); (b) bounds made only
from the keyframe poses miss the extreme of a 170-degree rotation, ours do not; (e) the adaptive
subdivision tightens s_r and stops by budget, target or depth (never judged by wall-clock speed);
the settings and bad input.

``random_rig_mesh`` is also used by tests/meshlod/test_skin_cull.py."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from paramlod.errors import MeshError
from paramlod.meshlod.build.skin_bounds import (NO_CONE, SkinBounds, SkinBoundsSettings, interval_boxes,
                                                skin_bounds)
from paramlod.meshlod.skinned import Channel, Rig, SkinnedMesh, trs_matrix


# --- random rigs ---------------------------------------------------------------------------------
def _quat(axis, angle):
    axis = np.asarray(axis, float)
    axis = axis / np.linalg.norm(axis)
    return np.append(axis * math.sin(angle / 2), math.cos(angle / 2))


def random_rig_mesh(seed: int, bones: int = 3, interp=("LINEAR", "STEP"), keys: int = 3, nx: int = 24, ny: int = 6,
                    max_angle: float = math.radians(170), amp: float = 1.0, name: str = "random rig") -> SkinnedMesh:
    """A wavy sheet along a chain of ``bones`` bones (each 1 long on x), weighted smoothly to the
    nearest bones plus random extra weights, animated by random channels (rotations up to
    ``max_angle`` between keys about random axes, scales 0.5..2 per axis and translations +-0.5 at
    ``amp`` = 1; ``amp`` < 1 shrinks the scales' and translations' ranges toward the rest pose)."""
    rng = np.random.default_rng(seed)
    length = float(bones)
    T = np.zeros((bones, 3))
    T[1:, 0] = 1.0
    Q = np.array([_quat(rng.normal(size=3), rng.uniform(-0.3, 0.3)) for _ in range(bones)])
    S = np.ones((bones, 3))
    parents = np.arange(bones) - 1
    rest = trs_matrix(T, Q, S)
    glob = np.empty_like(rest)
    for i in range(bones):
        glob[i] = rest[i] if i == 0 else glob[i - 1] @ rest[i]
    ib = np.linalg.inv(glob)
    # vertices: a sheet in the chain's rest frame (along the bones' x axes)
    xs, ys = np.meshgrid(np.linspace(0, length, nx), np.linspace(-0.4, 0.4, ny), indexing="ij")
    zs = 0.1 * np.sin(3 * xs) * np.cos(4 * ys)
    local = np.stack([xs.ravel(), ys.ravel(), zs.ravel()], 1)
    bone_of = np.minimum((local[:, 0]).astype(int), bones - 1)
    v = np.einsum("nij,nj->ni", glob[bone_of, :3, :3], local - np.c_[bone_of, 0 * bone_of, 0 * bone_of]) \
        + glob[bone_of, :3, 3]
    tris = []
    for i in range(nx - 1):
        for j in range(ny - 1):
            a, b, c, d = i * ny + j, (i + 1) * ny + j, (i + 1) * ny + j + 1, i * ny + j + 1
            tris += [[a, b, c], [a, c, d]]
    V = len(v)
    joints = np.zeros((V, 4), np.int64)
    w = np.zeros((V, 4))
    f = local[:, 0] - bone_of
    joints[:, 0] = bone_of
    joints[:, 1] = np.minimum(bone_of + 1, bones - 1)
    w[:, 0], w[:, 1] = 1 - 0.5 * f, 0.5 * f
    extra = rng.random(V) < 0.3
    joints[extra, 2] = rng.integers(0, bones, extra.sum())
    w[extra, 2] = rng.random(extra.sum()) * 0.5
    channels = []
    times = np.sort(rng.choice(np.arange(1, 40), keys - 1, replace=False)) / 10.0
    times = np.r_[0.0, times]
    for node in range(bones):
        for path in ("rotation", "translation", "scale"):
            if rng.random() < 0.35:
                continue
            kind = str(rng.choice(list(interp)))
            if path == "rotation":
                qs = [Q[node]]
                for _ in range(keys - 1):
                    qs.append(_quat_mul(qs[-1], _quat(rng.normal(size=3), rng.uniform(-max_angle, max_angle))))
                vals = np.array(qs)
            elif path == "translation":
                vals = T[node] + amp * rng.uniform(-0.5, 0.5, (keys, 3))
            else:
                vals = np.exp(amp * rng.uniform(math.log(0.5), math.log(2.0), (keys, 3)))
            if kind == "CUBICSPLINE":
                tan = rng.normal(size=(keys, 2, vals.shape[1])) * (0.5 if path == "rotation" else 0.3)
                vals = np.stack([tan[:, 0], vals, tan[:, 1]], axis=1)
            channels.append(Channel(node=node, path=path, interpolation=kind, times=times, values=vals))
    rig = Rig(parents=parents, joint_nodes=np.arange(bones), inverse_bind=ib, rest=(T, Q, S), channels=channels,
              name=name)
    return SkinnedMesh.build(v.astype(np.float32), np.array(tris), joints, w, rig, name=name)


def _quat_mul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz])


def _pbs(mesh: SkinnedMesh, principal, t):
    """(posed float64 [V, 3], principal skin matrices [C, 4, 4], PBS position of vertex v for meshlet m)."""
    p, _ = mesh.posed(t)
    m = mesh.rig.skin_matrices(t)[principal]
    return p, m


def _sample_times(rng, ta, tb, n=6):
    if tb <= ta:
        return [ta]
    return [ta] + list(ta + (tb - ta) * rng.random(n) * (1 - 1e-9))


def check_conservative(mesh: SkinnedMesh, b: SkinBounds, rng, per_interval: int = 6) -> int:
    """Asserts the three claims at sampled times of every interval; returns the checks made."""
    first, count = mesh.clusters["first"].astype(int), mesh.clusters["count"].astype(int)
    tri_m = np.repeat(np.arange(len(first)), count)
    tri = mesh.triangles[np.concatenate([np.arange(f, f + c) for f, c in zip(first, count)])].astype(int)
    bounded = b.classes < 2
    coned = b.classes == 0
    checks = 0
    iv = b.intervals
    for ta, tb in zip(iv[:-1], iv[1:]):
        lo, hi, principal, mv_m, mv_v, _, _ = interval_boxes(mesh, ta, tb)
        assert np.array_equal(principal, b.principal)
        for t in _sample_times(rng, ta, tb, per_interval):
            p, M = _pbs(mesh, b.principal, t)
            inv = np.linalg.inv(M)
            # box: the vertex in its meshlet's principal joint space
            q = np.einsum("nij,nj->ni", inv[mv_m, :3, :3], p[mv_v]) + inv[mv_m, :3, 3]
            # float32 weights sum to 1 +- a few ulps: the point moves by (1 - W) M_p^-1(0), which the
            # box (made for weights summing to 1) leaves to the sphere's float32 slack
            W = mesh.weights.astype(np.float64).sum(axis=1)[mv_v]
            z = np.linalg.norm(inv[mv_m, :3, 3], axis=1)
            scale = (1e-9 * (1 + np.abs(q).max()) + 2 * np.abs(1 - W) * z)[:, None]
            finite = np.isfinite(lo[mv_m]).all(axis=1) & np.isfinite(hi[mv_m]).all(axis=1)
            inside = np.all((q >= lo[mv_m] - scale) & (q <= hi[mv_m] + scale), axis=1)
            assert np.all(inside | ~finite), f"t={t}: vertex outside its meshlet's box"
            assert np.all(finite[bounded[mv_m]]), "a meshlet of class 0/1 has an unbounded box"
            # sphere: world-space (mesh space) test the cull makes, in float64
            c = np.einsum("nij,nj->ni", M[:, :3, :3], b.sphere[:, :3].astype(float)) + M[:, :3, 3]
            sigma = np.linalg.svd(M[:, :3, :3], compute_uv=False)[:, 0]
            R = b.sphere[:, 3].astype(float) * b.radius_scale * sigma
            d = np.linalg.norm(p[mv_v] - c[mv_m], axis=1)
            assert np.all((d <= R[mv_m] * (1 + 1e-12)) | ~bounded[mv_m]), f"t={t}: vertex outside the moved sphere"
            # cone: triangle normals in PBS within alpha_max of the reference normal
            if coned.any():
                qt = np.einsum("tij,tkj->tki", inv[tri_m, :3, :3], p[tri]) + inv[tri_m, None, :3, 3]
                n = np.cross(qt[:, 1] - qt[:, 0], qt[:, 2] - qt[:, 1])
                ln = np.linalg.norm(n, axis=1)
                cosang = (n * b.cone[tri_m, :3]).sum(axis=1) / np.maximum(ln, 1e-300)
                ok = cosang >= b.cone[tri_m, 3].astype(float) - 1e-9
                assert np.all((ok & (ln > 0)) | ~coned[tri_m]), f"t={t}: a normal leaves its cone"
            checks += 1
    return checks


# --- (a) conservativeness -----------------------------------------------------------------------
@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2 ** 31 - 1), bones=st.integers(2, 5), keys=st.integers(2, 4),
       depth=st.integers(0, 2), angle=st.sampled_from([10, 60, 170]), amp=st.sampled_from([0.05, 0.3, 1.0]))
def test_bounds_hold_at_sampled_times_linear_step(seed, bones, keys, depth, angle, amp):
    mesh = random_rig_mesh(seed, bones=bones, keys=keys, nx=40, ny=8, max_angle=math.radians(angle), amp=amp)
    b = skin_bounds(mesh, SkinBoundsSettings(time_budget_s=60.0, max_depth=depth, target_radius_scale=1.0,
                                             max_radius_scale=50.0, max_cone_angle_deg=89.0), progress=False)
    assert check_conservative(mesh, b, np.random.default_rng(seed)) >= len(b.intervals) - 1


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2 ** 31 - 1), bones=st.integers(2, 4))
def test_bounds_hold_for_cubic_splines(seed, bones):
    mesh = random_rig_mesh(seed, bones=bones, interp=("CUBICSPLINE", "LINEAR"), max_angle=1.2, amp=0.3)
    b = skin_bounds(mesh, SkinBoundsSettings(time_budget_s=60.0, max_depth=2, target_radius_scale=1.0,
                                             max_radius_scale=50.0, max_cone_angle_deg=89.0), progress=False)
    check_conservative(mesh, b, np.random.default_rng(seed), per_interval=8)


def test_bounds_hold_between_intervals_and_outside_the_clip():
    """Times not on the intervals' grid and clamped times before and after the clip."""
    mesh = random_rig_mesh(1, bones=4, keys=3, nx=48, ny=8, max_angle=math.radians(10), amp=0.05)
    b = skin_bounds(mesh, SkinBoundsSettings(time_budget_s=60, max_depth=3, max_radius_scale=50.0,
                                             max_cone_angle_deg=89.0), progress=False)
    assert check_conservative(mesh, b, np.random.default_rng(3)) > 0   # with cones (class 0) checked
    rig = mesh.rig
    bounded = b.classes < 2
    assert bounded.any() and (b.classes == 0).any(), b.stats
    for t in np.r_[np.linspace(rig.start - 1, rig.end + 1, 57), rig.times]:
        p, M = _pbs(mesh, b.principal, t)
        c = np.einsum("nij,nj->ni", M[:, :3, :3], b.sphere[:, :3].astype(float)) + M[:, :3, 3]
        sigma = np.linalg.svd(M[:, :3, :3], compute_uv=False)[:, 0]
        first, count = mesh.clusters["first"].astype(int), mesh.clusters["count"].astype(int)
        for m in np.nonzero(bounded)[0]:
            vs = np.unique(mesh.triangles[first[m]:first[m] + count[m]])
            assert np.linalg.norm(p[vs] - c[m], axis=1).max() <= b.sphere[m, 3] * b.radius_scale * sigma[m]


def test_constant_clip_and_single_bone():
    """A clip without channels: one point interval; every meshlet needs ~1 and its cone is the
    bind pose's exact spread (the boxes are points: the 512 corners are one triangle)."""
    mesh = random_rig_mesh(3, bones=2)
    rig = mesh.rig
    still = Rig(rig.parents, rig.joint_nodes, rig.inverse_bind, rig.rest, channels=[], name="still")
    m2 = SkinnedMesh.build(mesh.vertices, mesh.triangles, mesh.joints, mesh.weights, still, name="still")
    b = skin_bounds(m2, progress=False)
    assert len(b.intervals) == 2 and b.intervals[0] == b.intervals[1]
    assert b.radius_scale < 1.001 and np.all(b.classes == 0)
    v = m2.vertices.astype(float)
    for m, (f, c) in enumerate(zip(m2.clusters["first"], m2.clusters["count"])):
        p = v[m2.triangles[f:f + c].astype(int)]
        n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 1])
        exact = np.arccos(((n @ b.cone[m, :3].astype(float)) / np.linalg.norm(n, axis=1)).min())
        assert exact <= b.alpha[m] <= exact + 1e-3


# --- (b) keyframe poses alone miss the extremes ----------------------------------------------------
def _hinge(angle_deg=170.0, interp="LINEAR"):
    """Two bones on x; the second turns by ``angle_deg`` about z between t = 0 and t = 1. A small
    quad 1 beyond the hinge, weighted to the second bone."""
    ib = np.tile(np.eye(4), (2, 1, 1))
    ib[1, 0, 3] = -1.0
    T = np.array([[0, 0, 0], [1.0, 0, 0]])
    Q = np.array([[0, 0, 0, 1.0], [0, 0, 0, 1.0]])
    ch = [Channel(node=1, path="rotation", interpolation=interp, times=[0, 1],
                  values=[[0, 0, 0, 1], _quat([0, 0, 1], math.radians(angle_deg))])]
    rig = Rig(parents=[-1, 0], joint_nodes=[0, 1], inverse_bind=ib, rest=(T, Q, np.ones((2, 3))), channels=ch)
    v = np.array([[1.95, -0.05, 0], [2.05, -0.05, 0], [2.05, 0.05, 0], [1.95, 0.05, 0],
                  [0.0, -0.05, 0], [0.1, -0.05, 0], [0.1, 0.05, 0], [0.0, 0.05, 0], [-0.1, 0.0, 0]], np.float32)
    f = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7], [4, 7, 8]])
    joints = np.zeros((9, 4), np.int64)
    joints[:4, 0] = 1
    w = np.zeros((9, 4))
    w[:, 0] = 1
    return SkinnedMesh.build(v, f, joints, w, rig, name="hinge")


def test_keyframe_poses_miss_the_extremes_and_ours_do_not():
    mesh = _hinge()
    # principal joint 0 (the root) for the meshlet holding both the quad and the root triangle:
    lo, hi, principal, mv_m, mv_v, vlo, vhi = interval_boxes(mesh, 0.0, 1.0)
    rows = np.nonzero(mv_v < 4)[0]
    assert np.all(principal[mv_m[rows]] == 0), "the test needs the quad in the root bone's space"
    key = [mesh.posed(t)[0][mv_v[rows]] for t in (0.0, 1.0)]          # root joint = identity: PBS = mesh space
    k_hi = np.maximum(*key)
    mid = mesh.posed(0.5)[0][mv_v[rows]]                               # the quad at 85 degrees: far above both
    assert np.any(mid > k_hi + 0.1), "the keyframe-only box should miss the middle of the swing"
    assert np.all((mid >= vlo[rows] - 1e-12) & (mid <= vhi[rows] + 1e-12))
    ts = np.linspace(0, 1, 201)
    path = np.stack([mesh.posed(t)[0][mv_v[rows]] for t in ts])
    assert np.all(path >= vlo[rows] - 1e-12) and np.all(path <= vhi[rows] + 1e-12)
    # and the box is the swing's (radius ~1 about the hinge at x = 1, 0..170 degrees), not a ball
    assert vhi[rows, 1].max() < 1.1 and vlo[rows, 1].min() > -0.1 and vlo[rows, 0].min() > -0.1


def test_step_holds_the_pose_and_ends_on_the_last_key():
    mesh = _hinge(interp="STEP")
    b = skin_bounds(mesh, progress=False)
    assert b.intervals.tolist() == [0.0, 1.0, 1.0], "a STEP clip gets its end point as an interval"
    assert b.stats["subdivisions"] == 0
    check_conservative(mesh, b, np.random.default_rng(0))


# --- (e) adaptive subdivision ---------------------------------------------------------------------
def test_subdivision_tightens_and_stops_by_budget_or_target():
    mesh = random_rig_mesh(11, bones=3, keys=3, interp=("LINEAR",), max_angle=math.radians(120), amp=0.3)
    s0 = SkinBoundsSettings(time_budget_s=0.0, target_radius_scale=1.0, max_radius_scale=100.0)
    b0 = skin_bounds(mesh, s0, progress=False)
    assert b0.stats["stopped"] == "budget" and b0.stats["subdivisions"] == 0
    assert len(b0.intervals) == b0.stats["keyframe_intervals"] + 1
    s1 = SkinBoundsSettings(time_budget_s=600.0, target_radius_scale=1.0, max_radius_scale=100.0, max_depth=4)
    b1 = skin_bounds(mesh, s1, progress=False)
    assert b1.stats["stopped"] == "depth" and b1.stats["subdivisions"] > 0
    assert b1.radius_scale < b0.radius_scale
    assert np.all(b1.need <= b0.need * (1 + 1e-12))
    # a reachable target stops by target before the depth limit
    target = (1 + b1.radius_scale) / 2 if b1.radius_scale < b0.radius_scale else b0.radius_scale
    target = max(target, float(b1.need.max()) * 1.0001)
    s2 = SkinBoundsSettings(time_budget_s=600.0, target_radius_scale=target, max_radius_scale=100.0, max_depth=4)
    b2 = skin_bounds(mesh, s2, progress=False)
    assert b2.stats["stopped"] == "target"
    assert b2.radius_scale <= target * (1 + 1e-6)
    assert b2.stats["subdivisions"] <= b1.stats["subdivisions"]
    check_conservative(mesh, b1, np.random.default_rng(1), per_interval=2)


def test_classes_follow_the_thresholds():
    mesh = random_rig_mesh(5, bones=3, keys=3)
    loose = skin_bounds(mesh, SkinBoundsSettings(max_radius_scale=1000.0, max_cone_angle_deg=89.0), progress=False)
    strict = skin_bounds(mesh, SkinBoundsSettings(max_radius_scale=1.0, max_cone_angle_deg=1.0), progress=False)
    assert np.all(strict.classes[strict.need > 1.0] == 2)
    assert np.all(loose.classes[loose.need <= 1000.0] < 2)
    assert np.all((loose.classes == 0) == (loose.alpha <= math.radians(89.0)))
    assert np.all(loose.cone[loose.classes != 0, 3] == np.float32(NO_CONE))
    assert sum(loose.stats["classes"].values()) == len(mesh.clusters)
    assert loose.radius_scale >= loose.need[loose.classes < 2].max()


def test_progress_callback_and_bar():
    mesh = random_rig_mesh(2, bones=2, keys=3)
    calls = []
    skin_bounds(mesh, SkinBoundsSettings(max_depth=1), progress=lambda d, n: calls.append((d, n)))
    assert calls and calls[-1][0] == len(calls)
    skin_bounds(mesh, SkinBoundsSettings(max_depth=0), progress=True)


# --- settings and bad input ----------------------------------------------------------------------
@pytest.mark.parametrize("bad", [{"time_budget_s": -1}, {"target_radius_scale": 0.5}, {"max_radius_scale": float("nan")},
                                 {"max_cone_angle_deg": 90}, {"max_depth": 2.5}, {"max_depth": 99}])
def test_bad_settings_name_the_field(bad):
    name = next(iter(bad))
    with pytest.raises(MeshError, match=name):
        SkinBoundsSettings(**bad).validate()
    with pytest.raises(MeshError, match="unknown skin bounds settings"):
        SkinBoundsSettings.from_dict({"budget": 3})


def test_bad_input():
    with pytest.raises(MeshError, match="SkinnedMesh"):
        skin_bounds("worm.glb")
    with pytest.raises(MeshError, match="SkinBoundsSettings"):
        skin_bounds(random_rig_mesh(1, bones=2), settings={"time_budget_s": 1})
    with pytest.raises(MeshError, match="max_cone_angle_deg"):
        skin_bounds(random_rig_mesh(1, bones=2), SkinBoundsSettings(max_cone_angle_deg=120))
