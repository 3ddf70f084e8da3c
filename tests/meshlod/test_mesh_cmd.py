"""``paramlod mesh build | info``: output and errors (one line, no traceback, checked before the work)."""
import json

import numpy as np
import pytest
import trimesh

from helpers.meshes import sphere
from paramlod.app.cli import main
from paramlod.meshlod import source
from paramlod.meshlod.format import load_meshlod


@pytest.fixture
def ply(tmp_path, monkeypatch):
    monkeypatch.setenv("PARAMLOD_CACHE", str(tmp_path / "cache"))
    v, f = sphere(3)
    path = tmp_path / "ball.ply"
    trimesh.Trimesh(v, f, process=False).export(path)
    return path


def test_build_writes_the_file_and_prints_the_table(ply, tmp_path, capsys):
    out = tmp_path / "ball.meshlod"
    assert main(["mesh", "build", str(ply), "-o", str(out), "-q"]) == 0
    text = capsys.readouterr().out
    lod = load_meshlod(out)
    assert lod.name == "ball.ply" and lod.original_triangles == 1280
    assert f"ball.ply: lod dag, 1,280 triangles, {len(lod.vertices):,} vertices" in text
    assert f"{lod.levels} levels, {len(lod.clusters)} clusters, 1 root" in text
    lines = text.splitlines()
    table = lines[lines.index("  level  clusters  triangles") + 1:][:lod.levels]
    rows = [[int(x.replace(",", "")) for x in row.split()] for row in table]
    c = lod.clusters
    assert rows == [[k, int(np.sum(c["level"] == k)), int(c["count"][c["level"] == k].sum())] for k in range(lod.levels)]
    assert "error " in text and "object units" in text and f"file {out.stat().st_size:,}" in text
    assert "build " in text and f"written to {out}" in text


def test_info_of_a_file_and_of_a_mesh(ply, tmp_path, capsys):
    out = tmp_path / "ball.meshlod"
    assert main(["mesh", "build", str(ply), "-o", str(out), "--full", "-q"]) == 0
    capsys.readouterr()
    assert main(["mesh", "info", str(out), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["lod"] == "full" and info["levels"] == 1 and info["roots"] == info["clusters"]
    assert info["file_bytes"] == out.stat().st_size and info["triangles_per_level"] == [1280]
    assert main(["mesh", "info", str(ply)]) == 0   # a mesh file: its (cached) build
    text = capsys.readouterr().out
    assert "ball.ply: lod dag, 1,280 triangles" in text and "root" in text


def test_build_without_output_fills_the_cache(ply, tmp_path, capsys, monkeypatch):
    assert main(["mesh", "build", str(ply), "-q"]) == 0
    assert len(list((tmp_path / "cache" / "meshlod").glob("*.meshlod"))) == 1
    calls = []
    monkeypatch.setattr(source, "build_dag", lambda *a, **k: calls.append(1))
    assert main(["mesh", "info", str(ply)]) == 0   # served from the cache: no build
    assert calls == []


def _error(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.startswith("paramlod: error: ")
    return err


def test_output_is_checked_before_the_build(ply, tmp_path, capsys, monkeypatch):
    def no_build(*a, **k):
        raise AssertionError("built before checking the output")

    monkeypatch.setattr(source, "build_dag", no_build)
    assert main(["mesh", "build", str(ply), "-o", str(tmp_path / "missing" / "x.meshlod")]) == 2
    assert "folder" in _error(capsys) and not (tmp_path / "missing").exists()
    assert main(["mesh", "build", str(ply), "-o", str(tmp_path / "x.ply")]) == 2
    assert "must be a .meshlod file" in _error(capsys)


def test_errors_name_the_file(ply, tmp_path, capsys):
    assert main(["mesh", "build", str(tmp_path / "none.ply")]) == 2
    assert "none.ply does not exist" in _error(capsys)
    odd = tmp_path / "mesh.xyz1"
    odd.write_text("1 2 3")
    assert main(["mesh", "info", str(odd)]) == 2
    assert "unknown type" in _error(capsys)
    bad = tmp_path / "bad.meshlod"
    bad.write_bytes(b"PLMESHLD" + bytes(64))
    assert main(["mesh", "info", str(bad)]) == 2
    assert "bad.meshlod" in _error(capsys)
    assert main(["mesh", "build", str(bad)]) == 2
    assert "already a .meshlod file" in _error(capsys)
    far = tmp_path / "far.obj"
    far.write_text("v 0 0 0\nv 1e20 0 0\nv 0 1e20 0\nf 1 2 3\n")
    assert main(["mesh", "build", str(far), "--no-cache", "-o", str(tmp_path / "far.meshlod")]) == 2
    assert "far.obj: vertices reach 1e+20" in _error(capsys)
