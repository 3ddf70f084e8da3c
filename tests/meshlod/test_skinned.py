"""Skinned meshes (paramlod.meshlod.skinned): the samplers against hand-computed values, the rig's
hierarchy, the glTF loader and its errors, the real files of tests/data/skinned, our rigged worm
(paramlod.meshlod.build.worm_rig), frames drawn by both mesh renderers (the pose moves with the
time and is exactly the twin's), and scene files."""
from __future__ import annotations

import json
import math
import shutil
import struct
from pathlib import Path

import numpy as np
import pytest
import trimesh

import paramlod as pl
from paramlod.app.bench.skinned import cameras as bench_cameras
from paramlod.app.scenefile import load_scene
from paramlod.errors import MeshError, SceneError
from paramlod.meshlod.build.worm_rig import SMALL, tessellate, worm_rig, write_skinned_glb, write_worm
from paramlod.meshlod.format import MeshLod
from paramlod.meshlod.skin_reference import skin, skin_records
from paramlod.meshlod.skinned import Channel, Rig, SkinnedMesh, animation_names, load_skinned, slerp
from paramlod.scene.scene import SkinnedMeshObject

DATA = Path(__file__).resolve().parent.parent / "data" / "skinned"
REAL = {"BCN_Epileptic.glb": (3014, 5126, 54, "Epileptisch", 3.3),
        "animation_with_skeleton.glb": (2464, 2112, 14, "Armature|ArmatureAction", 0.8333),
        "simple_skin.glb": (10, 8, 2, "anim", 5.5)}


# --- samplers -------------------------------------------------------------------------------------
def test_linear_translation_and_clamping():
    c = Channel(0, "translation", "LINEAR", [1.0, 3.0], [[0, 0, 0], [4, -2, 1]])
    assert np.allclose(c.sample(1.5), [1.0, -0.5, 0.25])
    assert np.allclose(c.sample(0.0), [0, 0, 0]) and np.allclose(c.sample(9.0), [4, -2, 1])


def test_linear_rotation_is_slerp_on_the_shorter_arc():
    z90 = [0, 0, math.sin(math.pi / 4), math.cos(math.pi / 4)]
    c = Channel(0, "rotation", "LINEAR", [0.0, 1.0], [[0, 0, 0, 1], z90])
    half = [0, 0, math.sin(math.pi / 8), math.cos(math.pi / 8)]   # 45 degrees about z
    assert np.allclose(c.sample(0.5), half, atol=1e-12)
    # the same rotation with the sign flipped takes the same (short) way
    flipped = Channel(0, "rotation", "LINEAR", [0.0, 1.0], [[0, 0, 0, 1], [-x for x in z90]])
    q = flipped.sample(0.5)
    assert np.allclose(q * np.sign(q[3]), half, atol=1e-12)
    # a third of the way: 30 degrees
    assert np.allclose(c.sample(1 / 3), [0, 0, math.sin(math.pi / 12), math.cos(math.pi / 12)], atol=1e-12)
    assert np.allclose(slerp(np.array([0, 0, 0, 1.0]), np.array([0, 0, 1e-12, 1.0]), 0.5)[3], 1.0)


def test_step_holds_the_value_until_the_next_key():
    c = Channel(0, "scale", "STEP", [0.0, 1.0, 2.0], [[1, 1, 1], [2, 2, 2], [3, 3, 3]])
    assert np.allclose(c.sample(0.999), [1, 1, 1])
    assert np.allclose(c.sample(1.0), [2, 2, 2])
    assert np.allclose(c.sample(1.7), [2, 2, 2])
    assert np.allclose(c.sample(5.0), [3, 3, 3])


