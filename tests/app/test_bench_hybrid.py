"""Hybrid anti-aliasing against uniform anti-aliasing (paramlod.app.bench.hybrid, ``paramlod bench
--extras hybrid``, issue #21) at a tiny size on this device: every row has its fields with sane
values (FLIP in [0, 1], the hybrid's patches per tier summing to its render patches, the reference
redrawn giving FLIP 0), the aims are judged and written out, the markdown section has its table,
and the CLI refuses bad values of the extra's options before measuring anything. No speed is
asserted."""
from __future__ import annotations

import json
import math

import pytest

from paramlod.app.bench.hybrid import VARIANTS, aims, format_hybrid, run_hybrid
from paramlod.app.cli import main
from paramlod.errors import ParamlodError
from paramlod.renderers.aa import parse_aa

SIZE = (64, 48)
POINTS = ("points-hybrid", "points-16xSS", "points-noAA")


@pytest.fixture(scope="module")
def points_run():
    logged = []
    res = run_hybrid(SIZE, frames=1, warmup=0, scenes=["seashell3"], distances=[0.35, 1.0], variants=POINTS,
                     reference="points", log=logged.append)
    return res, logged


def test_rows_have_their_fields_with_sane_values(points_run):
    res, logged = points_run
    assert res["distances"] == [1.0, 0.35]   # far to near, whatever order they were given in
    sc = res["scenes"]["seashell3"]
    assert sc["instances"] == 1
    ref = sc["reference"]
    assert ref["variant"] == "points" and ref["aa"] == "16xSS" and ref["density"] > 1.5
    assert "points 16xSS" in ref["label"] and "fallback_because" not in ref
    # the points renderer is deterministic: the reference redrawn is the same image
    assert [p["redraw_flip"] for p in ref["per_distance"]] == [0.0, 0.0]
    rows = sc["rows"]
    assert [(r["distance"], r["variant"]) for r in rows] == [(d, v) for d in (1.0, 0.35) for v in POINTS]
    for r in rows:
        assert "error" not in r, r
        assert r["frames"] == 1 and r["frame_ms"] > 0 and r["fps"] > 0 and r["lod_ms"] >= 0
        assert 0.0 <= r["flip"] <= 1.0
        assert r["render_patches"] > 0 and len(r["tier_patches"]) == 3
        assert sum(r["tier_patches"]) == r["render_patches"]
        if r["aa"] != "hybrid":   # a uniform mode has no tiers: every patch in tier 0, none promoted
            assert r["tier_patches"][1:] == [0, 0] and r["promoted"] == 0
    by = {(r["variant"], r["distance"]): r for r in rows}
    # near, the shell's bumps are sub-pixel detail: the spot check promotes patches past the first tier
    near = by["points-hybrid", 0.35]
    assert near["promoted"] > 0 and sum(near["tier_patches"][1:]) > 0
    # anti-aliasing helps: noAA is further from the 16xSS reference than uniform 16xSS
    assert by["points-noAA", 0.35]["flip"] > by["points-16xSS", 0.35]["flip"]
    # the aims of the points pair, judged at both distances; no tess pair without tess rows
    a = sc["aims"]
    assert set(a) == {"points"} and a["points"]["distances"] == 2
    assert a["points"]["hybrid_spread"] >= 1 and a["points"]["uniform_spread"] >= 1
    assert all(isinstance(x, str) for x in a["points"]["losses"])
    assert any(m.startswith("hybrid seashell3 d=0.35 points-hybrid:") and "FLIP" in m for m in logged)
    json.dumps(res)   # goes into results.json as it is


def test_format_hybrid_writes_the_table_and_the_aims(points_run):
    res, _ = points_run
    md = "\n".join(format_hybrid(res))
    assert "## Hybrid anti-aliasing (issue #21)" in md and "### seashell3 (1 instance)" in md
    assert "| distance | variant | FPS | frame ms (p95) | LOD ms | render patches | patches per tier |" in md
    r = next(r for r in res["scenes"]["seashell3"]["rows"] if r["variant"] == "points-hybrid" and r["distance"] == 0.35)
    line = next(x for x in md.splitlines() if x.startswith("| 0.35 | points-hybrid | "))
    assert f"| {r['frame_ms']:.2f} ({r['frame_ms_p95']:.2f}) | {r['lod_ms']:.2f} | {r['render_patches']:,} | " in line
    assert f"| {' / '.join(f'{n:,}' for n in r['tier_patches'])} | {r['promoted']:,} | {r['flip']:.4f} |" in line
    assert "Reference: points 16xSS, density 3" in md
    assert "**points-hybrid against points-16xSS**" in md


def _row(variant, d, flip, ms):
    return {"variant": variant, "distance": d, "flip": flip, "frame_ms": ms}


def test_aims_name_every_loss():
    rows = [_row("tess-hybrid", 2.0, 0.050, 4.0), _row("tess-4xSS+8xMS", 2.0, 0.050, 10.0),
            _row("tess-hybrid", 0.5, 0.080, 6.0), _row("tess-4xSS+8xMS", 0.5, 0.060, 40.0)]
    a = aims(rows)["tess"]
    assert [p["quality_ok"] for p in a["per_distance"]] == [True, False]
    assert [p["time_ok"] for p in a["per_distance"]] == [True, True]
    assert a["hybrid_spread"] == 1.5 and a["uniform_spread"] == 4.0 and a["stable_ok"] is True
    assert a["losses"] == ["d=0.5: quality, FLIP 0.0800 against the uniform's 0.0600 (+33 %, aim <= +10 %)"]
    # slower than half the uniform's, and less stable than it
    rows[0]["frame_ms"], rows[2]["frame_ms"] = 2.0, 30.0
    a = aims(rows)["tess"]
    assert a["stable_ok"] is False and any("time, 30.00 ms" in x for x in a["losses"])
    assert any(x.startswith("stability: its frame time varies 15.00x") for x in a["losses"])


