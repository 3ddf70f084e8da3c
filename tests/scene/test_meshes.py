"""Mesh sources: paramlod.scene.meshes.read_mesh over every format and bad input, and the scene's
add_mesh / add_mesh_instances (validation, one load per source, object ids, subscenes).

The scene asks the loader registry for a "mesh" MeshLod; the fixture ``mesh_loader``
(tests/conftest.py) wraps the registered loader and counts the calls.
"""
import warnings

import numpy as np
import pytest
import trimesh

import paramlod as pl
from paramlod.errors import MeshError, SceneError
from paramlod.scene import loaders
from paramlod.scene.meshes import read_mesh, source_key


def icosphere(subdiv=1):
    return trimesh.creation.icosphere(subdivisions=subdiv)


def odd_normals(n, seed=0):
    """Unit normals no computation would give (to tell file normals from computed ones)."""
    v = np.random.default_rng(seed).normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


# --- formats ----------------------------------------------------------------------------------
@pytest.mark.parametrize("ext", ["obj", "ply", "stl", "off", "glb"])
def test_every_trimesh_format_reads_the_same_surface(tmp_path, ext):
    m = icosphere(1)
    p = tmp_path / f"ball.{ext}"
    m.export(p)
    tm = read_mesh(p)
    assert tm.name == f"ball.{ext}"
    assert tm.vertices.dtype == np.float32 and tm.faces.dtype == np.uint32 and tm.normals.dtype == np.float32
    # STL stores a soup of 3 corners per face: welding gives back the 42 shared vertices
    assert tm.vertices.shape == (42, 3) and tm.faces.shape == (80, 3)
    tri = tm.vertices[tm.faces].astype(np.float64)
    ref = np.asarray(m.vertices)[np.asarray(m.faces)]
    np.testing.assert_allclose(np.sort(tri.reshape(-1, 9), axis=0), np.sort(ref.reshape(-1, 9), axis=0), atol=1e-6)
    # computed normals of a sphere point outwards, unit length; winding kept outward
    np.testing.assert_allclose(np.linalg.norm(tm.normals, axis=1), 1, atol=1e-6)
    assert (np.sum(tm.normals * tm.vertices, axis=1) > 0.95).all()
    assert tm.normals_from == "computed"
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert (np.sum(fn * tri.mean(axis=1), axis=1) > 0).all()


def test_gifti_surface(tmp_path):
    nib = pytest.importorskip("nibabel")
    m = icosphere(2)
    img = nib.gifti.GiftiImage(darrays=[
        nib.gifti.GiftiDataArray(np.asarray(m.vertices, np.float32), intent="NIFTI_INTENT_POINTSET",
                                 datatype="NIFTI_TYPE_FLOAT32"),
        nib.gifti.GiftiDataArray(np.asarray(m.faces, np.int32), intent="NIFTI_INTENT_TRIANGLE",
                                 datatype="NIFTI_TYPE_INT32")])
    p = tmp_path / "lh.pial.surf.gii"
    nib.save(img, p)
    tm = read_mesh(p)
    np.testing.assert_array_equal(tm.vertices, np.asarray(m.vertices, np.float32))
    np.testing.assert_array_equal(tm.faces, np.asarray(m.faces, np.uint32))
    assert tm.name == "lh.pial.surf.gii" and tm.normals_from == "computed"
    # a data file on a surface is not a surface
    data = nib.gifti.GiftiImage(darrays=[nib.gifti.GiftiDataArray(np.zeros(42, np.float32),
                                                                  intent="NIFTI_INTENT_SHAPE")])
    q = tmp_path / "lh.thickness.shape.gii"
    nib.save(data, q)
    with pytest.raises(MeshError, match=r"lh\.thickness\.shape\.gii holds no surface.*surf\.gii"):
        read_mesh(q)
    (tmp_path / "junk.gii").write_text("<not gifti")
    with pytest.raises(MeshError, match=r"cannot read mesh file .*junk\.gii"):
        read_mesh(tmp_path / "junk.gii")


