"""``paramlod gallery``: render every scene file of a folder to PNG and EXR (and an animated GIF for
scenes with an [animation] table), with captions that state what was measured."""
from __future__ import annotations

import json
import tomllib
import time
from pathlib import Path

import numpy as np

from paramlod.app.args import add_size
from paramlod.app.scenefile import load_scene
from paramlod.core.files import write_atomically
from paramlod.core.frame import stats_aa
from paramlod.device.context import cl_device
from paramlod.errors import ParamlodError
from paramlod.pipeline.driver import render


def add_arguments(p):
    p.add_argument("--scenes", default="gallery", help="folder of .toml scenes (default gallery)")
    # not gallery/images: a trial render must not overwrite the committed images (--out gallery/images does)
    p.add_argument("--out", default="out/gallery", help="output folder (default out/gallery; the committed "
                                                        "gallery is made with --out gallery/images)")
    add_size(p, what="override every scene's size")
    p.add_argument("--only", nargs="+", metavar="NAME", help="render only these scenes (file stems)")


def _aa(sf, variant: str, stats: dict) -> str:
    if variant == "points-ssaa":
        n = sf.settings.ssaa.ss
        return f"{n * n}xSS (local framebuffer)"
    return stats_aa(stats)


def render_scene_file(path, size=None):
    """(SceneFile, frames, variant label) for one scene file; several frames if animated."""
    sf = load_scene(path, size=size)
    camera = sf.camera
    times = [sf.scene.time]
    if sf.animation:
        a = sf.animation
        times = list(np.linspace(a["t0"], a["t1"], a["frames"], endpoint=False))
    frames = []
    for t in times:
        sf.scene.time = float(t)
        frames.append(render(sf.scene, camera, variant=sf.variant, settings=sf.settings))
    variant = "mixed (" + ", ".join(sorted(set(sf.object_variants))) + ")" if sf.object_variants else sf.variant
    return sf, frames, variant


def caption(sf, frame, variant: str, device: str, elapsed_ms: float) -> dict:
    s = frame.stats
    ms = s.get("ms", {})
    patches = s["render_patches"]
    return {
        "title": sf.meta.get("title", sf.path.stem),
        "caption": sf.meta.get("caption", ""),
        "variant": variant,
        "aa": _aa(sf, sf.variant if not sf.object_variants else variant, s),
        "size": list(frame.size),
        "instances": sf.scene.instance_count + sum(m.count for m in sf.scene.meshes),
        "render_patches": patches,
        "clusters": s.get("clusters_drawn"),       # meshes: the cut's clusters and triangles
        "triangles": s.get("triangles_drawn"),
        "lod_ms": ms.get("lod"),
        "render_ms": ms.get("render", ms.get("draw")),
        "frame_ms": elapsed_ms,
        "device": device,
    }


def _fmt(x, nd=1):
    return "n/a" if x is None else f"{x:.{nd}f}"


def markdown(captions: list[dict]) -> str:
    lines = ["# Gallery", "", "Rendered by `paramlod gallery` from the scene files in `gallery/` (the repository's "
             "`gallery/images` is made with `--out gallery/images`; the default folder is `out/gallery`); "
             "each caption gives the variant, anti-aliasing, render patches, LOD and render times and the "
             "device (OpenCL / OpenGL) that produced the image.", ""]
    for c in captions:
        lines += [f"## {c['title']}", "", f"![{c['title']}]({c['image']})", ""]
        if c["caption"]:
            lines += [c["caption"], ""]
        lines += [f"{c['variant']}, {c['aa']}, {c['size'][0]}×{c['size'][1]}, {c['instances']:,} instances, "
                  f"{c['render_patches'] if c['render_patches'] is not None else 'n/a'} render patches, "
                  + (f"{c['clusters']:,} clusters and {c['triangles']:,} triangles drawn, " if c.get("clusters") else "")
                  + f"LOD {_fmt(c['lod_ms'])} ms, render {_fmt(c['render_ms'])} ms, whole frame {_fmt(c['frame_ms'])} ms "
                  f"(first frame includes kernel compilation), on {c['device']}.", ""]
    return "\n".join(lines)


def check_prepared(files) -> None:
    """Before any rendering: every file a scene's ``[meta] needs`` (paths beside the scene file) is
    there, else one message naming the ``[meta] prepare`` command that makes it (data too large to
    commit, such as the rigged worm)."""
    for f in files:
        try:
            meta = tomllib.loads(Path(f).read_text()).get("meta", {})
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
            continue   # render_scene_file reports it with the file's line
        missing = [n for n in meta.get("needs", []) if not (Path(f).parent / n).exists()]
        if missing:
            raise ParamlodError(f"gallery scene {Path(f).stem} needs {', '.join(missing)} (in {Path(f).parent}), "
                                f"made by `{meta.get('prepare', '?')}`; run that first, or leave the scene out "
                                f"with --only")


def run_gallery(args) -> int:
    from tqdm import tqdm

    folder = Path(args.scenes)
    if not folder.is_dir():   # the gallery's scenes are the repository's, not the installed package's
        raise ParamlodError(f"--scenes {folder}: no such folder; the gallery's scenes are in the gallery/ folder "
                            "of the paramlod repository: run from its root or give --scenes")
    files = sorted(folder.glob("*.toml"))
    if args.only:
        wanted = set(args.only)
        missing = wanted - {f.stem for f in files}
        if missing:
            raise ParamlodError(f"no gallery scene named {', '.join(sorted(missing))} in {folder} "
                                f"(available: {', '.join(f.stem for f in files)})")
        files = [f for f in files if f.stem in wanted]
    if not files:
        raise ParamlodError(f"no .toml scenes in {folder}")
    check_prepared(files)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    size = args.size
    captions = []
    bar = tqdm(files, unit="scene")
    for f in bar:
        bar.set_description(f.stem)
        t0 = time.perf_counter()
        sf, frames, variant = render_scene_file(f, size)
        elapsed = (time.perf_counter() - t0) * 1e3 / len(frames)
        frames[0].save(out / f"{f.stem}.png")
        frames[0].save(out / f"{f.stem}.exr")
        image = f"{f.stem}.png"
        if len(frames) > 1:
            from PIL import Image

            imgs = [Image.fromarray(fr.rgb8()) for fr in frames]
            dur = int(1000 / sf.animation["fps"])
            write_atomically(out / f"{f.stem}.gif", lambda tmp: imgs[0].save(
                tmp, format="GIF", save_all=True, append_images=imgs[1:], duration=dur, loop=0))
            image = f"{f.stem}.gif"
        device = cl_device().name
        if variant.startswith("tess") or "tess" in variant:
            device += " + " + str(frames[0].stats.get("device") or "OpenGL")
        c = caption(sf, frames[-1], variant, device, elapsed)
        c["image"] = image
        captions.append(c)
    write_atomically(out / "captions.json", lambda tmp: Path(tmp).write_text(json.dumps(captions, indent=2)))
    write_atomically(out / "README.md", lambda tmp: Path(tmp).write_text(markdown(captions)))
    print(f"{len(captions)} scene(s) rendered to {out}")
    return 0
