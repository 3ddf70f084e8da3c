"""``paramlod bench``: the thesis's measurements (section 5.6) on this machine's device.

For each scenario and variant the camera orbits the scene once at several distances (multiples of
the distance at which the scene just fills the frame), after warm-up frames; per distance we report
median and 95th-percentile frame time, LOD and render time, kernel (device) time, the Python time
spent preparing and enqueueing a frame (host) and the time the device waited (idle), the CL->GL
transfer of the tessellation variant, patches per LOD step, render patches, pixels written,
overdraw, our device buffers and the host RSS. In the same run: the random 64-bit
atom_min ceiling, the tessellated triangles/s of a trivial function, the OpenCL evaluation
throughput of every built-in function, and the blue-surfel sampling and prefix-rendering costs;
the mesh LOD measurements (extra "meshes", paramlod.app.bench.meshes) and, on request, the mesh-LOD
evaluation of full mesh / discrete chain / cluster DAG (extra "mesh-eval",
paramlod.app.bench.mesh_eval) and the skinned giant worm with its culling on and off (extra
"skinned", paramlod.app.bench.skinned), the viewer's presenting overhead (extra "viewer",
paramlod.app.bench.viewer), multi-view frames against as many single ones (extra "multiview",
paramlod.app.bench.multiview) and hybrid anti-aliasing against uniform anti-aliasing from far to near
(extra "hybrid", paramlod.app.bench.hybrid). ``--only-extras`` skips the parametric scenarios.
Results go to DIR/results.json (written after every measurement), DIR/results.md and plots.
"""
from __future__ import annotations

import importlib.resources
import importlib.util
import json
import os
import platform
import statistics
import time
from pathlib import Path

import numpy as np
import pyopencl as cl

from paramlod.app.args import add_size, check_folder, non_negative_int, positive_float, positive_int
from paramlod.app.bench.functions import format_function_throughput, function_throughput
from paramlod.app.bench.hybrid import add_arguments as add_hybrid_arguments, format_hybrid, plot_hybrid, run_hybrid
from paramlod.app.bench.mesh_eval import SCENARIOS as EVAL_SCENARIOS, THRESHOLDS as EVAL_THRESHOLDS
from paramlod.app.bench.mesh_eval import format_mesh_eval, plot_mesh_eval, run_mesh_eval
from paramlod.app.bench.meshes import format_meshes, run_meshes
from paramlod.app.bench.multiview import SCENES as MULTIVIEW_SCENES, VIEW_SETS, format_multiview, run_multiview
from paramlod.app.bench.plots import pyplot, save_figure
from paramlod.app.bench.peers import add_arguments as add_peers_arguments, format_peers_markdown, run_peers
from paramlod.app.bench.skinned import format_skinned, run_skinned
from paramlod.app.bench.viewer import format_viewer, run_viewer
from paramlod.app.bench.scenes import DEFAULT, SCENARIOS, apply_variant_settings
from paramlod.core.camera import Camera
from paramlod.core.files import write_atomically
from paramlod.device.context import cl_device
from paramlod.device.programs import start_timing, stop_timing
from paramlod.errors import ParamlodError
from paramlod.function.programs import kernel
from paramlod.lod.stage import LodSettings
from paramlod.pipeline.driver import render, render_on_device, scene_state
from paramlod.pipeline.settings import RenderSettings
from paramlod.renderers.aa import POINT_TIERS
from paramlod.renderers.tess import TessSettings
from paramlod.scene.framing import framing_camera, scene_box
from paramlod.scene.scene import Scene
from paramlod.surfels.build import sample_mesh
from paramlod.surfels.render import FixedCount, default_camera, render_surfels

# name -> (render variant, AA mode); points-4xSS is the direct variant drawn into 2x2 supersampled
# key buffers, points-ssaa the thesis's local-framebuffer 4xSS
VARIANTS = {"points": ("points", None), "points-4xSS": ("points", "4xSS"), "points-ssaa": ("points-ssaa", None),
            "tess": ("tess", "noAA"), "tess-4xSS+8xMS": ("tess", "4xSS+8xMS"),
            "points-hybrid": ("points", "hybrid"), "tess-hybrid": ("tess", "hybrid"), "points-centre": ("points", None),
            "points-quad": ("points", None), "points-quad-fine": ("points", None),
            "tess-grid": ("tess", "noAA"), "tess-chord": ("tess", "noAA"),
            "tess-segment": ("tess", "noAA"),
            "tess-detail": ("tess", "noAA")}   # their own settings: scenes.VARIANT_SETTINGS