@pytest.mark.parametrize("ext", ["obj", "ply", "glb"])
def test_normals_from_the_file_are_kept(tmp_path, ext):
    m = icosphere(1)
    normals = odd_normals(len(m.vertices))
    m.vertex_normals = normals
    p = tmp_path / f"n.{ext}"
    if ext == "obj":
        p.write_text(trimesh.exchange.obj.export_obj(m, include_normals=True))
    elif ext == "ply":
        p.write_bytes(trimesh.exchange.ply.export_ply(m, vertex_normal=True))
    else:
        m.export(p, include_normals=True)
    tm = read_mesh(p)
    assert tm.normals_from == "file"
    # no vertex merged, moved or reordered: the file's normals stay with their vertices
    np.testing.assert_allclose(tm.vertices, m.vertices, atol=1e-6)
    np.testing.assert_allclose(tm.normals, normals, atol=1e-6)


def test_obj_with_split_normals_keeps_the_crease(tmp_path):
    # two triangles share an edge but give it different normals: the crease stays (no weld)
    p = tmp_path / "crease.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvn 0 0 1\nvn 0 1 0\n"
                 "f 1//1 2//1 3//1\nf 2//2 4//2 3//2\n")
    tm = read_mesh(p)
    assert len(tm.vertices) == 6 and tm.normals_from == "file"
    assert {tuple(np.round(n, 6)) for n in tm.normals} == {(0, 0, 1), (0, 1, 0)}


def test_glb_scene_of_several_meshes_applies_node_transforms(tmp_path):
    a, b = icosphere(0), trimesh.creation.box()
    scene = trimesh.Scene()
    scene.add_geometry(a, node_name="a", transform=pl.translate(5, 0, 0))
    mirror = pl.scale(-1, 1, 1) @ pl.translate(0, 3, 0)
    scene.add_geometry(b, node_name="b", transform=mirror)
    p = tmp_path / "two.glb"
    scene.export(p)
    tm = read_mesh(p)
    assert len(tm.faces) == len(a.faces) + len(b.faces)
    centres = tm.vertices[tm.faces].mean(axis=1)
    near_a = np.linalg.norm(centres - [5, 0, 0], axis=1) < 1.01
    assert near_a.sum() == len(a.faces) and np.allclose(centres[~near_a].mean(axis=0), [0, 3, 0], atol=1e-5)
    # the mirrored box still winds outward
    tri = tm.vertices[tm.faces[~near_a]].astype(np.float64)
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert (np.sum(fn * (tri.mean(axis=1) - [0, 3, 0]), axis=1) > 0).all()


def test_trimesh_objects_and_arrays(tmp_path):
    m = icosphere(1)
    a = read_mesh(m)
    b = read_mesh((m.vertices, m.faces))
    c = read_mesh([np.asarray(m.vertices).tolist(), np.asarray(m.faces, np.float64)])   # integral floats
    assert b.name == c.name == "array"
    for t in (b, c):
        np.testing.assert_array_equal(t.vertices, a.vertices)
        np.testing.assert_array_equal(t.faces, a.faces)
        np.testing.assert_array_equal(t.normals, a.normals)
    normals = odd_normals(len(m.vertices), seed=3)
    d = read_mesh((m.vertices, m.faces, normals * 2.5))   # renormalised
    np.testing.assert_allclose(d.normals, normals, atol=1e-6)
    assert d.normals_from == "file"
    assert a.content_hash() == b.content_hash() != d.content_hash()


