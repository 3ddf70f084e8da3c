"""Hybrid anti-aliasing against uniform anti-aliasing in ``paramlod bench`` (extra "hybrid", issue #21;
the thesis's section 5.6.2, Figures 5.18 and 5.19).

``aa = "hybrid"`` lets the LOD stage's spot check send each patch with sub-pixel detail to a finer
tier (paramlod.renderers.aa.hybrid_tiers: tess noAA -> 8xMS -> 4xSS+8xMS, points 1x -> 4xSS ->
16xSS key buffers). This measures what that buys. Per scene (``seashell3``, the single shell with
sub-pixel bumps; the yarn curtain, 60k curves, the thesis's case against hybrid; the 19,600-glyph
field ``hardi12``) the camera moves from far to near along one fixed viewing direction (distances
as multiples of the distance at which the scene just fills the frame: 4, 2, 1, 0.6, 0.35), and at
each distance every variant of VARIANTS draws ``warmup`` untimed and ``frames`` timed frames of the
same camera: frame ms (median and 95th percentile of ``stats["ms"]["frame"]``, up to resolved
buffers on the device), LOD ms, render ms, render patches, patches per tier (the LOD steps'
``tiers`` summed: render patches per tier, the same schema for both variants; uniform rows have all
in tier 0), patches promoted by the spot check, triangles (tess) and the tess renderer's own
per-tier record where it gives one; then FLIP (paramlod.app.bench.mesh_eval.flip) of the last timed
frame against a reference frame of the same camera.

The reference is tess 16xSS+8xMS with inner levels from the longest LOD segment
(REFERENCE_INNER_MEASURE; multisampling capped to the device's: the row says what ran).
Where that fails or one frame takes longer than ``reference_budget_s``, the scene's reference is
points 16xSS at twice the default sample density (REFERENCE_POINTS_DENSITY), for every distance of
that scene; the result names the reference used and why. The reference is drawn twice per distance:
FLIP between the two draws (``redraw_flip``) is the floor under every row's FLIP (0 for a
deterministic renderer).

The tess hybrid's tiers measure patches at the thresholds divided by sqrt(8) and sqrt(32) (the
guideline the issue names; TessSettings.msaa_lod unset); ``tess-hybrid-ss-lod`` at those of the
tiers' uniform modes (1 and 2, as before December 2026), ``tess-4xSS+8xMS-msaa-lod`` the uniform mode
at the guideline's sqrt(32).

Aims (issue #21), per scene and per pair (tess-hybrid against tess-4xSS+8xMS, and against it at the
guideline's thresholds; points-hybrid against points-16xSS): at each distance the hybrid's FLIP
within 10 % of the uniform's (FLIP_AIM) and its frame time at most half the uniform's (TIME_AIM);
along the path the hybrid's frame time max / min at most 2 (SPREAD_AIM) while the uniform's varies
more. Every missed aim is written out as a loss.

Driven by paramlod.app.bench.run (``paramlod bench --only-extras --extras hybrid``); ``run_hybrid``
is usable alone. No twin (a measurement). flip_evaluator and matplotlib are imported when used
(``pip install 'paramlod[bench]'``).
"""
from __future__ import annotations

import argparse
import statistics
import time
import warnings
from pathlib import Path

import numpy as np

from paramlod.app.args import positive_float
from paramlod.app.bench.mesh_eval import flip
from paramlod.app.bench.plots import pyplot, save_figure
from paramlod.app.bench.scenes import SCENARIOS, apply_variant_settings
from paramlod.core.camera import Camera
from paramlod.errors import ParamlodError
from paramlod.pipeline.driver import render
from paramlod.pipeline.settings import RenderSettings
from paramlod.scene.framing import framing_camera, scene_box
from paramlod.scene.scene import Material, Scene