DEFAULT_VARIANTS = ["points", "points-4xSS", "points-ssaa", "tess", "tess-4xSS+8xMS"]
NO_CULLING = "(no culling)"   # the label of rows measured with --culling off / both


# --size, --distances, --frames and --warmup when not given, by the kind of OpenCL device: the
# thesis's 1080p orbit at four distances on a GPU; on a CPU that is hours of frames (the fibre
# curtain's tess-4xSS+8xMS on llvmpipe alone), so a smaller frame at the framing distance
RUN_DEFAULTS = {"GPU": {"size": (1920, 1080), "distances": (0.35, 0.6, 1.0, 2.0), "frames": 8, "warmup": 2},
                "CPU": {"size": (640, 360), "distances": (1.0,), "frames": 3, "warmup": 1}}


def apply_run_defaults(args, kind: str) -> list[str]:
    """Fill the run options not given with ``kind``'s (RUN_DEFAULTS); the names of those filled."""
    filled = []
    for name, value in RUN_DEFAULTS[kind].items():
        if getattr(args, name, None) is None:
            setattr(args, name, list(value) if name == "distances" else value)
            filled.append(name)
    return filled


def _run_text(d: dict) -> str:
    """RUN_DEFAULTS entry ``d`` in words."""
    return (f"{d['size'][0]}x{d['size'][1]}, distances {' '.join(f'{x:g}' for x in d['distances'])}, "
            f"{d['frames']} frames after {d['warmup']} warm-up")


def add_arguments(p):
    p.add_argument("scenarios", nargs="*", help=f"scenarios (default: {' '.join(DEFAULT)}; all: "
                                                f"{' '.join(SCENARIOS)})")
    p.add_argument("--variants", nargs="+", default=DEFAULT_VARIANTS, choices=list(VARIANTS),
                   help="render variants (default: all five)")
    gpu, cpu = RUN_DEFAULTS["GPU"], RUN_DEFAULTS["CPU"]
    add_size(p, what="frame size")
    p.add_argument("--distances", type=positive_float, nargs="+", default=None,
                   help="camera distances as multiples of the framing distance (default "
                        f"{' '.join(f'{d:g}' for d in gpu['distances'])} on a GPU, "
                        f"{' '.join(f'{d:g}' for d in cpu['distances'])} on a CPU)")
    p.add_argument("--frames", type=positive_int, default=None,
                   help=f"timed frames per orbit (default {gpu['frames']} on a GPU, {cpu['frames']} on a CPU)")
    p.add_argument("--warmup", type=non_negative_int, default=None,
                   help=f"untimed frames before each orbit (default {gpu['warmup']} on a GPU, {cpu['warmup']} on a CPU)")
    p.add_argument("--extras", nargs="*", default=None,
                   choices=["ceilings", "functions", "surfels", "meshes", "mesh-eval", "skinned", "viewer", "multiview",
                            "hybrid"],
                   help="extra measurements (default ceilings, functions, surfels and meshes, leaving out those whose "
                        "optional modules are missing; not by default: mesh-eval, the full / chain / DAG evaluation, "
                        "skinned, the rigged giant worm with its conservative culling, viewer, the "
                        "interactive viewer's presenting overhead, multiview, N views in one frame, and hybrid, "
                        "hybrid anti-aliasing against uniform 4xSS+8xMS / 16xSS from far to near, with FLIP)")
    p.add_argument("--views", type=positive_int, nargs="+", default=list(VIEW_SETS),
                   help="multiview: view counts (2: a stereo pair, others: quilts; default 2 6 48)")
    p.add_argument("--multiview-scenes", nargs="+", choices=list(SCENARIOS), default=list(MULTIVIEW_SCENES),
                   help="multiview: scenarios (default hardi12 yarn_curtain sphere)")
    add_hybrid_arguments(p)
    p.add_argument("--only-extras", action="store_true", help="skip the parametric scenarios: only the extras")
    p.add_argument("--big-mesh", choices=["auto", "yes", "no"], default="auto",
                   help="also measure a 1.6 M-triangle mesh (default: on a GPU only)")
    p.add_argument("--mesh-grid", type=positive_int, default=10, help="copies per side of the mesh grid (default 10)")
    p.add_argument("--eval-thresholds", type=positive_float, nargs="+", default=list(EVAL_THRESHOLDS),
                   help="mesh-eval: LOD thresholds in pixels (default 0.25 0.5 1 2 4)")
    p.add_argument("--eval-scenarios", nargs="+", choices=list(EVAL_SCENARIOS), default=list(EVAL_SCENARIOS),
                   help="mesh-eval: scenarios (default grid path close move)")
    p.add_argument("--eval-move-frames", type=positive_int, default=24,
                   help="mesh-eval: frames of the slow move that measures popping (default 24)")
    p.add_argument("--eval-parts", type=non_negative_int, default=1000,
                   help="mesh-eval: parts of the many-parts mesh, 80 triangles each (default 1000; 0: none)")
    p.add_argument("--culling", choices=["on", "off", "both"], default="on",
                   help="the points variants' occlusion and back-face culling (both: every points row also "
                        "without it, labelled 'no culling', for before/after ratios in one run; default on)")
    p.add_argument("--detail-angle", type=positive_float, default=LodSettings.detail_angle,
                   help="the LOD stage's detail_angle in degrees for the scenarios (180: off; default "
                        f"{LodSettings.detail_angle:g}, docs/lod.md)")
    p.add_argument("--cse-before", action="store_true",
                   help="functions: also measure the generated code without the shared CSE (before/after)")
    p.add_argument("--out", default="out/bench", help="folder for results (default out/bench)")
    add_peers_arguments(p)