def test_cubicspline_hermite_with_tangents():
    # keys at t = 0 and 2 (td = 2): value 0 -> 1 in x, out-tangent of key 0 = 1, in-tangent of key 1 = -1
    vals = [[[9, 9, 9], [0, 0, 0], [1, 0, 0]],      # (in-tangent, value, out-tangent) of key 0
            [[-1, 0, 0], [1, 0, 0], [9, 9, 9]]]     # of key 1 (its out-tangent and key 0's in-tangent are unused)
    c = Channel(0, "translation", "CUBICSPLINE", [0.0, 2.0], vals)
    # s = 0.5: h00 = 0.5, h10 = 0.125, h01 = 0.5, h11 = -0.125 -> 0 + 2*0.125*1 + 0.5*1 + 2*(-0.125)*(-1) = 1
    assert np.allclose(c.sample(1.0), [1.0, 0, 0])
    # s = 0.25: 2*0.140625 + 0.15625 + 2*0.046875 = 0.53125
    assert np.allclose(c.sample(0.5), [0.53125, 0, 0])
    assert np.allclose(c.sample(0.0), [0, 0, 0]) and np.allclose(c.sample(2.0), [1, 0, 0])


def test_cubicspline_rotation_is_normalised():
    vals = [[[0, 0, 0, 0], [0, 0, 0, 2], [0, 0, 1, 0]], [[0, 0, 1, 0], [0, 0, 2, 0], [0, 0, 0, 0]]]
    c = Channel(0, "rotation", "CUBICSPLINE", [0.0, 1.0], vals)
    for t in (0.0, 0.3, 0.5, 1.0):
        assert abs(np.linalg.norm(c.sample(t)) - 1) < 1e-12
    # at s = 0.5 the cubic is (h10 td) b0 + h01 v1 + (h11 td) a1 + h00 v0 = (0, 0, 0.125 + 1 - 0.125, 1) -> 45 deg about z
    assert np.allclose(c.sample(0.5), [0, 0, math.sqrt(0.5), math.sqrt(0.5)])


def test_channel_errors():
    with pytest.raises(MeshError, match="strictly increasing"):
        Channel(0, "translation", "LINEAR", [0.0, 0.0], [[0, 0, 0], [1, 1, 1]])
    with pytest.raises(MeshError, match="interpolation"):
        Channel(0, "translation", "SMOOTH", [0.0], [[0, 0, 0]])
    with pytest.raises(MeshError, match=r"values of shape \(2, 3, 4\)"):
        Channel(0, "rotation", "CUBICSPLINE", [0.0, 1.0], np.zeros((2, 4)))


# --- the rig ------------------------------------------------------------------------------------
def two_bone_rig(channels=()):
    """A root at the origin and a child one unit up; inverse binds of that rest pose."""
    t = np.array([[0, 0, 0], [0, 1, 0]], float)
    q = np.array([[0, 0, 0, 1], [0, 0, 0, 1]], float)
    bind = np.tile(np.eye(4), (2, 1, 1))
    bind[1, 1, 3] = 1
    return Rig(parents=[-1, 0], joint_nodes=[0, 1], inverse_bind=np.linalg.inv(bind), rest=(t, q, np.ones((2, 3))),
               channels=list(channels))


def test_rig_hierarchy_and_skin_matrices():
    z90 = [0, 0, math.sin(math.pi / 4), math.cos(math.pi / 4)]
    rig = two_bone_rig([Channel(0, "rotation", "LINEAR", [0.0, 2.0], [[0, 0, 0, 1], z90]),
                        Channel(1, "translation", "STEP", [0.0, 1.0], [[0, 1, 0], [0, 2, 0]])])
    assert rig.times.tolist() == [0.0, 1.0, 2.0] and rig.interpolation == "LINEAR"
    assert np.allclose(rig.skin_matrices(0.0), np.eye(4))   # the rest pose is the bind pose
    g = rig.node_matrices(2.0)
    # the root turned 90 degrees about z carries the child (2 up in its frame) to (-2, 0, 0)
    assert np.allclose(g[1][:3, 3], [-2, 0, 0])
    s = rig.skin_matrices(2.0)
    assert np.allclose(s[1] @ [0, 1, 0, 1], [-2, 0, 0, 1])   # a bind-pose point at the child joint
    assert np.allclose(rig.skin_matrices(-5.0), rig.skin_matrices(0.0))
    root = np.eye(4)
    root[:3, 3] = [5, 0, 0]
    moved = Rig(rig.parents, rig.joint_nodes, rig.inverse_bind, rig.rest, rig.channels, root=root)
    assert np.allclose(moved.node_matrices(2.0)[1][:3, 3], [3, 0, 0])


