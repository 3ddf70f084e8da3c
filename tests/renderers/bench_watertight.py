"""Cost of the direct point variant's boundary measure (issue 19): frames per second and samples
with the render patches sized for their boundary lines (w_u, w_v, today's default) against sized by
their interior lines only (s_u, s_v, before), alternating per scenario and distance in one process.

    python tests/renderers/bench_watertight.py [--size 1920x1080] [--frames 8] [scenario ...]

Default scenarios: sphere sh12 hardi12 yarn_curtain (paramlod bench's), distances 0.35 0.6 1 2.
Prints one line per row and per scenario the ratio new/old of the median frame rates (a speed
measurement: not a test, pytest does not collect it)."""
from __future__ import annotations

import argparse
import statistics
from types import SimpleNamespace

import numpy as np

from paramlod.app.args import parse_size
from paramlod.app.bench.run import measure
from paramlod.app.bench.scenes import SCENARIOS
from paramlod.renderers.sampling import MEASURE_SEGMENT, PointSettings
from paramlod.scene.framing import framing_camera, scene_box

NEW = PointSettings.measure


def old(self, boundary):
    return np.uint32(MEASURE_SEGMENT) if not self.use_extent else NEW(self, boundary)


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("scenarios", nargs="*", default=["sphere", "sh12", "hardi12", "yarn_curtain"])
    p.add_argument("--size", type=parse_size, default=(1920, 1080))
    p.add_argument("--frames", type=int, default=8)
    p.add_argument("--warmup", type=int, default=2)
    p.add_argument("--distances", type=float, nargs="+", default=[0.35, 0.6, 1.0, 2.0])
    p.add_argument("--variant", default="points", choices=["points"])
    a = p.parse_args(argv)
    args = SimpleNamespace(frames=a.frames, warmup=a.warmup)
    for name in a.scenarios:
        build, direction, up, threshold, l_max, l_min = SCENARIOS[name]
        scene = build()
        base = framing_camera(scene, direction, up, 40.0, a.size, margin=1.0)
        lo, hi = scene_box(scene)
        centre = (lo + hi) / 2
        ratios = []
        for dist in a.distances:
            row = {}
            for label, fn in (("old", old), ("new", NEW), ("old", old), ("new", NEW)):   # twice, interleaved
                PointSettings.measure = fn
                r = measure(scene, base, centre, dist, a.variant, None, args, threshold, l_max, l_min, a.size)
                row.setdefault(label, []).append(r)
            PointSettings.measure = NEW
            fps = {k: statistics.median(x["fps"] for x in v) for k, v in row.items()}
            smp = {k: statistics.median(x["samples"] for x in v) for k, v in row.items()}
            ratios.append(fps["new"] / fps["old"])
            print(f"{name} d={dist}: fps old {fps['old']:.1f} new {fps['new']:.1f} (new/old {ratios[-1]:.3f}), "
                  f"samples new/old {smp['new'] / max(smp['old'], 1):.4f}", flush=True)
        print(f"{name}: frames/s new/old, geometric mean over distances {np.exp(np.mean(np.log(ratios))):.3f}",
              flush=True)


if __name__ == "__main__":
    main()
