"""`paramlod bench --peers` (paramlod/app/bench/peers.py): the silhouette metric and its reference,
the matched-error view, rows for peers that are missing or fail, the markdown, a real paramlod row,
and (only where the peer is importable, e.g. after pip install 'paramlod[peers]') real peer rows."""
import argparse
import importlib.util
import json
import math

import numpy as np
import pytest
import trimesh

from paramlod.app.bench import peers as P
from paramlod.dmri.sh import coefficient_count
from paramlod.errors import ParamlodError


def _peer_or_skip(tool: str):
    """Skip unless ``tool`` imports: not installed, or installed but unable to load a system library
    it links (Open3D's wheel without libusb raises OSError, which importorskip lets through); the
    reason names what to install, as the bench's own row does."""
    module = P.PEERS[tool][0]   # as the bench looks for it
    if importlib.util.find_spec(module) is None:
        pytest.skip(f"{tool} is not installed: {P.missing_row(tool)['install']}")
    try:
        importlib.import_module(module)
    except (ImportError, OSError) as exc:
        hint = P.SYSTEM_HINTS[tool]
        pytest.skip(f"{tool} is installed but does not load ({exc})" + (f"; {hint}" if hint else ""))


def _args(*argv):
    p = argparse.ArgumentParser()
    P.add_arguments(p)
    return p.parse_args(list(argv))


def test_silhouette_error_of_known_masks():
    a = np.zeros((20, 20), bool)
    b = np.zeros((20, 20), bool)
    a[5:15, 0:10] = True
    b[5:15, 5:15] = True              # overlap 50 of a union of 150 pixels
    assert P.silhouette_error(a, b) == pytest.approx(1 - 50 / 150)
    assert P.silhouette_error(a, a) == 0.0
    assert P.silhouette_error(np.zeros((4, 4), bool), np.zeros((4, 4), bool)) == 0.0
    with pytest.raises(ParamlodError, match=r"\(20, 20\).*\(4, 4\)"):
        P.silhouette_error(a, np.zeros((4, 4), bool))


def test_coverage_counts_pixel_centres_inside_triangles():
    # a square (1,1)-(5,5) as two triangles of opposite winding holds the centres 1.5 .. 4.5
    xy = np.array([[1, 1], [5, 1], [5, 5], [1, 5]], float)
    m = P.coverage_mask(xy, [[0, 1, 2], [0, 3, 2]], (8, 8))
    want = np.zeros((8, 8), bool)
    want[1:5, 1:5] = True
    assert (m == want).all()
    # a triangle spanning many pixels: centres with (i + .5) + (j + .5) <= 8, i.e. i + j <= 7: 36
    big = P.coverage_mask(np.array([[0, 0], [8, 0], [0, 8]], float), [[0, 1, 2]], (10, 10))
    assert big.sum() == 36 and big[7, 0] and not big[7, 1]
    # a vertex behind the near plane drops the triangle
    assert not P.coverage_mask(xy, [[0, 1, 2]], (8, 8), w=np.array([1.0, 1.0, -1.0, 1.0]), near=0.1).any()


def test_reference_silhouette_of_a_sphere_is_the_analytic_disc():
    spec = P.scene_spec("glyphs8", (64, 64), grid=1)
    c = np.zeros((1, coefficient_count(8)))
    c[0, 0] = math.sqrt(4 * math.pi)             # r = 1 everywhere: a sphere of radius 0.45
    ref, info = P.reference_silhouette(spec, field=(c, np.zeros((1, 3))))
    assert info["max_edge_px"] <= P.MAX_EDGE_PX + 1e-9
    d = spec["camera"]["eye"][2]
    j, i = np.mgrid[0:64, 0:64]
    t = math.tan(math.radians(P.FOV / 2))
    x, y = ((i + 0.5) / 32 - 1) * t, (1 - (j + 0.5) / 32) * t      # ray directions (x, y, -1)
    inside = np.arccos(1 / np.sqrt(1 + x * x + y * y)) < math.asin(0.45 / d)
    assert P.silhouette_error(ref, inside) < 0.01
    assert P.silhouette_error(np.roll(ref, 1, axis=1), inside) > 0.05   # a one-pixel shift is seen


