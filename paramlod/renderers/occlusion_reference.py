"""numpy twin of kernels/points/occlusion.cl: the depth pyramid, the occlusion test (both exact),
the tiles of a patch's grid (exact) and their bounds (float32, to rounding)."""
from __future__ import annotations

import numpy as np

from paramlod.core.layouts import CAMERA
from paramlod.lod.reference import sampled_range, world_positions
from paramlod.renderers.occlusion import NODES, TILE, TILES, pyramid_levels
from paramlod.renderers.sampling import MEASURE_BOUNDARY, PointSettings, grid_axes, patch_measures

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


def occluded(bounds: np.ndarray, pyramid: list[np.ndarray], width: int, height: int) -> np.ndarray:
    """Twin of occluded(): bool per bound (float32 (n, 8): x0, y0, x1, y1, near)."""
    b = np.asarray(bounds, F32)
    near = b[:, 4].view(np.uint32)
    with np.errstate(invalid="ignore"):
        x0 = np.clip(np.floor(b[:, 0]).astype(np.int64) - 1, 0, width - 1)
        x1 = np.clip(np.floor(b[:, 2]).astype(np.int64) + 1, 0, width - 1)
        y0 = np.clip(np.floor(b[:, 1]).astype(np.int64) - 1, 0, height - 1)
        y1 = np.clip(np.floor(b[:, 3]).astype(np.int64) + 1, 0, height - 1)
    out = np.zeros(len(b), bool)
    done = near == 0
    for level, tex in enumerate(pyramid):
        s = level + 1
        tx0, tx1, ty0, ty1 = x0 >> s, x1 >> s, y0 >> s, y1 >> s
        here = ~done & (tx1 - tx0 <= 1) & (ty1 - ty0 <= 1)
        m = np.maximum(np.maximum(tex[ty0[here], tx0[here]], tex[ty0[here], tx1[here]]),
                       np.maximum(tex[ty1[here], tx0[here]], tex[ty1[here], tx1[here]]))
        out[here] = near[here] > m
        done |= here
    return out


