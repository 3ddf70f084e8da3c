"""``paramlod glyphs``: render the SH glyph field of a NIfTI SH volume or a paramlod field .npz
(paramlod.dmri; docs/dmri.md). ``--slices all`` renders every axial slice of a volume as a job of
paramlod.app.dist (one task per slice: serial, or on Dask with --workers / --gpus / --scheduler);
each slice's image is the one ``--slice K`` makes."""
from __future__ import annotations

from pathlib import Path

from paramlod.app import dist
from paramlod.app.args import add_output, add_size
from paramlod.dmri import BASES, load_field_npz, load_sh_volume
from paramlod.dmri.io import load_nifti
from paramlod.errors import DmriError
from paramlod.pipeline.driver import render
from paramlod.scene.framing import framing_camera

# load_sh_volume's message for a region without a voxel to draw: a slice outside the brain
EMPTY_REGION = "no voxels left to draw"


def add_subparser(sub):
    """Register ``glyphs`` on an argparse subparsers object."""
    g = sub.add_parser("glyphs", help="render the SH glyph field of a NIfTI SH volume (or a field .npz)")
    g.add_argument("path", help="4D NIfTI of SH coefficients (.nii/.nii.gz) or a paramlod field .npz")
    g.add_argument("--basis", choices=BASES, default="descoteaux07",
                   help="the file's SH basis: tournier07 for MRtrix3, descoteaux07 for dipy (default)")
    g.add_argument("--legacy", action="store_true", help="dipy's legacy variant of the basis (MRtrix 0.2, "
                                                         "dipy's Q-ball fits)")
    g.add_argument("--mask", help="a 3D NIfTI mask (non-zero = keep) of the volume's spatial shape")
    g.add_argument("--stride", type=int, default=1, help="keep every stride-th voxel along each axis")
    s = g.add_mutually_exclusive_group()
    s.add_argument("--slice", type=int, metavar="K", help="only axial slice K")
    s.add_argument("--slices", type=dist.parse_range, metavar="all|A:B",
                   help="every axial slice (all) or slices A to B-1, one image each: -o with {slice}, "
                        "e.g. out/slice_{slice:03d}.png; slices without a voxel to draw are skipped")
    g.add_argument("--color", choices=["direction", "none"], default="direction",
                   help="colour by the largest lobe's direction (default) or plain")
    g.add_argument("--subtract-min", action="store_true",
                   help="lower each glyph by its minimum over the sphere (min-max display normalization: "
                        "no negative lobes, sharper shapes; recommended for ODFs that dip below zero, "
                        "such as dipy's CSA fits)")
    g.add_argument("--variant", default="points", help="render variant (points, points-ssaa, tess)")
    add_size(g, "960x960")
    add_output(g)
    g.add_argument("-q", "--quiet", action="store_true", help="no progress bar (--slices)")
    dist.add_job_options(g)
    g.set_defaults(func=run_glyphs)
    return g


def glyph_frame(path, basis, legacy, mask, stride, k, color, variant, size, subtract_min=False):
    """(Frame, ShField) of the volume (or axial slice ``k``), framed from above."""
    path = Path(path)
    if path.suffix == ".npz":
        field = load_field_npz(path)
    else:
        region = (slice(None), slice(None), slice(k, k + 1)) if k is not None else None
        field = load_sh_volume(path, basis, mask=mask, stride=stride, legacy=legacy, region=region)
    scene = field.to_scene(color_by=None if color == "none" else "direction", subtract_min=subtract_min)
    camera = framing_camera(scene, (0.0, -0.35, 1.0), (0, 1, 0), 40.0, size)
    return render(scene, camera, variant), field


def render_slice(path, basis, legacy, mask, stride, k, color, variant, size, outputs, subtract_min=False) -> dict:
    """The task of a ``--slices`` job: slice ``k`` saved to ``outputs``; a slice without a voxel
    to draw writes nothing and says so."""
    try:
        frame, field = glyph_frame(path, basis, legacy, mask, stride, k, color, variant, size, subtract_min)
    except DmriError as exc:
        if EMPTY_REGION in str(exc):
            return {"empty": True}
        raise
    for out in outputs:
        frame.save(out)
    return {"glyphs": len(field), "device": frame.stats.get("device")}


def run_glyphs(args) -> int:
    volume_only = [opt for opt, given in (("--mask", args.mask), ("--stride", args.stride != 1),
                                          ("--slice", args.slice is not None), ("--legacy", args.legacy)) if given]
    if Path(args.path).suffix == ".npz" and volume_only:   # a field .npz would draw every glyph regardless
        raise DmriError(f"{args.path}: {', '.join(volume_only)} apply to NIfTI SH volumes; a field .npz is "
                        "stored already sampled")
    if args.slices is not None or dist.job_requested(args):
        return run_slices(args)
    frame, field = glyph_frame(args.path, args.basis, args.legacy, args.mask, args.stride, args.slice, args.color,
                               args.variant, args.size, args.subtract_min)
    for out in args.output:
        frame.save(out)
    print(f"{', '.join(args.output)}: {len(field)} glyphs of order {field.order} ({field.source_basis}"
          f"{', legacy' if field.source_legacy else ''}"
          f"{', minimum subtracted' if args.subtract_min else ''}), "
          f"{frame.stats.get('render_patches', '?')} render patches")
    return 0


def run_slices(args) -> int:
    path = Path(args.path)
    if path.suffix == ".npz":
        raise DmriError(f"{path}: --slices needs a NIfTI SH volume; a field .npz has no slices")
    depth = int(load_nifti(path).shape[2])
    spec = args.slices if args.slices is not None else ((args.slice, args.slice + 1, 1) if args.slice is not None
                                                       else "all")
    slices = dist.expand_range(spec, depth, "slices")
    outside = [k for k in slices if k >= depth]
    if outside:
        raise DmriError(f"{path}: has {depth} axial slices (0..{depth - 1}); --slices asks for slice {outside[0]}")
    names = dist.format_outputs(args.output, "slices", [{"slice": k} for k in slices], example="out/slice_{slice:03d}")
    mask = str(Path(args.mask).resolve()) if args.mask else None
    check = dist.image_check(args.size)
    tasks = [dist.Task(f"{path.name} slice {k}", render_slice,
                       (str(path.resolve()), args.basis, args.legacy, mask, args.stride, k, args.color, args.variant,
                        tuple(args.size), outs, args.subtract_min), outs, check)
             for k, outs in zip(slices, names)]
    job = dist.Job(tasks, "slice", dist.WorkerSetup.from_args(args))
    report = dist.run_job(job, dist.Where.from_args(args), progress=not args.quiet, overwrite=args.overwrite)
    print(report.summary())
    empty = [o.name for o in report.done if o.info.get("empty")]
    if empty:
        print(f"  {len(empty)} slice(s) without a voxel to draw, no image: {', '.join(empty)}")
    return 0
