"""Command line: ``paramlod render | info | functions | bench | gallery | surfels | mesh | glyphs``."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from paramlod.app import gallery, glyphs, mesh_cmd, surfels_cmd
from paramlod.app.args import add_output, add_size, add_stats, run_reporting_errors
from paramlod.app.bench import run as bench
from paramlod.app.scenefile import load_scene
from paramlod.device import context as device_context
from paramlod.errors import ParamlodError
from paramlod.function import registry
from paramlod.pipeline.driver import render


def cmd_render(args) -> int:
    sf = load_scene(args.scene, size=args.size)
    camera = sf.camera
    if args.aa:
        variant = args.variant or (None if sf.object_variants else sf.variant)
        sf.settings.apply_aa(args.aa, points_only=variant == "points")
    if args.variant:   # --variant draws every object with it (meshes with the mesh variant that goes with it)
        for obj in [*sf.scene.objects, *sf.scene.meshes]:
            obj.variant = obj.aa = None
        sf.scene.touch()
    variant = args.variant or sf.variant
    frame = render(sf.scene, camera, variant=variant, settings=sf.settings)
    if sf.object_variants and not args.variant:
        variant = "mixed (" + ", ".join(sorted(set(sf.object_variants))) + ")"
    outs = args.output or [str(Path("out") / (Path(args.scene).stem + ".png"))]
    for out in outs:
        frame.save(out)
    s = frame.stats
    ms = s["ms"]
    device = s.get("device") or s.get("lod_device")
    parts = [f"{camera.width}x{camera.height} {variant}" + (f" on {device}" if device else "")]
    if "render_patches" in s:
        parts.append(f"{s['render_patches']} render patches")
    parts.append(f"{s['pixels_written']} pixels, {ms['total']:.1f} ms")
    print(f"{', '.join(outs)}: " + ", ".join(parts))
    if args.stats:
        Path(args.stats).write_text(json.dumps(s, indent=2))
    return 0


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
        print(f"{name:20s} u=[{fn.u_range[0]:.4g}, {fn.u_range[1]:.4g}] v=[{fn.v_range[0]:.4g}, {fn.v_range[1]:.4g}]"
              f"  params: {params}  ({fn.source})")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="paramlod", description=__doc__)
    p.add_argument("--cl-device", help="OpenCL device by name substring (or PARAMLOD_CL_DEVICE)")
    p.add_argument("--functions", action="append", metavar="DIR",
                   help="a folder of plugin .py files (repeatable; or PARAMLOD_FUNCTIONS_PATH)")
    sub = p.add_subparsers(dest="command", required=True)

    r = sub.add_parser("render", help="render a TOML scene to PNG and/or EXR")
    r.add_argument("scene", help="scene file (.toml)")
    add_output(r, required=False, default_help="default out/<scene>.png")
    add_size(r, what="override the camera size")
    r.add_argument("--variant", help="override the render variant: points, points-ssaa or tess (meshes follow: "
                   "meshlets, or meshlets-gl with tess), or meshlets / meshlets-gl for the meshes")
    r.add_argument("--aa", help="anti-aliasing: noAA, msaa2/4/8, ssaa2x2/3x3/4x4, or a combination such "
                                "as 4xSS+8xMS (tess); the points variant takes the supersampling only")
    add_stats(r)
    r.set_defaults(func=cmd_render)

    i = sub.add_parser("info", help="print the OpenCL and OpenGL devices and their capabilities")
    i.set_defaults(func=cmd_info)

    f = sub.add_parser("functions", help="list the parametric functions")
    f.set_defaults(func=cmd_functions)

    b = sub.add_parser("bench", help="measure LOD and render times")
    bench.add_arguments(b)
    b.set_defaults(func=bench.run_bench)

    g = sub.add_parser("gallery", help="render every scene of the gallery to PNG, EXR (and GIF)")
    gallery.add_arguments(g)
    g.set_defaults(func=gallery.run_gallery)

    surfels_cmd.add_subparser(sub)
    mesh_cmd.add_subparser(sub)
    glyphs.add_subparser(sub)
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)

    def run() -> int:
        if args.cl_device:
            device_context.set_cl_device(args.cl_device)
        for folder in args.functions or []:
            registry.add_plugin_path(folder)
        return args.func(args)

    return run_reporting_errors(run)


if __name__ == "__main__":
    sys.exit(main())
