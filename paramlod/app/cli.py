"""Command line: ``paramlod render | view | info | functions | bench | bench-scale | gallery | surfels | mesh | glyphs``."""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path

from paramlod.app import dist, gallery, glyphs, mesh_cmd, scenefile, surfels_cmd, views_cmd
from paramlod.app.args import (Parser, add_size, add_stats, check_outputs, install_warning_format, positive_int, progress,
                               run_reporting_errors, write_all_or_none)
from paramlod.app.bench import run as bench
from paramlod.device import context as device_context
from paramlod.core.files import write_atomically
from paramlod.core.frame import stats_aa
from paramlod.errors import ParamlodError
from paramlod.function import registry
from paramlod.pipeline.driver import render
from paramlod.viewer import app as viewer_app


def _render_job_requested(args) -> bool:
    return (len(args.scene) > 1 or args.frames is not None or args.turntable is not None or bool(args.camera_path)
            or args.video is not None or args.fps is not None or dist.job_requested(args))


def _finite_time(text: str) -> float:
    try:
        t = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number (scene time), got {text!r}") from None
    if not math.isfinite(t):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    return t


def _named(text: str) -> str:
    # an empty --variant or --aa would be taken as not given, and the scene's own used instead
    if not text.strip():
        raise argparse.ArgumentTypeError("must not be empty")
    return text


def cmd_render(args) -> int:
    views_cmd.check(args)
    if views_cmd.requested(args):
        if _render_job_requested(args):
            raise ParamlodError("--stereo, --cubemap and --quilt render one multi-view frame of one scene; "
                                "they do not combine with several scenes or a job of frames")
        return views_cmd.run(args)
    if _render_job_requested(args):
        if args.time is not None:
            raise ParamlodError("--time is for one frame; a job of frames takes its times from --frames/--fps")
        return cmd_render_job(args)
    outs = args.output or [str(Path("out") / (Path(args.scene[0]).stem + ".png"))]
    if not args.output:
        Path("out").mkdir(exist_ok=True)
    # every output is checked before any work: a bad one fails the command with nothing written
    check_outputs(outs)
    if args.stats:
        check_outputs([args.stats], "--stats", suffixes=(".json",))
    with progress("loading the scene"):
        sf, variant = dist.prepare_scene(args.scene[0], args.size, args.variant, args.aa)
    camera = sf.camera
    with progress(f"rendering {camera.width}x{camera.height}"):
        frame = render(sf.scene, camera, variant=variant, settings=sf.settings, time=args.time)
    s = frame.stats
    label = drawn_variants(s)
    items = [(out, frame.save) for out in outs]
    if args.stats:
        text = json.dumps(s, indent=2)
        items.append((args.stats, lambda p: write_atomically(p, lambda tmp: Path(tmp).write_text(text))))
    with progress("writing"):
        write_all_or_none(items)
    ms = s["ms"]
    device = s.get("device") or s.get("lod_device")
    parts = [f"{camera.width}x{camera.height} {label}" + (f" on {device}" if device else "")]
    if s.get("render_patches"):   # meshes and surfels have none
        parts.append(f"{s['render_patches']} render patches")
    parts.append(f"{s['pixels_written']} pixels, {ms['total']:.1f} ms")
    print(f"{', '.join(outs)}: " + ", ".join(parts))
    for w in s.get("warnings", []):   # e.g. nothing_drawn: the frame drew no pixel, and why
        print(f"paramlod: warning: {w}", file=sys.stderr)
    return 0


def drawn_variants(stats) -> str:
    """What drew a frame, from its stats: one variant, the variants that shared its key buffers
    ("points, meshlets"), or a composite's passes in order ("tess, meshlets-gl"), each with its
    anti-aliasing unless noAA ("points (hybrid)", "tess (4xMS)"). A requested --variant may not be
    what drew: meshes follow points with meshlets, tess with meshlets-gl."""
    if stats.get("variant") == "composite":
        return ", ".join(dict.fromkeys(name.replace(" (noAA)", "") for name in stats.get("order", [])))
    aa = stats_aa(stats)
    return str(stats.get("variant", "?")) + ("" if aa == "noAA" else f" ({aa})")


