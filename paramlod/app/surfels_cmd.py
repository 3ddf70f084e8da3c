"""``paramlod surfels sample | render | info`` (paramlod/app/cli.py calls add_subparser). Sampling
many files is a job of paramlod.app.dist (serial, or on Dask with --workers / --gpus / --scheduler)."""
from __future__ import annotations

import argparse
import json
import math
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from paramlod.app import dist
from paramlod.app.args import add_output, add_size, add_stats, parse_vec3, run_reporting_errors
from paramlod.core.camera import Camera
from paramlod.errors import SurfelError
from paramlod.surfels.build.sampler import sample
from paramlod.surfels.build.schedule import auto_resolution
from paramlod.surfels.format import SurfelSet
from paramlod.surfels.render import FixedCount, FixedSize, default_camera, render_surfels, up_axis


def _fov(text: str) -> float:
    # checked here: a bad fov otherwise surfaces as the default camera's non-finite eye
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not 0 < v < 180:
        raise argparse.ArgumentTypeError(f"must be a number of degrees in (0, 180), got {text!r}")
    return v


def _check_output(path: Path):
    # the output is a .surfels file (an npz named x.png would pass for an image) in a folder that exists
    if path.suffix.lower() != ".surfels":
        raise SurfelError(f"-o {path}: the output of surfels sample must end with .surfels")
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise SurfelError(f"cannot write {path}: folder {folder} does not exist")


def cmd_sample(args) -> int:
    if len(args.source) > 1 or dist.job_requested(args):
        return cmd_sample_job(args)
    out = Path(args.output)
    _check_output(out)  # fail before the sampling, not after it
    s = sample(args.source[0], args.count, views=args.views, resolution=args.resolution, seed=args.seed,
               progress=not args.quiet)
    s.save(out)
    note = ""
    if len(s) < args.count:
        note = (f" (only {len(s)} of {args.count}: every covered G-buffer pixel is taken; "
                "raise --resolution for more)")
    print(f"{out}: {len(s)} surfels{note}, packing {s.packing:.6g}, "
          f"radius {float(s.radii[0]):.4g} .. {float(s.radii[-1]):.4g}, "
          f"{s.meta['views']} views at {s.meta['resolution']}^2, {s.meta['rounds']} rounds")
    return 0


def sample_file(source: str, out: str, count: int, views: int, resolution: int, seed: int) -> dict:
    """The task of a sampling job (paramlod.app.dist): one mesh or scene file sampled into ``out``."""
    with warnings.catch_warnings():   # "only k of n surfels" is in the file's meta (requested vs. length)
        warnings.simplefilter("ignore")
        s = sample(source, count, views=views, resolution=resolution, seed=seed, progress=False)
    s.save(out)
    return {"surfels": len(s)}


@dataclass(frozen=True)
class SampledWith:
    """check(path) for resume: a .surfels file that loads and was sampled with these settings."""
    count: int
    views: int
    resolution: int | None   # None: auto_resolution(count)
    seed: int

    def __call__(self, path) -> bool:
        try:
            m = SurfelSet.load(path).meta
        except SurfelError:
            return False
        return (m.get("requested"), m.get("views"), m.get("resolution"), m.get("seed")) == \
            (self.count, self.views, auto_resolution(self.count) if self.resolution is None else self.resolution, self.seed)


def cmd_sample_job(args) -> int:
    """``paramlod surfels sample A.ply B.ply ... -o out/{stem}.surfels``: one task per file."""
    sources = [Path(x) for x in args.source]
    for src in sources:
        if not src.is_file():
            raise SurfelError(f"{src}: no such file (sampling {len(sources)} files)")
    items = [{"stem": src.name.split(".")[0], "name": src.name} for src in sources]
    names = dist.format_outputs([args.output], "files", items, suffixes=(".surfels",),
                                example="out/{stem}")
    check = SampledWith(args.count, args.views, args.resolution, args.seed)
    tasks = [dist.Task(str(src), sample_file, (str(src.resolve()), outs[0], args.count, args.views, args.resolution,
                                               args.seed), outs, check)
             for src, outs in zip(sources, names)]
    job = dist.Job(tasks, "file", dist.WorkerSetup.from_args(args))
    report = dist.run_job(job, dist.Where.from_args(args), progress=not args.quiet, overwrite=args.overwrite)
    print(report.summary())
    return 0


def _camera(args, surfels):
    if args.up is not None and not np.linalg.norm(args.up) > 0:
        raise SurfelError(f"--up {','.join(f'{x:g}' for x in args.up)}: must be a non-zero vector")
    # without --up, the set's own up axis (up_axis: the face it rests on), so a z-up scan stands upright
    up = np.asarray(args.up, np.float64) if args.up is not None else up_axis(surfels)
    if args.eye is None:
        cam = default_camera(surfels, args.size, fov_y=args.fov, up=up)
        if args.target is None:
            return cam
        eye = cam.eye
    else:
        eye = np.asarray(args.eye)
    c, r = surfels.bounding_sphere()
    target = np.asarray(args.target) if args.target is not None else c
    dist = float(np.linalg.norm(eye - target))
    near = max(dist - 2 * r, dist * 1e-3) if dist > 2 * r else max(r * 1e-3, 1e-4)
    return Camera.look_at(eye, target, up=up, fov_y=args.fov, size=args.size,
                          near=near, far=dist + 2 * r)


