"""Composition of the frames of several renderers into one Frame, by depth (thesis section 5.5.7,
Figure 5.10: one scene may draw each object with another variant).

Every renderer delivers a resolved Frame of the same size: straight-alpha colour whose alpha is
the pixel's coverage, the linear depth, normal and object id of the pixel's nearest sample.
``composite`` merges them per pixel:

* depth, normal, object id: those of the nearest frame (smallest depth);
* colour: the frames' colours composited front to back with the "over" operator, weighted by
  coverage, so that an anti-aliased edge in front of another object blends with that object rather
  than with the background;
* frames are taken coarsest target first (fewest samples per pixel, ``stats["samples_per_pixel"]``,
  1 when absent); at equal depth the later, finer frame wins, so the finer target's detail is kept.

This is a merge of resolved frames. The thesis instead copies the coarse targets' colour and depth
into every sample of the next finer target before drawing into it, which also depth-tests the fine
geometry against the coarse one per sample; at a pixel where objects of different variants overlap
partially, merging resolved frames approximates that per-sample test by the per-pixel "over"
(docs/tessellation.md).

``split_by_variant`` and ``render_mixed`` build such a frame for a scene whose objects use
different variants.
"""
from __future__ import annotations

import time
from typing import Sequence

import numpy as np

from paramlod.errors import SceneError
from paramlod.core.frame import Frame


def _samples_per_pixel(frame: Frame) -> float:
    try:
        return float(frame.stats.get("samples_per_pixel", 1))
    except (TypeError, ValueError, AttributeError):
        return 1.0


def composite(frames: Sequence[Frame], background=None) -> Frame:
    """Merge ``frames`` (all of one size) by depth into one Frame; see the module docstring."""
    frames = list(frames)
    if not frames:
        raise SceneError("composite needs at least one frame")
    for i, f in enumerate(frames):
        if not isinstance(f, Frame):
            raise SceneError(f"composite: item {i} is not a Frame but {type(f).__name__}")
    size = frames[0].size
    bad = [i for i, f in enumerate(frames) if f.size != size]
    if bad:
        raise SceneError(f"composite: frames must share one size; frame 0 is {size[0]}x{size[1]}, "
                         + ", ".join(f"frame {i} is {frames[i].size[0]}x{frames[i].size[1]}" for i in bad))
    t0 = time.perf_counter()
    # coarsest first (stable, so equal sample counts keep the given order)
    order = sorted(range(len(frames)), key=lambda i: _samples_per_pixel(frames[i]))
    fs = [frames[i] for i in order]
    k = len(fs)
    depth = np.stack([np.where(np.isfinite(f.depth), f.depth, np.inf).astype(np.float32) for f in fs])
    alpha = np.stack([np.clip(f.color[..., 3], 0.0, 1.0) for f in fs])
    alpha = np.where(np.isfinite(depth), alpha, 0.0)
    # per pixel, frames front to back; at equal depth the finer (later) frame comes first
    rank = np.broadcast_to(np.arange(k)[:, None, None], depth.shape)
    front = np.lexsort((-rank, depth), axis=0) if k > 1 else np.zeros(depth.shape, np.intp)

    color = np.stack([f.color[..., :3] for f in fs])        # (k, h, w, 3), straight alpha
    acc = np.zeros(color.shape[1:], np.float32)
    acc_a = np.zeros(depth.shape[1:], np.float32)
    for j in range(k):
        idx = front[j]
        a = np.take_along_axis(alpha, idx[None], 0)[0]
        c = np.take_along_axis(color, idx[None, ..., None], 0)[0]
        w = (1.0 - acc_a) * a
        acc += w[..., None] * c
        acc_a += w
    rgb = np.where(acc_a[..., None] > 0, acc / np.maximum(acc_a, 1e-30)[..., None], 0.0)

    near = front[0]
    out_depth = np.take_along_axis(depth, near[None], 0)[0]
    normals = np.stack([f.normal for f in fs])
    ids = np.stack([f.object_id for f in fs])
    covered = np.isfinite(out_depth)
    out_normal = np.where(covered[..., None], np.take_along_axis(normals, near[None, ..., None], 0)[0], 0.0)
    out_ids = np.where(covered, np.take_along_axis(ids, near[None], 0)[0], 0).astype(np.uint32)

    out = Frame(color=np.ascontiguousarray(np.concatenate([rgb, acc_a[..., None]], axis=-1), np.float32),
                depth=np.ascontiguousarray(out_depth, np.float32),
                normal=np.ascontiguousarray(out_normal, np.float32),
                object_id=np.ascontiguousarray(out_ids))
    out.background = tuple(background) if background is not None else fs[0].background
    ms = (time.perf_counter() - t0) * 1e3
    parts_ms = sum(float(f.stats.get("ms", {}).get("total", 0.0)) for f in fs if isinstance(f.stats, dict))
    out.stats = {
        "variant": "composite",
        "size": list(size),
        "parts": [dict(f.stats) for f in fs],
        "order": [f.stats.get("variant", "?") + (f" ({f.stats['aa_effective']})" if "aa_effective" in f.stats else "")
                  for f in fs],
        "samples_per_pixel": max(_samples_per_pixel(f) for f in fs),
        "pixels_written": int(np.count_nonzero(covered)),
        "ms": {"composite": ms, "total": parts_ms + ms},
    }
    return out