# --- ceilings ------------------------------------------------------------------------------------
def atomics_ceiling(width, height, repeats=5) -> float:
    """Random 64-bit atom_min per second into a width x height buffer."""
    k = kernel("random_atom_min", ["bench/bench.cl"])
    dev = cl_device()
    n = width * height
    buf = cl.Buffer(dev.context, cl.mem_flags.READ_WRITE, n * 8)
    items = 1 << 22 if dev.is_gpu else 1 << 16
    per_item = 64
    best = 0.0
    for r in range(repeats + 1):
        cl.enqueue_fill_buffer(dev.queue, buf, np.uint64(0xFFFFFFFFFFFFFFFF), 0, n * 8)
        evt = k(dev.queue, (items,), None, buf, np.uint32(n), np.uint32(per_item), np.uint32(r))
        evt.wait()
        if r:  # the first launch includes warm-up
            best = max(best, items * per_item / ((evt.profile.end - evt.profile.start) * 1e-9))
    return best


def tess_ceiling(size, level=64, repeats=3) -> dict:
    """Triangles/s of hardware tessellation of a trivial function (a sphere) at a fixed level."""
    s = Scene()
    s.add("sphere")
    cam = Camera.look_at((0, 0, 3.2), (0, 0, 0), size=size)
    rs = RenderSettings(lod=LodSettings(threshold=(1e6, 1e6), initial_grid=(32, 32)),
                        tess=TessSettings(mode="fixed", levels=(float(level), float(level))))
    best = None
    for _ in range(repeats + 1):
        f = render(s, cam, "tess", rs)
        ms = f.stats["ms"]["draw"]
        if best is None or ms < best[0]:
            best = (ms, f.stats["render_patches"])
    ms, patches = best
    tris = patches * 2 * level * level
    return {"level": level, "patches": patches, "triangles": tris, "draw_ms": ms, "triangles_per_s": tris / (ms * 1e-3)}


# --- frames --------------------------------------------------------------------------------------
def _orbit(base: Camera, centre, dist, k, n, size) -> Camera:
    d = base.eye - centre
    up = base.view[1, :3]
    a = 2 * np.pi * k / max(n, 1)
    # rotate the viewing direction about the camera's up axis (Rodrigues)
    d = d * np.cos(a) + np.cross(up, d) * np.sin(a) + up * np.dot(up, d) * (1 - np.cos(a))
    r = np.linalg.norm(d)
    return Camera.look_at(centre + d * dist, centre, up, base.fov_y, size,
                          near=max(r * dist * 1e-3, r * dist - 2 * r), far=r * dist + 2 * r)


def _frame_ms(ms: dict) -> float:
    return ms["frame"] if "frame" in ms else ms["total"] - ms.get("readback", 0.0)


def _rss_mib() -> float:
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2 ** 20
    except OSError:
        return float("nan")


