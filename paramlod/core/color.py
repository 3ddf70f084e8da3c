"""sRGB, the one copy: the transfer curve on the host (numpy only) and what the device gets of it.

The device reads everything of sRGB from here: ``cl_tables()`` (part of the OpenCL prelude,
``paramlod.core.layouts.cl_prelude``) emits ``srgb8_decoded()`` as the ``SRGB8_DECODED`` table that
the resolve in kernels/points/resolve.cl looks codes up in, and ``srgb8_thresholds()`` as the
``SRGB8_THRESHOLDS`` table and ``srgb8_bucket_codes()`` as the ``SRGB8_BUCKET_CODES`` table that
``srgb8()`` in kernels/common/keys.cl encodes with; ``srgb_tables()``
are uploaded for the integer encoder ``encode_srgb8`` in kernels/points/subsamples.cl
(paramlod.renderers.targets). The tessellation shaders write linear colour; the GL resolve encodes
the image with ``linear_to_srgb8_buckets()``, the host's ``linear_to_srgb8`` bit for bit. The
numpy twins of the kernels call the functions here.

Two encoders share the curve and differ only in the precision of the arithmetic, which matters:
on float32 input the two disagree by one code on 203 of the 1,065,353,217 float32 values in
[0, 1] (e.g. 0.00015176348 -> 1 in float32, 0 in float64), so each caller keeps the one whose
bits it has always produced:

- ``linear_to_srgb8``: in the input's own precision (float32 for a float32 Frame); ``Frame.rgb8``.
- ``linear_to_srgb8_f64``: in float64 whatever the input; the surfel sampler and the prefix
  renderer's twin. ``linear_rgba_to_srgb8_f64`` adds an alpha channel that stays linear.
"""
from __future__ import annotations

import functools

import numpy as np

_ONE_BITS = 0x3F800000   # 1.0f
LIN_BITS = 24   # fixed-point scale of linear colour in the resolve: 9 x 2^24 fits in 32 bits

# The curve (IEC 61966-2-1). Python floats, so that float32 arrays stay float32 in the arithmetic.
SRGB_DECODE_CUTOFF = 0.04045     # encoded values at or below it are linear / SRGB_SLOPE
SRGB_ENCODE_CUTOFF = 0.0031308   # linear values at or below it are encoded x SRGB_SLOPE
SRGB_SLOPE = 12.92
SRGB_OFFSET = 0.055
SRGB_SCALE = 1.055               # 1 + SRGB_OFFSET (kept as its own literal: its float32 is not 1 + 0.055f)
SRGB_GAMMA = 2.4


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """sRGB values in [0, 1] to linear, float64."""
    c = np.asarray(c, np.float64)
    return np.where(c <= SRGB_DECODE_CUTOFF, c / SRGB_SLOPE, ((c + SRGB_OFFSET) / SRGB_SCALE) ** SRGB_GAMMA)


def linear_to_srgb8(c: np.ndarray) -> np.ndarray:
    """Linear values to 8-bit sRGB codes (every channel given; clamped to [0, 1]; rounded half
    up), computed in the input's precision: float32 in, float32 arithmetic."""
    c = np.clip(c, 0.0, 1.0)
    s = np.where(c <= SRGB_ENCODE_CUTOFF, SRGB_SLOPE * c, SRGB_SCALE * np.power(c, 1 / SRGB_GAMMA) - SRGB_OFFSET)
    return (s * 255.0 + 0.5).astype(np.uint8)


@functools.lru_cache(maxsize=None)
def linear_to_srgb8_thresholds() -> np.ndarray:
    """float32 [255]: element k - 1 is the smallest float32 x with ``linear_to_srgb8(x)`` >= k, so
    the count of elements <= x is ``linear_to_srgb8(x)`` of a float32 x, bit for bit (checked for
    every float32 in [0, 1]: the encoder is monotone there; below 0 both give 0, above 1 both 255)."""
    codes = np.arange(1, 256)
    lo, hi = np.zeros(255, np.int64), np.full(255, _ONE_BITS, np.int64)   # bit patterns of 0.0 and 1.0
    while np.any(lo < hi):   # bisection over the bit patterns, which order non-negative floats
        mid = (lo + hi) // 2
        up = linear_to_srgb8(mid.astype(np.uint32).view(np.float32)) >= codes
        lo, hi = np.where(up, lo, mid + 1), np.where(up, mid, hi)
    return hi.astype(np.uint32).view(np.float32)


SRGB8_BUCKETS = 4096   # [0, 1] in buckets of 1/4096: each holds at most one of the 255 thresholds


@functools.lru_cache(maxsize=None)
def linear_to_srgb8_buckets() -> np.ndarray:
    """float32 [SRGB8_BUCKETS, 2]: for bucket i, the values [i, i + 1) / SRGB8_BUCKETS, the code of
    its start and the one threshold inside it (2.0 where none is), so that for a float32 x in
    [0, 1], with i = min(floor(x * SRGB8_BUCKETS), SRGB8_BUCKETS - 1) (exact: a power of two),
    code[i] + (x >= threshold[i]) is ``linear_to_srgb8(x)`` bit for bit: one table read where a
    search of ``linear_to_srgb8_thresholds()`` takes several (the tess resolve's image)."""
    thr = linear_to_srgb8_thresholds()
    starts = (np.arange(SRGB8_BUCKETS) / SRGB8_BUCKETS).astype(np.float32)
    out = np.stack([linear_to_srgb8(starts).astype(np.float32), np.full(SRGB8_BUCKETS, 2.0, np.float32)], axis=1)
    inside = thr > starts[np.floor(thr.astype(np.float64) * SRGB8_BUCKETS).astype(int)]   # not at a start
    buckets = np.floor(thr[inside].astype(np.float64) * SRGB8_BUCKETS).astype(int)
    if len(np.unique(buckets)) != len(buckets):
        raise AssertionError("two sRGB thresholds share a bucket: make SRGB8_BUCKETS larger")
    out[buckets, 1] = thr[inside]
    return out