DISTANCES = (4.0, 2.0, 1.0, 0.6, 0.35)
SCENES = ("seashell3", "yarn_curtain", "hardi12")
# name -> (render variant, AA mode), in the order they are drawn at each distance
VARIANTS = {"tess-hybrid": ("tess", "hybrid"), "tess-hybrid-pair": ("tess", "hybrid"),
            "tess-hybrid-finest": ("tess", "hybrid"),
            "tess-4xSS+8xMS": ("tess", "4xSS+8xMS"),
            "points-hybrid": ("points", "hybrid"), "points-16xSS": ("points", "16xSS"),
            # the points' tiers with quad coverage: their silhouettes are the sampled polygon's, not
            # grown by a (sub)pixel (docs/points.md, "Quad coverage")
            "points-hybrid-quad": ("points", "hybrid"), "points-hybrid-quad-half": ("points", "hybrid"),
            "points-noAA": ("points", "noAA"), "tess-noAA": ("tess", "noAA"),
            # uniform 4xSS: on llvmpipe and an H100 it came closer to 4xSS+8xMS's (16xSS's) FLIP at
            # under half the time than the hybrid with its tiers' uniform divisors did (docs/hybrid.md)
            "tess-4xSS": ("tess", "4xSS"), "points-4xSS": ("points", "4xSS"),
            # TessSettings.msaa_lod: the hybrid's tiers at the thresholds of their uniform modes (1, 2)
            # instead of the guideline's sqrt(8), sqrt(32); the uniform mode at the guideline's
            "tess-hybrid-ss-lod": ("tess", "hybrid"), "tess-4xSS+8xMS-msaa-lod": ("tess", "4xSS+8xMS"),
            # inner levels (TessSettings.inner_measure) from the longest LOD segment in every tier
            # (tier 0's too), or from the extents in every tier (the default until 2026-12-06)
            "tess-hybrid-segment": ("tess", "hybrid"), "tess-hybrid-extent": ("tess", "hybrid")}
# the hybrid variant and the uniform mode it is measured against
PAIRS = {"tess": ("tess-hybrid", "tess-4xSS+8xMS"), "tess-pair": ("tess-hybrid-pair", "tess-4xSS+8xMS"),
         "tess-finest": ("tess-hybrid-finest", "tess-4xSS+8xMS"),
         "tess-guideline": ("tess-hybrid", "tess-4xSS+8xMS-msaa-lod"),   # both at the guideline's thresholds
         "tess-ss-lod": ("tess-hybrid-ss-lod", "tess-4xSS+8xMS"),
         "tess-segment": ("tess-hybrid-segment", "tess-4xSS+8xMS"),
         "tess-extent": ("tess-hybrid-extent", "tess-4xSS+8xMS"),
         "points": ("points-hybrid", "points-16xSS"), "points-quad": ("points-hybrid-quad", "points-16xSS")}
REFERENCE_TESS = ("tess", "16xSS+8xMS")
# the tess reference's inner levels: from the longest LOD segment, so that thin lobes are whole (the
# extents cut 10-px order-8 glyphs' lobes short, silhouette IoU 0.64 against 0.91; docs/hybrid.md)
REFERENCE_INNER_MEASURE = "segment"
REFERENCE_POINTS = ("points", "16xSS")
REFERENCE_POINTS_DENSITY = 3.0   # samples per pixel of a segment: twice PointSettings.density
REFERENCES = ("auto", "tess", "points")
REFERENCE_BUDGET_S = 20.0        # one reference frame slower than this: the points reference
FLIP_AIM = 1.10                  # hybrid FLIP <= 1.1 x the uniform's
TIME_AIM = 0.5                   # hybrid frame ms <= 0.5 x the uniform's
SPREAD_AIM = 2.0                 # hybrid frame ms max / min along the path <= 2


def seashell3() -> Scene:
    """The third seashell alone: the shell with sub-pixel bumps (Figure 5.9)."""
    s = Scene()
    s.add("seashell3", material=Material((0.9, 0.8, 0.7)))
    return s


# name -> (builder, viewing direction, up, LOD threshold, tess l_max, l_min): paramlod.app.bench.scenes
# SCENARIOS, and seashell3 with the seashells' settings
HYBRID_SCENES = {"seashell3": (seashell3, *SCENARIOS["seashells"][1:]), **SCENARIOS}


# --- options -------------------------------------------------------------------------------------
class _Distinct(argparse.Action):
    """A list option whose values must differ (a distance or scene given twice is a typo)."""

    def __call__(self, parser, namespace, values, option_string=None):
        seen = set()
        for v in values:
            if v in seen:
                raise argparse.ArgumentError(self, f"{v!r} is given twice; give each value once")
            seen.add(v)
        setattr(namespace, self.dest, list(values))


