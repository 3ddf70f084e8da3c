"""``paramlod render SCENE --stereo IPD | --cubemap | --quilt 8x6``: one multi-view frame of a
scene file (``paramlod.render_views``), written as one file per view (``-o`` with ``{view}``) or as
one assembled image: a side-by-side pair, an equirectangular panorama, or a light-field quilt."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from PIL import Image

from paramlod.app import dist
from paramlod.app.args import check_outputs, positive_float, progress, write_all_or_none
from paramlod.core import views
from paramlod.core.files import write_atomically
from paramlod.errors import ParamlodError, SceneError
from paramlod.pipeline.driver import render_views
from paramlod.scene.framing import scene_box

DEFAULT_VIEW_CONE = 40.0   # degrees; applied late, so that None tells that --view-cone was not given


def _grid(text: str) -> tuple[int, int]:
    try:
        return views.parse_grid(text)
    except SceneError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def add_arguments(r) -> None:
    g = r.add_argument_group("multi-view (one LOD pass for every view; docs/multiview.md)")
    m = g.add_mutually_exclusive_group()
    m.add_argument("--stereo", type=positive_float, metavar="IPD",
                   help="a left/right pair IPD apart (scene units), converging at the scene's centre")
    m.add_argument("--cubemap", action="store_true",
                   help="six 90-degree views from the camera's eye (assembled: an equirectangular panorama)")
    m.add_argument("--quilt", type=_grid, metavar="COLSxROWS",
                   help="a light-field quilt, e.g. 8x6 (Looking Glass order: view 0 bottom left)")
    g.add_argument("--view-cone", type=positive_float, metavar="DEG",
                   help="--quilt: the angle the views span, seen from the focal plane "
                        f"(default {DEFAULT_VIEW_CONE:g})")


def requested(args) -> bool:
    return bool(args.stereo or args.cubemap or args.quilt)


def check(args) -> None:
    """Options that would be ignored: --view-cone shapes the quilt's views only."""
    if args.view_cone is not None and not args.quilt:
        raise ParamlodError(f"--view-cone {args.view_cone:g}: is the angle the views of --quilt span; "
                            "it has no effect without --quilt")


def _kind(args) -> str:
    return "stereo" if args.stereo else "cubemap" if args.cubemap else "quilt"


def cameras(args, sf) -> list:
    cam = sf.camera
    lo, hi = scene_box(sf.scene)
    centre = np.append((lo + hi) / 2, 1.0)
    focus = max(-float(cam.view[2] @ centre), 2 * cam.near)   # view depth of the scene's centre
    if args.stereo:
        return views.stereo(cam, args.stereo, focus=focus)
    if args.cubemap:
        return views.cube_faces(cam.eye, size=cam.height, near=cam.near, far=cam.far)
    cols, rows = args.quilt
    return views.quilt(cam, cols, rows, view_cone=args.view_cone or DEFAULT_VIEW_CONE, focus=focus)


def outputs(args, scene_path) -> list[str]:
    """The output files, checked before any work: with ``{view}`` one per view (PNG or EXR), else
    one assembled PNG."""
    outs = args.output or [str(Path("out") / f"{Path(scene_path).stem}_{_kind(args)}.png")]
    if not args.output:
        Path("out").mkdir(exist_ok=True)
    for out in outs:
        if "{view" not in out and Path(out).suffix.lower() != ".png":
            raise ParamlodError(f"-o {out}: an assembled {_kind(args)} image is a .png; for one file per view "
                                "(.png or .exr) put {view} in the name, e.g. out/view_{view:02d}.exr")
        try:
            out.format(view=0)
        except dist.PATTERN_ERRORS as e:
            raise ParamlodError(f"-o {out}: only {{view}} may be filled in ({e})") from None
    return outs


def run(args) -> int:
    scene_path = args.scene[0]
    outs = outputs(args, scene_path)
    if args.stats:
        check_outputs([args.stats], "--stats", suffixes=(".json",))
    with progress("loading the scene"):
        sf, variant = dist.prepare_scene(scene_path, args.size, args.variant, args.aa)
    cams = cameras(args, sf)
    per_view = [o for o in outs if "{view" in o]
    check_outputs([*(o.format(view=v) for o in per_view for v in range(len(cams))),
                   *(o for o in outs if o not in per_view)])
    w, h = cams[0].size
    with progress(f"rendering {len(cams)} views of {w}x{h}"):
        frames = render_views(sf.scene, cams, variant=variant, settings=sf.settings, time=args.time)
    items = []
    for out in outs:
        if "{view" in out:
            items += [(out.format(view=v), f.save) for v, f in enumerate(frames)]
        else:
            image = assemble(args, frames, cams)
            items.append((out, lambda p, image=image: write_atomically(
                p, lambda tmp: Image.fromarray(image).save(tmp, format="PNG"))))
    if args.stats:
        text = json.dumps([f.stats for f in frames], indent=2)
        items.append((args.stats, lambda p: write_atomically(p, lambda tmp: Path(tmp).write_text(text))))
    with progress("writing"):
        write_all_or_none(items)
    s = frames[0].stats
    device = s.get("device") or s.get("lod_device")
    print(f"{', '.join(outs)}: {len(frames)} views of {w}x{h} {s.get('variant', '')}"
          + (f" on {device}" if device else "")
          + f", {s.get('render_patches', 0)} render patches shared, "
          + f"{sum(int(f.stats['pixels_written']) for f in frames)} pixels, {s['ms']['total']:.1f} ms")
    for v, f in enumerate(frames):
        for warning in f.stats.get("warnings", []):
            print(f"paramlod: warning: view {v}: {warning}", file=sys.stderr)
    return 0


def assemble(args, frames, cams) -> np.ndarray:
    if args.stereo:
        return views.strip_image(frames)
    if args.cubemap:
        return views.equirect(frames, cams)
    return views.quilt_image(frames, *args.quilt)