def _device_buffers_mib(scene, size, ss=(1,)) -> float:
    """Device memory of the frame's buffers; ``ss``: the subsamples per pixel side of each key
    buffer set drawn into (a hybrid pass has one per tier)."""
    total = 0
    for r in scene_state(scene).renderer_states():
        lod, points = getattr(r, "lod", None), getattr(r, "points", None)
        if lod is not None:
            total += sum(b.capacity * b.dtype.itemsize for b in (*lod.bufs, lod.render))
        if points is not None:
            total += points.order_capacity * 8   # the point renderer's schedule
    w, h = size
    total += w * h * (16 + 40)   # key buffers + resolved outputs
    total += sum(w * h * k * k * 16 for k in ss if k > 1)   # supersampled key buffers (points-4xSS, hybrid tiers)
    return total / 2 ** 20


def measure(scene, base, centre, dist, variant, aa, args, threshold, l_max, l_min, size, culling: bool = True,
            name: str = ""):
    """Frames of bench variant ``name`` (renderer ``variant``, AA mode ``aa``, its VARIANT_SETTINGS)."""
    rs = RenderSettings()
    rs.lod.threshold = (threshold, threshold)
    rs.lod.detail_angle = args.detail_angle
    if not culling:   # on: the defaults (occlusion "auto", back faces of one-sided materials)
        rs.points.occlusion = rs.lod.backface_cull = False
    rs.tess.l_max = l_max
    rs.tess.l_min = l_min
    apply_variant_settings(rs, name)
    if aa:
        rs.apply_aa(aa, variant=variant)
    # frames run one after another without copying each to the host, as an interactive viewer
    # does (a frame's 80 MB read-back at 1080p is no part of a viewer's frame, and the next
    # frame's Python measured slower after it); one more frame, read back, gives the pixel
    # statistics and the read-back time
    rows = []
    for k in range(args.warmup + args.frames):
        cam = _orbit(base, centre, dist, k, args.frames, size)
        start_timing()
        stats = render_on_device(scene, cam, variant, rs)
        by_kernel = stop_timing()
        if k >= args.warmup:
            rows.append((stats, by_kernel))
    st = [r[0] for r in rows]
    kernels = [r[1] for r in rows]
    # the frame's image read back, then the rest of its arrays
    extra = render(scene, cam, variant, rs)
    t0 = time.perf_counter()
    extra.rgb8()
    t1 = time.perf_counter()
    extra.materialize()
    pixels = dict(extra.stats, image_readback_ms=(t1 - t0) * 1e3, readback_ms=(time.perf_counter() - t0) * 1e3)
    frame = [_frame_ms(s["ms"]) for s in st]
    med = statistics.median
    out = {
        "distance": dist, "frames": len(rows),
        "frame_ms": med(frame), "frame_ms_p95": float(np.percentile(frame, 95)),
        "lod_ms": med(s["ms"].get("lod", 0.0) for s in st),
        "render_ms": med(s["ms"]["render"] for s in st),
        "cl_kernel_ms": med(sum(k.values()) for k in kernels),
        # each OpenCL kernel's device ms a frame (summed over its launches), largest first: where
        # the frame's device time goes
        "kernel_ms": dict(sorted(((name, med(k.get(name, 0.0) for k in kernels))
                                  for name in {n for k in kernels for n in k}), key=lambda kv: -kv[1])),
        "render_patches": med(s.get("render_patches", 0) for s in st),
        "lod_steps_in": [med(s["lod_steps"][i]["in"] for s in st) for i in range(len(st[0].get("lod_steps", [])))],
        "samples": med(s.get("samples", 0) for s in st),
        "atomics": med(s.get("atomics", 0) for s in st),
        "device_buffers_mib": _device_buffers_mib(scene, size, (1,) if variant != "points" else
                                                  tuple(t.ss for t in POINT_TIERS) if rs.points.hybrid else
                                                  (rs.points.supersample,)),
        "host_rss_mib": _rss_mib(),
        # pixel statistics and read-back time of the extra frame read back
        "pixels_written": pixels["pixels_written"], "overdraw": pixels.get("overdraw", 0.0),
        "readback_ms": pixels["readback_ms"], "image_readback_ms": pixels["image_readback_ms"],
    }
    if variant == "tess":
        out["cl_gl_transfer_ms"] = med(s["ms"].get("render_list", 0.0) for s in st)
        out["aa_effective"] = st[0].get("aa_effective")
        out["triangles"] = med(s.get("triangles", 0) for s in st)
        out["host_ms"] = None   # GL work is not timed by OpenCL events
    else:
        # host: Python time preparing and enqueueing the frame (it overlaps the device's work);
        # idle: the part of the frame not covered by OpenCL kernels (launch gaps, waits, transfers)
        out["host_ms"] = med(s["ms"]["host"] for s in st)
        # samples evaluated per pixel of the frame that shows something (issue #22's measure of waste)
        out["samples_per_pixel"] = out["samples"] / max(pixels["pixels_written"], 1)
        culled = [s["occlusion"] for s in st if "occlusion" in s]   # "auto" culls some frames
        if culled:
            out["occlusion"] = {k: med(c[k] for c in culled) for k in culled[0]}
            out["occlusion"]["culled_frames"] = len(culled)
        out["idle_ms"] = max(0.0, out["frame_ms"] - out["cl_kernel_ms"])
    out["fps"] = 1e3 / out["frame_ms"] if out["frame_ms"] > 0 else float("inf")
    return out


