"""The mesh-LOD evaluation (paramlod.app.bench.mesh_eval, ``paramlod bench --extras mesh-eval``):
its quality metrics (exactly 0 on identical images, growing with the difference, bad images refused
before flip_evaluator sees them), the equal-quality comparison, and the bench end to end at a tiny
size on this device, writing JSON, markdown and plots with every representation and threshold. No
speed is asserted."""
from __future__ import annotations

import json

import numpy as np
import pytest

from paramlod.app.bench import mesh_eval
from paramlod.app.bench.mesh_eval import as_image, equal_quality, flip, ssim_error
from paramlod.app.cli import main
from paramlod.core.camera import Camera
from paramlod.errors import MeshError
from paramlod.meshlod.build.chain import build_chain
from paramlod.pipeline.driver import render
from paramlod.scene.scene import Scene

from helpers import meshes as test_meshes


def test_identical_images_give_exactly_zero():
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)
    assert ssim_error(img, img.copy()) == 0.0 and flip(img, img.copy()) == 0.0
    f = img.astype(np.float32) / 255
    assert ssim_error(f, f) == 0.0 and flip(f, f) == 0.0
    # a rendered frame, drawn twice: the renderer is deterministic and the metrics see no difference
    scene = Scene()
    scene.add_mesh(build_chain(*test_meshes.sphere(3)))
    cam = Camera.look_at((0, 0.5, 3), (0, 0, 0), size=(64, 48))
    a, b = render(scene, cam, "meshlets").rgb8(), render(scene, cam, "meshlets").rgb8()
    assert np.array_equal(a, b) and ssim_error(a, b) == 0.0 and flip(a, b) == 0.0


def test_metrics_grow_with_the_difference_and_take_uint8_as_srgb():
    rng = np.random.default_rng(1)
    ref = rng.integers(40, 200, (48, 64, 3), dtype=np.uint8)
    small, large = ref.copy(), ref.copy()
    small[10:14, 10:14] = 255
    large[5:40, 5:50] = 255
    for metric in (ssim_error, flip):
        assert 0 < metric(ref, small) < metric(ref, large) <= 1
    # uint8 is sRGB 0..255, the same as its float image in [0, 1] (not taken as 0..255 floats)
    assert flip(ref, large) == flip(ref.astype(np.float32) / 255, large.astype(np.float32) / 255)
    assert as_image(ref).dtype == np.float32 and as_image(ref).max() <= 1


@pytest.mark.parametrize("bad, match", [
    (np.zeros((48, 64), np.uint8), "H x W x 3"),
    (np.zeros((48, 64, 4), np.float32), "H x W x 3"),
    (np.zeros((48, 64, 3), np.int16), "uint8 sRGB or float"),
    (np.full((48, 64, 3), 255.0, np.float32), "in \\[0, 1\\]"),
    (np.full((48, 64, 3), np.nan, np.float32), "finite"),
    (np.zeros((40, 64, 3), np.uint8), "compare images of one size"),
])
def test_bad_images_are_refused_before_the_metrics(bad, match):
    ref = np.zeros((48, 64, 3), np.uint8)
    for metric in (flip, ssim_error):
        with pytest.raises(MeshError, match=match):
            metric(ref, bad)


def test_small_images_and_a_flip_exit_are_errors(monkeypatch):
    tiny = np.zeros((8, 8, 3), np.uint8)
    with pytest.raises(MeshError, match="at least 11 x 11"):
        ssim_error(tiny, tiny)
    import flip_evaluator

    def exits(*a, **k):
        raise SystemExit(1)

    monkeypatch.setattr(flip_evaluator, "evaluate", exits)
    with pytest.raises(MeshError, match="flip_evaluator refused"):
        flip(tiny, tiny)


def test_equal_quality_interpolates_the_chain_at_the_dags_flip():
    rows = [{"mesh": "m", "scenario": "grid", "representation": "chain", "threshold_px": t, "flip": fl, "frame_ms": ms,
             "triangles_drawn": n} for t, fl, ms, n in ((0.5, 0.01, 10.0, 4000), (1.0, 0.02, 6.0, 2000), (2.0, 0.04, 4.0, 1000))]
    rows += [{"mesh": "m", "scenario": "grid", "representation": "dag", "threshold_px": t, "flip": fl, "frame_ms": ms,
              "triangles_drawn": n} for t, fl, ms, n in ((1.0, 0.015, 2.0, 1500), (4.0, 0.08, 1.0, 300))]
    eq = equal_quality(rows)
    assert [e["dag_threshold_px"] for e in eq] == [1.0, 4.0]
    assert eq[0]["chain_ms_at_flip"] == pytest.approx(8.0) and eq[0]["chain_over_dag"] == pytest.approx(4.0)
    assert eq[0]["chain_triangles_at_flip"] == pytest.approx(3000) and eq[0]["chain_over_dag_triangles"] == pytest.approx(2.0)
    assert eq[1]["chain_ms_at_flip"] is None and eq[1]["chain_over_dag"] is None   # outside the chain's range
    assert eq[1]["chain_over_dag_triangles"] is None


