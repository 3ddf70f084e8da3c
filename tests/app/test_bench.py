"""`paramlod bench` runs end to end (tiny sizes) and writes what it promises; no speed is asserted."""
import json

from paramlod.app.cli import main
from paramlod.device.context import cl_device


def test_bench_writes_json_markdown_and_per_distance_rows(tmp_path):
    assert main(["bench", "sphere", "--variants", "points", "--size", "64x48", "--distances", "0.6", "1.5",
                 "--frames", "2", "--warmup", "1", "--extras", "ceilings", "--out", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "results.json").read_text())
    assert res["atomics_ceiling_per_s"] > 0
    rows = res["scenarios"]["sphere"]["variants"]["points"]
    assert [r["distance"] for r in rows] == [0.6, 1.5]
    for r in rows:
        assert r["frames"] == 2 and r["render_patches"] > 0 and r["pixels_written"] > 0
        assert len(r["lod_steps_in"]) == 12 and r["lod_steps_in"][0] == 1
    assert rows[0]["pixels_written"] > rows[1]["pixels_written"]      # nearer covers more
    # where the device time goes: each kernel's ms a frame, the largest first
    for r in rows:
        ms = list(r["kernel_ms"].values())
        assert {"lod_step", "points_schedule", "points_direct", "resolve"} <= set(r["kernel_ms"])
        assert ms == sorted(ms, reverse=True) and min(ms) >= 0 and max(ms) <= r["cl_kernel_ms"]
    md = (tmp_path / "results.md").read_text()
    assert "| sphere | points | 0.6 |" in md
    assert "Device ms a frame by OpenCL kernel" in md and "| sphere | points | 1.5 | " in md


def test_bench_measures_supersampled_points(tmp_path):
    assert main(["bench", "sphere", "--variants", "points", "points-4xSS", "--size", "64x48", "--distances",
                 "1", "--frames", "2", "--warmup", "1", "--extras", "--out", str(tmp_path)]) == 0
    v = json.loads((tmp_path / "results.json").read_text())["scenarios"]["sphere"]["variants"]
    plain, ss = v["points"][0], v["points-4xSS"][0]
    # the same silhouette from about four times the samples, in buffers 4x the size
    assert abs(ss["pixels_written"] - plain["pixels_written"]) < 0.1 * plain["pixels_written"]
    assert 2.5 * plain["samples"] < ss["samples"] < 6 * plain["samples"]
    assert ss["device_buffers_mib"] > plain["device_buffers_mib"]


def test_bench_measures_points_with_centre_coverage(tmp_path):
    assert main(["bench", "sphere", "--variants", "points", "points-centre", "--size", "64x48", "--distances",
                 "1", "--frames", "2", "--warmup", "1", "--extras", "--out", str(tmp_path)]) == 0
    v = json.loads((tmp_path / "results.json").read_text())["scenarios"]["sphere"]["variants"]
    plain, centre = v["points"][0], v["points-centre"][0]
    # the same samples; the silhouette no longer grown by up to a pixel: fewer pixels written
    assert centre["samples"] == plain["samples"]
    assert 0.8 * plain["pixels_written"] < centre["pixels_written"] < plain["pixels_written"]


def test_bench_measures_tess_with_the_grid_and_chord_levels(tmp_path):
    assert main(["bench", "sphere", "--variants", "tess", "tess-grid", "tess-chord", "--size", "64x48", "--distances",
                 "1", "--frames", "2", "--warmup", "1", "--extras", "--out", str(tmp_path)]) == 0
    v = json.loads((tmp_path / "results.json").read_text())["scenarios"]["sphere"]["variants"]
    tess, grid, chord = (v[k][0] for k in ("tess", "tess-grid", "tess-chord"))
    assert tess["render_patches"] == grid["render_patches"] == chord["render_patches"]
    # a sphere of 48 px: chords within 0.25 px need far fewer triangles than 1-pixel segments
    assert 0 < chord["triangles"] * 4 < grid["triangles"]


def test_bench_measures_what_tess_detail_levels_cost(tmp_path):
    assert main(["bench", "sh12", "--variants", "tess", "tess-detail", "--size", "64x48", "--distances", "1",
                 "--frames", "1", "--warmup", "0", "--extras", "--out", str(tmp_path)]) == 0
    v = json.loads((tmp_path / "results.json").read_text())["scenarios"]["sh12"]["variants"]
    plain, detail = v["tess"][0], v["tess-detail"][0]
    # a glyph of 48 px: its thin lobes have detail finer than a pixel, measured again and split finer
    assert detail["render_patches"] > plain["render_patches"] and detail["triangles"] > plain["triangles"]


def test_bench_names_unknown_scenarios(tmp_path, capsys):
    assert main(["bench", "teapot", "--out", str(tmp_path)]) == 2
    assert "unknown scenario(s) teapot" in capsys.readouterr().err


def test_bench_measures_meshes_with_and_without_lod(tmp_path):
    assert main(["bench", "sphere", "--variants", "points", "--size", "64x48", "--distances", "1", "--frames", "2",
                 "--warmup", "1", "--extras", "meshes", "--mesh-grid", "2", "--big-mesh", "no",
                 "--out", str(tmp_path)]) == 0
    m = json.loads((tmp_path / "results.json").read_text())["meshes"]
    assert m["builds"][0]["mesh"] == "bunny" and m["builds"][0]["triangles"] == 99_785 and m["builds"][0]["roots"] <= 4
    rows = {(r["scenario"], r["variant"], r["threshold_px"]): r for r in m["scenarios"]}
    assert len(rows) == 8
    for scenario in ("mesh_grid", "mesh_path"):
        for variant in ("meshlets", "meshlets-gl"):
            lod, full = rows[scenario, variant, 1.0], rows[scenario, variant, 0.0]
            assert 0 < lod["triangles_drawn"] < full["triangles_drawn"]
            assert lod["triangle_ratio_vs_full"] > 1
    assert m["cut_alone"][0]["tests"] >= 10 ** 6 * 0.9
    assert "## Meshes" in (tmp_path / "results.md").read_text()


def test_bench_on_a_cpu_takes_the_cpu_defaults_and_says_so(tmp_path, capsys):
    """Without --size, --distances, --frames and --warmup a CPU device runs 640x360 at the framing
    distance, 3 frames after 1 (the GPU's 1080p orbit at four distances is hours of frames there);
    what is given stays as given."""
    assert not cl_device().is_gpu   # the test machines' PoCL
    assert main(["bench", "sphere", "--variants", "points", "--extras", "--out", str(tmp_path / "a")]) == 0
    res = json.loads((tmp_path / "a" / "results.json").read_text())
    assert (res["size"], res["frames"], res["warmup"]) == ([640, 360], 3, 1)
    assert [r["distance"] for r in res["scenarios"]["sphere"]["variants"]["points"]] == [1.0]
    assert "on a CPU device the defaults are 640x360" in capsys.readouterr().out
    assert main(["bench", "sphere", "--variants", "points", "--extras", "--size", "64x48", "--distances", "2",
                 "--frames", "2", "--warmup", "0", "--out", str(tmp_path / "b")]) == 0
    res = json.loads((tmp_path / "b" / "results.json").read_text())
    assert (res["size"], res["frames"], res["warmup"]) == ([64, 48], 2, 0)
    assert "defaults are" not in capsys.readouterr().out
