"""``paramlod bench``: LOD and render times of standard scenes at several camera distances, and
the device's random 64-bit atom_min ceiling measured in the same run."""
from __future__ import annotations

import json
import platform
import statistics
import time
from pathlib import Path

import numpy as np

from .camera import Camera
from .device import cl_device
from .render import render
from .scene import Scene

# name -> (function, distances in object radii from the centre)
SCENARIOS = {
    "sphere": ("sphere", (1.6, 3.0, 8.0)),
    "torus": ("torus", (1.8, 3.5, 9.0)),
}


def add_arguments(p):
    p.add_argument("scenarios", nargs="*", help=f"scenarios (default all: {', '.join(SCENARIOS)})")
    p.add_argument("--size", default="1920x1080", help="frame size (default 1920x1080)")
    p.add_argument("--frames", type=int, default=10, help="timed frames per distance (default 10)")
    p.add_argument("--warmup", type=int, default=2, help="untimed frames per distance (default 2)")
    p.add_argument("--out", default="out/bench", help="folder for results.json (default out/bench)")


def atomics_ceiling(width, height, repeats=5) -> float:
    """Random 64-bit atom_min per second into a width x height buffer."""
    import pyopencl as cl

    from .programs import kernel

    k = kernel("random_atom_min", ["bench.cl"])
    dev = cl_device()
    n = width * height
    buf = cl.Buffer(dev.context, cl.mem_flags.READ_WRITE, n * 8)
    items = 1 << 16 if not dev.is_gpu else 1 << 22
    per_item = 64
    best = 0.0
    for r in range(repeats + 1):
        cl.enqueue_fill_buffer(dev.queue, buf, np.uint64(0xFFFFFFFFFFFFFFFF), 0, n * 8)
        dev.queue.finish()
        t0 = time.perf_counter()
        k(dev.queue, (items,), None, buf, np.uint32(n), np.uint32(per_item), np.uint32(r))
        dev.queue.finish()
        dt = time.perf_counter() - t0
        if r:  # the first launch includes compilation and warm-up
            best = max(best, items * per_item / dt)
    return best


def _orbit_eye(dist, k, n):
    a = 2 * np.pi * k / max(n, 1)
    return (dist * np.sin(a), 0.35 * dist, dist * np.cos(a))


def run_bench(args) -> int:
    from .cli import _size

    w, h = _size(args.size)
    names = args.scenarios or list(SCENARIOS)
    unknown = [n for n in names if n not in SCENARIOS]
    if unknown:
        from .errors import ParamlodError

        raise ParamlodError(f"unknown scenario(s) {', '.join(unknown)} (available: {', '.join(SCENARIOS)})")
    dev = cl_device()
    ceiling = atomics_ceiling(w, h)
    rows = []
    for name in names:
        fn, dists = SCENARIOS[name]
        scene = Scene()
        scene.add(fn)
        for dist in dists:
            frames = []
            for k in range(args.warmup + args.frames):
                cam = Camera.look_at(_orbit_eye(dist, k, args.frames), (0, 0, 0), size=(w, h))
                f = render(scene, cam)
                if k >= args.warmup:
                    frames.append(f.stats)
            ms = {key: statistics.median(s["ms"][key] for s in frames) for key in frames[0]["ms"]}
            samples = statistics.median(s["samples"] for s in frames)
            atomics = statistics.median(s["atomics"] for s in frames)
            rows.append({
                "scenario": name, "distance": dist, "frames": len(frames),
                "frame_ms": ms["frame"], "lod_ms": ms["lod"], "render_ms": ms["render"],
                "resolve_ms": ms["resolve"], "upload_ms": ms["upload"], "readback_ms": ms["readback"],
                "render_patches": statistics.median(s["render_patches"] for s in frames),
                "samples": samples, "samples_per_s": samples / (ms["render"] / 1e3),
                "atomics_per_s": atomics / (ms["render"] / 1e3),
                "pixels_written": statistics.median(s["pixels_written"] for s in frames),
                "lod_steps_in": [statistics.median(s["lod_steps"][i]["in"] for s in frames)
                                 for i in range(len(frames[0]["lod_steps"]))],
            })
            r = rows[-1]
            print(f"  {name} d={dist}: frame {r['frame_ms']:.2f} ms, LOD {r['lod_ms']:.2f}, "
                  f"render {r['render_ms']:.2f}, {r['render_patches']:.0f} patches", flush=True)
    result = {
        "device": dev.name, "device_type": "GPU" if dev.is_gpu else "CPU", "host": platform.node(),
        "size": [w, h], "atomics_ceiling_per_s": ceiling, "rows": rows,
    }
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "results.json").write_text(json.dumps(result, indent=2))
    print(format_table(result))
    print(f"results: {out / 'results.json'}")
    return 0


def format_table(result) -> str:
    lines = [f"device: {result['device']} ({result['device_type']}), {result['size'][0]}x{result['size'][1]}; "
             f"random 64-bit atom_min ceiling {result['atomics_ceiling_per_s'] / 1e9:.2f} G/s",
             "frame ms = upload + LOD + render + resolve on the device (median); readback of the Frame to the host is extra.",
             "", "| scenario | distance | frame ms | LOD ms | render ms | readback ms | render patches | samples/s | atomics % of ceiling |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in result["rows"]:
        lines.append(f"| {r['scenario']} | {r['distance']} | {r['frame_ms']:.2f} | {r['lod_ms']:.2f} | "
                     f"{r['render_ms']:.2f} | {r['readback_ms']:.2f} | {r['render_patches']:.0f} | {r['samples_per_s'] / 1e6:.1f} M | "
                     f"{100 * r['atomics_per_s'] / result['atomics_ceiling_per_s']:.1f}% |")
    return "\n".join(lines)