def test_matched_error_picks_the_closest_resolution_and_the_time_ratio():
    rows = [{"tool": "paramlod", "variant": "points", "scene": "torus", "ms": 10.0, "error": 0.05},
            {"tool": "paramlod", "variant": "points", "scene": "glyphs8", "ms": 20.0, "error": 0.2}]
    rows += [{"tool": "pyvista", "scene": "torus", "resolution": n, "ms": ms, "error": e, "variant": f"mesh {n}"}
             for n, ms, e in ((16, 2.0, 0.3), (32, 4.0, 0.07), (64, 8.0, 0.04), (128, 30.0, 0.01))]
    rows.append({"tool": "fury", "status": "not installed"})          # rows without times are ignored
    m = P.matched(rows)
    assert len(m) == 1
    assert m[0]["resolution"] == 64 and m[0]["peer"] == "pyvista" and m[0]["scene"] == "torus"
    assert m[0]["ratio"] == pytest.approx(0.8)
    # between mesh 32 (0.07, 4 ms) and mesh 64 (0.04, 8 ms), straight in logs: 8 * 0.5 ** (ln(5/4) / ln(7/4))
    assert m[0]["peer_ms_at_error"] == pytest.approx(8.0 * 0.5 ** (math.log(1.25) / math.log(1.75)))
    assert m[0]["ratio_at_error"] == pytest.approx(m[0]["peer_ms_at_error"] / 10.0)
    # outside the peer's errors, or at error 0: no interpolation
    assert P.peer_ms_at(rows[2:6], 0.5) is None and P.peer_ms_at(rows[2:6], 0.005) is None
    assert P.peer_ms_at(rows[2:6], 0.0) is None and P.peer_ms_at(rows[2:6], 0.04) == pytest.approx(8.0)


def test_evenness_of_a_hexagonal_lattice_is_one():
    d = 0.1
    pts = np.array([[(i + 0.5 * (j % 2)) * d, j * d * math.sqrt(3) / 2, 0] for j in range(30) for i in range(30)])
    area = len(pts) * math.sqrt(3) / 2 * d * d
    e = P.evenness(pts, area)
    assert e["min"] == pytest.approx(1.0) and e["mean"] == pytest.approx(1.0) and e["cv"] < 1e-9
    clumped = P.evenness(np.concatenate([pts, pts[:10] + 0.01]), area)
    assert clumped["min"] < 0.2 and clumped["cv"] > 0.1
    with pytest.raises(ParamlodError, match="at least 2 points"):
        P.evenness(pts[:1], area)


def test_missing_peers_are_rows_with_their_pip_command(tmp_path, monkeypatch):
    monkeypatch.setattr(P.importlib.util, "find_spec", lambda name: None)
    result = P.run_peers(_args("--peers-tools", "pyvista", "fury", "open3d", "pymeshlab"), tmp_path, log=lambda m: None)
    assert [r["tool"] for r in result["missing"]] == ["pyvista", "fury", "open3d", "pymeshlab"]
    assert not result["render"] and not result["sampling"] and not result["failed"]
    md = (tmp_path / "peers.md").read_text()
    assert "pyvista: not installed (pip install pyvista==0.49.2 vtk==9.7.2)" in md
    assert "fury: not installed (pip install fury==2.0.0)" in md
    assert json.loads((tmp_path / "peers.json").read_text())["missing"][2]["install"].startswith("pip install open3d")