def cmd_render(args) -> int:
    s = SurfelSet.load(args.surfels)
    strategy = FixedCount(args.count) if args.count is not None else FixedSize(args.px if args.px is not None else 2.0)
    frame = render_surfels(s, _camera(args, s), strategy)
    outs = args.output
    for out in outs:
        frame.save(out)
    st = frame.stats["surfels"]
    size = "" if st["size_px"] is None else f" ({st['size_px']:g} px)"
    sat = " (all surfels: the set is sparser than asked)" if st["saturated"] else ""
    print(f"{', '.join(outs)}: prefix {st['prefix']} of {st['surfels']}{size}{sat}, disc radius "
          f"{st['radius']:.4g}, {frame.stats['pixels_written']} pixels, {st['ms']:.1f} ms on {frame.stats['device']}")
    if args.stats:
        Path(args.stats).write_text(json.dumps(frame.stats, indent=2))
    return 0


def cmd_info(args) -> int:
    path = Path(args.surfels)
    s = SurfelSet.load(path)
    lo, hi = s.bounds
    info = {
        "file": str(path), "bytes": path.stat().st_size, "surfels": len(s), "packing": s.packing,
        "radius_first": float(s.radii[0]), "radius_last": float(s.radii[-1]),
        "bounds": [lo.tolist(), hi.tolist()],
        "spacing": {str(n): s.spacing(n) for n in (100, 1000, 10000, 100000, len(s)) if n <= len(s)},
        "meta": s.meta,
    }
    if args.json:
        print(json.dumps(info, indent=2))
        return 0
    print(f"{path}: {len(s)} surfels, {info['bytes']} bytes")
    print(f"  packing {s.packing:.6g} (spacing of a prefix of n: sqrt(packing / n))")
    print(f"  insertion radius {info['radius_first']:.4g} (first) .. {info['radius_last']:.4g} (last)")
    print(f"  bounds {np.array2string(lo, precision=4)} .. {np.array2string(hi, precision=4)}")
    for n, r in info["spacing"].items():
        print(f"  prefix {n:>8}: spacing {r:.4g}")
    for k, v in sorted(s.meta.items()):
        print(f"  {k}: {v}")
    return 0


def add_subparser(subparsers) -> argparse.ArgumentParser:
    """Register ``surfels`` with its commands on an argparse subparsers object."""
    p = subparsers.add_parser("surfels", help="blue surfels: sample a mesh or scene, render prefixes, inspect files",
                              description="Blue surfels: progressive blue-noise sampling and the prefix renderer.")
    sub = p.add_subparsers(dest="surfels_command", required=True, metavar="{sample,render,info}")

    s = sub.add_parser("sample", help="sample N blue surfels of a mesh or a scene file into a .surfels file")
    s.add_argument("source", nargs="+", help="mesh (.obj .ply .stl .glb .gltf .off) or scene file (.toml); "
                                             "several make a job (docs/scale-out.md)")
    s.add_argument("-n", "--count", type=int, required=True, help="number of surfels")
    s.add_argument("-o", "--output", required=True, help="output .surfels file; for several sources a pattern "
                                                         "with {stem} or {name}, e.g. out/{stem}.surfels")
    s.add_argument("--views", type=int, default=16, help="orthographic views on a Fibonacci sphere (1..32, default 16)")
    s.add_argument("--resolution", type=int, default=None,
                   help="G-buffer resolution per view (default: from the count, 128 up to 11k surfels, 384 up to 102k, then 512)")
    s.add_argument("--seed", type=int, default=0, help="seed of the first sample (default 0)")
    s.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    dist.add_job_options(s)
    s.set_defaults(func=cmd_sample)

    r = sub.add_parser("render", help="render a prefix of a .surfels file to PNG or EXR")
    r.add_argument("surfels", help=".surfels file")
    g = r.add_mutually_exclusive_group()
    g.add_argument("--px", type=float, help="surfel size in pixels at the object's distance (default 2)")
    g.add_argument("--count", type=int, help="draw this many surfels instead")
    add_size(r, "512x512")
    add_output(r)
    r.add_argument("--eye", type=parse_vec3, help="camera position x,y,z (default: a 3/4 view framing the set)")
    r.add_argument("--target", type=parse_vec3, help="camera target x,y,z (default: the set's centre)")
    r.add_argument("--up", type=parse_vec3, help="camera up vector (default: the set's up axis, opposite the flat base "
                                                   "it rests on, else 0,1,0; the view is a 3/4 view of its widest side)")
    r.add_argument("--fov", type=_fov, default=35.0, help="vertical field of view in degrees (default 35)")
    add_stats(r)
    r.set_defaults(func=cmd_render)

    i = sub.add_parser("info", help="print what a .surfels file holds")
    i.add_argument("surfels", help=".surfels file")
    i.add_argument("--json", action="store_true", help="print JSON")
    i.set_defaults(func=cmd_info)
    return p


def main(argv=None) -> int:
    """Stand-alone entry (``python -m paramlod.app.surfels_cmd ...``): the same commands without the
    ``paramlod surfels`` prefix's global options."""
    parser = argparse.ArgumentParser(prog="paramlod")
    add_subparser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return run_reporting_errors(lambda: args.func(args))


if __name__ == "__main__":
    sys.exit(main())