def add_arguments(p):
    p.add_argument("--hybrid-distances", type=positive_float, nargs="+", default=list(DISTANCES), action=_Distinct,
                   metavar="D", help="hybrid: camera distances as multiples of the framing distance, drawn far to "
                                     f"near (default {' '.join(f'{d:g}' for d in DISTANCES)})")
    p.add_argument("--hybrid-scenes", nargs="+", choices=list(HYBRID_SCENES), default=list(SCENES), action=_Distinct,
                   metavar="SCENE", help=f"hybrid: scenes (default {' '.join(SCENES)}; also any bench scenario: "
                                         f"{' '.join(SCENARIOS)})")
    p.add_argument("--hybrid-variants", nargs="+", choices=list(VARIANTS), default=list(VARIANTS), action=_Distinct,
                   metavar="VARIANT", help=f"hybrid: the variants drawn at each distance (default all: "
                                           f"{' '.join(VARIANTS)})")
    p.add_argument("--hybrid-reference", choices=REFERENCES, default="auto",
                   help="hybrid: the reference image for FLIP: tess 16xSS+8xMS, points 16xSS at twice the "
                        "density, or auto (tess, points where tess fails or is too slow; default)")


# --- frames --------------------------------------------------------------------------------------
def path_camera(base: Camera, centre, dist: float, size) -> Camera:
    """``base``'s viewing direction at ``dist`` times its distance from ``centre``."""
    d = base.eye - centre
    r = float(np.linalg.norm(d))
    return Camera.look_at(centre + d * dist, centre, base.view[1, :3], base.fov_y, size,
                          near=max(r * dist * 1e-3, r * dist - 2 * r), far=r * dist + 2 * r)


def settings(variant: str, aa: str, threshold: float, l_max: float, l_min: float,
             density: float | None = None) -> RenderSettings:
    rs = RenderSettings()
    rs.lod.threshold = (threshold, threshold)
    rs.tess.l_max = l_max
    rs.tess.l_min = l_min
    if density is not None:
        rs.points.density = density
    rs.apply_aa(aa, variant=variant)
    return rs


def _draw(scene, cam, variant, rs):
    """One frame, the renderer's warnings (e.g. multisampling capped to the device's) kept, not shown."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        frame = render(scene, cam, variant, rs)
    return frame, sorted({str(w.message) for w in caught})


def tier_patches(stats) -> list[int]:
    """Render patches per hybrid tier: the LOD steps' ``tiers`` summed (all in tier 0 without hybrid)."""
    out = [0, 0, 0]
    for step in stats.get("lod_steps", []):
        for k, n in enumerate(step.get("tiers", ())):
            if k >= len(out):
                out.append(0)
            out[k] += int(n)
    return out


def measure(scene, cam, variant: str, aa: str, rs: RenderSettings, frames: int, warmup: int) -> tuple[dict, np.ndarray]:
    """(row, sRGB image of the last timed frame) of ``frames`` frames of ``cam`` after ``warmup``."""
    stats, notes = [], set()
    frame = None
    for k in range(warmup + frames):
        frame, w = _draw(scene, cam, variant, rs)
        notes.update(w)
        if k >= warmup:
            stats.append(frame.stats)
    image = np.array(frame.rgb8(), copy=True)
    last = stats[-1]
    med = statistics.median
    frame_ms = [s["ms"]["frame"] for s in stats]
    row = {"render_variant": variant, "aa": aa, "frames": len(stats),
           "frame_ms": med(frame_ms), "frame_ms_p95": float(np.percentile(frame_ms, 95)),
           "lod_ms": med(s["ms"].get("lod", 0.0) for s in stats),
           "render_ms": med(s["ms"].get("render", 0.0) for s in stats),
           # counts of the last timed frame (the camera does not move: every frame has the same LOD)
           "render_patches": int(last.get("render_patches", 0)),
           "tier_patches": tier_patches(last),
           "promoted": sum(int(s.get("promoted", 0)) for s in last.get("lod_steps", [])),
           "lod_patches_in": sum(int(s.get("in", 0)) for s in last.get("lod_steps", []))}
    if variant == "tess":
        row["aa_effective"] = str(last.get("aa_effective", aa))
        row["triangles"] = int(last.get("triangles", 0))
        if isinstance(last.get("tiers"), list):   # the tess renderer's per-tier record (hybrid frames)
            row["renderer_tiers"] = [{k: v for k, v in t.items() if isinstance(v, (int, float, str, list))}
                                     for t in last["tiers"]]
        elif aa == "hybrid":
            notes.add("the tess renderer reported no tiers for its hybrid frames (stats['tiers'] missing)")
    row["fps"] = 1e3 / row["frame_ms"] if row["frame_ms"] > 0 else float("inf")
    if notes:
        row["notes"] = sorted(notes)
    return row, image


