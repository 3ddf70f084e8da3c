"""Multi-view measurements of ``paramlod bench`` (extra "multiview"): for the 19,600-glyph field,
the yarn curtain and the sphere, view sets of 2 (a stereo pair), 6 and 48 (light-field quilts
over 40 degrees) around the framing camera, drawn as one multi-view frame
(``render_views``: one LOD pass) against the N separate frames of the same cameras and against
one frame of the first camera, in the same run: frame ms (up to resolved buffers on the device),
LOD ms, render ms, render patches and pixels written, per variant (points, tess).

Aims (issue 20): 2 views at most 1.3x the time of one view, 6 at most 3x, 48 at most 12x; the LOD
stage's time grows by at most 1.5x from 1 to 48 views."""
from __future__ import annotations

import statistics

from paramlod.app.bench.scenes import SCENARIOS
from paramlod.core.views import quilt, stereo
from paramlod.errors import ParamlodError
from paramlod.pipeline.driver import render, render_views
from paramlod.pipeline.settings import RenderSettings
from paramlod.scene.framing import framing_camera, scene_box

SCENES = ("hardi12", "yarn_curtain", "sphere")
VARIANTS = ("points", "tess")
VIEW_SETS = (2, 6, 48)
AIMS = {2: 1.3, 6: 3.0, 48: 12.0}


def view_set(base, n: int, scale: float, focus: float) -> list:
    """A stereo pair 2 % of the scene's size apart, or a quilt of n views (the same cameras for
    any grid shape: a quilt's views spread horizontally), both focused at the scene's centre."""
    if n == 2:
        return stereo(base, 0.02 * scale, focus=focus)
    return quilt(base, n, 1, focus=focus)


def _ms(stats) -> tuple[float, float, float]:
    ms = stats["ms"]
    return ms["frame"], ms.get("lod", 0.0), ms.get("render", 0.0)


def _median_frames(draw, frames: int, warmup: int) -> dict:
    rows = []
    for k in range(warmup + frames):
        out = draw()
        if k >= warmup:
            rows.append(out)
    return {key: statistics.median(r[key] for r in rows) for key in rows[0]}


def measure(scene, cams, variant, threshold, frames, warmup) -> dict:
    rs = RenderSettings()
    rs.lod.threshold = (threshold, threshold)

    def multi():
        fs = render_views(scene, cams, variant, rs)
        frame, lod, rend = _ms(fs[0].stats)
        return {"frame_ms": frame, "lod_ms": lod, "render_ms": rend, "render_patches": fs[0].stats["render_patches"],
                "pixels": sum(int(f.stats["pixels_written"]) for f in fs)}

    def one(cam):
        f = render(scene, cam, variant, rs)
        frame, lod, rend = _ms(f.stats)
        return {"frame_ms": frame, "lod_ms": lod, "render_ms": rend, "render_patches": f.stats["render_patches"],
                "pixels": int(f.stats["pixels_written"])}

    def separate():
        rows = [one(c) for c in cams]
        return {k: sum(r[k] for r in rows) for k in rows[0]}

    return {"multi": _median_frames(multi, frames, warmup), "separate": _median_frames(separate, frames, warmup),
            "single": _median_frames(lambda: one(cams[0]), frames, warmup)}


def run_multiview(size, frames: int, warmup: int, scenes=SCENES, variants=VARIANTS, view_sets=VIEW_SETS,
                  log=print) -> dict:
    out = {"size": list(size), "rows": []}
    for name in scenes:
        build, direction, up, threshold, _, _ = SCENARIOS[name]
        scene = build()
        base = framing_camera(scene, direction, up, 40.0, size, margin=1.0)
        lo, hi = scene_box(scene)
        scale = float(max(hi - lo))
        focus = -float(base.view[2, :3] @ ((lo + hi) / 2) + base.view[2, 3])
        for variant in variants:
            for n in view_sets:
                cams = view_set(base, n, scale, focus)
                try:
                    r = measure(scene, cams, variant, threshold, frames, warmup)
                except ParamlodError as exc:
                    r = {"error": str(exc)}
                r.update(scene=name, variant=variant, views=n)
                if "error" not in r:
                    m, s, one = r["multi"], r["separate"], r["single"]
                    r["vs_one_view"] = m["frame_ms"] / one["frame_ms"]
                    r["vs_separate"] = s["frame_ms"] / m["frame_ms"]
                    r["lod_growth"] = m["lod_ms"] / one["lod_ms"] if one["lod_ms"] else None
                    r["aim"] = AIMS.get(n)
                    log(f"multiview {name} {variant} {n} views: {m['frame_ms']:.2f} ms = {r['vs_one_view']:.2f}x one view "
                        f"(aim <= {AIMS.get(n)}), {r['vs_separate']:.2f}x faster than {n} frames, LOD "
                        f"{m['lod_ms']:.3f} ms ({r['lod_growth'] or 0:.2f}x), {m['render_patches']:.0f} patches")
                else:
                    log(f"multiview {name} {variant} {n} views: error: {r['error']}")
                out["rows"].append(r)
    return out


def format_multiview(result: dict) -> list[str]:
    w, h = result["size"]
    lines = ["", f"Multi-view ({w}x{h} per view): one frame of N views against one view and against N frames",
             "", "| scene | variant | views | frame ms | x one view (aim) | N frames ms | speed-up | LOD ms | LOD x one "
             "| render ms | patches (one view) |", "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in result["rows"]:
        if "error" in r:
            lines.append(f"| {r['scene']} | {r['variant']} | {r['views']} | error: {r['error'][:60]} ||||||||")
            continue
        m, s, one = r["multi"], r["separate"], r["single"]
        growth = f"{r['lod_growth']:.2f}" if r["lod_growth"] else "n/a"
        lines.append(f"| {r['scene']} | {r['variant']} | {r['views']} | {m['frame_ms']:.2f} | {r['vs_one_view']:.2f} "
                     f"(<= {r['aim']}) | {s['frame_ms']:.2f} | {r['vs_separate']:.2f} | {m['lod_ms']:.3f} | {growth} | "
                     f"{m['render_ms']:.2f} | {m['render_patches']:.0f} ({one['render_patches']:.0f}) |")
    return lines


__all__ = ["run_multiview", "format_multiview", "SCENES", "VIEW_SETS"]