def test_rig_errors():
    with pytest.raises(MeshError, match="parents must come before"):
        Rig(parents=[1, -1], joint_nodes=[0], inverse_bind=np.eye(4)[None], rest=(np.zeros((2, 3)),
            np.tile([0, 0, 0, 1.0], (2, 1)), np.ones((2, 3))))
    with pytest.raises(MeshError, match="inverse_bind"):
        Rig(parents=[-1], joint_nodes=[0], inverse_bind=np.eye(4), rest=(np.zeros((1, 3)), [[0, 0, 0, 1]], np.ones((1, 3))))


def test_skinned_mesh_build_normalises_and_clusters():
    rig = two_bone_rig()
    rng = np.random.default_rng(3)
    v = rng.normal(size=(900, 3)).astype(np.float32)
    f = rng.integers(0, 900, size=(700, 3))
    f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])]
    f = np.concatenate([f, [[0, 0, 1]]])   # one degenerate triangle
    w = rng.random((900, 4)) * 3
    w[5] = 0
    j = rng.integers(0, 2, size=(900, 4))
    m = SkinnedMesh.build(v, f, j, w, rig, name="rand")
    assert np.allclose(m.weights.sum(axis=1), 1, atol=1e-6)
    assert m.info["unweighted"] == 1 and m.weights[5].tolist() == [1, 0, 0, 0]
    assert m.info["degenerate_dropped"] == 1 and len(m.triangles) == len(f) - 1
    c = m.clusters
    assert c["count"].max() <= 128 and c["first"][0] == 0
    assert np.all(c["first"][1:] == c["first"][:-1] + c["count"][:-1]) and c["count"].sum() == len(m.triangles)
    # the same triangles, reordered
    key = lambda t: sorted(map(tuple, np.sort(t, axis=1).tolist()))
    assert key(m.triangles) == key(f[:-1])
    with pytest.raises(MeshError, match="rand: vertex 0 is weighted to joint"):
        SkinnedMesh.build(v, f, np.full((900, 4), 7), w + 1, rig, name="rand")
    with pytest.raises(MeshError, match="joints .* and weights must be"):
        SkinnedMesh.build(v, f, j[:10], w, rig, name="rand")


# --- files ----------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def small_worm(tmp_path_factory):
    path = tmp_path_factory.mktemp("worm") / "worm.glb"
    write_worm(path, "small")
    return path


@pytest.fixture(scope="module")
def culling_worm(tmp_path_factory):
    """A worm fine enough around (64 samples) that most meshlets get a backface cone."""
    path = tmp_path_factory.mktemp("worm") / "worm64.glb"
    write_worm(path, {"nu": 40, "nv": 64, "bones": 12})
    return load_skinned(path)


@pytest.mark.parametrize("name", sorted(REAL))
def test_real_files_load_and_animate(name):
    verts, tris, joints, anim, end = REAL[name]
    m = load_skinned(DATA / name)
    assert (len(m.vertices), len(m.triangles), len(m.rig.joint_nodes)) == (verts, tris, joints)
    assert m.rig.animation == anim and m.info["animations"] == [anim] and abs(m.rig.end - end) < 1e-3
    assert m.info["ignored"] == {}
    poses = [m.posed(t)[0] for t in np.linspace(m.rig.start, m.rig.end, 7)]
    size0 = np.ptp(poses[0], axis=0).max()
    moved = max(np.abs(p - poses[0]).max() for p in poses)
    assert moved > 0.05 * size0   # the clip moves the mesh
    for p in poses:   # and keeps it in one piece, about its size (no joint flies away)
        assert np.isfinite(p).all() and 0.5 < np.ptp(p, axis=0).max() / size0 < 2.0


