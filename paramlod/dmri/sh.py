"""SH bookkeeping, the one copy: coefficient counts, orders, degrees, sampled bases, evaluation and
basis conversion of real, even-band spherical-harmonic series.

Convention (shared with ``functions/sh_glyph.py`` and dipy): theta is the polar angle from +z, phi
the azimuth from +x; even l only; coefficients in dipy's order, l = 0, 2, ..., order and m = -l..l,
index l(l+1)/2 + m; (order+1)(order+2)/2 of them (1, 6, 15, 28, 45, 66, 91 for orders 0..12). The
project's canonical basis is dipy's **non-legacy descoteaux07**:

* ``descoteaux07``: m > 0: sqrt2 Im(Y_l^m); m = 0: Y_l^0; m < 0: sqrt2 Re(Y_l^m);
* ``tournier07`` (MRtrix3): m > 0: sqrt2 Re(Y_l^m); m = 0: Y_l^0; m < 0: sqrt2 Im(Y_l^|m|).

Imports numpy only at module level: scipy (``sh_matrix``) and dipy (the legacy bases) are imported
when first needed, so the ``sh_glyph`` plugin can use this module without the ``dmri`` extra.
"""
from __future__ import annotations

import math
import warnings
from functools import lru_cache

import numpy as np

from paramlod.errors import DmriError, FunctionError

CANONICAL_BASIS = "descoteaux07"
BASES = ("descoteaux07", "tournier07")
SH_ORDERS = (0, 2, 4, 6, 8, 10, 12)
MAX_ORDER = 12


class ShError(DmriError, FunctionError):
    """A coefficient count, order or basis that is not a supported SH set. Both a DmriError (for
    ``paramlod.dmri``) and a FunctionError (for the ``sh_glyph`` plugin's parameters), since the
    two share this bookkeeping."""


# --- counts, orders, degrees ---------------------------------------------------------------------

def coefficient_count(order: int) -> int:
    """(order+1)(order+2)/2: 1, 6, 15, 28, 45, 66, 91 for orders 0..12."""
    return (order + 1) * (order + 2) // 2


def sh_index(l: int, m: int) -> int:
    """Position of (l, m) in the coefficient vector (dipy's ordering, even l only)."""
    return l * (l + 1) // 2 + m


def order_for_count(n: int) -> int | None:
    """The even order whose basis has ``n`` coefficients, or None."""
    for order in SH_ORDERS:
        if coefficient_count(order) == n:
            return order
    return None


def allowed_counts() -> str:
    """The supported coefficient counts with their orders, for error messages."""
    return ", ".join(f"{coefficient_count(o)} (order {o})" for o in SH_ORDERS)


def order_of(n: int) -> int:
    """The even order whose basis has ``n`` coefficients; ShError if there is none."""
    order = order_for_count(n)
    if order is None:
        raise ShError(f"{n} coefficients is not a full even-band SH set; allowed: {allowed_counts()}")
    return order


def check_order(order) -> int:
    """``order`` if it is a supported even order (0..12), else ShError."""
    if order not in SH_ORDERS:
        raise ShError(f"SH order must be one of {SH_ORDERS}, got {order!r}")
    return order


def check_basis(basis: str) -> str:
    """``basis`` if it is one of BASES, else ShError."""
    if basis not in BASES:
        raise ShError(f"unknown SH basis {basis!r}; use 'descoteaux07' (dipy) or 'tournier07' (MRtrix3)")
    return basis


def sh_degrees(order: int) -> tuple[np.ndarray, np.ndarray]:
    """(l, m) of each coefficient in dipy's order: l = 0, 2, .., order; m = -l..l."""
    ls, ms = [], []
    for l in range(0, order + 1, 2):
        for m in range(-l, l + 1):
            ls.append(l)
            ms.append(m)
    return np.array(ls), np.array(ms)


def pad_to_order(coeffs, order: int = MAX_ORDER) -> np.ndarray:
    """Zero-pad [..., n] coefficients to ``order`` (lower bands come first in dipy's ordering)."""
    c = np.asarray(coeffs, dtype=np.float64)
    have = order_of(c.shape[-1])
    if have > order:
        raise ShError(f"{c.shape[-1]} coefficients (order {have}) do not fit order {order}")
    out = np.zeros(c.shape[:-1] + (coefficient_count(order),))
    out[..., :c.shape[-1]] = c
    return out


# --- directions ----------------------------------------------------------------------------------