def cmd_render_job(args) -> int:
    """Frames of one or more scenes (--frames, --turntable, --camera-path), serial or on Dask."""
    if args.stats:
        raise ParamlodError("--stats is for one frame; a job of frames reports its throughput instead")
    job = dist.render_job(args.scene, args.output, frames=args.frames, fps=args.fps, turntable=args.turntable,
                          camera_path=args.camera_path, size=args.size, variant=args.variant, aa=args.aa,
                          video=args.video, setup=dist.WorkerSetup.from_args(args))
    report = dist.run_job(job, dist.Where.from_args(args), progress=not args.quiet, overwrite=args.overwrite)
    print(report.summary())
    for product in job.products:
        print(f"video: {product}")
    return 0


def cmd_view(args) -> int:
    """The interactive viewer (docs/viewer.md); headless with --script/--record/--frames and no display."""
    return viewer_app.view(args.source, size=args.size, variant=args.variant, aa=args.aa, script=args.script,
                           record=args.record, frames=args.frames, video=args.video,
                           headless=True if args.headless else None, vsync=not args.no_vsync,
                           overwrite=args.overwrite)


def cmd_info(args) -> int:
    print("OpenCL")
    print("  " + device_context.all_cl_devices_summary().replace("\n", "\n  "))
    info = device_context.cl_info()
    print(f"  selected: {info['device']} ({info['platform']}), {info['type']}, {info['version']}")
    for k in ("compute_units", "global_memory_mib", "max_work_group_size", "local_memory_kib", "int64_atomics"):
        print(f"    {k}: {info[k]}")
    print("OpenGL (EGL, headless)")
    try:
        for k, v in device_context.gl_info().items():
            print(f"    {k}: {v}")
    except ParamlodError as exc:
        print(f"    unavailable: {exc}")
    return 0