def test_animation_choice_and_errors(tmp_path, small_worm):
    assert animation_names(DATA / "BCN_Epileptic.glb") == ["Epileptisch"]
    assert load_skinned(DATA / "BCN_Epileptic.glb", animation=0).rig.animation == "Epileptisch"
    with pytest.raises(MeshError, match=r"BCN_Epileptic.glb.*no animation named 'jump'; the file has 'Epileptisch'"):
        load_skinned(DATA / "BCN_Epileptic.glb", animation="jump")
    with pytest.raises(MeshError, match="animation index 3 is out of range"):
        load_skinned(DATA / "BCN_Epileptic.glb", animation=3)
    still = tmp_path / "still.glb"
    arrays = worm_rig(**SMALL)
    arrays["channels"] = []
    write_skinned_glb(still, **arrays)
    m = load_skinned(still)   # no animation: the rest pose, one time
    assert m.rig.times.tolist() == [0.0] and m.info["animations"] == []
    with pytest.raises(MeshError, match="still.glb.*'wave' was asked for but the file has no animations"):
        load_skinned(still, animation="wave")


def _edit_glb(src: Path, dst: Path, edit) -> Path:
    """Rewrite the JSON chunk of a GLB file with ``edit(json_dict)``, keeping its binary chunk."""
    data = src.read_bytes()
    n = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20:20 + n])
    edit(doc)
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    rest = data[20 + n:]
    dst.write_bytes(b"glTF" + struct.pack("<II", 2, 12 + 8 + len(js) + len(rest)) + struct.pack("<I", len(js))
                    + b"JSON" + js + rest)
    return dst