def test_computed_normals_are_area_weighted():
    # a vertex where a large and a small triangle meet at a right angle: its normal leans to the large one
    v = np.array([[0, 0, 0], [4, 0, 0], [0, 4, 0], [0, 0, 1], [0, -1, 0]], np.float32)
    f = np.array([[0, 1, 2], [0, 3, 4]])   # z-facing area 8, x-facing area 0.5
    tm = read_mesh((v, f))
    want = np.array([0.5, 0, 8]) / np.hypot(0.5, 8)
    np.testing.assert_allclose(tm.normals[0], want, atol=1e-6)
    np.testing.assert_allclose(tm.normals[1], [0, 0, 1], atol=1e-6)


def test_welding_and_compaction():
    # a soup of two triangles sharing an edge, plus an unused vertex and a -0.0 coordinate
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0], [1, 1, 0], [-0.0, 1, 0], [9, 9, 9]], np.float32)
    f = np.array([[0, 1, 2], [3, 4, 5]])
    tm = read_mesh((v, f))
    np.testing.assert_array_equal(tm.vertices, [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    np.testing.assert_array_equal(tm.faces, [[0, 1, 2], [1, 3, 2]])


def test_degenerate_faces_are_dropped_with_a_warning(tmp_path):
    m = icosphere(1)
    f = np.concatenate([m.faces, [[0, 0, 1], [0, 1, 1]]])
    v = np.concatenate([m.vertices, [[0, 0, 5], [0, 0, 6], [0, 0, 7]]])   # collinear: zero area
    f = np.concatenate([f, [[42, 43, 44]]])
    p = tmp_path / "degenerate.ply"
    trimesh.Trimesh(v, f, process=False).export(p)
    with pytest.warns(UserWarning, match=r"degenerate\.ply: dropped 3 of 83 faces"):
        tm = read_mesh(p)
    assert len(tm.faces) == 80 and len(tm.vertices) == 42   # the collinear vertices went with their face
    with pytest.raises(MeshError, match=r"mesh array: all 2 faces are degenerate"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            read_mesh((v, [[0, 0, 1], [42, 43, 44]]))


# --- bad input --------------------------------------------------------------------------------
def test_bad_files_are_named(tmp_path):
    with pytest.raises(MeshError, match=r"mesh file .*missing\.ply does not exist"):
        read_mesh(tmp_path / "missing.ply")
    with pytest.raises(MeshError, match=r"is a folder"):
        read_mesh(tmp_path)
    (tmp_path / "x.fbx").write_text("x")
    with pytest.raises(MeshError, match=r"x\.fbx: unknown type '\.fbx' \(known: \.obj, \.ply, \.stl, \.off, \.glb, "
                                        r"\.gltf, \.gii"):
        read_mesh(tmp_path / "x.fbx")
    (tmp_path / "empty.ply").write_bytes(b"")
    with pytest.raises(MeshError, match=r"empty\.ply is empty"):
        read_mesh(tmp_path / "empty.ply")
    (tmp_path / "corrupt.ply").write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 99\n"
                                           b"property float x\nend_header\n\x00\x01")
    with pytest.raises(MeshError, match=r"cannot read mesh file .*corrupt\.ply: it is corrupt or not a PLY file"):
        read_mesh(tmp_path / "corrupt.ply")
    cloud = tmp_path / "cloud.ply"
    trimesh.PointCloud(np.random.default_rng(0).random((20, 3))).export(cloud)
    with pytest.raises(MeshError, match=r"cloud\.ply is not a triangle mesh .*PointCloud"):
        read_mesh(cloud)
    nan = tmp_path / "nan.obj"
    nan.write_text("v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n")
    with pytest.raises(MeshError, match=r"nan\.obj has 1 vertices with NaN or infinite coordinates \(first: vertex 2\)"):
        read_mesh(nan)
    noface = tmp_path / "noface.obj"
    noface.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    with pytest.raises(MeshError, match=r"noface\.obj is not a triangle mesh"):
        read_mesh(noface)


def test_quads_in_files_are_triangulated(tmp_path):
    p = tmp_path / "quad.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")
    tm = read_mesh(p)
    assert tm.faces.shape == (2, 3)
    np.testing.assert_allclose(tm.normals, np.tile([0, 0, 1], (4, 1)), atol=1e-6)


@pytest.mark.parametrize("source,expect", [
    (([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2, 3]]),
     r"mesh array: faces must be triangles, got shape \(1, 4\) \(quads\): split each into two"),
    (([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 3]]), r"mesh array: face 0 \[0, 1, 3\] refers to a vertex out of range 0\.\.2"),
    (([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[-1, 1, 2]]), r"out of range"),
    (([[0, 0, 0], [1, 0, np.inf], [0, 1, 0]], [[0, 1, 2]]), r"mesh array has 1 vertices with NaN or infinite"),
    (([[0, 0], [1, 0], [0, 1]], [[0, 1, 2]]), r"vertices must have shape \(V, 3\), got \(3, 2\)"),
    ((np.zeros((0, 3)), np.zeros((0, 3), int)), r"mesh array is empty \(0 vertices, 0 faces\)"),
    (([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 1.5]]), r"faces must be integer vertex indices"),
    (([[0, 0, 0]],), r"give \(vertices, faces\)"),
    (42, r"cannot read a mesh from a int"),
])
def test_bad_arrays_are_named(source, expect):
    with pytest.raises(MeshError, match=expect):
        read_mesh(source)