def cmd_functions(args) -> int:
    for name, fn in sorted(registry.all_functions().items()):
        params = ", ".join(
            f"{p.name}={float(p.default):g}" if not p.is_array else f"{p.name}=[{p.size} values]"
            for p in fn.params) or "-"
        periodic = f" periodic {''.join(fn.periodic)}" if fn.periodic else ""
        print(f"{name:20s} u=[{fn.u_range[0]:.4g}, {fn.u_range[1]:.4g}] v=[{fn.v_range[0]:.4g}, {fn.v_range[1]:.4g}]"
              f"{periodic}  params: {params}  ({fn.source})")
        if fn.summary:   # the first line of its docstring (docs/writing-plugins.md promises it)
            print(f"{'':20s} {fn.summary}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = Parser(prog="paramlod", description=__doc__)
    p.add_argument("--cl-device", help="OpenCL device by name substring (or PARAMLOD_CL_DEVICE)")
    p.add_argument("--functions", action="append", metavar="DIR",
                   help="a folder of plugin .py files (repeatable; or PARAMLOD_FUNCTIONS_PATH)")
    p.add_argument("--trust-scene", action="store_true",
                   help="let scene files name any importable module:function as an instance builder: this "
                        "RUNS CODE named by the scene file; without it only registered builders are allowed")
    sub = p.add_subparsers(dest="command", required=True)

    r = sub.add_parser("render", help="render a TOML scene to PNG and/or EXR (one frame, or a job of frames)")
    r.add_argument("scene", nargs="+", help="scene file(s) (.toml); several make one job (use {scene} in -o)")
    r.add_argument("-o", "--output", action="append", metavar="FILE",
                   help="output .png or .exr (repeatable); for several frames a pattern with {frame} "
                        "(also {time}, {angle}, {scene}), e.g. out/frame_{frame:04d}.png; default "
                        "out/<scene>.png, or out/<scene>_{frame:04d}.png for a job")
    add_size(r, what="override the camera size")
    r.add_argument("--variant", type=_named,
                   help="override the render variant: points, points-ssaa or tess (meshes follow: "
                   "meshlets, or meshlets-gl with tess), or meshlets / meshlets-gl for the meshes")
    r.add_argument("--aa", type=_named, help="anti-aliasing: noAA, msaa2/4/8, ssaa2x2/3x3/4x4, or a combination such "
                                             "as 4xSS+8xMS (tess); the points variant takes the supersampling only")
    add_stats(r)
    r.add_argument("--time", type=_finite_time, metavar="T",
                   help="scene time of the frame (the implicit parameter t of animated functions; default 0)")
    views_cmd.add_arguments(r)
    a = r.add_argument_group("frames (a job: each frame is a task, see docs/scale-out.md)")
    a.add_argument("--frames", type=dist.parse_range, metavar="A:B",
                   help="frames A to B-1 (A:B:STEP, one number, or 'all' of the [animation] table); frame i is "
                        "at time t0 + i*dt (dt from [animation], or 1/fps)")
    a.add_argument("--fps", type=float, help="frames per second: frames 1/fps apart in scene time, and the "
                                             "video's rate (default: the [animation] table's)")
    a.add_argument("--turntable", type=int, metavar="N", help="N frames around the scene's up axis, at fixed time")
    a.add_argument("--camera-path", nargs="?", const=True, metavar="FILE",
                   help="the camera follows the [camera_path] keyframes of the scene file (or of FILE)")
    a.add_argument("--video", metavar="FILE", help="assemble the PNG frames into FILE (.gif or .mp4) at the end")
    a.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    dist.add_job_options(r)
    r.set_defaults(func=cmd_render)

    v = sub.add_parser("view", help="an interactive window: fly through a scene, a plugin file or a function, "
                                     "reloaded when its files change (docs/viewer.md)")
    v.add_argument("source", help="a scene file (.toml), a plugin file (.py), a mesh file (OBJ, PLY, STL, OFF, glTF, "
                                  "GIfTI, .meshlod), a .surfels file or a function name (see `paramlod functions`)")
    add_size(v, what="window size (default: the scene camera's, or 1280x720)")
    v.add_argument("--variant", help="render variant to start with (V cycles them)")
    v.add_argument("--aa", help="anti-aliasing mode to start with, e.g. 4xSS (B cycles them)")
    v.add_argument("--script", metavar="FILE", help="play a TOML script of camera keyframes and key events")
    v.add_argument("--record", metavar="DIR", help="write every frame to DIR/frame_00000.png ... (atomically)")
    v.add_argument("--frames", type=positive_int, metavar="N", help="stop after N frames (default: the script's, "
                                                                    "or until the window closes)")
    v.add_argument("--video", metavar="FILE", help="with --record: assemble the frames into FILE (.gif or .mp4)")
    v.add_argument("--headless", action="store_true", help="no window: draw through EGL (with --script/--record)")
    v.add_argument("--no-vsync", action="store_true", help="do not wait for the display (measuring)")
    v.add_argument("--overwrite", action="store_true", help="--record may replace frames already in DIR")
    v.set_defaults(func=cmd_view)

    i = sub.add_parser("info", help="print the OpenCL and OpenGL devices and their capabilities")
    i.set_defaults(func=cmd_info)

    f = sub.add_parser("functions", help="list the parametric functions")
    f.set_defaults(func=cmd_functions)

    b = sub.add_parser("bench", help="measure LOD and render times")
    bench.add_arguments(b)
    b.set_defaults(func=bench.run_bench)

    bs = sub.add_parser("bench-scale", help="frames per second of an animation against the Dask worker count "
                                            "(docs/scale-out.md)")
    dist.add_bench_arguments(bs)
    bs.set_defaults(func=dist.run_bench_scaling)

    g = sub.add_parser("gallery", help="render every scene of the gallery to PNG, EXR (and GIF)")
    gallery.add_arguments(g)
    g.set_defaults(func=gallery.run_gallery)

    surfels_cmd.add_subparser(sub)
    mesh_cmd.add_subparser(sub)
    glyphs.add_subparser(sub)
    return p


def main(argv=None) -> int:
    install_warning_format()   # a warning is one line naming the input, not paramlod's source line
    args = build_parser().parse_args(argv)

    def run() -> int:
        if args.cl_device:
            device_context.set_cl_device(args.cl_device)
        for folder in args.functions or []:
            registry.add_plugin_path(folder)
        if not args.trust_scene:
            return args.func(args)
        # through the environment, so that Dask workers (child processes) trust the scenes too
        old = os.environ.get(scenefile.TRUST_ENV)
        os.environ[scenefile.TRUST_ENV] = "1"
        try:
            return args.func(args)
        finally:
            if old is None:
                os.environ.pop(scenefile.TRUST_ENV, None)
            else:
                os.environ[scenefile.TRUST_ENV] = old

    return run_reporting_errors(run)


if __name__ == "__main__":
    sys.exit(main())