def test_bench_runs_end_to_end_and_writes_every_representation_and_threshold(tmp_path):
    assert main(["bench", "--only-extras", "--extras", "mesh-eval", "--size", "64x48", "--frames", "2", "--warmup", "1",
                 "--mesh-grid", "2", "--eval-thresholds", "0.5", "2", "--eval-move-frames", "3", "--eval-parts", "40",
                 "--big-mesh", "no", "--out", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "results.json").read_text())
    assert res["scenarios"] == {}
    ev = res["mesh_eval"]
    assert ev["thresholds"] == [0.5, 2.0] and ev["representations"] == ["full", "chain", "dag"]
    assert [m["mesh"] for m in ev["meshes"]] == ["bunny", "parts-40"]
    assert ev["meshes"][0]["triangles"] == 99_785 and ev["meshes"][1]["triangles"] == 40 * 80
    for m in ev["meshes"]:
        reps = m["representations"]
        assert reps["full"]["levels"] == 1 and reps["chain"]["levels"] > 4 and reps["dag"]["levels"] > 4
        assert reps["full"]["triangles_stored"] == m["triangles"]
        for r in ("chain", "dag"):
            assert reps[r]["device_bytes"] > reps["full"]["device_bytes"] and reps[r]["disk_bytes"] > 0
            assert reps[r]["triangles_stored"] > m["triangles"] and reps[r]["build_s"] > 0
        assert reps["full"]["device_vs_original"] >= 1
    rows = {(r["mesh"], r["scenario"], r["representation"], r["threshold_px"]): r for r in ev["rows"]}
    assert all("error" not in r for r in ev["rows"])
    md = (tmp_path / "results.md").read_text()
    assert "## Mesh LOD: full mesh, discrete chain, cluster DAG" in md
    for mesh in ("bunny", "parts-40"):
        for scenario, n in (("grid", 2), ("path", 2), ("close", 2), ("move", 3)):
            want = [("full", None)] + [(r, t) for r in ("chain", "dag") for t in (0.5, 2.0)]
            for rep, t in want:
                r = rows[mesh, scenario, rep, t]
                assert r["frames"] == n and r["frame_ms"] > 0 and r["triangles_drawn"] > 0
                assert len(r["flip_frames"]) == n and len(r["ssim_error_frames"]) == n
                assert 0 <= r["flip"] <= 1 and 0 <= r["ssim_error"] <= 1
                assert r["flip"] == pytest.approx(np.mean(r["flip_frames"]))
                if scenario == "move":
                    assert len(r["consecutive_flip_frames"]) == n - 1
                    assert r["popping"] == pytest.approx(r["consecutive_flip"] - rows[mesh, "move", "full", None]["consecutive_flip"])
                    assert r["popping_max"] >= r["popping"]
                px = "-" if t is None else f"{t:g}"
                assert f"| {mesh} | {scenario} | {rep} | {px} | " in md
            # a coarser threshold draws a coarser level
            assert rows[mesh, scenario, "chain", 2.0]["triangles_drawn"] <= rows[mesh, scenario, "chain", 0.5]["triangles_drawn"]
        # seen from inside its bounding sphere a chain draws level 0 at any threshold: the full mesh's clusters
        for t in (0.5, 2.0):
            assert rows[mesh, "close", "chain", t]["triangles_frames"] == rows[mesh, "close", "full", None]["triangles_frames"]
        # where the DAG refines only what is near
        assert rows[mesh, "close", "dag", 2.0]["triangles_drawn"] < rows[mesh, "close", "full", None]["triangles_drawn"]
    assert {(e["mesh"], e["scenario"], e["dag_threshold_px"]) for e in ev["equal_quality"]} == {
        (m, s, t) for m in ("bunny", "parts-40") for s in ("grid", "path", "close", "move") for t in (0.5, 2.0)}
    assert (tmp_path / "mesh_eval_bunny.png").stat().st_size > 1000
    assert (tmp_path / "mesh_eval_parts-40.png").stat().st_size > 1000


def test_bench_option_errors(tmp_path, capsys):
    assert main(["bench", "sphere", "--only-extras", "--extras", "mesh-eval", "--out", str(tmp_path)]) == 2
    assert "--only-extras skips the scenarios" in capsys.readouterr().err
    with pytest.raises(MeshError, match="thresholds must be pixel counts"):
        mesh_eval.run_mesh_eval((64, 48), thresholds=[-1.0])
    with pytest.raises(MeshError, match="unknown mesh-eval scenario"):
        mesh_eval.run_mesh_eval((64, 48), scenarios=["orbit"])
