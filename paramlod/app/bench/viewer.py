"""The viewer's presenting overhead (extra "viewer" of ``paramlod bench``): for the same cameras,
the viewer's frame (paramlod.viewer.app.Viewer.draw_frame: render, the 8-bit image to the host,
the upload into the window's texture, the full-screen draw and the HUD, the swap, and a finish of
the window's context so that its GL work is counted) against ``render_on_device`` of the frame
(up to resolved buffers on the device). Scenes: the sphere, the 19,600-glyph field (hardi12) and
a mesh (the Stanford bunny, cluster DAG). A real window when DISPLAY is set (on the GPU machine
Xvfb with NVIDIA's GLX), else the headless backend (EGL); vsync off, so that the display's rate
does not hide the cost.

Run alone: ``python -m paramlod.app.bench.viewer [--size 1920x1080] [--frames 30] [--out DIR]``."""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from paramlod.app.args import Parser, add_size, check_folder, non_negative_int, positive_int, run_reporting_errors
from paramlod.app.bench.meshes import bench_meshes, normalizing
from paramlod.app.bench.scenes import SCENARIOS
from paramlod.core.camera import Camera
from paramlod.core.files import write_atomically
from paramlod.errors import ParamlodError
from paramlod.meshlod.build.dag import build_dag
from paramlod.pipeline.driver import render_on_device
from paramlod.pipeline.settings import RenderSettings
from paramlod.scene.framing import framing_camera, scene_box
from paramlod.scene.scene import Material, Scene
from paramlod.viewer.app import Viewer, open_window
from paramlod.viewer.reload import Source

SCENES = ("sphere", "hardi12", "bunny")


def _scene(name: str):
    """(scene, variant, viewing direction, up, LOD threshold)."""
    if name == "bunny":
        _, v, f, n = bench_meshes(False)[0]
        lod = build_dag(v, f, n, name="bunny")
        s = Scene()
        s.add_mesh(lod, transform=normalizing(lod.vertices), material=Material((0.75, 0.7, 0.62)))
        return s, "meshlets", (0.3, 0.4, 1.0), (0, 1, 0), 84.0
    build, direction, up, threshold, _, _ = SCENARIOS[name]
    return build(), "points", direction, up, threshold


def _orbit(base: Camera, centre, k: int, n: int) -> Camera:
    """The base camera turned ``k / n`` of a quarter turn about its up axis round ``centre``."""
    d, up = base.eye - centre, base.view[1, :3]
    a = 0.5 * np.pi * k / max(n, 1)
    d = d * np.cos(a) + np.cross(up, d) * np.sin(a) + up * np.dot(up, d) * (1 - np.cos(a))
    r = float(np.linalg.norm(d))
    return Camera.look_at(centre + d, centre, up, base.fov_y, base.size, near=r * 1e-3, far=r * 4)


