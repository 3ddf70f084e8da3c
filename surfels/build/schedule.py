"""What the sampler (sampler.py, on the device) and its numpy twin (reference.py) share: the
64-bit sample key (float32 squared radius << 32 | pixel index) and the round and level schedule.
Host code only (numpy; scipy's k-d tree for pair_survivors), so the twin runs without a device;
both import it, neither imports the other."""
from __future__ import annotations

import numpy as np

ALL_ONES = np.uint64(0xFFFFFFFFFFFFFFFF)
HI = np.uint64(0xFFFFFFFF00000000)

THRESHOLD = 0.75            # candidates under this fraction of the largest radius wait
SPLAT_SLACK = 1.001         # Voronoi discs are splatted with this much more than the covering radius^2

# Coarse-to-fine levels: while the radius is large, rounds run on G-buffers point-subsampled by a
# stride (every stride-th pixel of every stride-th row), which costs 1/stride^2 of a full round and
# samples just as evenly while the radius spans many of their pixels.
MAX_STRIDE = 8
MIN_LEVEL_RESOLUTION = 32   # a level has at least this many pixels per side
SWITCH_PIXELS = 8.0         # a level hands over when the largest radius drops under this many of its pixels


# --- keys ---------------------------------------------------------------------------------------
def f32_bits(x) -> np.ndarray:
    return np.asarray(x, np.float32).view(np.uint32).astype(np.uint64)


def key_r2(key) -> np.ndarray:
    """The float32 squared radius in a key's high half."""
    return (np.asarray(key, np.uint64) >> np.uint64(32)).astype(np.uint32).view(np.float32)


def key_pixel(key) -> np.ndarray:
    return (np.asarray(key, np.uint64) & np.uint64(0xFFFFFFFF)).astype(np.int64)


def dist2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Squared distances in float32 in the kernels' order: (dx*dx + dy*dy) + dz*dz."""
    a = np.asarray(a, np.float32)
    b = np.asarray(b, np.float32)
    d = a[..., :3] - b[..., :3]
    return (d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1]) + d[..., 2] * d[..., 2]


# --- rounds -------------------------------------------------------------------------------------
def threshold_r2(r2max, fraction=THRESHOLD) -> np.float32:
    return np.float32(r2max) * np.float32(fraction * fraction)


def splat_r2(r2max, slack=SPLAT_SLACK) -> np.float32:
    return np.float32(r2max) * np.float32(slack)


def kd_tree(points):
    """scipy's cKDTree of ``points``. scipy.spatial is imported on first use: importing it took
    0.4 s, which every start of the command line paid (the CLI imports the sampler)."""
    from scipy.spatial import cKDTree

    return cKDTree(points)


def pair_survivors(cand: np.ndarray, pos: np.ndarray, thr2) -> tuple[np.ndarray, int]:
    """The conflict removal of one round from the candidates' pairs: (the survivors' keys in site
    order, 0 for the others; the eligible count). Candidate B is dropped when an eligible A with
    a larger key has B's pixel strictly inside its disc (float32 dist2 < A's squared radius):
    exactly the pixels A's conflict_splat reaches, so the same survivors as conflict_splat +
    survive (the twin's and the kernels') without splatting a disc into every view. ``pos``: the
    G-buffer's positions (float32 (pixels, 4)); a k-d tree finds the pairs, then the exact test."""
    r2 = key_r2(cand)
    ok = (r2 >= np.float32(thr2)) & (r2 > 0)
    idx = np.flatnonzero(ok)
    out = np.zeros(len(cand), np.uint64)
    if not len(idx):
        return out, 0
    keys, r2k = cand[idx], r2[idx]
    p = pos[key_pixel(keys), :3]
    # float64 distances within the largest radius, widened past float32 rounding of dist2
    reach = float(np.sqrt(np.float64(r2k.max()))) * (1 + 1e-5)
    i, j = kd_tree(p.astype(np.float64)).query_pairs(reach, output_type="ndarray").T
    d2 = dist2(p[i], p[j])
    dropped = np.zeros(len(idx), bool)
    dropped[j[(keys[i] > keys[j]) & (d2 < r2k[i])]] = True
    dropped[i[(keys[j] > keys[i]) & (d2 < r2k[j])]] = True
    out[idx[~dropped]] = keys[~dropped]
    return out, len(idx)


def compact_sort(out: np.ndarray) -> np.ndarray:
    """Survivor keys (non-zero entries of ``out``) in site order, then stably sorted by decreasing
    radius: what the device's copy_if + radix sort produce (and the host path on CPU devices)."""
    s = out[out != 0]
    hi = (s >> np.uint64(32)).astype(np.uint32)
    return s[np.argsort(~hi, kind="stable")]


def auto_resolution(n: int) -> int:
    """G-buffer resolution for n surfels when none is given: the smallest of 64, 128, 256, 384, 512
    with at least 1.2 sqrt(n) pixels per side, else 512: 128 up to 11,377 surfels, 256 up to
    45,511, 384 up to 102,400 (on the bunny about 1.5 pixels per final spacing at 10k; the
    relaxation moves surfels off the pixel grid, and fewer pixels make the G-buffers and rounds
    cheaper; relax.auto_iterations gives coarse G-buffers more iterations)."""
    for r in (64, 128, 256, 384):
        if r >= 1.2 * np.sqrt(n):
            return r
    return 512


# --- levels -------------------------------------------------------------------------------------
def level_strides(resolution: int) -> list[int]:
    """Strides from coarse to fine, ending with 1."""
    out = [s for s in (8, 4, 2) if s <= MAX_STRIDE and resolution % s == 0 and resolution // s >= MIN_LEVEL_RESOLUTION]
    return out + [1]


def stop_r2(stride: int, pixel_size: float) -> np.float32:
    return np.float32((SWITCH_PIXELS * stride * pixel_size) ** 2)


def resume_radii(r2, tries: int = 8):
    """Squared splat radii for handing samples to a finer level: r2, 4 r2, 16 r2, ..., then all."""
    r2 = np.float32(r2)
    for _ in range(tries):
        yield r2
        r2 = np.float32(r2 * np.float32(4.0))
    yield np.float32(np.inf)


def handover_r2(r2max, coarse_stride: int, pixel_size: float) -> np.float32:
    """First splat radius^2 at the finer level: the coarse covering radius plus two coarse pixels."""
    return np.float32((float(np.sqrt(np.float32(r2max))) + 2.0 * coarse_stride * pixel_size) ** 2)


def remap_keys(keys: np.ndarray, shape, stride_from: int, stride_to: int) -> np.ndarray:
    """Sample keys of a level with ``stride_from`` as keys of the level with ``stride_to``
    (``shape`` = (K, H, W) of the full-resolution G-buffer)."""
    k, h, w = shape
    hf, wf = h // stride_from, w // stride_from
    ht, wt = h // stride_to, w // stride_to
    f = stride_from // stride_to
    q = key_pixel(keys)
    layer, rest = np.divmod(q, hf * wf)
    y, x = np.divmod(rest, wf)
    q2 = (layer * ht + y * f) * wt + x * f
    return (np.asarray(keys, np.uint64) & HI) | q2.astype(np.uint64)
