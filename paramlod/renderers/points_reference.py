"""numpy reference of the local-framebuffer point renderer (kernels/points_lfb.cl), for small scenes.

Given the samples the kernel evaluated (its PL_RECORD hook: each sample's global subsample index
and its colour and attribute keys), it repeats the algorithm with numpy: the padded screen box of
each patch and the tiles it touches, per-tile patch lists, the local framebuffers (a sample is kept
only when its patch is listed for the tile it lands in, smallest key wins), and the integer
resolve. The result must equal the kernel's key buffers bit for bit. ``resolve_blocks`` (the
per-pixel resolve, kernels/subsamples.cl) is also the twin of the supersampled direct variant's
downsample.
"""
from __future__ import annotations

import numpy as np

from paramlod.core.color import LIN_BITS, srgb_tables  # noqa: F401  (the twin's tables)
from paramlod.renderers.points_lfb import tile_grid

CLEAR = np.uint64(0xFFFFFFFFFFFFFFFF)
def encode_srgb8(x: np.ndarray, thr: np.ndarray) -> np.ndarray:
    """Twin of encode_srgb8() in subsamples.cl."""
    return (np.searchsorted(thr, np.asarray(x, np.uint32), side="right") - 1).astype(np.uint32)


def tile_rects(render_list: np.ndarray, width: int, height: int, margin: float, widen: float,
               tile: int = 16) -> np.ndarray:
    """Twin of tile_rect() in points_lfb.cl: int32 [n, 4] inclusive tile rectangles
    (x0, y0, x1, y1); (0, 0, -1, -1) for a patch that touches no tile."""
    f32 = np.float32
    tiles_x, tiles_y = tile_grid(width, height, tile)
    box = render_list["bbox"].astype(f32)
    ext = render_list["ext"].astype(f32)
    W, H, T = f32(width), f32(height), f32(tile)
    with np.errstate(invalid="ignore", over="ignore"):
        pad = f32(margin) + np.fmax(ext[:, 2], ext[:, 3]) * (f32(1) / f32(7) + f32(widen))
        unbounded = ~(pad < f32(np.inf))
        x0, y0 = box[:, 0] - pad, box[:, 1] - pad
        x1, y1 = box[:, 2] + pad, box[:, 3] + pad
        valid = (box[:, 0] <= box[:, 2]) & (box[:, 1] <= box[:, 3])
        off = (x1 < 0) | (y1 < 0) | (x0 >= W) | (y0 >= H)
        place = unbounded | (valid & ~off)
        x0 = np.where(unbounded, f32(0), np.fmax(x0, f32(0)))
        y0 = np.where(unbounded, f32(0), np.fmax(y0, f32(0)))
        x1 = np.where(unbounded, W, np.fmin(x1, W))
        y1 = np.where(unbounded, H, np.fmin(y1, H))
        out = np.zeros((len(render_list), 4), np.int64)
        for col, (v, lim) in enumerate(((x0, tiles_x), (y0, tiles_y), (x1, tiles_x), (y1, tiles_y))):
            t = np.floor(np.where(place, v, f32(0)) / T)
            out[:, col] = np.minimum(t.astype(np.int64), lim - 1)
    out[~place] = (0, 0, -1, -1)
    return out.astype(np.int32)


def tile_lists(rects: np.ndarray, width: int, height: int, tile: int = 16):
    """Per-tile patch lists from the rectangles: (counts uint32 [tiles], offsets uint32 [tiles]
    = exclusive scan of counts, pairs uint32 [total] = patch ids, each tile's ids ascending)."""
    tiles_x, tiles_y = tile_grid(width, height, tile)
    tiles, pids = [], []
    for pid, (x0, y0, x1, y1) in enumerate(np.asarray(rects)):
        if x1 < x0:
            continue
        ys, xs = np.mgrid[y0:y1 + 1, x0:x1 + 1]
        tiles.append((ys * tiles_x + xs).reshape(-1))
        pids.append(np.full(xs.size, pid))
    tiles = np.concatenate(tiles) if tiles else np.zeros(0, np.int64)
    pids = np.concatenate(pids) if pids else np.zeros(0, np.int64)
    order = np.lexsort((pids, tiles))
    counts = np.bincount(tiles, minlength=tiles_x * tiles_y).astype(np.uint32)
    offsets = (np.cumsum(counts, dtype=np.uint64) - counts).astype(np.uint32)
    return counts, offsets, pids[order].astype(np.uint32)


