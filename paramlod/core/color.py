"""sRGB on the host: the one copy of the transfer curve in Python (numpy only).

The device copies are ``encode_srgb8`` in kernels/points/subsamples.cl (through ``srgb_tables``)
and the shading in kernels/common/keys.cl; their numpy twins call the functions here.

Two encoders share the curve and differ only in the precision of the arithmetic, which matters:
on float32 input the two disagree by one code on 203 of the 1,065,353,217 float32 values in
[0, 1] (e.g. 0.00015176348 -> 1 in float32, 0 in float64), so each caller keeps the one whose
bits it has always produced:

- ``linear_to_srgb8``: in the input's own precision (float32 for a float32 Frame); ``Frame.rgb8``.
- ``linear_to_srgb8_f64``: in float64 whatever the input; the surfel sampler and the prefix
  renderer's twin. ``linear_rgba_to_srgb8_f64`` adds an alpha channel that stays linear.
"""
from __future__ import annotations

import numpy as np

LIN_BITS = 24   # fixed-point scale of linear colour in the resolve: 9 x 2^24 fits in 32 bits


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """sRGB values in [0, 1] to linear, float64."""
    c = np.asarray(c, np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_to_srgb8(c: np.ndarray) -> np.ndarray:
    """Linear values to 8-bit sRGB codes (every channel given; clamped to [0, 1]; rounded half
    up), computed in the input's precision: float32 in, float32 arithmetic."""
    c = np.clip(c, 0.0, 1.0)
    s = np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)
    return (s * 255.0 + 0.5).astype(np.uint8)


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
