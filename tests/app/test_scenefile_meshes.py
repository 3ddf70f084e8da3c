"""Scene files with meshes: ``[[objects]] mesh = "x.ply"`` with lod, material, transform, variant,
instances (a builder or a grid), and every error naming the file, the line and the field.

The registered "mesh" loader is wrapped to count its calls (the ``mesh_loader`` fixture, tests/conftest.py).
"""
import numpy as np
import pytest
import trimesh

import paramlod as pl
from paramlod.app.cli import main
from paramlod.app.scenefile import load_scene


HEAD = """[camera]
eye = [0, 0, 6]
size = [64, 48]

"""


@pytest.fixture
def files(tmp_path):
    (tmp_path / "meshes").mkdir()
    trimesh.creation.icosphere(1).export(tmp_path / "meshes" / "ball.ply")
    trimesh.creation.box().export(tmp_path / "box.obj")
    return tmp_path


def write(tmp_path, body):
    p = tmp_path / "s.toml"
    p.write_text(HEAD + body)
    return p


def test_mesh_objects(files, mesh_loader):
    p = write(files, '''[[objects]]
function = "sphere"

[[objects]]
mesh = "meshes/ball.ply"
color = [0.9, 0.2, 0.1]
specular = 0.5
translate = [1, 0, 0]
scale = 2

[[objects]]
mesh = "meshes/ball.ply"
lod = "full"
variant = "meshlets:4xSS"
rotate = [90, [0, 1, 0]]

[[objects]]
mesh = "box.obj"
matrix = [[1, 0, 0, 0], [0, 1, 0, 5], [0, 0, 1, 0], [0, 0, 0, 1]]
''')
    sf = load_scene(p)
    s = sf.scene
    assert len(s.objects) == 1 and len(s.meshes) == 3 and [o.object_id for o in s.meshes] == [2, 3, 4]
    a, b, c = s.meshes
    assert a.mesh.name == "ball.ply" and a.mesh.original_triangles == 80 and c.mesh.original_triangles == 12
    assert a.material.color == (0.9, 0.2, 0.1) and a.material.specular == 0.5
    np.testing.assert_allclose(a.transform, pl.translate(1, 0, 0) @ pl.scale(2))
    np.testing.assert_allclose(b.transform, pl.rotate(90, (0, 1, 0)))
    assert c.transform[1, 3] == 5
    assert (a.variant, a.aa) == (None, None) and (b.variant, b.aa) == ("meshlets", "4xSS")
    assert [opt["lod"] for _, opt in mesh_loader] == ["dag", "full", "dag"]
    assert all(src.is_absolute() for src, _ in mesh_loader)   # relative to the scene file
    # the scene's objects keep their variants: the parametric one uses the frame's
    assert sf.object_variants == ["points", "meshlets", "meshlets:4xSS", "meshlets"]


def test_mesh_instances(files, mesh_loader, monkeypatch):
    monkeypatch.setenv("PARAMLOD_TRUST_SCENE", "1")   # numpy:eye is not a registered builder
    p = write(files, '''[[objects]]
mesh = "meshes/ball.ply"
instances = { grid = [3, 1, 2], spacing = [2, 1, 4] }

[[objects]]
mesh = "meshes/ball.ply"
instances = { builder = "numpy:eye", args = { N = 4 } }
''')
    with pytest.raises(pl.SceneError, match=r"s\.toml:11: objects\[1\]\.instances: builder numpy:eye must return "
                                            r"a dict with count and optionally colors, transforms"):
        load_scene(p)
    p.write_text(p.read_text().replace('builder = "numpy:eye", args = { N = 4 }', 'grid = [2, 2, 2]'))
    mesh_loader.clear()
    s = load_scene(p).scene
    a, b = s.meshes
    assert a.mesh is b.mesh and len(mesh_loader) == 1 and a.count == 6 and b.count == 8
    xs, zs = a.transforms[:, 0, 3], a.transforms[:, 2, 3]
    assert sorted(set(xs)) == [-2, 0, 2] and sorted(set(zs)) == [-2, 2] and set(a.transforms[:, 1, 3]) == {0}
    np.testing.assert_array_equal(b.transforms[:, :3, 3].min(axis=0), [-0.5, -0.5, -0.5])


