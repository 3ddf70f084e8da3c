"""The .meshlod file (paramlod.meshlod.format), mesh_info, and load_mesh with its cache
(paramlod.meshlod.source)."""
import warnings

import numpy as np
import pytest

from helpers.meshes import grid, sphere
from paramlod.errors import MeshError
from paramlod.meshlod import format as fmt
from paramlod.meshlod import source
from paramlod.meshlod.build.dag import BuildSettings, build_dag
from paramlod.meshlod.format import MeshLod, load_meshlod, mesh_info, meshlod_bytes, save_meshlod


@pytest.fixture(scope="module")
def lod():
    v, f = sphere(3)
    m = build_dag(v, f, None, progress=False, name="sphere")
    m.info["content_hash"] = "abc"
    return m


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("PARAMLOD_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache" / "meshlod"


@pytest.fixture
def builds(monkeypatch):
    """Counts the builds load_mesh makes."""
    calls = []

    def counting(*args, **kwargs):
        calls.append(kwargs.get("name"))
        return build_dag(*args, **kwargs)

    monkeypatch.setattr(source, "build_dag", counting)
    return calls


def same(a: MeshLod, b: MeshLod):
    for name in ("vertices", "normals", "triangles", "clusters"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes(), name
    assert (a.name, a.lod, a.info) == (b.name, b.lod, b.info)


# --- the file --------------------------------------------------------------------------------------
def test_round_trip_is_bit_exact(lod, tmp_path):
    path = save_meshlod(lod, tmp_path / "s.meshlod")
    back = load_meshlod(path)
    same(lod, back)
    assert back.clusters.flags.writeable and back.vertices.flags.writeable
    assert np.isinf(back.clusters["parent_error"][lod.roots]).all()


def test_bytes_are_deterministic(lod, tmp_path):
    a = save_meshlod(lod, tmp_path / "a.meshlod").read_bytes()
    b = save_meshlod(lod, tmp_path / "b.meshlod").read_bytes()
    assert a == b == meshlod_bytes(load_meshlod(tmp_path / "a.meshlod"))
    assert a[:8] == fmt.MAGIC and int.from_bytes(a[8:12], "little") == fmt.VERSION
    # a different MeshLod gives different bytes (the hash covers everything)
    other = MeshLod(lod.vertices, lod.normals, lod.triangles, lod.clusters, name="other", lod=lod.lod, info=lod.info)
    assert meshlod_bytes(other) != a


@pytest.mark.parametrize("damage, message", [
    (lambda b: b[:len(b) // 2], "truncated"),
    (lambda b: b[:-1], "truncated"),
    (lambda b: b[:40], "truncated"),
    (lambda b: b + b"x", "after its end"),
    (lambda b: b[:len(b) // 2] + bytes([b[len(b) // 2] ^ 1]) + b[len(b) // 2 + 1:], "checksum"),
    (lambda b: b[:8] + (2).to_bytes(4, "little") + b[12:], "version 2; this paramlod reads version 1"),
    (lambda b: b"PLY\n" + b[4:], "not a .meshlod file"),
    (lambda b: b"", "not a .meshlod file"),
    (lambda b: b[:16] + b"{" * 8 + b[24:], "corrupt"),
])
def test_damaged_files_are_refused_by_name(lod, tmp_path, damage, message):
    good = meshlod_bytes(lod)
    path = tmp_path / "bad.meshlod"
    path.write_bytes(damage(good))
    with pytest.raises(MeshError, match=message) as exc:
        load_meshlod(path)
    assert str(path) in str(exc.value)


def test_missing_file_folder_and_unwritable_target(lod, tmp_path):
    with pytest.raises(MeshError, match="does not exist"):
        load_meshlod(tmp_path / "none.meshlod")
    with pytest.raises(MeshError, match="is a folder"):
        load_meshlod(tmp_path)
    with pytest.raises(MeshError, match="does not exist"):
        save_meshlod(lod, tmp_path / "no" / "such" / "x.meshlod")
    assert not (tmp_path / "no").exists()


def test_a_failed_save_leaves_the_old_file(lod, tmp_path):
    path = save_meshlod(lod, tmp_path / "s.meshlod")
    before = path.read_bytes()
    bad = MeshLod(lod.vertices, lod.normals, lod.triangles, lod.clusters, name="x", lod="dag", info={"f": object()})
    with pytest.raises(MeshError, match="info cannot be stored"):
        save_meshlod(bad, path)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["s.meshlod"]   # no temporary file left


def test_invalid_meshlods_are_not_written(lod, tmp_path):
    t = lod.triangles.copy()
    t[0, 0] = len(lod.vertices)
    bad = MeshLod(lod.vertices, lod.normals, t, lod.clusters, name="x")
    with pytest.raises(MeshError, match="out of range"):
        save_meshlod(bad, tmp_path / "x.meshlod")
    c = lod.clusters.copy()
    c["count"][-1] += 1
    with pytest.raises(MeshError, match="triangle range"):
        save_meshlod(MeshLod(lod.vertices, lod.normals, lod.triangles, c, name="x"), tmp_path / "x.meshlod")
    assert not (tmp_path / "x.meshlod").exists()


def test_mesh_info(lod):
    info = mesh_info(lod)
    c = lod.clusters
    assert info["levels"] == lod.levels >= 4 and info["clusters"] == len(c) and info["roots"] == len(lod.roots)
    assert info["triangles"] == 1280 and sum(info["triangles_per_level"]) == len(lod.triangles)
    assert info["triangles_per_level"][0] == 1280 and info["triangles_per_level"][1] == 640
    assert sum(info["clusters_per_level"]) == len(c)
    assert info["bytes"] == lod.nbytes
    lo, hi = info["error_range"]
    assert 0 < lo <= hi == float(c["error"].max())
    assert info["build_seconds"] == lod.info["build_seconds"] and info["content_hash"] == "abc"


# --- load_mesh and the cache -------------------------------------------------------------------------
def test_cache_hit_does_not_build_again(cache, builds):
    v, f = grid(16)
    first = source.load_mesh((v, f))
    assert builds == ["array"] and len(list(cache.glob("*.meshlod"))) == 1
    second = source.load_mesh((v.copy(), f.copy()))
    assert builds == ["array"]   # served from the cache
    same(first, second)
    assert first.info["content_hash"] and first.info["settings"] == BuildSettings().as_dict()


def test_cache_keys_cover_lod_settings_and_content(cache, builds):
    v, f = grid(12)
    source.load_mesh((v, f))
    source.load_mesh((v, f), lod="full")
    source.load_mesh((v, f), settings={"group_size": 4})
    source.load_mesh((v, f), settings=BuildSettings(group_size=4))
    v2 = v.copy()
    v2[0, 2] += 0.01
    source.load_mesh((v2, f))
    assert len(builds) == 4 and len(list(cache.glob("*.meshlod"))) == 4


def test_a_corrupt_cache_file_is_rebuilt_with_a_warning(cache, builds):
    v, f = grid(10)
    source.load_mesh((v, f))
    (path,) = cache.glob("*.meshlod")
    good = path.read_bytes()
    path.write_bytes(good[:len(good) // 3])
    with pytest.warns(RuntimeWarning, match="truncated"):
        again = source.load_mesh((v, f))
    assert len(builds) == 2 and again.original_triangles == len(f)
    assert load_meshlod(path).original_triangles == len(f)   # the cache file is whole again


def test_an_unwritable_cache_warns_and_still_builds(tmp_path, monkeypatch, builds):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("PARAMLOD_CACHE", str(blocker))
    v, f = grid(8)
    with pytest.warns(RuntimeWarning, match="not cached"):
        lod = source.load_mesh((v, f))
    assert lod.original_triangles == len(f)


def test_cache_off_writes_nothing(cache, builds):
    v, f = grid(8)
    source.load_mesh((v, f), cache=False)
    source.load_mesh((v, f), cache=False)
    assert len(builds) == 2 and not cache.exists()


def test_sources(cache, tmp_path):
    import trimesh

    v, f = sphere(2)
    mesh = trimesh.Trimesh(v, f, process=False)
    ply = tmp_path / "ball.ply"
    mesh.export(ply)
    from_file = source.load_mesh(ply)
    assert from_file.name == "ball.ply" and from_file.original_triangles == len(f)
    from_trimesh = source.load_mesh(mesh)
    assert from_trimesh.original_triangles == len(f)
    out = save_meshlod(from_file, tmp_path / "ball.meshlod")
    same(source.load_mesh(out), from_file)
    assert source.load_mesh(from_file) is from_file
    # the same content under another name takes the cached build with its own name
    ply2 = tmp_path / "copy.ply"
    mesh.export(ply2)
    assert source.load_mesh(ply2).name == "copy.ply"


def test_load_mesh_bad_input(cache, tmp_path):
    v, f = sphere(1)
    with pytest.raises(MeshError, match="lod must be one of 'dag', 'full'"):
        source.load_mesh((v, f), lod="coarse")
    with pytest.raises(MeshError, match="unknown build settings"):
        source.load_mesh((v, f), settings={"max_tris": 64})
    with pytest.raises(MeshError, match="does not exist"):
        source.load_mesh(tmp_path / "none.ply")
    with pytest.raises(MeshError, match="does not exist"):
        source.load_mesh(tmp_path / "none.meshlod")
    with pytest.raises(MeshError, match="NaN"):
        bad = v.copy()
        bad[3] = np.nan
        source.load_mesh((bad, f))
    bad_file = tmp_path / "bad.meshlod"
    bad_file.write_bytes(b"PLMESHLD" + bytes(30))
    with pytest.raises(MeshError, match="bad.meshlod"):
        source.load_mesh(bad_file)
    with warnings.catch_warnings():
        warnings.simplefilter("error")   # a good build from a good source warns about nothing
        source.load_mesh((v, f))