# --- the reference -------------------------------------------------------------------------------
def _draw_twice(scene, cams: dict, order, variant: str, rs, budget_s: float | None = None):
    """({distance: image}, per-distance records, None) of ``variant`` drawn twice per distance (the
    redraw's FLIP against the first is the floor under every row's); or (.., .., why) when a first
    draw took longer than ``budget_s``."""
    images, per = {}, []
    for d in order:
        t0 = time.perf_counter()
        f, notes = _draw(scene, cams[d], variant, rs)
        a = np.array(f.rgb8(), copy=True)
        secs = time.perf_counter() - t0
        if budget_s is not None and secs > budget_s:
            return images, per, f"{variant} took {secs:.1f} s for one frame at distance {d:g} (budget {budget_s:g} s)"
        b = np.array(_draw(scene, cams[d], variant, rs)[0].rgb8(), copy=True)
        images[d] = a
        per.append({"distance": d, "seconds": secs, "aa_effective": str(f.stats.get("aa_effective", "")),
                    "render_patches": int(f.stats.get("render_patches", 0)), "redraw_flip": flip(a, b),
                    **({"notes": notes} if notes else {})})
    return images, per, None


def references(scene, cams: dict, threshold, l_max, l_min, reference: str = "auto",
               budget_s: float = REFERENCE_BUDGET_S, log=print) -> tuple[dict, dict]:
    """({distance: image}, info) of the scene's reference, drawn twice per distance (nearest first:
    the costliest frame decides early whether tess is too slow)."""
    order = sorted(cams, key=float)
    why = None
    if reference in ("auto", "tess"):
        variant, aa = REFERENCE_TESS
        try:
            rs = settings(variant, aa, threshold, l_max, l_min)
            rs.tess.inner_measure = REFERENCE_INNER_MEASURE
            images, per, why = _draw_twice(scene, cams, order, variant, rs, budget_s if reference == "auto" else None)
            if why is None:
                ran = sorted({p["aa_effective"] for p in per})
                return images, {"variant": variant, "aa": aa, "ran": ", ".join(ran), "per_distance": per,
                                "inner_measure": REFERENCE_INNER_MEASURE,
                                "label": f"tess {aa}, {REFERENCE_INNER_MEASURE} inner levels"
                                         + (f" (ran {', '.join(ran)})" if ran != [aa] else "")}
        except Exception as exc:   # any failure of the reference (GL limits, memory, ...) means: the points one
            if reference == "tess":
                raise
            why = f"tess {aa} failed: {type(exc).__name__}: {exc}"
        log(f"hybrid reference: {why}; using points {REFERENCE_POINTS[1]} at density {REFERENCE_POINTS_DENSITY:g}")
    variant, aa = REFERENCE_POINTS
    rs = settings(variant, aa, threshold, l_max, l_min, density=REFERENCE_POINTS_DENSITY)
    images, per, _ = _draw_twice(scene, cams, order, variant, rs)
    for p in per:   # the points variant has no effective AA of its own
        p.pop("aa_effective")
    info = {"variant": variant, "aa": aa, "density": REFERENCE_POINTS_DENSITY, "per_distance": per,
            "label": f"points {aa}, density {REFERENCE_POINTS_DENSITY:g}"}
    if why:
        info["fallback_because"] = why
    return images, info


# --- the aims ------------------------------------------------------------------------------------
def _spread(values) -> float | None:
    v = [x for x in values if x is not None]
    return max(v) / min(v) if v and min(v) > 0 else None