def test_a_peer_that_fails_is_a_one_line_row():
    if P.importlib.util.find_spec("pyvista") is not None:
        pytest.skip("pyvista is installed here: its worker would not fail")
    row = P.run_worker("pyvista", {"scenes": [P.scene_spec("torus", (16, 16))], "frames": 1, "warmup": 0}, timeout=120)
    assert isinstance(row, dict) and row["status"].startswith("failed (exit 1): ModuleNotFoundError")
    assert "Traceback" not in row["status"] and "xvfb" in row["hint"]


def test_bad_size_and_scene_are_named():
    with pytest.raises(ParamlodError, match="--peers-size must be square.*640x480"):
        P.scene_spec("torus", (640, 480))
    with pytest.raises(ParamlodError, match="unknown peers scene 'cube'"):
        P.scene_spec("cube", (64, 64))


def test_markdown_has_time_and_error_side_by_side():
    result = {"size": [64, 64], "frames": 3, "warmup": 1,
              "render": [{"tool": "paramlod", "version": "0.1.0", "variant": "points", "scene": "torus", "ms": 12.34,
                          "error": 0.0456},
                         {"tool": "pyvista", "version": "pyvista 0.49.2 / vtk 9.7.2", "variant": "mesh 64",
                          "scene": "torus", "resolution": 64, "ms": 3.21, "error": 0.0401}],
              "sampling": [{"tool": "open3d", "version": "open3d 0.20.0", "n": 10000, "got": 10000, "seconds": 0.5,
                            "all": {"min": 0.74, "mean": 0.9, "cv": 0.077}, "prefix": {"min": 0.1, "mean": 0.5, "cv": 0.5}}],
              "missing": [{"tool": "fury", "status": "not installed", "install": "pip install fury==2.0.0"}],
              "failed": [{"tool": "pymeshlab", "status": "timed out after 900 s", "hint": ""}]}
    result["matched"] = P.matched(result["render"])
    md = P.format_peers_markdown(result)
    assert "| torus | paramlod | 0.1.0 | points | 12.3 | 0.046 |" in md
    assert "| torus | pyvista | pyvista 0.49.2 / vtk 9.7.2 | mesh 64 | 3.2 | 0.040 |" in md
    assert "| torus | points | 12.3 | 0.046 | pyvista | 64 | 3.2 | 0.040 | 0.26 | - | - |" in md   # one peer row: no front
    assert "| open3d | open3d 0.20.0 | 10,000 | 10,000 | 0.50 | 0.74 | 0.077 | 0.10 | 0.500 |" in md
    assert "fury: not installed (pip install fury==2.0.0)" in md and "pymeshlab: timed out after 900 s" in md


def test_a_real_paramlod_row(tmp_path):
    result = P.run_peers(_args("--peers-tools", "paramlod", "--peers-scenes", "torus", "--peers-size", "64x64",
                               "--peers-frames", "1", "--peers-samples"), tmp_path, log=lambda m: None)
    rows = {r["variant"]: r for r in result["render"]}
    assert set(rows) == {"points", "points-centre", "points-quad", "points-quad-fine", "tess", "tess-grid", "tess-chord"}
    assert result["references"]["torus"]["vertices"] > 10_000
    for r in rows.values():
        assert r["tool"] == "paramlod" and r["scene"] == "torus" and r["ms"] > 0
        assert r["error"] < 0.12              # a torus of ~50 px drawn by either variant
    assert "| torus | paramlod |" in (tmp_path / "peers.md").read_text()