def fibonacci_sphere(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` near-uniform unit vectors and their (theta, phi)."""
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    phi = np.mod(k * math.pi * (3 - math.sqrt(5)), 2 * math.pi)
    theta = np.arccos(z)
    s = np.sin(theta)
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1), theta, phi


def cart_to_angles(xyz) -> tuple[np.ndarray, np.ndarray]:
    """(theta, phi) of the directions [..., 3] (need not be unit length)."""
    xyz = np.asarray(xyz, dtype=np.float64)
    r = np.linalg.norm(xyz, axis=-1)
    theta = np.arccos(np.clip(xyz[..., 2] / np.where(r > 0, r, 1), -1, 1))
    phi = np.mod(np.arctan2(xyz[..., 1], xyz[..., 0]), 2 * math.pi)
    return theta, phi


# --- evaluation (numpy and scipy) ----------------------------------------------------------------

def _complex_sh(l, m, theta, phi):
    """Complex orthonormal Y_l^m (Condon-Shortley phase), theta polar, phi azimuth."""
    import scipy.special as sps

    if hasattr(sps, "sph_harm_y"):          # scipy >= 1.15
        return sps.sph_harm_y(l, m, theta, phi)
    return sps.sph_harm(m, l, phi, theta)   # older scipy: (order, degree, azimuth, polar)


def sh_matrix(order: int, theta, phi) -> np.ndarray:
    """Canonical basis (non-legacy descoteaux07) sampled at the directions: [P, n_coeffs].

    m > 0: sqrt2 Im(Y_l^m); m = 0: Y_l^0; m < 0: sqrt2 Re(Y_l^m) (m itself, not |m|).
    """
    check_order(order)
    theta = np.asarray(theta, dtype=np.float64).reshape(-1, 1)
    phi = np.asarray(phi, dtype=np.float64).reshape(-1, 1)
    l, m = sh_degrees(order)
    y = _complex_sh(l[None, :], m[None, :], theta, phi)
    return np.where(m > 0, math.sqrt(2) * y.imag, np.where(m == 0, y.real, math.sqrt(2) * y.real))


def sh_evaluate(coeffs, theta, phi) -> np.ndarray:
    """Values of canonical-basis SH series [..., n] at P directions: [..., P]."""
    c = np.asarray(coeffs, dtype=np.float64)
    return c @ sh_matrix(order_of(c.shape[-1]), theta, phi).T


# --- basis conversion ----------------------------------------------------------------------------

def convert_basis(coeffs, source: str, target: str) -> np.ndarray:
    """Coefficients of the same function in the other non-legacy basis (descoteaux07 <-> tournier07),
    exactly (a signed permutation; numpy only). Works on the last axis, so a whole [..., n] array
    converts at once. For the legacy bases use ``to_canonical`` / ``from_canonical``."""
    check_basis(source)
    check_basis(target)
    c = np.asarray(coeffs, dtype=np.float64)
    if source == target:
        return c.copy()
    order = order_of(c.shape[-1])
    out = c.copy()
    for l in range(2, order + 1, 2):
        for m in range(1, l + 1):
            pos, neg = sh_index(l, m), sh_index(l, -m)
            if source == "descoteaux07":   # sin part: D[l,+m] -> T[l,-m]; cos part: (-1)^m D[l,-m] -> T[l,+m]
                out[..., neg], out[..., pos] = c[..., pos], (-1) ** m * c[..., neg]
            else:
                out[..., pos], out[..., neg] = c[..., neg], (-1) ** m * c[..., pos]
    return out


def require_dipy():
    """dipy's ``dipy.reconst.shm``, or a DmriError naming the extra to install (nibabel is checked
    here too, so the message names both)."""
    try:
        import dipy.reconst.shm as shm
        import nibabel  # noqa: F401
    except ImportError as e:
        raise DmriError("diffusion-MRI support needs dipy and nibabel: pip install 'paramlod[dmri]' "
                        f"({e})") from None
    return shm


def dipy_basis_matrix(order: int, basis: str, legacy: bool, theta, phi) -> np.ndarray:
    """dipy's real SH basis ``basis`` (legacy or not) sampled at the directions: [P, n]."""
    check_basis(basis)
    shm = require_dipy()
    fn = shm.real_sh_descoteaux if basis == "descoteaux07" else shm.real_sh_tournier
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # dipy warns that the legacy bases are deprecated
        B, m, l = fn(order, np.asarray(theta, np.float64), np.asarray(phi, np.float64), legacy=legacy)
    want_l, want_m = sh_degrees(order)
    if not (np.array_equal(l, want_l) and np.array_equal(m, want_m)):
        raise DmriError(f"dipy's {basis} basis has an unexpected coefficient order")  # dipy changed?
    return np.asarray(B, np.float64)


@lru_cache(maxsize=None)
def conversion_matrix(order: int, source: str, legacy: bool = False) -> np.ndarray:
    """K with c_canonical = K @ c_source, for dipy's ``source`` basis (``legacy`` as dipy means it).

    Found by least squares between dipy's basis functions on 1200 directions, so it holds for any
    pair of bases spanning the even bands (for the orthonormal ones K is a signed permutation).
    """
    xyz, theta, phi = fibonacci_sphere(1200)
    b_src = dipy_basis_matrix(order, source, legacy, theta, phi)
    b_can = dipy_basis_matrix(order, CANONICAL_BASIS, False, theta, phi)
    K, *_ = np.linalg.lstsq(b_can, b_src, rcond=None)
    K[np.abs(K) < 1e-12] = 0.0
    K.setflags(write=False)
    return K


def _sh_set(coeffs, basis: str) -> tuple[np.ndarray, int]:
    """(coefficients as float64, their order), checking the basis name and the count."""
    check_basis(basis)
    c = np.asarray(coeffs, dtype=np.float64)
    return c, order_of(c.shape[-1])


def to_canonical(coeffs, basis: str, legacy: bool = False) -> np.ndarray:
    """Coefficients [..., n] in dipy's ``basis`` -> the canonical non-legacy descoteaux07."""
    c, order = _sh_set(coeffs, basis)
    if basis == CANONICAL_BASIS and not legacy:
        return c.copy()
    return c @ conversion_matrix(order, basis, bool(legacy)).T


def from_canonical(coeffs, basis: str, legacy: bool = False) -> np.ndarray:
    """Inverse of ``to_canonical``."""
    c, order = _sh_set(coeffs, basis)
    if basis == CANONICAL_BASIS and not legacy:
        return c.copy()
    return c @ np.linalg.inv(conversion_matrix(order, basis, bool(legacy))).T