# --- surfels ------------------------------------------------------------------------------------
def surfel_costs(size) -> dict:
    try:
        mesh = str(importlib.resources.files("pymeshfix").joinpath("examples/StanfordBunny.ply"))
        name = "Stanford bunny (pymeshfix)"
    except ModuleNotFoundError:
        import trimesh

        mesh, name = trimesh.creation.icosphere(subdivisions=5), "icosphere (pymeshfix not installed)"
    out = {"mesh": name, "sampling": [], "render": []}
    big = None
    sample_mesh(mesh, 1_000)   # warm: the programs built once, as in a session (the rows read the file each)
    for n in (10_000, 100_000):
        t0 = time.perf_counter()
        s = sample_mesh(mesh, n)
        out["sampling"].append({"n": n, "got": len(s), "seconds": time.perf_counter() - t0})
        big = s
    cam = default_camera(big, size)
    for n in (1_000, 3_000, 10_000, 30_000, 100_000):
        if n > len(big):
            break
        times = []
        for r in range(6):
            f = render_surfels(big, cam, FixedCount(n))
            if r:
                times.append(f.stats["surfels"]["ms"] if isinstance(f.stats.get("surfels"), dict)
                             else f.stats["surfels"][0]["ms"])
        out["render"].append({"prefix": n, "ms": statistics.median(times)})
    return out


# --- driver -----------------------------------------------------------------------------------------
DEFAULT_EXTRAS = ("ceilings", "functions", "surfels", "meshes")
_BENCH_EXTRA = "pip install 'paramlod[bench]'"
_BUNNY = "it ships the Stanford bunny scan that is measured (pip install pymeshfix)"
# the optional modules an extra imports, and where each comes from
EXTRA_NEEDS = {
    "meshes": {"pymeshfix": _BUNNY},
    "mesh-eval": {"pymeshfix": _BUNNY, "flip_evaluator": _BENCH_EXTRA, "skimage": _BENCH_EXTRA},
    "hybrid": {"flip_evaluator": _BENCH_EXTRA},
}


def _usable_extras(asked) -> list:
    """The extras to measure. Extras asked for by name whose modules are missing stop the bench
    before anything is measured; of the default ones, those are left out with a note."""
    extras = DEFAULT_EXTRAS if asked is None else asked
    missing = {e: [m for m in EXTRA_NEEDS.get(e, {}) if importlib.util.find_spec(m) is None] for e in extras}
    missing = {e: ms for e, ms in missing.items() if ms}
    if asked is not None and missing:
        raise ParamlodError("; ".join(f"--extras {e} needs {m}: {EXTRA_NEEDS[e][m]}" for e, ms in missing.items()
                                      for m in ms))
    for e, ms in missing.items():
        print(f"paramlod bench: leaving out the {e} extra: it needs {', '.join(ms)} "
              f"({'; '.join(EXTRA_NEEDS[e][m] for m in ms)})", flush=True)
    return [e for e in extras if e not in missing]


