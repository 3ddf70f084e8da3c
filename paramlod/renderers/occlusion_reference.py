"""numpy twin of kernels/points/occlusion.cl: the depth pyramid, the occlusion test (both exact)
and the patches' bounds (float32, to rounding)."""
from __future__ import annotations

import numpy as np

from paramlod.core.layouts import CAMERA
from paramlod.lod.reference import sampled_range, world_positions
from paramlod.renderers.occlusion import GRID, pyramid_levels

F32 = np.float32


def depth_pyramid(color_keys: np.ndarray) -> list[np.ndarray]:
    """The levels of the max-depth pyramid of uint64 colour keys (h, w): uint32 (h_l, w_l) each."""
    depth = (np.asarray(color_keys, np.uint64) >> np.uint64(32)).astype(np.uint32)
    out = []
    img = depth
    for w, h in pyramid_levels(depth.shape[1], depth.shape[0]):
        padded = np.zeros((2 * h, 2 * w), np.uint32)   # outside the image: 0, left out of the max
        padded[:img.shape[0], :img.shape[1]] = img
        img = padded.reshape(h, 2, w, 2).max(axis=(1, 3))
        out.append(img)
    return out


def occluded(bounds: np.ndarray, pyramid: list[np.ndarray], width: int, height: int, span: int) -> np.ndarray:
    """Twin of occluded(): bool per bound (float32 (n, 8): x0, y0, x1, y1, near); ``span``: the
    kernel's OCC_SPAN (occlusion.occlusion_span)."""
    b = np.asarray(bounds, F32)
    near = b[:, 4].view(np.uint32)
    with np.errstate(invalid="ignore"):
        x0 = np.clip(np.floor(b[:, 0]).astype(np.int64) - 1, 0, width - 1)
        x1 = np.clip(np.floor(b[:, 2]).astype(np.int64) + 1, 0, width - 1)
        y0 = np.clip(np.floor(b[:, 1]).astype(np.int64) - 1, 0, height - 1)
        y1 = np.clip(np.floor(b[:, 3]).astype(np.int64) + 1, 0, height - 1)
    out = np.zeros(len(b), bool)
    done = near == 0
    steps = np.arange(span)
    for level, tex in enumerate(pyramid):
        s = level + 1
        tx0, tx1, ty0, ty1 = x0 >> s, x1 >> s, y0 >> s, y1 >> s
        here = np.flatnonzero(~done & (tx1 - tx0 < span) & (ty1 - ty0 < span))
        # the box's texels (at most span x span; indices past its edge repeat the last one)
        tx = np.minimum(tx0[here, None] + steps, tx1[here, None])
        ty = np.minimum(ty0[here, None] + steps, ty1[here, None])
        m = tex[ty[:, :, None], tx[:, None, :]].max(axis=(1, 2)) if len(here) else np.zeros(0, np.uint32)
        out[here] = near[here] > m
        done[here] = True
    return out


def patch_bounds(render_list: np.ndarray, scene_inst, functions, cam, widen: float) -> np.ndarray:
    """Twin of patch_bound(): float32 (n, 8) bounds of the render patches (the kernel's float
    rounding may differ in the last bits)."""
    inst_f = scene_inst[0]
    cam = np.asarray(cam, F32).reshape(CAMERA.length)
    n = len(render_list)
    inst = render_list["inst"].astype(np.int64)
    u0, u1, v0, v1 = sampled_range(render_list, inst_f, widen)
    t = np.arange(GRID, dtype=F32) / F32(GRID - 1)
    u = u0[:, None, None] + (u1 - u0)[:, None, None] * t[None, None, :]
    v = v0[:, None, None] + (v1 - v0)[:, None, None] * t[None, :, None]
    u, v = np.broadcast_to(u, (n, GRID, GRID)), np.broadcast_to(v, (n, GRID, GRID))
    world, bad = world_positions(scene_inst, functions, np.broadcast_to(inst[:, None, None], u.shape), u, v)
    view = cam[0:16].reshape(4, 4)
    e = world @ view[:3, :3].T + view[:3, 3]
    edge = np.maximum(np.linalg.norm(np.diff(e, axis=2), axis=-1).max(axis=(1, 2)),
                      np.linalg.norm(np.diff(e, axis=1), axis=-1).max(axis=(1, 2)))
    lo, hi = e.min(axis=(1, 2)), e.max(axis=(1, 2))
    grow = edge + F32(1e-5) * np.maximum(np.linalg.norm(lo, axis=-1), np.linalg.norm(hi, axis=-1))
    lo, hi = lo - grow[:, None], hi + grow[:, None]
    near = -hi[:, 2]
    W, H = cam[CAMERA.offset("w")], cam[CAMERA.offset("h")]
    out = np.zeros((n, 8), F32)
    out[:, 2], out[:, 3] = W, H
    ok = ~bad.any(axis=(1, 2)) & (near > cam[CAMERA.offset("near")])
    corners = np.stack([np.where(np.array([k & 1, k & 2, k & 4]) != 0, hi, lo) for k in range(8)], axis=1)
    proj = cam[16:32].reshape(4, 4)
    c = corners @ proj[:, :3].T + proj[:, 3]
    with np.errstate(invalid="ignore", divide="ignore"):
        x = (c[..., 0] / c[..., 3] * F32(0.5) + F32(0.5)) * W
        y = (F32(0.5) - c[..., 1] / c[..., 3] * F32(0.5)) * H
    out[ok, 0], out[ok, 1] = x[ok].min(axis=1), y[ok].min(axis=1)
    out[ok, 2], out[ok, 3] = x[ok].max(axis=1), y[ok].max(axis=1)
    out[ok, 4] = near[ok]
    return out