def linear_to_srgb8_f64(c: np.ndarray) -> np.ndarray:
    """``linear_to_srgb8`` with the arithmetic in float64 whatever the input's precision."""
    return linear_to_srgb8(np.asarray(c, np.float64))


def linear_rgba_to_srgb8_f64(rgba: np.ndarray) -> np.ndarray:
    """(..., 4) linear RGB + alpha to uint8 (..., 4): RGB through ``linear_to_srgb8_f64``, alpha
    linearly (clamped, x 255, rounded half up, in the input's precision), not through the curve."""
    out = np.empty(rgba.shape[:-1] + (4,), np.uint8)
    out[..., :3] = linear_to_srgb8_f64(rgba[..., :3])
    out[..., 3] = (np.clip(rgba[..., 3], 0, 1) * 255 + 0.5).astype(np.uint8)
    return out


def srgb_tables() -> tuple[np.ndarray, np.ndarray]:
    """(lin, thr), uint32 [256] each: lin[c] = linear value of sRGB code c in 2^-24 units;
    thr[c] = linear value of code c - 1/2 (thr[0] = 0), so encoding x gives the largest c with
    thr[c] <= x, the nearest code in sRGB space."""
    scale = float(1 << LIN_BITS)
    codes = np.arange(256, dtype=np.float64)
    lin = np.rint(srgb_to_linear(codes / 255.0) * scale).astype(np.uint32)
    thr = np.rint(srgb_to_linear(np.maximum(codes - 0.5, 0.0) / 255.0) * scale).astype(np.uint32)
    thr[0] = 0
    return lin, thr


def srgb8_thresholds() -> np.ndarray:
    """float32 [256]: the linear value at which each sRGB 8-bit code begins (code k from
    (k - 1/2) / 255 in sRGB, decoded in float64), entry 0 below every input (-1). The largest k
    with t[k] <= x is the code that rounding the exact curve gives: ``srgb8()`` in keys.cl
    searches it instead of calling pow(x, 1/2.4), which dominated the point renderer's
    per-sample cost on CPUs."""
    codes = np.arange(256, dtype=np.float64)
    t = srgb_to_linear(np.maximum(codes - 0.5, 0.0) / 255.0).astype(np.float32)
    t[0] = -1.0
    return t


@functools.lru_cache(maxsize=None)
def srgb8_bucket_codes() -> np.ndarray:
    """uint8 [SRGB8_BUCKETS]: the code ``srgb8()`` gives at the start of each bucket of [0, 1]
    (value i / SRGB8_BUCKETS, the count of ``srgb8_thresholds()[1:]`` at or below it). Each
    bucket's inside holds at most one threshold, so for x in bucket i the code is this one, plus 1
    where x reaches the next threshold: one table read and one comparison (keys.cl ``srgb8``)
    where the search of the thresholds took eight."""
    thr = srgb8_thresholds()[1:].astype(np.float64)
    starts = np.arange(SRGB8_BUCKETS, dtype=np.float64) / SRGB8_BUCKETS
    codes = np.searchsorted(thr, starts, side="right")
    if np.any(np.searchsorted(thr, starts + 1.0 / SRGB8_BUCKETS, side="left") - codes > 1):
        raise AssertionError("two sRGB thresholds share a bucket: make SRGB8_BUCKETS larger")
    return codes.astype(np.uint8)


def srgb8_decoded() -> np.ndarray:
    """float32 [256]: the linear value of each sRGB 8-bit code (decoded in float64, rounded once).
    The resolve looks codes up here instead of calling pow(x, 2.4) per channel: pow was a third of
    a 640 x 640 resolve on PoCL (2-core AMD EPYC)."""
    return srgb_to_linear(np.arange(256, dtype=np.float64) / 255.0).astype(np.float32)


def _cl_float(x) -> str:
    """An OpenCL float literal that parses back to the same float32 (shortest round trip)."""
    return np.format_float_positional(np.float32(x), unique=True, trim="0") + "f"


def cl_tables() -> str:
    """The sRGB part of the OpenCL prelude: SRGB8_DECODED, SRGB8_THRESHOLDS, SRGB8_BUCKETS and
    SRGB8_BUCKET_CODES."""
    lines = ["// sRGB (paramlod/core/color.py): each 8-bit code's linear value, the encoder's thresholds",
             "// and its code at the start of each of SRGB8_BUCKETS buckets of [0, 1]",
             f"#define SRGB8_BUCKETS {SRGB8_BUCKETS}"]
    for name, table in (("SRGB8_DECODED", srgb8_decoded()), ("SRGB8_THRESHOLDS", srgb8_thresholds())):
        t = [_cl_float(x) for x in table]
        lines.append(f"__constant float {name}[256] = {{")
        lines += ["    " + ", ".join(t[i:i + 8]) + "," for i in range(0, 256, 8)]
        lines.append("};")
    codes = [str(c) for c in srgb8_bucket_codes()]
    lines.append("__constant uchar SRGB8_BUCKET_CODES[SRGB8_BUCKETS] = {")
    lines += ["    " + ",".join(codes[i:i + 32]) + "," for i in range(0, len(codes), 32)]
    lines.append("};")
    return "\n".join(lines)