def run_bench(args) -> int:
    names = [] if args.only_extras else args.scenarios or DEFAULT
    if args.only_extras and args.scenarios:
        raise ParamlodError(f"--only-extras skips the scenarios; leave out {' '.join(args.scenarios)} or the option")
    unknown = [n for n in names if n not in SCENARIOS]
    if unknown:
        raise ParamlodError(f"unknown scenario(s) {', '.join(unknown)} (available: {', '.join(SCENARIOS)})")
    if not args.peers:   # --peers measures no extras
        args.extras = _usable_extras(args.extras)
    # the results folder is checked (made, and a file created in it) before anything is measured
    out = check_folder(Path(args.out), "--out", create=True)
    if args.peers:
        result = run_peers(args, out, log=lambda m: print(m, flush=True))
        print(format_peers_markdown(result))
        print(f"results: {out / 'peers.json'}, {out / 'peers.md'}")
        return 0
    dev = cl_device()
    kind = "GPU" if dev.is_gpu else "CPU"
    filled = apply_run_defaults(args, kind)
    if kind == "CPU" and filled:
        print(f"paramlod bench: on a CPU device the defaults are {_run_text(RUN_DEFAULTS['CPU'])} "
              f"(a GPU's: {_run_text(RUN_DEFAULTS['GPU'])}, hours of frames here); set --size, --distances, --frames, --warmup "
              "to change them", flush=True)
    size = args.size
    result = {"device": dev.name, "device_type": kind, "host": platform.node(),
              "size": list(size), "frames": args.frames, "warmup": args.warmup, "detail_angle": args.detail_angle,
              "scenarios": {}}

    def save():
        write_atomically(out / "results.json", lambda tmp: Path(tmp).write_text(json.dumps(result, indent=1)))

    if "ceilings" in args.extras:
        result["atomics_ceiling_per_s"] = atomics_ceiling(*size)
        print(f"random 64-bit atom_min: {result['atomics_ceiling_per_s'] / 1e9:.2f} G/s", flush=True)
        if any(VARIANTS[v][0] == "tess" for v in args.variants) or "meshes" in args.extras:
            result["tess_ceiling"] = tess_ceiling(size)
            print(f"tessellation, level 64: {_rate(result['tess_ceiling']['triangles_per_s'])} triangles/s",
                  flush=True)
        save()
    for name in names:
        build, direction, up, threshold, l_max, l_min = SCENARIOS[name]
        scene = build()
        base = framing_camera(scene, direction, up, 40.0, size, margin=1.0)
        lo, hi = scene_box(scene)
        centre = (lo + hi) / 2
        per = result["scenarios"].setdefault(name, {"instances": scene.instance_count, "threshold": threshold,
                                                     "l_max": l_max, "l_min": l_min, "variants": {}})
        for vname in args.variants:
            variant, aa = VARIANTS[vname]
            for culling in {"on": (True,), "off": (False,), "both": (True, False)}[args.culling]:
                key = vname if culling else f"{vname} {NO_CULLING}"
                rows = per["variants"].setdefault(key, [])
                for dist in args.distances:
                    try:
                        r = measure(scene, base, centre, dist, variant, aa, args, threshold, l_max, l_min, size, culling,
                                    vname)
                    except ParamlodError as exc:
                        r = {"distance": dist, "error": str(exc)}
                    rows.append(r)
                    msg = (f"{name} {_row_label(key, r)} d={dist}: " + (
                        f"{r['frame_ms']:.2f} ms ({r['fps']:.0f} FPS), LOD {r['lod_ms']:.2f}, render "
                        f"{r['render_ms']:.2f}, {r['render_patches']:.0f} patches"
                        + (f", {r['samples_per_pixel']:.1f} samples/px" if "samples_per_pixel" in r else "")
                        if "error" not in r else f"error: {r['error']}"))
                    print(msg, flush=True)
                    save()
    if "functions" in args.extras:
        result["function_throughput"] = function_throughput(before=args.cse_before)
        save()
    if "surfels" in args.extras:
        result["surfels"] = surfel_costs(size)
        save()
    if "meshes" in args.extras:
        big = args.big_mesh == "yes" or (args.big_mesh == "auto" and dev.is_gpu)
        result["meshes"] = run_meshes(size, args.frames, args.warmup, big, args.mesh_grid,
                                      log=lambda m: print(m, flush=True))
        save()
    if "skinned" in args.extras:
        result["skinned"] = run_skinned(size, args.frames, args.warmup, log=lambda m: print(m, flush=True))
        save()
    if "viewer" in args.extras:
        result["viewer"] = run_viewer(size, args.frames, args.warmup, log=lambda m: print(m, flush=True))
        save()
    if "multiview" in args.extras:
        variants = [v for v in ("points", "tess") if v in args.variants] or ["points", "tess"]
        result["multiview"] = run_multiview(size, args.frames, args.warmup, args.multiview_scenes, variants,
                                            args.views, log=lambda m: print(m, flush=True))
        save()
    if "hybrid" in args.extras:
        result["hybrid"] = run_hybrid(size, args.frames, args.warmup, args.hybrid_scenes, args.hybrid_distances,
                                      args.hybrid_variants, reference=args.hybrid_reference,
                                      log=lambda m: print(m, flush=True))
        save()
    if "mesh-eval" in args.extras:
        big = args.big_mesh == "yes" or (args.big_mesh == "auto" and dev.is_gpu)
        result["mesh_eval"] = run_mesh_eval(size, args.frames, args.warmup, big, args.mesh_grid, args.eval_thresholds,
                                            args.eval_move_frames, args.eval_parts, args.eval_scenarios,
                                            log=lambda m: print(m, flush=True))
        save()
    md = format_markdown(result)
    write_atomically(out / "results.md", lambda tmp: Path(tmp).write_text(md))
    plots = make_plots(result, out)
    print(md)
    print(f"results: {out / 'results.json'}, {out / 'results.md'}" + (f", {len(plots)} plots" if plots else ""))
    return 0