def subscene(scene, objects, surfels=()):
    """A scene that draws only ``objects`` (SceneObjects of ``scene``) and ``surfels`` (its
    SurfelObjects), keeping their object ids, background and time, so that frames of several
    subscenes composite into the whole scene."""
    from paramlod.scene.scene import Scene

    sub = Scene(background=scene.background, time=scene.time)
    ids = {id(o) for o in scene.objects}
    for o in objects:
        if id(o) not in ids:
            raise SceneError("subscene: an object does not belong to the scene")
    sub.objects = list(objects)
    sub.surfels = list(surfels)
    sub.touch()
    return sub


def split_by_variant(scene, variants) -> dict[str, object]:
    """{variant: subscene} for ``variants``, one variant name per object of ``scene`` (a sequence)
    or a mapping {object index (0-based) or SceneObject: variant} with "points" for the rest."""
    objs = list(scene.objects)
    if isinstance(variants, dict):
        per = ["points"] * len(objs)
        for key, var in variants.items():
            if isinstance(key, int):
                if not 0 <= key < len(objs):
                    raise SceneError(f"variant for object index {key}, but the scene has {len(objs)} objects")
                per[key] = var
            else:
                matches = [i for i, o in enumerate(objs) if o is key]
                if not matches:
                    raise SceneError("variant given for an object that is not in the scene")
                per[matches[0]] = var
    else:
        per = list(variants)
        if len(per) != len(objs):
            raise SceneError(f"{len(per)} variants given for a scene of {len(objs)} objects")
    groups: dict[str, list] = {}
    for o, var in zip(objs, per):
        if not isinstance(var, str):
            raise SceneError(f"a variant must be a name such as 'points' or 'tess', got {var!r}")
        groups.setdefault(var, []).append(o)
    # surfels are points: they go with the point-based objects
    if scene.surfels:
        groups.setdefault("points", [])
    return {var: subscene(scene, objs_, scene.surfels if var == "points" else ())
            for var, objs_ in groups.items()}


def render_mixed(scene, camera, variants, settings=None, tess_settings=None) -> Frame:
    """Render each object of ``scene`` with its variant and composite the frames by depth.

    ``variants``: as in ``split_by_variant``; names are "points", "tess", or "tess:<AA mode>" (for
    example "tess:4xSS+8xMS") to give tessellated objects their own anti-aliasing.
    ``settings`` is a RenderSettings (LOD and point settings); ``tess_settings`` a TessSettings.
    """
    from dataclasses import replace

    from paramlod.pipeline.driver import RenderSettings, render
    from paramlod.renderers.tess import TessSettings, render_tess

    settings = settings or RenderSettings()
    base = tess_settings or TessSettings()
    frames = []
    for var, sub in split_by_variant(scene, variants).items():
        if var == "points":
            frames.append(render(sub, camera, variant="points", settings=settings))
        elif var == "tess" or var.startswith("tess:"):
            ts = replace(base, aa=var.split(":", 1)[1]) if ":" in var else base
            frames.append(render_tess(sub, camera, ts, settings.lod))
        else:
            raise SceneError(f"unknown variant '{var}' for a mixed scene (use 'points', 'tess' or 'tess:<AA mode>')")
    return composite(frames, background=scene.background)