def test_run_hybrid_refuses_bad_arguments():
    for kwargs, match in (({"scenes": ["teapot"]}, "unknown scene"), ({"variants": ["tess-2xSS"]}, "unknown variant"),
                          ({"distances": [1.0, 1.0]}, "distinct"), ({"distances": [0.0]}, "> 0"),
                          ({"reference": "best"}, "reference must be one of auto, tess, points")):
        with pytest.raises(ParamlodError, match=match):
            run_hybrid(SIZE, **kwargs)


@pytest.mark.parametrize("argv, message", [
    (["--hybrid-distances", "0"], "--hybrid-distances: must be a finite number > 0, got '0'"),
    (["--hybrid-distances", "-1"], "--hybrid-distances: must be a finite number > 0, got '-1'"),
    (["--hybrid-distances", "far"], "--hybrid-distances: must be a number > 0, got 'far'"),
    (["--hybrid-distances", "1", "1"], "--hybrid-distances: 1.0 is given twice"),
    (["--hybrid-scenes", "teapot"], "--hybrid-scenes: invalid choice: 'teapot'"),
    (["--hybrid-scenes", "seashell3", "seashell3"], "--hybrid-scenes: 'seashell3' is given twice"),
    (["--hybrid-reference", "best"], "--hybrid-reference: invalid choice: 'best'"),
    (["--hybrid-variants", "tess-2xSS"], "--hybrid-variants: invalid choice: 'tess-2xSS'"),
    (["--hybrid-variants", "tess-hybrid", "tess-hybrid"], "--hybrid-variants: 'tess-hybrid' is given twice"),
])
def test_cli_refuses_bad_values_of_the_options(tmp_path, capsys, argv, message):
    with pytest.raises(SystemExit) as exc:
        main(["bench", "--only-extras", "--extras", "hybrid", *argv, "--out", str(tmp_path)])
    assert exc.value.code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "results.json").exists()


def test_bench_cli_runs_the_extra_with_tess_and_writes_json_markdown_plot(tmp_path):
    """The whole extra through the CLI, every variant (tess included) against the default (auto)
    reference, one distance: results.json holds result["hybrid"], results.md its section."""
    assert main(["bench", "--only-extras", "--extras", "hybrid", "--hybrid-scenes", "seashell3",
                 "--hybrid-distances", "0.6", "--size", "64x48", "--frames", "1", "--warmup", "0",
                 "--out", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "results.json").read_text())["hybrid"]
    sc = res["scenes"]["seashell3"]
    assert sc["reference"]["variant"] in ("tess", "points")
    assert sorted(r["variant"] for r in sc["rows"]) == sorted(VARIANTS)
    for r in sc["rows"]:
        assert "error" not in r, r
        assert 0.0 <= r["flip"] <= 1.0 and sum(r["tier_patches"]) == r["render_patches"]
        if r["render_variant"] == "tess":
            assert r["aa_effective"] and r["triangles"] > 0
    assert set(sc["aims"]) == {"tess", "tess-pair", "tess-finest", "tess-guideline", "tess-ss-lod", "tess-segment",
                               "tess-extent", "points", "points-quad"}
    # the hybrid's tiers divide their thresholds by sqrt(multisamples) too, unless msaa_lod is false
    tiers = {r["variant"]: r["renderer_tiers"] for r in sc["rows"] if "renderer_tiers" in r}
    for k in (1, 2):
        finer, plain = tiers["tess-hybrid"][k], tiers["tess-hybrid-ss-lod"][k]
        msaa = parse_aa(plain["aa"]).msaa
        assert msaa > 1, plain
        assert finer["threshold"][0] == pytest.approx(plain["threshold"][0] / math.sqrt(msaa)), (plain, finer)
    # the default inner levels are the extents' in tier 0 and the segments' in the tiers the spot check
    # sent patches to (TessSettings.inner_measure "detail"); each tier has the same patches in all three
    by_measure = {m: tiers[f"tess-hybrid-{m}"] for m in ("extent", "segment")}
    for k, tier in enumerate(tiers["tess-hybrid"]):
        assert tier["patches"] == by_measure["extent"][k]["patches"] == by_measure["segment"][k]["patches"]
        assert tier["triangles"] == by_measure["segment" if k else "extent"][k]["triangles"], (k, tiers)
    md = (tmp_path / "results.md").read_text()
    assert "## Hybrid anti-aliasing (issue #21)" in md and "| 0.6 | tess-hybrid" in md
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return
    assert (tmp_path / "hybrid_seashell3.png").stat().st_size > 0


def test_one_distance_is_no_path_for_the_stability_aim():
    a = aims([_row("points-hybrid", 1.0, 0.02, 5.0), _row("points-16xSS", 1.0, 0.02, 20.0)])["points"]
    assert a["stable_ok"] is None and a["losses"] == [] and a["quality_met"] == a["time_met"] == 1
