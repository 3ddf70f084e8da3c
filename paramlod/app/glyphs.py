"""``paramlod glyphs``: render the SH glyph field of a NIfTI SH volume or a paramlod field .npz
(paramlod.dmri; docs/dmri.md)."""
from __future__ import annotations

from pathlib import Path

from paramlod.app.args import add_output, add_size
from paramlod.dmri import BASES, load_field_npz, load_sh_volume
from paramlod.pipeline.driver import render
from paramlod.scene.framing import framing_camera


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
    g.add_argument("--slice", type=int, metavar="K", help="only axial slice K")
    g.add_argument("--color", choices=["direction", "none"], default="direction",
                   help="colour by the largest lobe's direction (default) or plain")
    g.add_argument("--variant", default="points", help="render variant (points, points-ssaa, tess)")
    add_size(g, "960x960")
    add_output(g)
    g.set_defaults(func=run_glyphs)
    return g


def run_glyphs(args) -> int:
    path = Path(args.path)
    if path.suffix == ".npz":
        field = load_field_npz(path)
    else:
        region = (slice(None), slice(None), slice(args.slice, args.slice + 1)) if args.slice is not None else None
        field = load_sh_volume(path, args.basis, mask=args.mask, stride=args.stride, legacy=args.legacy,
                               region=region)
    scene = field.to_scene(color_by=None if args.color == "none" else "direction")
    camera = framing_camera(scene, (0.0, -0.35, 1.0), (0, 1, 0), 40.0, args.size)
    frame = render(scene, camera, args.variant)
    for out in args.output:
        frame.save(out)
    print(f"{', '.join(args.output)}: {len(field)} glyphs of order {field.order} ({field.source_basis}"
          f"{', legacy' if field.source_legacy else ''}), {frame.stats.get('render_patches', '?')} render patches")
    return 0