def test_a_builder_gives_mesh_instances(files, mesh_loader, tmp_path, monkeypatch):
    monkeypatch.setenv("PARAMLOD_TRUST_SCENE", "1")   # my_rows:rows is the user's own code
    (tmp_path / "my_rows.py").write_text(
        "import numpy as np\n"
        "def rows(n):\n"
        "    t = np.repeat(np.eye(4)[None], n, axis=0)\n"
        "    t[:, 0, 3] = np.arange(n)\n"
        "    return {'count': n, 'transforms': t, 'colors': np.full((n, 3), 0.5)}\n"
        "def with_params(n):\n"
        "    return {'count': n, 'params': {'radius': 1}}\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    p = write(files, '[[objects]]\nmesh = "box.obj"\ninstances = { builder = "my_rows:rows", args = { n = 5 } }\n')
    (o,) = load_scene(p).scene.meshes
    assert o.count == 5 and o.colors.shape == (5, 3) and list(o.transforms[:, 0, 3]) == [0, 1, 2, 3, 4]
    p.write_text(p.read_text().replace("my_rows:rows", "my_rows:with_params"))
    with pytest.raises(pl.SceneError, match=r"objects\[0\]\.instances: builder my_rows:with_params must return .*got "
                                            r"\['count', 'params'\]"):
        load_scene(p)


def test_function_objects_take_a_grid_too(files, mesh_loader):
    p = write(files, '[[objects]]\nfunction = "sphere"\ninstances = { grid = [2, 1, 1], spacing = 3 }\n')
    (o,) = load_scene(p).scene.objects
    assert o.count == 2 and sorted(o.transforms[:, 0, 3]) == [-1.5, 1.5]


@pytest.mark.parametrize("body,expect", [
    ('mesh = "missing.ply"', r"s\.toml:6: objects\[0\]\.mesh: mesh file .*missing\.ply does not exist"),
    ('mesh = "notes.txt"', r"s\.toml:6: objects\[0\]\.mesh: mesh file .*notes\.txt: unknown type '\.txt' \(known: "),
    ('mesh = "empty.ply"', r"s\.toml:6: objects\[0\]\.mesh: mesh file .*empty\.ply is empty"),
    ("mesh = 3", r"s\.toml:6: objects\[0\]\.mesh: must be a file name"),
    ('mesh = "box.obj"\nlod = "half"', r"s\.toml:7: objects\[0\]\.lod: must be one of 'dag', 'full'"),
    ('function = "sphere"\nlod = "full"', r"s\.toml:7: objects\[0\]\.lod: is for mesh objects"),
    ('mesh = "box.obj"\nfunction = "sphere"', r"objects\[0\]\.mesh: an object is one of function, mesh, surfels, "
                                              r"sh_field; it has both function and mesh"),
    ('mesh = "box.obj"\nparams = { radius = 1 }', r"s\.toml:7: objects\[0\]\.params: a mesh takes no params"),
    ('mesh = "box.obj"\nvariant = "tess"', r"s\.toml:7: objects\[0\]\.variant: unknown variant 'tess' for a mesh "
                                           r"\(available: .*meshlets"),
    ('mesh = "box.obj"\ncolor = [2, 0, 0]', r"s\.toml:5: objects\[0\]: material color must be three numbers in \[0, 1\]"),
    ('mesh = "box.obj"\nscale = [1, 0, 1]', r"objects\[0\]: mesh 'box\.obj': a transform must be invertible"),
    ('mesh = "box.obj"\nlodd = "full"', r"s\.toml:7: objects\[0\]\.lodd: unknown field \(allowed: .*lod, matrix, mesh"),
    ('mesh = "box.obj"\ninstances = { grid = [0, 1, 1] }', r"s\.toml:7: objects\[0\]\.instances: grid must be \[nx, ny, nz\]"),
    ('mesh = "box.obj"\ninstances = { grid = [2, 1, 1], spacing = -1 }', r"instances: spacing must be a positive"),
    ('mesh = "box.obj"\ninstances = { grid = [10000000, 10000000, 10000000] }', r"at most 2\^24 copies"),
    ('mesh = "box.obj"\ninstances = { grid = [2, 1, 1], seed = 3 }', r"instances: must be \{ builder = "),
    ('mesh = "box.obj"\ninstances = 4', r"instances: must be \{ builder = "),
    ('mesh = "box.obj"\ninstances = { builder = "no_such_module:f" }', r"s\.toml:7: objects\[0\]\.instances: cannot load builder 'no_such_module:f'"),
    ('color = [1, 0, 0]', r"s\.toml:5: objects\[0\]\.function: is required .*or mesh = "),
])
def test_mesh_errors_name_file_line_and_field(files, mesh_loader, body, expect, monkeypatch):
    monkeypatch.setenv("PARAMLOD_TRUST_SCENE", "1")   # so that a missing builder module is what fails
    (files / "notes.txt").write_text("hello")
    (files / "empty.ply").write_bytes(b"")
    p = write(files, "[[objects]]\n" + body + "\n")
    with pytest.raises(pl.SceneError, match=expect):
        load_scene(p)


def test_corrupt_and_degenerate_mesh_files(files, mesh_loader):
    (files / "bad.stl").write_bytes(b"solid x\nfacet normal 0 0 1\n outer loop\n vertex 0 0 nonsense\n")
    p = write(files, '[[objects]]\nmesh = "bad.stl"\n')
    with pytest.raises(pl.SceneError, match=r"s\.toml:6: objects\[0\]\.mesh: (cannot read mesh file .*bad\.stl|"
                                            r"mesh file .*bad\.stl is not a triangle mesh)"):
        load_scene(p)
    v = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], float)
    trimesh.Trimesh(v, [[0, 1, 2]], process=False).export(files / "flat.ply")
    p.write_text(p.read_text().replace("bad.stl", "flat.ply"))
    with pytest.raises(pl.SceneError, match=r"objects\[0\]\.mesh: mesh file .*flat\.ply: all 1 faces are degenerate"):
        load_scene(p)


