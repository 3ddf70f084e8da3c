"""``paramlod mesh build | info`` (paramlod/app/cli.py calls add_subparser): build a mesh's level of
detail (the cluster DAG, the original triangles only, or a discrete chain of whole-mesh levels:
``--lod dag|full|chain``, ``--full`` and ``--chain`` for short) into a ``.meshlod`` file (or the
cache) and print what it holds."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from paramlod.app import dist
from paramlod.app.args import Parser, check_folder, run_reporting_errors
from paramlod.errors import MeshError
from paramlod.meshlod.format import LODS, SUFFIX, load_meshlod, mesh_info, save_meshlod
from paramlod.meshlod.source import load_mesh


def _check_output(out: Path, source: Path):
    if not out.name.lower().endswith(SUFFIX):
        raise MeshError(f"cannot write {out}: the output must be a {SUFFIX} file (e.g. -o {source.stem}{SUFFIX})")
    if out.is_dir():
        raise MeshError(f"-o/--output {out}: is a folder")
    check_folder(out.parent, f"-o/--output {out}")   # exists and takes a file (read-only, /proc: refused)


def _size(n: int) -> str:
    for unit in ("bytes", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n} {unit}" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1024


def _lod(args) -> str:
    """The lod the options ask for; --full and --chain are --lod full and --lod chain."""
    asked = {x for x in (args.lod, "full" if args.full else None, "chain" if args.chain else None) if x}
    if len(asked) > 1:
        raise MeshError(f"give one level-of-detail kind: --lod {' / --lod '.join(sorted(asked))} contradict each other")
    return asked.pop() if asked else "dag"


def format_info(info: dict, file_bytes: int | None = None) -> str:
    """The table ``paramlod mesh build`` and ``paramlod mesh info`` print."""
    roots = info["roots"]
    lines = [f"{info['name']}: lod {info['lod']}, {info['triangles']:,} triangles, {info['vertices']:,} vertices",
             f"  {info['levels']} levels, {info['clusters']:,} clusters, {roots} root{'s' if roots != 1 else ''} "
             f"({info['root_triangles']:,} triangles)",
             "  level  clusters  triangles"]
    for k, (c, t) in enumerate(zip(info["clusters_per_level"], info["triangles_per_level"])):
        lines.append(f"  {k:5d}  {c:8,d}  {t:9,d}")
    lo, hi = info["error_range"]
    lines.append(f"  error {lo:.4g} .. {hi:.4g} (object units; 0 at level 0)" if hi > 0 else
                 "  error 0 (the original triangles only)")
    size = f"  bytes {info['bytes']:,} ({_size(info['bytes'])}) in memory"
    if file_bytes is not None:
        size += f", file {file_bytes:,} ({_size(file_bytes)})"
    lines.append(size)
    if info.get("build_seconds") is not None:
        lines.append(f"  build {info['build_seconds']:.2f} s")
    return "\n".join(lines)


def cmd_build(args) -> int:
    if len(args.mesh) > 1 or dist.job_requested(args):
        job = dist.mesh_build_job(args.mesh, out=args.output or "{stem}" + SUFFIX, lod=_lod(args),
                                  cache=not args.no_cache, setup=dist.WorkerSetup.from_args(args))
        print(dist.run_job(job, dist.Where.from_args(args), progress=not args.quiet,
                           overwrite=args.overwrite).summary())
        return 0
    source = Path(args.mesh[0])
    if source.name.lower().endswith(SUFFIX):
        raise MeshError(f"{source} is already a {SUFFIX} file; give the mesh file it was built from")
    out = Path(args.output) if args.output else None
    if out is not None:
        _check_output(out, source)   # fail before the build, not after it
    lod = load_mesh(source, lod=_lod(args), cache=not args.no_cache,
                    progress=False if args.quiet else True)
    file_bytes = None
    if out is not None:
        save_meshlod(lod, out)
        file_bytes = out.stat().st_size
    info = mesh_info(lod)
    if args.json:
        print(json.dumps(dict(info, file=str(out) if out else None, file_bytes=file_bytes), indent=2))
    else:
        print(format_info(info, file_bytes))
        if out is not None:
            print(f"  written to {out}")
    return 0


def cmd_info(args) -> int:
    path = Path(args.mesh)
    if path.name.lower().endswith(SUFFIX):
        lod = load_meshlod(path)
        file_bytes = path.stat().st_size
    else:
        lod = load_mesh(path, lod=_lod(args), progress=None)
        file_bytes = None
    info = mesh_info(lod)
    if args.json:
        print(json.dumps(dict(info, file=str(path), file_bytes=file_bytes), indent=2))
    else:
        print(format_info(info, file_bytes))
    return 0


def _lod_options(p, prefix: str) -> None:
    p.add_argument("--lod", choices=LODS, default=None,
                   help=f"{prefix}dag (cluster DAG, the default), full (only the original triangles) or chain "
                        "(whole-mesh levels halving down to about 100 triangles)")
    p.add_argument("--full", action="store_true", help=f"{prefix}the same as --lod full")
    p.add_argument("--chain", action="store_true", help=f"{prefix}the same as --lod chain")


def add_subparser(subparsers) -> argparse.ArgumentParser:
    """Register ``mesh`` with its commands on an argparse subparsers object."""
    p = subparsers.add_parser("mesh", help="mesh level of detail: build a cluster DAG or a LOD chain, inspect it",
                              description="Mesh level of detail: the cluster DAG or a discrete LOD chain "
                                          "(.meshlod files and the build cache).")
    sub = p.add_subparsers(dest="mesh_command", required=True, metavar="{build,info}")

    b = sub.add_parser("build", help="build a mesh's cluster DAG or LOD chain (into the cache, or a .meshlod file "
                                     "with -o)")
    b.add_argument("mesh", nargs="+", help="mesh file(s) (.obj .ply .stl .off .glb .gltf .surf.gii); several "
                                          "files (or --workers/--gpus/--scheduler) run as a job (docs/scale-out.md)")
    b.add_argument("-o", "--output", help=f"write the result to this {SUFFIX} file (several files: a pattern "
                                          "with {stem} or {name}, default {stem}.meshlod beside each mesh)")
    _lod_options(b, "")
    b.add_argument("--no-cache", action="store_true", help="build again even if the cache holds the build")
    b.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    b.add_argument("--json", action="store_true", help="print JSON")
    dist.add_job_options(b)
    b.set_defaults(func=cmd_build)

    i = sub.add_parser("info", help=f"print the levels of a {SUFFIX} file or of a mesh file's (cached) build")
    i.add_argument("mesh", help=f"{SUFFIX} file or mesh file")
    _lod_options(i, "for a mesh file: ")
    i.add_argument("--json", action="store_true", help="print JSON")
    i.set_defaults(func=cmd_info)
    return p


def main(argv=None) -> int:
    """Stand-alone entry (``python -m paramlod.app.mesh_cmd ...``)."""
    parser = Parser(prog="paramlod")
    add_subparser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return run_reporting_errors(lambda: args.func(args))


if __name__ == "__main__":
    sys.exit(main())
