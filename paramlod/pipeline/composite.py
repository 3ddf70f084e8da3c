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

The frame driver (``paramlod.pipeline.driver``) composites the passes of a scene whose objects
use different variants or anti-aliasing modes.
"""
from __future__ import annotations

import time
from typing import Sequence

import numpy as np

from paramlod.core.frame import Frame, FrameStats
from paramlod.errors import SceneError


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
    out.stats = FrameStats({
        "variant": "composite",
        "device": ", ".join(dict.fromkeys(str(f.stats.get("device", "")) for f in fs)),
        "size": list(size),
        "supersample": max(int(f.stats.get("supersample", 1)) for f in fs),
        "render_patches": sum(int(f.stats.get("render_patches", 0)) for f in fs),
        "warnings": [w for f in fs for w in f.stats.get("warnings", [])],
        "passes": [dict(f.stats) for f in fs],
        "order": [f.stats.get("variant", "?") + (f" ({f.stats['aa_effective']})" if "aa_effective" in f.stats else "")
                  for f in fs],
        "samples_per_pixel": max(_samples_per_pixel(f) for f in fs),
        "pixels_written": int(np.count_nonzero(covered)),
        "ms": {"composite": ms, "total": parts_ms + ms},
    })
    return out