def _row_label(vname: str, r: dict) -> str:
    """The variant's name, and what it really ran when the device gave fewer samples than it asks
    (e.g. tess-4xSS+8xMS on a device of 4 MSAA samples), so that a row is never mislabelled."""
    _, asked = VARIANTS.get(vname.removesuffix(f" {NO_CULLING}"), (None, None))
    ran = r.get("aa_effective")
    return f"{vname} (ran {ran})" if asked and ran and str(ran) != asked else vname


def _rate(per_s: float) -> str:
    return f"{per_s / 1e9:.2f} G" if per_s >= 1e8 else f"{per_s / 1e6:.1f} M"


def format_markdown(result) -> str:
    ceil = result.get("atomics_ceiling_per_s")
    lines = [f"Device: {result['device']} ({result['device_type']}), {result['size'][0]}x{result['size'][1]}, "
             f"{result['frames']} frames per orbit after {result['warmup']} warm-up frames; medians."]
    if ceil:
        lines.append(f"Random 64-bit atom_min ceiling: {ceil / 1e9:.2f} G/s.")
    if "tess_ceiling" in result:
        t = result["tess_ceiling"]
        lines.append(f"Tessellation ceiling (sphere, level {t['level']}): {_rate(t['triangles_per_s'])} triangles/s.")
    if result["scenarios"]:
        lines += ["", "| scenario | variant | distance | FPS | frame ms (p95) | LOD ms | render ms | host ms | render patches "
                  "| samples / written px | % of ceiling |", "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name, sc in result["scenarios"].items():
        for vname, rows in sc["variants"].items():
            for r in rows:
                if "error" in r:
                    lines.append(f"| {name} | {vname} | {r['distance']} | error: {r['error'][:60]} ||||||||")
                    continue
                frac = ""
                if vname.startswith("points") and ceil:
                    frac = f"{100 * r['atomics'] / (r['render_ms'] * 1e-3) / ceil:.1f}% atomics"
                elif vname.startswith("tess") and "tess_ceiling" in result and r.get("triangles"):
                    frac = f"{100 * r['triangles'] / (r['render_ms'] * 1e-3) / result['tess_ceiling']['triangles_per_s']:.1f}% tris"
                host = "n/a" if r.get("host_ms") is None else f"{r['host_ms']:.2f}"
                spp = f"{r['samples_per_pixel']:.1f}" if "samples_per_pixel" in r else ""
                label = _row_label(vname, r)
                lines.append(f"| {name} | {label} | {r['distance']} | {r['fps']:.0f} | {r['frame_ms']:.2f} "
                             f"({r['frame_ms_p95']:.2f}) | {r['lod_ms']:.2f} | {r['render_ms']:.2f} | {host} | "
                             f"{r['render_patches']:.0f} | {spp} | {frac} |")
    lines += format_kernels(result["scenarios"])
    lines += format_culling(result["scenarios"])
    if "function_throughput" in result:
        lines += format_function_throughput(result["function_throughput"])
    if "surfels" in result:
        s = result["surfels"]
        lines += ["", f"Blue surfels of the {s['mesh']}:", "",
                  "| surfels | sampling s (warm) |", "|---:|---:|"]
        lines += [f"| {r['n']:,} | {r['seconds']:.2f} |" for r in s["sampling"]]
        lines += ["", "| prefix | render ms |", "|---:|---:|"]
        lines += [f"| {r['prefix']:,} | {r['ms']:.3f} |" for r in s["render"]]
    if "meshes" in result:
        lines += format_meshes(result["meshes"], ceil, result.get("tess_ceiling", {}).get("triangles_per_s"))
    if "skinned" in result:
        lines += format_skinned(result["skinned"])
    if "viewer" in result:
        lines += format_viewer(result["viewer"])
    if "multiview" in result:
        lines += format_multiview(result["multiview"])
    if "mesh_eval" in result:
        lines += format_mesh_eval(result["mesh_eval"])
    if "hybrid" in result:
        lines += format_hybrid(result["hybrid"])
    return "\n".join(lines) + "\n"


def format_kernels(scenarios: dict, most: int = 4) -> list[str]:
    """Per row, the ``most`` OpenCL kernels that took the most device time a frame."""
    lines = []
    for name, sc in scenarios.items():
        for vname, rows in sc["variants"].items():
            for r in rows:
                if r.get("kernel_ms"):
                    top = ", ".join(f"{k} {ms:.2f}" for k, ms in list(r["kernel_ms"].items())[:most])
                    lines.append(f"| {name} | {_row_label(vname, r)} | {r['distance']} | {top} |")
    if not lines:
        return []
    return ["", "Device ms a frame by OpenCL kernel (medians; the largest first; GL work is not in it):", "",
            "| scenario | variant | distance | kernels |", "|---|---|---:|---|", *lines]


def format_culling(scenarios: dict) -> list[str]:
    """With --culling both: per scenario, variant and distance, FPS and samples per written pixel
    with culling against without it, measured in the same run."""
    lines = []
    for name, sc in scenarios.items():
        for vname, rows in sc["variants"].items():
            off = sc["variants"].get(f"{vname} {NO_CULLING}")
            if off is None:
                continue
            for on_r, off_r in zip(rows, off):
                if "error" in on_r or "error" in off_r:
                    continue
                if not lines:
                    lines = ["", "Culling (occlusion, back faces) against none, same run:", "",
                             "| scenario | variant | distance | FPS off | FPS on | speed-up | samples/px off | on |",
                             "|---|---|---:|---:|---:|---:|---:|---:|"]
                spp = [f"{r['samples_per_pixel']:.1f}" if "samples_per_pixel" in r else "" for r in (off_r, on_r)]
                lines.append(f"| {name} | {vname} | {on_r['distance']} | {off_r['fps']:.0f} | {on_r['fps']:.0f} | "
                             f"{on_r['fps'] / off_r['fps']:.2f}x | {spp[0]} | {spp[1]} |")
    return lines


def make_plots(result, out: Path) -> list[Path]:
    """FPS against distance per scenario, and patches per LOD step at the nearest distance; the
    mesh-LOD evaluation's plots (paramlod.app.bench.mesh_eval.plot_mesh_eval)."""
    plt = pyplot()
    if plt is None:
        print("matplotlib is not installed: no plots (pip install 'paramlod[bench]')")
        return []
    paths = []
    for name, sc in result["scenarios"].items():
        fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.6))
        for vname, rows in sc["variants"].items():
            ok = [r for r in rows if "error" not in r]
            a.plot([r["distance"] for r in ok], [r["fps"] for r in ok], marker="o", label=vname)
        a.set_xlabel("camera distance (x framing distance)")
        a.set_ylabel("FPS")
        a.set_yscale("log")
        a.set_title(f"{name}: FPS against distance")
        a.legend(fontsize=8)
        first = next(iter(sc["variants"].values()))
        near = next((r for r in first if "error" not in r), None)
        if near and near["lod_steps_in"]:
            b.bar(range(1, len(near["lod_steps_in"]) + 1), near["lod_steps_in"])
            b.set_xlabel("LOD step")
            b.set_ylabel("patches evaluated")
            b.set_title(f"patches per LOD step (distance {near['distance']})")
        fig.suptitle(f"{result['device']}, {result['size'][0]}x{result['size'][1]}", fontsize=9)
        paths.append(save_figure(fig, out / f"{name}.png"))
    if "mesh_eval" in result:
        paths += plot_mesh_eval(result["mesh_eval"], out)
    if "hybrid" in result:
        paths += plot_hybrid(result["hybrid"], out)
    return paths