def aims(rows: list) -> dict:
    """Per pair (tess, points) present in ``rows`` (one scene): per distance the FLIP and time
    ratios hybrid / uniform and whether each aim holds; the frame-time spreads along the path; and
    ``losses``: every missed aim in words."""
    out = {}
    by = {(r["variant"], r["distance"]): r for r in rows if "error" not in r}
    for pair, (hname, uname) in PAIRS.items():
        dists = [r["distance"] for r in rows if r["variant"] == hname]
        if not dists or not any(r["variant"] == uname for r in rows):
            continue
        per, losses = [], []
        for d in dists:
            h, u = by.get((hname, d)), by.get((uname, d))
            if h is None or u is None:
                losses.append(f"d={d:g}: not measured ({'hybrid' if h is None else 'uniform'} failed)")
                per.append({"distance": d, "quality_ok": None, "time_ok": None})
                continue
            fr = h["flip"] / u["flip"] if u["flip"] > 0 else (1.0 if h["flip"] == 0 else float("inf"))
            tr = h["frame_ms"] / u["frame_ms"] if u["frame_ms"] > 0 else float("inf")
            q_ok, t_ok = fr <= FLIP_AIM, tr <= TIME_AIM
            per.append({"distance": d, "flip_ratio": fr, "time_ratio": tr, "quality_ok": q_ok, "time_ok": t_ok})
            if not q_ok:
                losses.append(f"d={d:g}: quality, FLIP {h['flip']:.4f} against the uniform's {u['flip']:.4f} "
                              f"({100 * (fr - 1):+.0f} %, aim <= +{100 * (FLIP_AIM - 1):.0f} %)")
            if not t_ok:
                losses.append(f"d={d:g}: time, {h['frame_ms']:.2f} ms against the uniform's {u['frame_ms']:.2f} ms "
                              f"({tr:.2f}x, aim <= {TIME_AIM:g}x)")
        hs = _spread(by[(hname, d)]["frame_ms"] for d in dists if (hname, d) in by)
        us = _spread(by[(uname, d)]["frame_ms"] for d in dists if (uname, d) in by)
        # one distance is no path: stability is judged from two on
        stable = None if hs is None or us is None or len(dists) < 2 else (hs <= SPREAD_AIM and us > hs)
        if stable is False:
            why = []
            if hs > SPREAD_AIM:
                why.append(f"its frame time varies {hs:.2f}x along the path (aim <= {SPREAD_AIM:g}x)")
            if us <= hs:
                why.append(f"the uniform's varies no more ({us:.2f}x against {hs:.2f}x)")
            losses.append("stability: " + "; ".join(why))
        out[pair] = {"hybrid": hname, "uniform": uname, "per_distance": per, "hybrid_spread": hs,
                     "uniform_spread": us, "stable_ok": stable,
                     "quality_met": sum(1 for p in per if p["quality_ok"]),
                     "time_met": sum(1 for p in per if p["time_ok"]), "distances": len(per), "losses": losses}
    return out


