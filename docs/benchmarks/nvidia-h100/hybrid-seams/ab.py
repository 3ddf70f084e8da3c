"""The tess hybrid's seams between carried tiers, before and after (one device call).

Per scene and distance of `paramlod bench --extras hybrid`'s path: the reference (tess
16xSS+8xMS), uniform tess 4xSS+8xMS, and the tess hybrid with its carried tiers reaching 0 pixels
(before) and CARRY_OVERLAP_PX (after) past their patches' edges; "tier0-half": after, with tier 0
tessellated at half its thresholds (an experiment done here by wrapping the renderer, not in the
product). Each row: frame ms (median), FLIP against the reference, and "seam pixels": pixels the
reference covers whole (eroded by one) where the row leaves a sample uncovered.

    python3 -P docs/benchmarks/nvidia-h100/hybrid-seams/ab.py OUT [--size 1920x1080] [--frames 4]
"""
import argparse
import json
import statistics
import sys
import warnings
from pathlib import Path

import numpy as np
from scipy import ndimage

import paramlod.renderers.tess as tess
from paramlod.app.bench import hybrid as H
from paramlod.app.bench.mesh_eval import flip
from paramlod.device.programs import set_uniform
from paramlod.pipeline.driver import render
from paramlod.scene.framing import framing_camera, scene_box

p = argparse.ArgumentParser()
p.add_argument("out")
p.add_argument("--size", default="1920x1080")
p.add_argument("--frames", type=int, default=4)
p.add_argument("--scenes", nargs="+", default=["seashell3", "yarn_curtain", "hardi12"])
p.add_argument("--distances", nargs="+", type=float, default=[4.0, 1.0, 0.35])
a = p.parse_args()
size = tuple(int(x) for x in a.size.split("x"))
out = Path(a.out)
out.mkdir(parents=True, exist_ok=True)
warnings.simplefilter("ignore")

ORIGINAL_DRAW_LIST = tess.TessRenderer._draw_list
TIER0 = {"base": None}


def tier0_half(self, prog, patches, settings, threshold, *args, **kw):
    """tier 0 of a hybrid frame (its thresholds are the frame's own) tessellated at half of them"""
    if TIER0["base"] is not None and tuple(threshold) == TIER0["base"]:
        threshold = tuple(x / 2 for x in threshold)
        set_uniform(prog, "u_threshold", threshold)
        if kw.get("chord") is not None:
            kw["chord"] = kw["chord"] / 2
    return ORIGINAL_DRAW_LIST(self, prog, patches, settings, threshold, *args, **kw)


def frames(scene, cam, rs, n):
    ms, f = [], None
    for k in range(n + 1):
        f = render(scene, cam, "tess", rs)
        img = np.array(f.rgb8(), copy=True)
        if k:
            ms.append(f.stats["ms"]["frame"])
    return statistics.median(ms), img, f


ROWS = {"uniform-4xSS+8xMS": ("4xSS+8xMS", 1.0, False), "hybrid-before": ("hybrid", 0.0, False),
        "hybrid-after": ("hybrid", tess.CARRY_OVERLAP_PX, False), "hybrid-after-tier0-half": ("hybrid", tess.CARRY_OVERLAP_PX, True)}
results = []
for name in a.scenes:
    build, direction, up, thr, l_max, l_min = H.HYBRID_SCENES[name]
    scene = build()
    base = framing_camera(scene, direction, up, 40.0, size, margin=1.0)
    lo, hi = scene_box(scene)
    for d in a.distances:
        cam = H.path_camera(base, (lo + hi) / 2, d, size)
        rs = H.settings("tess", "16xSS+8xMS", thr, l_max, l_min)
        ref = render(scene, cam, "tess", rs)
        ref_img = np.array(ref.rgb8(), copy=True)
        inside = ndimage.binary_erosion(ref.color[..., 3] == 1)
        for row, (aa, reach, half) in ROWS.items():
            tess.CARRY_OVERLAP_PX = reach
            TIER0["base"] = (float(thr), float(thr)) if half else None
            tess.TessRenderer._draw_list = tier0_half if half else ORIGINAL_DRAW_LIST
            ms, img, f = frames(scene, cam, H.settings("tess", aa, thr, l_max, l_min), a.frames)
            r = {"scene": name, "distance": d, "row": row, "frame_ms": ms, "flip": flip(img, ref_img),
                 "seam_pixels": int((inside & (f.color[..., 3] < 1)).sum()), "covered": int(inside.sum()),
                 "triangles": int(f.stats.get("triangles", 0)),
                 "tiers": [t["patches"] for t in f.stats.get("tiers", [])], "device": f.stats.get("device")}
            results.append(r)
            print(f"{name} d={d:g} {row}: {ms:.2f} ms, FLIP {r['flip']:.4f}, seam pixels {r['seam_pixels']}, "
                  f"triangles {r['triangles']:,}, tiers {r['tiers']}", flush=True)
        tess.CARRY_OVERLAP_PX, tess.TessRenderer._draw_list = ROWS["hybrid-after"][1], ORIGINAL_DRAW_LIST
(out / "ab.json").write_text(json.dumps(results, indent=1))
print("\n| scene | d | " + " | ".join(ROWS) + " |")
print("|---|---:|" + "---|" * len(ROWS))
for name in a.scenes:
    for d in a.distances:
        cells = []
        for row in ROWS:
            r = next(x for x in results if x["scene"] == name and x["distance"] == d and x["row"] == row)
            cells.append(f"{r['frame_ms']:.1f} / {r['flip']:.4f} / {r['seam_pixels']}")
        print(f"| {name} | {d:g} | " + " | ".join(cells) + " |")