def lfb_keys(rects: np.ndarray, sample_patch: np.ndarray, sub: np.ndarray, key: np.ndarray,
             aux: np.ndarray, width: int, height: int, ss: int, tile: int = 16):
    """The key buffers the local-framebuffer renderer produces from cleared buffers.

    Per sample: its patch id, its global subsample index (row-major over (height*ss, width*ss),
    0xFFFFFFFF when not drawable), its colour and attribute keys. Returns (colour, aux) uint64
    (height, width) and a dict of the counts that do not depend on execution order."""
    side = tile * ss
    SW, SH = width * ss, height * ss
    sub = np.asarray(sub, np.uint32)
    drawable = sub != np.uint32(0xFFFFFFFF)
    s = sub[drawable].astype(np.int64)
    p = np.asarray(sample_patch)[drawable]
    k = np.asarray(key, np.uint64)[drawable]
    a = np.asarray(aux, np.uint64)[drawable]
    sx, sy = s % SW, s // SW
    stx, sty = sx // side, sy // side
    r = np.asarray(rects)[p]
    kept = (stx >= r[:, 0]) & (stx <= r[:, 2]) & (sty >= r[:, 1]) & (sty <= r[:, 3])
    lc = np.full(SW * SH, CLEAR, np.uint64)
    la = np.full(SW * SH, CLEAR, np.uint64)
    np.minimum.at(lc, s[kept], k[kept])
    np.minimum.at(la, s[kept], a[kept])
    color, auxo, cnt = resolve_blocks(lc, la, width, height, ss)
    stats = {"pixels": int(np.count_nonzero(cnt)), "covered": int(cnt.sum()),
             # a sample lands in one tile, which renders it once if it lists the sample's patch
             "hits": int(np.count_nonzero(kept)), "bbox_miss": int(np.count_nonzero(~kept))}
    return color, auxo, stats


def resolve_blocks(color_ss: np.ndarray, aux_ss: np.ndarray, width: int, height: int, ss: int):
    """Twin of resolve_subsamples() in kernels/subsamples.cl over whole buffers: the colour and aux
    keys of (height*ss, width*ss) subsamples (any shape of that size) -> (colour, aux) uint64
    (height, width) and the covered subsamples per pixel. A pixel's colour is the average of its
    covered subsamples' colours in linear light, alpha the coverage, depth the nearest's."""
    lin, thr = srgb_tables()

    def blocks(a):
        a = np.asarray(a, np.uint64).reshape(height, ss, width, ss)
        return a.transpose(0, 2, 1, 3).reshape(height, width, ss * ss)

    lc, la = blocks(color_ss), blocks(aux_ss)
    cov = lc != CLEAR
    cnt = cov.sum(axis=-1).astype(np.uint64)
    low = lc & np.uint64(0xFFFFFFFF)
    safe = np.maximum(cnt, 1)
    half = cnt >> np.uint64(1)
    rgba = np.zeros((height, width), np.uint64)
    for shift in (24, 16, 8):
        ch = ((low >> np.uint64(shift)) & np.uint64(255)).astype(np.int64)
        total = np.where(cov, lin[ch].astype(np.uint64), np.uint64(0)).sum(axis=-1)
        rgba |= encode_srgb8((total + half) // safe, thr).astype(np.uint64) << np.uint64(shift)
    n2 = ss * ss
    rgba |= (cnt * np.uint64(255) + np.uint64(n2 // 2)) // np.uint64(n2)
    kmin = lc.min(axis=-1)
    color = np.where(cnt > 0, (kmin & np.uint64(0xFFFFFFFF00000000)) | rgba, CLEAR).astype(np.uint64)
    aux = np.where(cnt > 0, la.min(axis=-1), CLEAR).astype(np.uint64)
    return color, aux, cnt


def resolve_image(color_keys: np.ndarray, background_code) -> np.ndarray:
    """Twin of the image of resolve() in kernels/points/resolve.cl: colour keys (h, w) -> sRGB8 RGB
    (h, w, 3) over the background (its sRGB8 codes), blended in linear fixed point."""
    lin, thr = srgb_tables()
    k = np.asarray(color_keys, np.uint64)
    rgba = (k & np.uint64(0xFFFFFFFF)).astype(np.uint32)
    al = (rgba & 255).astype(np.uint64)
    out = np.empty((*k.shape, 3), np.uint8)
    for c in range(3):
        code = (rgba >> np.uint32(24 - 8 * c)) & 255
        bg = np.uint64(background_code[c])
        mixed = (lin[code].astype(np.uint64) * al + np.uint64(lin[int(bg)]) * (255 - al) + 127) // 255
        value = np.where(al == 255, code, encode_srgb8(mixed.astype(np.uint32), thr))
        out[..., c] = np.where(k == CLEAR, np.uint32(bg), value)
    return out


def upsample_keys(color: np.ndarray, aux: np.ndarray, ratio: int):
    """Twin of upsample_keys() in kernels/subsamples.cl: (colour, aux) keys (height, width) ->
    (height * ratio, width * ratio), each key copied into its ratio x ratio block."""
    def up(a):
        return np.repeat(np.repeat(np.asarray(a, np.uint64), ratio, axis=0), ratio, axis=1)
    return up(color), up(aux)