# --- driver --------------------------------------------------------------------------------------
def run_hybrid(size, frames: int = 8, warmup: int = 2, scenes=SCENES, distances=DISTANCES, variants=tuple(VARIANTS),
               reference: str = "auto", reference_budget_s: float = REFERENCE_BUDGET_S, log=print) -> dict:
    """The hybrid measurement (module docstring): {"size", "frames", "warmup", "distances",
    "variants", "scenes": {name: {"reference", "rows", "aims", ...}}}."""
    unknown = [s for s in scenes if s not in HYBRID_SCENES]
    if unknown:
        raise ParamlodError(f"hybrid: unknown scene(s) {', '.join(unknown)} (available: {', '.join(HYBRID_SCENES)})")
    bad = [v for v in variants if v not in VARIANTS]
    if bad:
        raise ParamlodError(f"hybrid: unknown variant(s) {', '.join(bad)} (available: {', '.join(VARIANTS)})")
    if reference not in REFERENCES:
        raise ParamlodError(f"hybrid: reference must be one of {', '.join(REFERENCES)}, got {reference!r}")
    if not distances or any(not (np.isfinite(d) and d > 0) for d in distances) or len(set(distances)) != len(distances):
        raise ParamlodError(f"hybrid: distances must be distinct finite numbers > 0, got {list(distances)}")
    if frames < 1 or warmup < 0:
        raise ParamlodError(f"hybrid: needs frames >= 1 and warmup >= 0, got {frames} and {warmup}")
    dists = sorted((float(d) for d in distances), reverse=True)   # far to near
    out = {"size": list(size), "frames": frames, "warmup": warmup, "distances": dists, "variants": list(variants),
           "aims": {"flip_ratio_max": FLIP_AIM, "time_ratio_max": TIME_AIM, "spread_max": SPREAD_AIM}, "scenes": {}}
    for name in scenes:
        build, direction, up, threshold, l_max, l_min = HYBRID_SCENES[name]
        scene = build()
        base = framing_camera(scene, direction, up, 40.0, size, margin=1.0)
        lo, hi = scene_box(scene)
        cams = {d: path_camera(base, (lo + hi) / 2, d, size) for d in dists}
        refs, info = references(scene, cams, threshold, l_max, l_min, reference, reference_budget_s, log)
        for p in info["per_distance"]:
            log(f"hybrid {name} reference {info['label']} d={p['distance']:g}: {p['seconds']:.2f} s, "
                f"{p['render_patches']} patches, redrawn FLIP {p['redraw_flip']:.4f}")
        sc = {"instances": scene.instance_count, "threshold": threshold, "l_max": l_max, "l_min": l_min,
              "reference": info, "rows": []}
        out["scenes"][name] = sc
        for d in dists:
            for vname in variants:
                variant, aa = VARIANTS[vname]
                try:
                    rs = settings(variant, aa, threshold, l_max, l_min)
                    apply_variant_settings(rs, vname)   # the variants' own settings: scenes.VARIANT_SETTINGS
                    row, image = measure(scene, cams[d], variant, aa, rs, frames, warmup)
                    row["flip"] = flip(refs[d], image)
                except (ParamlodError, NotImplementedError) as exc:
                    row = {"error": f"{type(exc).__name__}: {exc}"}
                row.update(variant=vname, distance=d)
                sc["rows"].append(row)
                if "error" in row:
                    log(f"hybrid {name} d={d:g} {vname}: error: {row['error']}")
                    continue
                tiers = f" [tiers {'/'.join(map(str, row['tier_patches']))}]" if aa == "hybrid" else ""
                ran = f" (ran {row['aa_effective']})" if row.get("aa_effective", aa) != aa else ""
                log(f"hybrid {name} d={d:g} {vname}{ran}: {row['frame_ms']:.2f} ms ({row['fps']:.0f} FPS), LOD "
                    f"{row['lod_ms']:.2f}, {row['render_patches']} patches{tiers}, FLIP {row['flip']:.4f}")
        sc["aims"] = aims(sc["rows"])
        for pair, a in sc["aims"].items():
            log(f"hybrid {name} {pair}: FLIP aim met at {a['quality_met']}/{a['distances']}, time aim at "
                f"{a['time_met']}/{a['distances']}, spread {_num(a['hybrid_spread'], '.2f')}x against "
                f"{_num(a['uniform_spread'], '.2f')}x" + (f"; loses: {'; '.join(a['losses'])}" if a["losses"] else ""))
        del scene, refs
    return out


# --- output --------------------------------------------------------------------------------------
def _num(x, fmt: str) -> str:
    return "n/a" if x is None else format(x, fmt)


HEADER = ("| distance | variant | FPS | frame ms (p95) | LOD ms | render patches | patches per tier | promoted "
          "| FLIP |")


def _fps(fps: float) -> str:
    return f"{fps:.0f}" if fps >= 10 else f"{fps:.2g}"