def test_a_chain_mesh_renders_one_level(files):
    p = write(files, '''[[objects]]
mesh = "meshes/ball.ply"
lod = "chain"
''')
    sf = load_scene(p)
    (m,) = sf.scene.meshes
    assert m.mesh.lod == "chain" and m.mesh.levels >= 1
    sf.settings.mesh.cull_backface = sf.settings.mesh.cull_frustum = False
    f = pl.render(sf.scene, sf.camera, settings=sf.settings)
    assert (f.object_id == 1).sum() > 0
    c = m.mesh.clusters
    per_level = [int(c["count"][c["level"] == k].sum()) for k in range(m.mesh.levels)]
    assert f.stats["triangles_drawn"] in per_level   # one whole level, whichever the camera asks for


SPHERE, BALL = '[[objects]]\nfunction = "sphere"\n', '[[objects]]\nmesh = "meshes/ball.ply"\n'


@pytest.mark.parametrize("body, options, said", [
    (SPHERE, ["--variant", "meshlets"], "64x48 points on"),   # meshlets draw only meshes
    (BALL, ["--variant", "tess"], "64x48 meshlets-gl on"),    # meshes follow tess so
    (SPHERE + "\n" + BALL, [], "64x48 points, meshlets on"),
    (SPHERE, ["--aa", "4xSS"], "64x48 points (4xSS) on"),
    (SPHERE, ["--variant", "tess", "--aa", "hybrid"], "64x48 tess (hybrid) on"),
])
def test_render_says_what_drew_the_frame(files, capsys, body, options, said):
    argv = ["render", str(write(files, body)), "-o", str(files / "f.png")]
    assert main(argv + options) == 0
    out = capsys.readouterr().out
    assert said in out and ("render patches" in out) == ("function" in body), out