# --- the scene --------------------------------------------------------------------------------
def test_add_mesh_loads_each_source_once(tmp_path, mesh_loader):
    m = icosphere(1)
    p = tmp_path / "ball.ply"
    m.export(p)
    s = pl.Scene()
    s.add("sphere")
    a = s.add_mesh(p, material=pl.Material(color=(1, 0, 0)))
    b = s.add_mesh(str(tmp_path / "." / "ball.ply"), transform=pl.translate(3, 0, 0))   # same resolved path
    c = s.add_mesh(p, lod="full")
    d = s.add_mesh(m)
    e = s.add_mesh(m)
    assert a.mesh is b.mesh and d.mesh is e.mesh and c.mesh is not a.mesh and d.mesh is not a.mesh
    assert [opt["lod"] for _, opt in mesh_loader] == ["dag", "full", "dag"]
    assert [o.object_id for o in s.meshes] == [2, 3, 4, 5, 6] and s.object_count == 6
    assert a.mesh.original_triangles == 80 and a.mesh.name == "ball.ply" and c.mesh.lod == "full"
    assert a.material.color == (1.0, 0.0, 0.0) and b.transform[0, 3] == 3
    # a file changed on disk is a new source
    icosphere(2).export(p)
    assert s.add_mesh(p).mesh.original_triangles == 320


def test_add_mesh_instances(mesh_loader):
    m = icosphere(0)
    tr = np.repeat(np.eye(4)[None], 3, axis=0)
    tr[:, 0, 3] = [-2, 0, 2]
    s = pl.Scene()
    o = s.add_mesh_instances((m.vertices, m.faces), 3, transforms=tr, transform=pl.scale(2),
                             colors=[[1, 0, 0], [0, 1, 0], [0, 0, 1]], variant="meshlets", aa="4xSS")
    assert o.count == 3 and o.variant == "meshlets" and o.aa == "4xSS" and o.colors.dtype == np.float32
    assert s.mesh_instance_count == 3 and s.instance_count == 0 and s.object_count == 1
    np.testing.assert_array_equal(o.transforms, tr)
    np.testing.assert_array_equal(o.transform, pl.scale(2))
    np.testing.assert_array_equal(o.colors, np.eye(3))


