"""Bad input gives clear errors and writes nothing; the ``surfels`` command line."""
import json
import zipfile

import numpy as np
import pytest

trimesh = pytest.importorskip("trimesh")

from paramlod.errors import ParamlodError  # noqa: E402
from paramlod.surfels import SurfelError, SurfelSet  # noqa: E402
from paramlod.surfels.build import load_mesh, mesh_gbuffer, sample_mesh, soup_from_trimesh  # noqa: E402
from paramlod.app.surfels_cmd import main  # noqa: E402

PLY_HEAD = ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
            "property float z\n")


@pytest.fixture
def small_set():
    return sample_mesh(trimesh.creation.icosphere(subdivisions=2), 300, views=4, resolution=32)


@pytest.fixture
def mesh_file(tmp_path):
    p = tmp_path / "box.stl"
    trimesh.creation.box((1, 2, 0.5)).export(p)
    return p


@pytest.mark.parametrize("name,content,message", [
    ("missing.obj", None, "does not exist"),
    ("empty.ply", b"", "is empty"),
    ("garbage.glb", bytes(range(256)) * 2, "corrupt or not a GLB"),
    ("cut.ply", (PLY_HEAD + "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0\n").encode(),
     "corrupt or not a PLY"),
    ("nan.obj", b"v 0 0 0\nv 1 0 0\nv 0 nan 0\nf 1 2 3\n", "NaN or infinite"),
    ("points.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", "has no faces"),
    ("cloud.ply", (PLY_HEAD + "end_header\n0 0 0\n1 0 0\n0 1 0\n").encode(), "has no faces"),
    ("flat.obj", b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", "zero area"),
    ("mesh.xyz", b"0 0 0\n", "unknown type"),
])
def test_bad_mesh_files(tmp_path, name, content, message):
    p = tmp_path / name
    if content is not None:
        p.write_bytes(content)
    with pytest.raises(SurfelError, match=message):
        load_mesh(p)


@pytest.mark.parametrize("kw,message", [
    ({"n": 0}, "positive integer"), ({"n": -5}, "positive integer"), ({"n": 2.5}, "positive integer"),
    ({"n": "many"}, "positive integer"), ({"n": 10, "views": 0}, "views"), ({"n": 10, "views": 33}, "views"),
    ({"n": 10, "resolution": 4}, "resolution"),
    ({"n": 10, "seed": -1}, "seed must be a non-negative integer, got -1"), ({"n": 10, "seed": 1.5}, "seed"),
])
def test_bad_sampling_parameters(mesh_file, kw, message):
    n = kw.pop("n")
    with pytest.raises(SurfelError, match=message):
        sample_mesh(mesh_file, n, **kw)


def test_a_mesh_too_large_to_square_in_float32_names_its_file(tmp_path):
    # its squared distances were infinite: "surfel set: 'radii' contains NaN or infinite values"
    far, near = tmp_path / "far.obj", tmp_path / "near.obj"
    far.write_text("v 0 0 0\nv 1e20 0 0\nv 0 1e20 0\nf 1 2 3\n")
    near.write_text("v 0 0 0\nv 1e19 0 0\nv 0 1e19 0\nf 1 2 3\n")
    with pytest.raises(SurfelError, match=r"mesh 'far.obj' spans 1.41e\+20, beyond 1.84e\+19"):
        sample_mesh(far, 10, views=4, resolution=32)
    assert np.isfinite(sample_mesh(near, 10, views=4, resolution=32).radii).all()


def test_a_gbuffer_with_non_finite_positions_is_refused_where_covered():
    # GBuffer.check: a NaN position at a covered pixel is named; at an uncovered one it is ignored
    g = mesh_gbuffer(soup_from_trimesh(trimesh.creation.icosphere(subdivisions=2)), views=2, resolution=16)
    covered = int(g.valid.sum())
    assert g.check() == covered
    empty = np.flatnonzero(~g.valid.reshape(-1))[0]
    g.position.reshape(-1, 4)[empty, 0] = np.nan
    assert g.check() == covered
    hit = np.flatnonzero(g.valid.reshape(-1))[:2]
    g.position.reshape(-1, 4)[hit, 2] = np.inf
    with pytest.raises(SurfelError, match="2 G-buffer pixels have non-finite positions"):
        g.check()


def test_truncated_or_corrupt_surfels_files(tmp_path, small_set):
    good = small_set.save(tmp_path / "good.surfels")
    data = good.read_bytes()
    for cut in (len(data) // 2, len(data) - 10, 30):
        bad = tmp_path / f"cut{cut}.surfels"
        bad.write_bytes(data[:cut])
        with pytest.raises(SurfelError, match="truncated or corrupt"):
            SurfelSet.load(bad)
    (tmp_path / "noise.surfels").write_bytes(b"\x00" * 100)
    with pytest.raises(SurfelError, match="truncated or corrupt"):
        SurfelSet.load(tmp_path / "noise.surfels")
    with pytest.raises(SurfelError, match="does not exist"):
        SurfelSet.load(tmp_path / "nope.surfels")
    # a valid zip that is not a surfel file, and one whose arrays disagree
    np.savez(tmp_path / "other.npz", a=np.zeros(3))
    with pytest.raises(SurfelError, match="not a .surfels file"):
        SurfelSet.load(tmp_path / "other.npz")
    with zipfile.ZipFile(good) as zf:
        entries = {n: zf.read(n) for n in zf.namelist()}
    import io
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.full((len(small_set) - 1,), 0.1, np.float32))
    entries["radii.npy"] = buf.getvalue()
    with zipfile.ZipFile(tmp_path / "mismatch.surfels", "w") as zf:
        for n, b in entries.items():
            zf.writestr(n, b)
    with pytest.raises(SurfelError, match="'radii' must be float32"):
        SurfelSet.load(tmp_path / "mismatch.surfels")


def test_nothing_half_written(tmp_path, small_set, monkeypatch):
    with pytest.raises(ParamlodError, match="does not exist"):
        small_set.save(tmp_path / "no" / "such" / "x.surfels")
    target = tmp_path / "x.surfels"
    calls = []

    def failing(buf, arr, **kw):
        calls.append(1)
        if len(calls) > 3:
            raise OSError(28, "No space left on device")
        return real(buf, arr, **kw)

    real = np.lib.format.write_array
    monkeypatch.setattr(np.lib.format, "write_array", failing)
    with pytest.raises(ParamlodError, match="No space left"):
        small_set.save(target)
    monkeypatch.undo()
    assert list(tmp_path.iterdir()) == []
    # bad arrays are refused before anything is written
    bad = small_set.prefix(len(small_set))
    bad.positions = bad.positions.copy()
    bad.positions[3, 1] = np.nan
    with pytest.raises(SurfelError, match="NaN"):
        bad.save(target)
    assert not target.exists()


def test_cli_sample_info_render(tmp_path, mesh_file, capsys):
    out = tmp_path / "box.surfels"
    assert main(["surfels", "sample", str(mesh_file), "-n", "500", "-o", str(out),
                 "--views", "4", "--resolution", "32"]) == 0
    captured = capsys.readouterr()
    assert "500 surfels" in captured.out and "sampling" in captured.err   # progress bar on stderr
    s = SurfelSet.load(out)
    assert len(s) == 500 and s.meta["views"] == 4
    assert main(["surfels", "info", str(out), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["surfels"] == 500 and info["packing"] == pytest.approx(s.packing)
    assert main(["surfels", "info", str(out)]) == 0
    assert "packing" in capsys.readouterr().out
    png, exr = tmp_path / "a.png", tmp_path / "a.exr"
    assert main(["surfels", "render", str(out), "--px", "3", "--size", "64x48", "-o", str(png), "-o", str(exr),
                 "--stats", str(tmp_path / "s.json")]) == 0
    assert "prefix" in capsys.readouterr().out
    from PIL import Image
    assert Image.open(png).size == (64, 48) and exr.stat().st_size > 0
    assert json.loads((tmp_path / "s.json").read_text())["surfels"]["size_px"] == 3
    assert main(["surfels", "render", str(out), "--count", "100", "-o", str(png), "--eye", "3,2,4"]) == 0
    assert "prefix 100 of 500" in capsys.readouterr().out


def test_cli_bad_input(tmp_path, mesh_file, capsys):
    out = tmp_path / "x.surfels"
    for args, message in [
        (["sample", str(tmp_path / "missing.obj"), "-n", "10", "-o", str(out)], "does not exist"),
        (["sample", str(mesh_file), "-n", "0", "-o", str(out)], "positive integer"),
        (["sample", str(mesh_file), "-n", "10", "--seed=-1", "-o", str(out)], "seed must be a non-negative integer"),
        (["sample", str(mesh_file), "-n", "10", "-o", str(tmp_path / "nodir" / "x.surfels")], "does not exist"),
        (["info", str(mesh_file)], "truncated or corrupt"),
        (["render", str(tmp_path / "none.surfels"), "-o", str(tmp_path / "a.png")], "does not exist"),
    ]:
        assert main(["surfels", *args]) == 2
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err
    assert list(p.name for p in tmp_path.iterdir()) == ["box.stl"]
    with pytest.raises(SystemExit):
        main(["surfels", "render", "x.surfels", "--px", "2", "--count", "5", "-o", "a.png"])


def test_cli_scene_file(tmp_path, capsys):
    scene = tmp_path / "s.toml"
    scene.write_text('[[objects]]\nfunction = "sphere"\ncolor = [0.2, 0.6, 0.3]\n')
    out = tmp_path / "s.surfels"
    assert main(["surfels", "sample", str(scene), "-n", "200", "-o", str(out), "--views", "4",
                 "--resolution", "48", "-q"]) == 0
    s = SurfelSet.load(out)
    assert len(s) == 200 and np.all(s.colors[:, 1] > s.colors[:, 0])
    assert np.abs(np.linalg.norm(s.positions, axis=1) - 1).max() < 0.06