def format_hybrid(result: dict) -> list[str]:
    """The markdown section: per scene a table over distance and variant, then the aims and losses."""
    w, h = result["size"]
    frames = f"{result['frames']} timed frame{'s' if result['frames'] != 1 else ''}"
    intro = (f"{w}x{h}, {frames} of a fixed camera after {result['warmup']} warm-up frames per distance (medians); "
             f"distances are multiples of the framing distance, far to near. Patches per tier: render patches drawn "
             f"at each hybrid tier (tess noAA / 8xMS / 4xSS+8xMS, points 1x / 4xSS / 16xSS). FLIP against the "
             f"scene's reference. Aims per distance: hybrid FLIP <= {FLIP_AIM:g}x the uniform's and frame time <= "
             f"{TIME_AIM:g}x; along the path hybrid frame time max/min <= {SPREAD_AIM:g} and below the uniform's.")
    lines = ["", "## Hybrid anti-aliasing (issue #21)", "", intro]
    for name, sc in result["scenes"].items():
        ref = sc["reference"]
        floor = max((p["redraw_flip"] for p in ref["per_distance"]), default=0.0)
        count = sc["instances"]
        why = f" - tess was not used: {ref['fallback_because']}" if "fallback_because" in ref else ""
        lines += ["", f"### {name} ({count:,} instance{'s' if count != 1 else ''})", "",
                  f"Reference: {ref['label']}{why}; FLIP of the reference against itself redrawn: at most {floor:.4f}.",
                  "", HEADER, "|---:|---|---:|---:|---:|---:|---:|---:|---:|"]
        for r in sc["rows"]:
            if "error" in r:
                lines.append(f"| {r['distance']:g} | {r['variant']} | error: {r['error'][:80]} |||||||")
                continue
            ran = f" (ran {r['aa_effective']})" if r.get("aa_effective", r["aa"]) != r["aa"] else ""
            hybrid = r["aa"] == "hybrid"
            tiers = " / ".join(f"{n:,}" for n in r["tier_patches"]) if hybrid else ""
            lines.append(f"| {r['distance']:g} | {r['variant']}{ran} | {_fps(r['fps'])} | {r['frame_ms']:.2f} "
                         f"({r['frame_ms_p95']:.2f}) | {r['lod_ms']:.2f} | {r['render_patches']:,} | {tiers} | "
                         f"{format(r['promoted'], ',') if hybrid else ''} | {r['flip']:.4f} |")
        notes = sorted({n for r in sc["rows"] for n in r.get("notes", ())})
        ran = sorted({" / ".join(t["aa"] for t in r["renderer_tiers"]) for r in sc["rows"] if "renderer_tiers" in r})
        notes += [f"tess-hybrid drew its tiers as {t}." for t in ran]
        if notes:
            lines += [""] + [f"Note: {n}" for n in notes]
        for a in sc["aims"].values():
            stable = {True: "met", False: "missed", None: "n/a"}[a["stable_ok"]]
            summary = (f"**{a['hybrid']} against {a['uniform']}**: FLIP within {100 * (FLIP_AIM - 1):.0f} % at "
                       f"{a['quality_met']} of {a['distances']} distances; half the time or less at {a['time_met']} "
                       f"of {a['distances']}; frame time max/min {_num(a['hybrid_spread'], '.2f')} against the "
                       f"uniform's {_num(a['uniform_spread'], '.2f')} (stability aim {stable}).")
            lines += ["", summary]
            if a["losses"]:
                lines += ["", f"Where {a['hybrid']} loses:"] + [f"- {x}" for x in a["losses"]]
            else:
                lines += ["", f"{a['hybrid']} meets every aim on this path."]
    return lines


def plot_hybrid(result: dict, out: Path) -> list[Path]:
    """Per scene: FPS and FLIP against distance for every variant; [] without matplotlib."""
    plt = pyplot()
    if plt is None:
        return []
    paths = []
    for name, sc in result["scenes"].items():
        fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.6))
        for vname in result["variants"]:
            ok = [r for r in sc["rows"] if r["variant"] == vname and "error" not in r]
            if not ok:
                continue
            style = "-" if "hybrid" in vname else "--"
            a.plot([r["distance"] for r in ok], [r["fps"] for r in ok], style, marker="o", label=vname)
            b.plot([r["distance"] for r in ok], [r["flip"] for r in ok], style, marker="o", label=vname)
        for ax, what in ((a, "FPS"), (b, "mean FLIP against the reference")):
            ax.set_xscale("log")
            ax.invert_xaxis()   # far to near, as the camera moves
            ax.set_xlabel("camera distance (x framing distance)")
            ax.set_ylabel(what)
            ax.legend(fontsize=7)
        a.set_yscale("log")
        a.set_title(f"{name}: FPS")
        b.set_title(f"{name}: FLIP ({sc['reference']['label']})", fontsize=9)
        fig.suptitle(f"hybrid AA, {result['size'][0]}x{result['size'][1]}", fontsize=9)
        paths.append(save_figure(fig, Path(out) / f"hybrid_{name}.png"))
    return paths


__all__ = ["DISTANCES", "HYBRID_SCENES", "SCENES", "VARIANTS", "add_arguments", "aims", "format_hybrid", "plot_hybrid",
           "run_hybrid"]