@pytest.mark.parametrize("kwargs,expect", [
    ({"count": 0}, r"mesh 'array': instance count must be an integer of at least 1"),
    ({"count": 2.5}, r"instance count must be an integer"),
    ({"count": 2, "transforms": np.zeros((3, 4, 4))}, r"transforms must be a finite \[2, 4, 4\] array, got shape \(3, 4, 4\)"),
    ({"count": 1, "transforms": np.full((1, 4, 4), np.nan)}, r"transforms must be a finite"),
    ({"count": 2, "transforms": np.stack([np.eye(4), np.diag([1, 0, 1, 1])])}, r"instance 1's transform is singular"),
    ({"count": 1, "transform": pl.scale(0, 1, 1)}, r"mesh 'array': a transform must be invertible"),
    ({"count": 2, "colors": [[1, 0, 0]]}, r"colors must be a \[2, 3\] array of values in \[0, 1\]"),
    ({"count": 1, "colors": [[1.5, 0, 0]]}, r"colors must be a \[1, 3\] array"),
    ({"count": 1, "colors": [[np.nan, 0, 0]]}, r"colors must be"),
    ({"count": 1, "lod": "nanite"}, r"lod must be one of 'dag', 'full', 'chain', got 'nanite'"),
    ({"count": 1, "material": (1, 0, 0)}, r"material must be a paramlod\.Material"),
    ({"count": 1, "variant": ""}, r"variant must be a name"),
    ({"count": 1, "aa": 4}, r"aa must be a name"),
])
def test_add_mesh_instances_validation(mesh_loader, kwargs, expect):
    m = icosphere(0)
    s = pl.Scene()
    with pytest.raises(SceneError, match=expect):
        s.add_mesh_instances((m.vertices, m.faces), **kwargs)
    assert not s.meshes and not mesh_loader   # checked before anything is loaded


def test_mesh_errors_reach_the_caller(tmp_path, mesh_loader):
    with pytest.raises(MeshError, match=r"nothing\.ply does not exist"):
        pl.Scene().add_mesh(tmp_path / "nothing.ply")


def test_object_limit_counts_meshes(mesh_loader, monkeypatch):
    from paramlod.scene import scene as scene_module

    monkeypatch.setattr(scene_module, "MAX_OBJECTS", 3)
    m = icosphere(0)
    s = pl.Scene()
    s.add("sphere")
    s.add_mesh(m)
    s.add_mesh(m)
    with pytest.raises(SceneError, match="at most 3 objects"):
        s.add_mesh(m)
    with pytest.raises(SceneError, match="at most 3 objects"):
        s.add("torus")


def test_subscene_with_meshes(mesh_loader):
    m = icosphere(0)
    s = pl.Scene(background=(0, 0, 0))
    f = s.add("sphere")
    g = s.add_mesh(m)
    h = s.add_mesh(m)
    sub = s.subscene(meshes=[h])
    assert sub.meshes == [h] and sub.objects == [] and sub.surfels == [] and sub.background == (0, 0, 0)
    assert sub.meshes[0].object_id == 3
    both = s.subscene([f], (), [g])                 # the positional call of the pipeline, plus meshes
    assert both.objects == [f] and both.meshes == [g]
    assert s.subscene([f], ()).meshes == []
    with pytest.raises(SceneError, match="does not belong"):
        s.subscene(meshes=[pl.Scene().add_mesh(m)])


def test_loader_options_pass_through():
    got = []
    previous = loaders.LOADERS.get("probe")
    loaders.register_loader("probe", lambda src, **opt: got.append((src, opt)) or "done")
    try:
        assert loaders.load("probe", "x", lod="full", a=1) == "done"
        assert loaders.load("probe", "y") == "done"
        assert got == [("x", {"lod": "full", "a": 1}), ("y", {})]
    finally:
        loaders.LOADERS.pop("probe")
        if previous is not None:
            loaders.register_loader("probe", previous)
    with pytest.raises(SceneError, match=r"no loader for 'nothing' objects"):
        loaders.load("nothing", "x")


def test_source_keys():
    a = np.zeros(3)
    assert source_key(a) == source_key(a) != source_key(np.zeros(3))
    assert source_key("a/../b.ply")[1] == source_key("b.ply")[1]
