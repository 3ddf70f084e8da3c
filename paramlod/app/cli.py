"""Command line: ``paramlod render | info | functions | bench | surfels``."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from paramlod.errors import ParamlodError


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(x) for x in text.lower().split("x"))
        if w <= 0 or h <= 0:
            raise ValueError
        return w, h
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must look like 960x540, got {text!r}") from None


def cmd_render(args) -> int:
    from paramlod.pipeline.driver import render
    from paramlod.app.scenefile import load_scene

    sf = load_scene(args.scene, size=args.size)
    camera = sf.camera
    if args.aa:
        variant = args.variant or (None if sf.object_variants else sf.variant)
        sf.settings.apply_aa(args.aa, points_only=variant == "points")
    if sf.object_variants and not args.variant:
        from paramlod.pipeline.composite import render_mixed

        variant = "mixed (" + ", ".join(sorted(set(sf.object_variants))) + ")"
        frame = render_mixed(sf.scene, camera, sf.object_variants, sf.settings, sf.settings.tess)
    else:
        variant = args.variant or sf.variant
        frame = render(sf.scene, camera, variant=variant, settings=sf.settings)
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
    from paramlod.device import context as device

    print("OpenCL")
    print("  " + device.all_cl_devices_summary().replace("\n", "\n  "))
    info = device.cl_info()
    print(f"  selected: {info['device']} ({info['platform']}), {info['type']}, {info['version']}")
    for k in ("compute_units", "global_memory_mib", "max_work_group_size", "local_memory_kib", "int64_atomics"):
        print(f"    {k}: {info[k]}")
    print("OpenGL (EGL, headless)")
    try:
        for k, v in device.gl_info().items():
            print(f"    {k}: {v}")
    except ParamlodError as exc:
        print(f"    unavailable: {exc}")
    return 0


def cmd_functions(args) -> int:
    from paramlod.function.registry import all_functions

    for name, fn in sorted(all_functions().items()):
        params = ", ".join(
            f"{p.name}={float(p.default):g}" if not p.is_array else f"{p.name}=[{p.size} values]"
            for p in fn.params) or "-"
        print(f"{name:20s} u=[{fn.u_range[0]:.4g}, {fn.u_range[1]:.4g}] v=[{fn.v_range[0]:.4g}, {fn.v_range[1]:.4g}]"
              f"  params: {params}  ({fn.source})")
    return 0


def cmd_bench(args) -> int:
    from paramlod.app.bench.run import run_bench

    return run_bench(args)


def cmd_gallery(args) -> int:
    from paramlod.app.gallery import run_gallery

    return run_gallery(args)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="paramlod", description=__doc__)
    p.add_argument("--cl-device", help="OpenCL device by name substring (or PARAMLOD_CL_DEVICE)")
    p.add_argument("--functions", action="append", metavar="DIR",
                   help="a folder of plugin .py files (repeatable; or PARAMLOD_FUNCTIONS_PATH)")
    sub = p.add_subparsers(dest="command", required=True)

    r = sub.add_parser("render", help="render a TOML scene to PNG and/or EXR")
    r.add_argument("scene", help="scene file (.toml)")
    r.add_argument("-o", "--output", action="append", help="output .png or .exr (repeatable)")
    r.add_argument("--size", type=_size, help="override the camera size, e.g. 1920x1080")
    r.add_argument("--variant", help="override the render variant: points, points-ssaa or tess")
    r.add_argument("--aa", help="anti-aliasing: noAA, msaa2/4/8, ssaa2x2/3x3/4x4, or a combination such "
                                "as 4xSS+8xMS (tess); the points variant takes the supersampling only")
    r.add_argument("--stats", help="write the frame statistics as JSON to this file")
    r.set_defaults(func=cmd_render)

    i = sub.add_parser("info", help="print the OpenCL and OpenGL devices and their capabilities")
    i.set_defaults(func=cmd_info)

    f = sub.add_parser("functions", help="list the parametric functions")
    f.set_defaults(func=cmd_functions)

    b = sub.add_parser("bench", help="measure LOD and render times")
    from paramlod.app.bench.run import add_arguments

    add_arguments(b)
    b.set_defaults(func=cmd_bench)

    g = sub.add_parser("gallery", help="render every scene of the gallery to PNG, EXR (and GIF)")
    from paramlod.app.gallery import add_arguments as gallery_arguments

    gallery_arguments(g)
    g.set_defaults(func=cmd_gallery)

    from paramlod.app.surfels_cmd import add_subparser as surfels_subparser

    surfels_subparser(sub)

    from paramlod.dmri.field import add_subparser as glyphs_subparser

    glyphs_subparser(sub)
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        if args.cl_device:
            from paramlod.device.context import set_cl_device

            set_cl_device(args.cl_device)
        for folder in args.functions or []:
            from paramlod.function.registry import add_plugin_path

            add_plugin_path(folder)
        return args.func(args)
    except ParamlodError as exc:
        print(f"paramlod: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("paramlod: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