def measure_scene(window, name: str, size, frames: int, warmup: int, log=print) -> dict:
    scene, variant, direction, up, threshold = _scene(name)
    settings = RenderSettings()
    settings.lod.threshold = (threshold, threshold)
    base = framing_camera(scene, direction, up, 40.0, size, margin=1.0)
    lo, hi = scene_box(scene)
    centre = (lo + hi) / 2
    cams = [_orbit(base, centre, k, frames) for k in range(frames)]
    viewer = Viewer(Source.of_scene(scene, base, settings, variant, name), window, hud_on=True)
    viewer.paused = True
    if viewer.render_size() != tuple(size):   # a display that gave a smaller window would compare other frames
        raise ParamlodError(f"viewer bench: the window is {viewer.render_size()[0]}x{viewer.render_size()[1]}, "
                            f"not {size[0]}x{size[1]}; use a larger screen (Xvfb -screen 0 2560x1440x24)")
    device, view, present = [], [], []
    for k, cam in enumerate([*cams[:warmup], *cams]):
        t0 = time.perf_counter()
        dev_stats = render_on_device(scene, cam, variant, settings)
        t1 = time.perf_counter()
        t2 = time.perf_counter()
        viewer.draw_frame(0.0, camera=cam)
        viewer.finish()
        t3 = time.perf_counter()
        if viewer.error:
            raise ParamlodError(f"viewer frame of {name}: {viewer.error}")
        if k >= warmup:
            device.append((t1 - t0) * 1e3)
            view.append((t3 - t2) * 1e3)
            present.append(viewer.timings["present"])
    med = statistics.median
    row = {"scenario": name, "variant": variant, "size": list(size), "frames": frames,
           "render_patches": int(viewer.frame.stats.get("render_patches", 0)),
           "same_frame": int(viewer.frame.stats.get("pixels_written", -1)) == int(dev_stats.get("pixels_written", -2)),
           "device_ms": med(device), "viewer_ms": med(view), "overhead_ms": med(view) - med(device),
           "overhead_ms_p95": float(np.percentile(np.array(view) - np.array(device), 95)),
           "present_ms": med(present)}
    log(f"viewer {name} {variant} {size[0]}x{size[1]}: render_on_device {row['device_ms']:.2f} ms, viewer frame "
        f"{row['viewer_ms']:.2f} ms, overhead {row['overhead_ms']:.2f} ms (present {row['present_ms']:.2f})")
    return row


def run_viewer(size=(1920, 1080), frames: int = 30, warmup: int = 3, scenes=SCENES, log=print) -> dict:
    """The extra "viewer": one row per scene (see the module's docstring)."""
    headless = not os.environ.get("DISPLAY")
    window = open_window(size, headless=headless, vsync=False, title="paramlod bench viewer")
    try:
        info = window.ctx.info
        where = ("headless (EGL)" if headless else f"window on DISPLAY={os.environ['DISPLAY']}") + \
            f", {info.get('GL_RENDERER', '?')}"
        log(f"viewer bench: {where}")
        rows = [measure_scene(window, name, size, frames, warmup, log) for name in scenes]
    finally:
        window.destroy()
    return {"window": where, "rows": rows}


def format_viewer(res: dict) -> list[str]:
    lines = ["", "## Viewer", "", f"{res['window']}.", "",
             "| scene | variant | size | render_on_device ms | viewer frame ms | overhead ms | p95 | present ms |",
             "|---|---|---|---:|---:|---:|---:|---:|"]
    for r in res["rows"]:
        lines.append(f"| {r['scenario']} | {r['variant']} | {r['size'][0]}x{r['size'][1]} | {r['device_ms']:.2f} | "
                     f"{r['viewer_ms']:.2f} | {r['overhead_ms']:.2f} | {r['overhead_ms_p95']:.2f} | {r['present_ms']:.2f} |")
    return lines


def main(argv=None) -> int:
    p = Parser(prog="python -m paramlod.app.bench.viewer", description=__doc__,
               formatter_class=argparse.RawDescriptionHelpFormatter)
    add_size(p, "1920x1080", what="frame size")
    p.add_argument("--frames", type=positive_int, default=30, help="timed frames per scene (default 30)")
    p.add_argument("--warmup", type=non_negative_int, default=3, help="untimed frames first (default 3)")
    p.add_argument("--scenes", nargs="+", choices=SCENES, default=list(SCENES), help="scenes (default all)")
    p.add_argument("--out", default="out/bench-viewer", help="folder for results.json and results.md")
    args = p.parse_args(argv)

    def run() -> int:
        out = check_folder(Path(args.out), "--out", create=True)
        res = run_viewer(args.size, args.frames, args.warmup, args.scenes, log=lambda m: print(m, flush=True))
        write_atomically(out / "results.json", lambda tmp: Path(tmp).write_text(json.dumps(res, indent=1)))
        md = "\n".join(format_viewer(res)) + "\n"
        write_atomically(out / "results.md", lambda tmp: Path(tmp).write_text(md))
        print(md)
        return 0

    return run_reporting_errors(run)


if __name__ == "__main__":
    sys.exit(main())