def test_loader_errors_name_the_file(tmp_path, small_worm):
    obj = tmp_path / "body.obj"
    obj.write_text("v 0 0 0\n")
    with pytest.raises(MeshError, match=r"'body.obj'.*assimp export body.obj body.glb -fglb2"):
        load_skinned(obj)
    junk = tmp_path / "junk.glb"
    junk.write_bytes(b"not a glb at all")
    with pytest.raises(MeshError, match="'junk.glb': not a GLB file"):
        load_skinned(junk)
    bad_json = tmp_path / "bad.gltf"
    bad_json.write_text("{ this is not json")
    with pytest.raises(MeshError, match="'bad.gltf': not a readable glTF file"):
        load_skinned(bad_json)
    with pytest.raises(MeshError, match="'missing.glb': no such file"):
        load_skinned(tmp_path / "missing.glb")

    def no_skin(d):
        d.pop("skins")
        d["nodes"][0].pop("skin")
    with pytest.raises(MeshError, match="'noskin.glb': the file has no skin .*add_mesh"):
        load_skinned(_edit_glb(small_worm, tmp_path / "noskin.glb", no_skin))

    def long_accessor(d):
        d["accessors"][d["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]["count"] = 10 ** 7
    with pytest.raises(MeshError, match="'long.glb': mesh 0 primitive 0 POSITION: accessor 0 reads past the end"):
        load_skinned(_edit_glb(small_worm, tmp_path / "long.glb", long_accessor))

    def string_count(d):
        d["accessors"][0]["count"] = "many"
    with pytest.raises(MeshError, match="'typed.glb': (not a readable glTF file|malformed glTF data)"):
        load_skinned(_edit_glb(small_worm, tmp_path / "typed.glb", string_count))

    def bad_joint(d):
        d["skins"][0]["joints"][0] = 999
    with pytest.raises(MeshError, match="'joint.glb': skin 0 names a joint node that does not exist"):
        load_skinned(_edit_glb(small_worm, tmp_path / "joint.glb", bad_joint))

    def lines(d):
        d["meshes"][0]["primitives"][0]["mode"] = 1
    with pytest.raises(MeshError, match="'lines.glb': mesh 0 primitive 0 draws points or lines"):
        load_skinned(_edit_glb(small_worm, tmp_path / "lines.glb", lines))


def test_unskinned_meshes_of_the_file_ride_on_their_nodes(tmp_path, small_worm):
    """A second, unskinned mesh node is drawn rigidly with its node (nothing is left out)."""
    def add_rigid(d):
        d["nodes"].append({"name": "hat", "mesh": 0, "translation": [0, 10, 0]})
        d["scenes"][0]["nodes"].append(len(d["nodes"]) - 1)
    m0 = load_skinned(small_worm)
    m = load_skinned(_edit_glb(small_worm, tmp_path / "hat.glb", add_rigid))
    assert len(m.vertices) == 2 * len(m0.vertices) and len(m.rig.joint_nodes) == len(m0.rig.joint_nodes) + 1
    p, _ = m.posed(0.3)
    p0, _ = m0.posed(0.3)
    hat = p[len(m0.vertices):]
    assert np.allclose(np.sort(hat, axis=0), np.sort(m0.vertices.astype(float) + [0, 10, 0], axis=0), atol=1e-5)
    assert np.allclose(np.sort(p[:len(m0.vertices)], axis=0), np.sort(p0, axis=0), atol=1e-9)


def test_cubicspline_and_step_files_go_through_the_loader(tmp_path):
    arrays = worm_rig(**SMALL)
    lin = tmp_path / "lin.glb"
    write_skinned_glb(lin, **arrays)
    cub = tmp_path / "cubic.glb"
    # CUBICSPLINE with zero tangents: the keys are the same, between them a smoothstep in quaternion space
    arrays["channels"] = [(n, p, t, np.stack([np.zeros_like(v), v, np.zeros_like(v)], 1)) for n, p, t, v in arrays["channels"]]
    write_skinned_glb(cub, interpolation="CUBICSPLINE", **arrays)
    step = tmp_path / "step.glb"
    arrays = worm_rig(**SMALL)
    write_skinned_glb(step, interpolation="STEP", **arrays)
    a, b, c = load_skinned(lin), load_skinned(cub), load_skinned(step)
    assert (a.rig.interpolation, b.rig.interpolation, c.rig.interpolation) == ("LINEAR", "CUBICSPLINE", "STEP")
    k1 = float(a.rig.times[1])
    for t in (0.0, k1):   # at the keys all three agree
        assert np.allclose(a.rig.skin_matrices(t), b.rig.skin_matrices(t), atol=1e-6)
        assert np.allclose(a.rig.skin_matrices(t), c.rig.skin_matrices(t), atol=1e-6)
    mid = k1 / 4   # smoothstep(1/4) = 5/32 of the way, linear 1/4
    assert np.allclose(c.rig.skin_matrices(mid), c.rig.skin_matrices(0.0))   # STEP holds
    assert not np.allclose(b.rig.skin_matrices(mid), a.rig.skin_matrices(mid), atol=1e-4)
    assert not np.allclose(b.rig.skin_matrices(mid), b.rig.skin_matrices(0.0), atol=1e-4)


# --- the worm ---------------------------------------------------------------------------------------
def test_worm_bind_pose_is_the_tessellated_body(tmp_path):
    nu, nv, bones = 20, 16, 8
    path = write_worm(tmp_path / "w.glb", {"nu": nu, "nv": nv, "bones": bones}, amplitude=0.0)
    m = load_skinned(path)
    assert len(m.triangles) == 4 * (nu - 1) * nv + 4 * nv and len(m.rig.joint_nodes) == bones
    v, n, f, u, centre = tessellate(nu, nv)
    body = pl.evaluate("giant_worm", np.linspace(0, 1, nu)[:, None], (np.arange(nv) * 2 * np.pi / nv)[None, :], t=0.0)
    assert np.allclose(v, body.reshape(-1, 3), atol=1e-6)
    assert np.allclose(m.vertices[:nu * nv], v)   # the outer wall is the body surface
    # no wave: every time of the clip is the bind pose
    for t in (0.0, 0.7, 2.0):
        assert np.allclose(m.posed(t)[0], m.vertices, atol=1e-4)
    # a closed shell, consistently wound outwards: no back face shows to a camera outside it
    tm = trimesh.Trimesh(m.vertices, m.triangles)   # merges the rims' own vertices with the walls'
    assert tm.is_watertight and tm.is_winding_consistent and tm.volume > 0
    # outer normals point away from the centreline, the inner wall's towards it
    ring_centre = np.repeat(centre, nv, axis=0)
    assert np.all(np.sum((v - ring_centre) * m.normals[:nu * nv], axis=1) > 0)
    assert np.all(np.sum((m.vertices[nu * nv:2 * nu * nv] - ring_centre) * m.normals[nu * nv:2 * nu * nv], axis=1) < 0)


def test_worm_wave_moves_and_loops(small_worm):
    m = load_skinned(small_worm)
    assert m.rig.animation == "wave" and len(m.rig.joint_nodes) == SMALL["bones"]
    assert np.allclose(m.weights.sum(axis=1), 1, atol=1e-6) and (m.weights > 0).sum(axis=1).min() >= 2
    p0, p1 = m.posed(0.0)[0], m.posed(0.5)[0]
    assert np.abs(p1 - p0).max() > 0.05
    assert np.allclose(m.posed(m.rig.end)[0], p0, atol=1e-5)   # one period: back where it began
    # the wave bends sideways (x), as the parametric worm sways
    d = np.abs(p1 - p0).max(axis=0)
    assert d[0] == d.max()


# --- frames ----------------------------------------------------------------------------------------
def _camera(mesh, size=(96, 72)):
    c, r = mesh.bounding_sphere()
    d = np.array([0.8, 0.45, 1.0])
    d /= np.linalg.norm(d)
    return pl.Camera.look_at(c + d * r * 2.6, c, (0, 1, 0), 40.0, size, near=r * 0.05, far=r * 8)


def _no_cull():
    rs = pl.RenderSettings()
    rs.mesh.cull_frustum = rs.mesh.cull_backface = False
    return rs


@pytest.mark.parametrize("variant", ["meshlets", "meshlets-gl"])
def test_frame_moves_with_time_and_is_the_twins_pose(small_worm, variant):
    mesh = load_skinned(small_worm)
    cam = _camera(mesh)
    s = pl.Scene()
    s.add_skinned_mesh(mesh, variant=variant)
    a = pl.render(s, cam, settings=_no_cull(), time=0.0)
    b = pl.render(s, cam, settings=_no_cull(), time=0.5)
    assert a.stats["variant"] == variant and (a.object_id == 1).sum() > 200
    assert (a.object_id != b.object_id).sum() > 20
    for t, frame in ((0.0, a), (0.5, b)):
        # the same clusters and triangles with the twin's posed vertices, drawn as a static mesh
        pv, pn = skin(mesh.vertices, mesh.normals, mesh.joints, mesh.weights, skin_records(mesh.rig.skin_matrices(t)))
        static = MeshLod(vertices=pv[:, :3].copy(), normals=pn[:, :3].copy(), triangles=mesh.triangles,
                         clusters=mesh.clusters, name="twin pose", lod="full")
        ref_scene = pl.Scene()
        ref_scene.add_mesh(static, variant=variant)
        ref = pl.render(ref_scene, cam, settings=_no_cull())
        assert np.array_equal(frame.object_id, ref.object_id)
        assert np.array_equal(frame.depth, ref.depth)
        assert np.array_equal(frame.color, ref.color)
    assert a.stats["skinned_objects"] == 1 and a.stats["skinned_vertices"] == len(mesh.vertices)
    assert a.stats["clusters_drawn"] == len(mesh.clusters)   # no culling: every meshlet


@pytest.mark.parametrize("variant", ["meshlets", "meshlets-gl"])
def test_culling_on_and_off_draw_the_same_pixels_over_the_clip(culling_worm, variant):
    """The skinned cull (SkinCull with the clip's bounds) only drops meshlets that draw nothing: the
    frames with culling on and off are bit-identical at every frame, with the camera close enough
    that the frustum and the back faces cull something."""
    mesh = culling_worm
    c, r = mesh.bounding_sphere()
    cams = [pl.Camera.look_at(c + np.array([0.3, 0.2, 1.0]) * r * 0.9, c + [0, r * 0.3, 0], (0, 1, 0), 40.0, (80, 60),
                              near=r * 0.02, far=r * 8),
            pl.Camera.look_at(c + np.array([1.0, -0.3, 0.2]) * r * 1.6, c, (0, 1, 0), 40.0, (80, 60),
                              near=r * 0.02, far=r * 8),
            bench_cameras(mesh, (80, 60), 1)["mouth"][0]]   # into the mouth: the inner wall shows
    on = pl.RenderSettings()
    s = pl.Scene()
    s.add_skinned_mesh(mesh, variant=variant, material=pl.Material(two_sided=False))   # closed: back faces hidden
    culled = {"frustum": 0, "backface": 0}
    for t in np.linspace(mesh.rig.start, mesh.rig.end, 5)[:-1] + 0.07:
        for cam in cams:
            a = pl.render(s, cam, settings=on, time=float(t))
            b = pl.render(s, cam, settings=_no_cull(), time=float(t))
            assert a.stats["skin_cull"] == "skin_cull" and b.stats["skin_cull"] == "none"
            assert np.array_equal(a.object_id, b.object_id) and np.array_equal(a.depth, b.depth)
            assert np.array_equal(a.color, b.color)
            assert b.stats["clusters_drawn"] == len(mesh.clusters)
            culled["frustum"] += a.stats["clusters_culled_frustum"]
            culled["backface"] += a.stats["clusters_culled_backface"]
            assert a.stats["clusters_drawn"] + a.stats["clusters_culled_frustum"] + \
                a.stats["clusters_culled_backface"] == len(mesh.clusters)
    assert culled["frustum"] > 0 and culled["backface"] > 0
    assert mesh.bounds is not None and len(mesh.bounds.principal) == len(mesh.clusters)
    # two-sided (the default material): back faces show, so no meshlet goes to the backface test
    two = pl.Scene()
    two.add_skinned_mesh(mesh, variant=variant)
    f = pl.render(two, cams[0], settings=on, time=0.07)
    assert f.stats["clusters_culled_backface"] == 0 and f.stats["clusters_culled_frustum"] > 0


def test_culling_a_real_file_changes_no_pixel():
    mesh = load_skinned(DATA / "BCN_Epileptic.glb")
    c, r = mesh.bounding_sphere()
    s = pl.Scene()
    s.add_skinned_mesh(mesh)
    culled = 0
    for t in (0.4, 1.9, 2.8):
        for d in ([1, 0.2, -0.5], [-0.2, 1, 0.1]):
            d = np.array(d) / np.linalg.norm(d)
            cam = pl.Camera.look_at(c + d * r * 1.5, c, (0, 1, 0) if abs(d[1]) < 0.9 else (1, 0, 0), 40.0, (96, 72),
                                    near=r * 0.02, far=r * 8)
            a = pl.render(s, cam, time=t)
            b = pl.render(s, cam, settings=_no_cull(), time=t)
            assert np.array_equal(a.object_id, b.object_id) and np.array_equal(a.depth, b.depth)
            culled += a.stats["clusters_culled_frustum"] + a.stats["clusters_culled_backface"]
    assert culled > 0


def test_pinned_time_and_two_objects_of_one_mesh(small_worm):
    mesh = load_skinned(small_worm)
    cam = _camera(mesh)
    s = pl.Scene()
    s.add_skinned_mesh(mesh, time=0.5)
    a = pl.render(s, cam, settings=_no_cull(), time=0.0)
    b = pl.render(s, cam, settings=_no_cull(), time=1.3)
    assert np.array_equal(a.depth, b.depth)   # pinned: the scene's time does not move it
    two = pl.Scene()
    two.add_skinned_mesh(mesh, time=0.5)
    two.add_skinned_mesh(mesh, time=0.0, transform=pl.translate(4, 0, 0))
    f = pl.render(two, _camera(mesh, (128, 72)), settings=_no_cull())
    assert (f.object_id == 1).sum() > 100 and (f.object_id == 2).sum() > 100


def test_scene_errors(small_worm):
    s = pl.Scene()
    with pytest.raises(SceneError, match="time must be a finite number"):
        s.add_skinned_mesh(small_worm, time=float("nan"))
    with pytest.raises(SceneError, match="animation must be a name or an index"):
        s.add_skinned_mesh(small_worm, animation=1.5)
    with pytest.raises(MeshError, match="a skinned mesh is a path to a glTF/GLB file or a SkinnedMesh"):
        s.add_skinned_mesh(42)
    assert not s.meshes


def test_scene_file_round_trip(tmp_path):
    shutil.copy(DATA / "simple_skin.glb", tmp_path / "arm.glb")
    text = """
[camera]
direction = [0, 0, 1]
size = [64, 48]

[[objects]]
skinned = "arm.glb"
animation = "anim"
color = [0.7, 0.5, 0.4]

[[objects]]
skinned = "arm.glb"
animation = "anim"
time = 2.0
translate = [1.5, 0, 0]
variant = "meshlets-gl"
"""
    (tmp_path / "s.toml").write_text(text)
    sf = load_scene(tmp_path / "s.toml")
    a, b = sf.scene.meshes
    assert isinstance(a, SkinnedMeshObject) and a.time is None and a.mesh.rig.animation == "anim"
    assert b.time == 2.0 and b.variant == "meshlets-gl" and a.mesh is b.mesh   # loaded once (same file and clip)
    assert a.material.color == (0.7, 0.5, 0.4)
    f0 = pl.render(sf.scene, sf.camera, settings=sf.settings, time=0.0)
    f1 = pl.render(sf.scene, sf.camera, settings=sf.settings, time=1.5)
    left = slice(0, 32)
    assert (f0.object_id == 1).sum() > 20 and (f0.object_id == 2).sum() > 20
    assert not np.array_equal(f0.object_id[:, left] == 1, f1.object_id[:, left] == 1)   # --time moves the first
    assert np.array_equal(f0.object_id == 2, f1.object_id == 2)                           # the second is pinned
    for bad, msg in [('animation = "jump"', r"s2.toml:\d+: objects\[0\].animation: .*no animation named 'jump'"),
                     ('time = "soon"', r"objects\[0\].time: must be a number"),
                     ('lod = "dag"', r"objects\[0\].lod: a skinned mesh takes no lod"),
                     ('animation = true', r"objects\[0\].animation: must be the animation's name or index"),
                     ('mesh = "arm.glb"', r"objects\[0\].skinned: a skinned mesh is an object of its own; this one has mesh")]:
        (tmp_path / "s2.toml").write_text(f'[[objects]]\nskinned = "arm.glb"\n{bad}\n')
        with pytest.raises(SceneError, match=msg):
            load_scene(tmp_path / "s2.toml")
    (tmp_path / "s3.toml").write_text('[[objects]]\nfunction = "sphere"\ntime = 1.0\n')
    with pytest.raises(SceneError, match=r"objects\[0\].time: is for skinned meshes"):
        load_scene(tmp_path / "s3.toml")
    (tmp_path / "s4.toml").write_text('[[objects]]\nskinned = "nothere.glb"\n')
    with pytest.raises(SceneError, match=r"objects\[0\].skinned: .*'nothere.glb': no such file"):
        load_scene(tmp_path / "s4.toml")