def tiles_along(n: np.ndarray, most: int = TILES) -> np.ndarray:
    """Twin of tiles_along() in points.cl: tiles a side for ``n`` grid lines, at most ``most``
    (the device's PL_OCC_TILES, DirectPointRenderer.occlusion_tiles)."""
    return np.clip(-(-np.asarray(n, np.int64) // TILE), 1, most)


def tile_grids(render_list: np.ndarray, inst_f, settings: PointSettings, most: int = TILES) -> dict:
    """Twin of the grids point_grid() samples (float32 to rounding) and of their tiles (exact):
    per render patch and direction ("u", "v"), the grid lines' first and last parameter, strip
    and middle steps, counts (lines, strip steps) and tiles; the settings' measure with boundary
    strips, as the direct variant samples; at most ``most`` tiles a side."""
    code = settings.measure(True)
    m = patch_measures(render_list, code)
    ext = render_list["ext"]
    ends = sampled_range(render_list, inst_f, settings.widen)
    out = {}
    for k, axis in enumerate("uv"):
        n, na, nm = grid_axes(ext[:, 2 + k], m[:, k], int(code) == MEASURE_BOUNDARY, settings)
        x0, x1 = ends[2 * k], ends[2 * k + 1]
        span = (x1 - x0).astype(F32)
        strip = (span * F32(1.0 / 7.0)).astype(F32)
        with np.errstate(divide="ignore", invalid="ignore"):
            a = np.where(na > 0, strip / np.maximum(na, 1).astype(F32), F32(0)).astype(F32)
            mid = np.where(na > 0, (span - F32(2) * strip) / np.maximum(nm, 1).astype(F32),
                           span / np.maximum(n - 1, 1).astype(F32)).astype(F32)
        out[axis] = {"x0": x0, "x1": x1, "a": a, "m": mid, "n": n, "na": na, "tiles": tiles_along(n, most)}
    return out


def grid_at(ax: dict, i: np.ndarray) -> np.ndarray:
    """Twin of grid_at() in points.cl: parameter of grid line ``i`` (one per patch) of axis ``ax``."""
    x0, x1, a, m, n, na = ax["x0"], ax["x1"], ax["a"], ax["m"], ax["n"], ax["na"]
    i = np.asarray(i, np.int64)
    uniform = x0 + m * i.astype(F32)
    first = x0 + a * i.astype(F32)
    last = x1 - a * (n - 1 - i).astype(F32)
    middle = (x0 + a * na.astype(F32)) + m * (i - na).astype(F32)
    return np.where(na == 0, uniform, np.where(i <= na, first, np.where(i + na >= n - 1, last, middle))).astype(F32)


def tile_spans(ax: dict, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The parameters a tile's bound spans along an axis (tile ``k`` of each patch): from the line
    before its first to the line after its last, clamped to the grid (occlusion.cl grid_line)."""
    n, t = ax["n"], ax["tiles"]
    lo = np.maximum(k * n // t - 1, 0)
    hi = np.minimum((k + 1) * n // t, n - 1)
    return grid_at(ax, lo), grid_at(ax, hi)


def tile_bounds(render_list: np.ndarray, scene_inst, functions, cam, settings: PointSettings,
                most: int = TILES) -> np.ndarray:
    """Twin of tile_bound(): float32 (n, TILES², 8) bounds of every tile of the render patches
    (slot ty * tu + tx; slots past a patch's tiles zero; the kernel's float rounding may differ in
    the last bits)."""
    inst_f = scene_inst[0]
    cam = np.asarray(cam, F32).reshape(CAMERA.length)
    grids = tile_grids(render_list, inst_f, settings, most)
    n = len(render_list)
    out = np.zeros((n, TILES * TILES, 8), F32)
    W, H = cam[CAMERA.offset("w")], cam[CAMERA.offset("h")]
    view, proj = cam[0:16].reshape(4, 4), cam[16:32].reshape(4, 4)
    t = np.arange(NODES, dtype=F32) / F32(NODES - 1)
    gu, gv = grids["u"], grids["v"]
    for slot in range(TILES * TILES):
        has = slot < gu["tiles"] * gv["tiles"]
        if not has.any():
            continue
        p = np.flatnonzero(has)
        sub = {axis: {key: val[p] for key, val in grids[axis].items()} for axis in "uv"}
        tx, ty = slot % sub["u"]["tiles"], slot // sub["u"]["tiles"]
        u0, u1 = tile_spans(sub["u"], tx)
        v0, v1 = tile_spans(sub["v"], ty)
        m = len(p)
        u = np.broadcast_to(u0[:, None, None] + (u1 - u0)[:, None, None] * t[None, None, :], (m, NODES, NODES))
        v = np.broadcast_to(v0[:, None, None] + (v1 - v0)[:, None, None] * t[None, :, None], (m, NODES, NODES))
        inst = np.broadcast_to(render_list["inst"][p].astype(np.int64)[:, None, None], u.shape)
        world, bad = world_positions(scene_inst, functions, inst, u, v)
        e = world @ view[:3, :3].T + view[:3, 3]
        edge = np.maximum(np.linalg.norm(np.diff(e, axis=2), axis=-1).max(axis=(1, 2)),
                          np.linalg.norm(np.diff(e, axis=1), axis=-1).max(axis=(1, 2)))
        lo, hi = e.min(axis=(1, 2)), e.max(axis=(1, 2))
        grow = edge + F32(1e-5) * np.maximum(np.linalg.norm(lo, axis=-1), np.linalg.norm(hi, axis=-1))
        lo, hi = lo - grow[:, None], hi + grow[:, None]
        near = -hi[:, 2]
        b = np.zeros((m, 8), F32)
        b[:, 2], b[:, 3] = W, H
        ok = ~bad.any(axis=(1, 2)) & (near > cam[CAMERA.offset("near")])
        corners = np.stack([np.where(np.array([k & 1, k & 2, k & 4]) != 0, hi, lo) for k in range(8)], axis=1)
        c = corners @ proj[:, :3].T + proj[:, 3]
        with np.errstate(invalid="ignore", divide="ignore"):
            x = (c[..., 0] / c[..., 3] * F32(0.5) + F32(0.5)) * W
            y = (F32(0.5) - c[..., 1] / c[..., 3] * F32(0.5)) * H
        b[ok, 0], b[ok, 1] = x[ok].min(axis=1), y[ok].min(axis=1)
        b[ok, 2], b[ok, 3] = x[ok].max(axis=1), y[ok].max(axis=1)
        b[ok, 4] = near[ok]
        out[p, slot] = b
    return out