def test_rounds_take_turns_and_give_each_rounds_ratio(tmp_path, monkeypatch):
    """--peers-rounds: paramlod's rows, then the peers', then again; a row's time is the median of
    its rounds, and the matched table gives the ratio of each round (times taken minutes apart)."""
    spec = P.scene_spec("torus", (64, 64))
    ref, _ = P.reference_silhouette(spec)
    calls, times = [], iter([10.0, 30.0, 20.0])   # paramlod's row, round by round
    peer_times = iter([(4.0, 8.0), (9.0, 18.0), (5.0, 10.0)])   # pyvista's mesh 32 / 64, round by round

    def paramlod_row(spec, variant, frames, warmup, field, threshold):
        calls.append("paramlod")
        return {"tool": "paramlod", "version": "0", "variant": variant, "threshold": threshold, "ms": next(times),
                "mask": ref}

    def worker(tool, job):
        calls.append(tool)
        a, b = next(peer_times)
        rows = [{"scene": "torus", "resolution": 32, "ms": a, "mask": "m32"},
                {"scene": "torus", "resolution": 64, "ms": b, "mask": "m64"}]
        return rows, {"m32": ref, "m64": ref}

    monkeypatch.setattr(P, "PARAMLOD_ROWS", {"points": "points"})
    monkeypatch.setattr(P, "paramlod_render_row", paramlod_row)
    monkeypatch.setattr(P, "run_worker", worker)
    monkeypatch.setattr(P.importlib.util, "find_spec", lambda name: object() if name == "pyvista" else None)
    monkeypatch.setattr(P, "peer_versions", lambda tool: "test")
    result = P.run_peers(_args("--peers-tools", "paramlod", "pyvista", "--peers-scenes", "torus", "--peers-size",
                               "64x64", "--peers-rounds", "3", "--peers-samples"), tmp_path, log=lambda m: None)
    assert calls == ["paramlod", "pyvista"] * 3
    rows = {(r["tool"], r["variant"]): r for r in result["render"]}
    assert rows["paramlod", "points"]["ms"] == 20.0 and rows["paramlod", "points"]["ms_rounds"] == [10.0, 30.0, 20.0]
    assert rows["pyvista", "mesh 32"]["ms"] == 5.0 and rows["pyvista", "mesh 64"]["ms_rounds"] == [8.0, 18.0, 10.0]
    # the same error everywhere: the closest resolution is the smaller, mesh 32; per round 4/10, 9/30, 5/20
    assert [m["ratio"] for ms in result["matched_rounds"] for m in ms] == [0.4, 0.3, 0.25]
    md = (tmp_path / "peers.md").read_text()
    assert "the median of 3 rounds" in md and "| (0.40) / (0.30) / (0.25) |" in md


# --- real peers: run where they are importable (pip install 'paramlod[peers]'), skipped elsewhere -----------
# Through the bench's worker subprocess, as the bench runs them: a peer's GL or Vulkan libraries
# loaded into this process broke every later OpenGL test (moderngl: "cannot create buffer").
def _torus_errors(tool):
    spec = P.scene_spec("torus", (64, 64))
    ref, _ = P.reference_silhouette(spec)
    got = P.run_worker(tool, {"scenes": [spec], "frames": 1, "warmup": 1, "resolutions": [8, 128]})
    assert not isinstance(got, dict), got
    rows, arrays = got
    return [P.silhouette_error(arrays[r["mask"]], ref) for r in rows]


def test_pyvista_draws_the_reference_silhouette():
    _peer_or_skip("pyvista")
    coarse, fine = _torus_errors("pyvista")
    assert fine < 0.01 < coarse        # same camera and pixel rule as the reference


def test_fury_draws_the_reference_silhouette():
    _peer_or_skip("fury")
    coarse, fine = _torus_errors("fury")
    assert fine < 0.01 < coarse


@pytest.mark.parametrize("tool", ["open3d", "pymeshlab"])
def test_poisson_disk_peers_sample_the_bunny_evenly(tool):
    _peer_or_skip(tool)
    pytest.importorskip("pymeshfix")

    path = P.bunny_path()
    got = P.run_worker(tool, {"mesh": path, "counts": [2000]})
    assert not isinstance(got, dict), got
    (r,), arrays = got
    row = P.sampling_row(tool, P.peer_versions(tool), 2000, r["seconds"], arrays[r["points"]],
                         float(trimesh.load(path, force="mesh").area))
    assert abs(row["got"] - 2000) < 100 and row["all"]["min"] > 0.3 and row["all"]["cv"] < 0.2
