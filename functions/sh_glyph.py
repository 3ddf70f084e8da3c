"""Spherical-harmonics glyphs: a sphere whose signed radius is a real, orthonormal, even-band SH
series (dissertation sections 5.4 and 5.6; Peters et al. 2023; anchors.md section 2).

Domain (shared with dipy and ARCHITECTURE.md): u = theta in [0, pi], the polar angle from +z;
v = phi in [0, 2 pi), the azimuth from +x; f(u, v) = r(theta, phi) (sin theta cos phi,
sin theta sin phi, cos theta) with signed r (negative lobes are drawn through the origin).
Coefficients are ordered as in dipy: for l = 0, 2, ..., order and m = -l..l, index l(l+1)/2 + m;
(order+1)(order+2)/2 of them (6, 15, 28, 45, 66, 91 for orders 2..12).

Bases, with dipy's non-legacy definitions (Y_l^m complex, with the Condon-Shortley phase):

* ``descoteaux07``: m > 0: sqrt2 Im(Y_l^m); m = 0: Y_l^0; m < 0: sqrt2 Re(Y_l^m);
* ``tournier07`` (MRtrix3): m > 0: sqrt2 Re(Y_l^m); m = 0: Y_l^0; m < 0: sqrt2 Im(Y_l^|m|).

Evaluation: fully normalized associated Legendre functions of cos(theta) by the standard stable
three-term recurrence in l for each m (no factorials, no large intermediate values), and
cos(m phi), sin(m phi) by repeated rotation, so the cost grows with the number of coefficients
and order 12 stays cheap. The per-m sums are formed first, so each Legendre value is used once.

Registered functions: ``sh_glyph`` (order 12, descoteaux07) and ``sh_glyph_tournier`` (order 12,
tournier07), each with one parameter, the array ``coeffs`` (91 floats, default: a glyph with a lobe
along z and a weaker one along x; ``pad_coefficients`` zero-pads
a shorter, lower-order set). ``make_sh_glyph(order, basis)`` builds a cheaper lower-order glyph.

The bookkeeping (counts, ``sh_index``, ``order_of``, ``pad_coefficients``, ``convert_basis``, the
bases and orders) is ``paramlod.dmri.sh``'s, re-exported here; this module holds only the symbolic
series the glyph is compiled from. Errors are ``ShError``, a FunctionError (and a DmriError).
"""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import sympy as sp

from paramlod import parametric
from paramlod.dmri.sh import check_basis, check_order, coefficient_count, sh_index
from paramlod.dmri.sh import BASES, SH_ORDERS as ORDERS, convert_basis, order_of  # noqa: F401 (re-exported)
from paramlod.dmri.sh import pad_to_order as pad_coefficients  # noqa: F401 (re-exported)
from paramlod.dsl import let


def _legendre(order: int, x, s) -> dict:
    """Fully normalized associated Legendre functions (Condon-Shortley phase) P[l, m] for
    0 <= m <= l <= order, as expressions in x = cos(theta), s = sin(theta)."""
    P = {(0, 0): sp.Float(math.sqrt(1 / (4 * math.pi)), 17)}
    for m in range(0, order + 1):
        if m > 0:
            P[m, m] = let(sp.Float(-math.sqrt((2 * m + 1) / (2 * m)), 17) * s * P[m - 1, m - 1])
        if m + 1 <= order:
            P[m + 1, m] = let(sp.Float(math.sqrt(2 * m + 3), 17) * x * P[m, m])
        for l in range(m + 2, order + 1):
            a = math.sqrt((4 * l * l - 1) / (l * l - m * m))
            b = math.sqrt(((l - 1) ** 2 - m * m) / (4 * (l - 1) ** 2 - 1))
            P[l, m] = let(sp.Float(a, 17) * (x * P[l - 1, m] - sp.Float(b, 17) * P[l - 2, m]))
    return P


def sh_radius(coeffs, theta, phi, order: int, basis: str):
    """The SH series r(theta, phi) as a sympy expression of the coefficient symbols."""
    check_basis(basis)
    x, s = let(sp.cos(theta)), let(sp.sin(theta))
    P = _legendre(order, x, s)
    c1, s1 = let(sp.cos(phi)), let(sp.sin(phi))
    cos_m, sin_m = sp.Integer(1), sp.Integer(0)
    sqrt2 = sp.Float(math.sqrt(2), 17)
    r = sum(coeffs[sh_index(l, 0)] * P[l, 0] for l in range(0, order + 1, 2))
    for m in range(1, order + 1):
        cos_m, sin_m = let(cos_m * c1 - sin_m * s1), let(sin_m * c1 + cos_m * s1)  # rotate by phi
        ls = [l for l in range(0, order + 1, 2) if l >= m]
        if not ls:
            continue
        if basis == "descoteaux07":
            a = sum((-1) ** m * coeffs[sh_index(l, -m)] * P[l, m] for l in ls)
            b = sum(coeffs[sh_index(l, m)] * P[l, m] for l in ls)
        else:
            a = sum(coeffs[sh_index(l, m)] * P[l, m] for l in ls)
            b = sum(coeffs[sh_index(l, -m)] * P[l, m] for l in ls)
        r = r + sqrt2 * (let(a) * cos_m + let(b) * sin_m)
    return let(r)


def default_coefficients(order: int) -> list[float]:
    """A recognisable default glyph: a fat lobe along z with a weaker crossing lobe along x."""
    c = np.zeros(coefficient_count(order))
    c[sh_index(0, 0)] = 1.0
    if order >= 2:
        c[sh_index(2, 0)] = 0.45
        c[sh_index(2, 2)] = 0.25
    if order >= 4:
        c[sh_index(4, 0)] = 0.3
        c[sh_index(4, 4)] = 0.2
    if order >= 6:
        c[sh_index(6, 0)] = 0.12
    return c.tolist()


@lru_cache(maxsize=None)
def make_sh_glyph(order: int = 12, basis: str = "descoteaux07", name: str | None = None):
    """An SH glyph function of even ``order`` (0..12) in ``basis``; cached, so equal arguments give
    the same object. Its parameter ``coeffs`` has (order+1)(order+2)/2 floats."""
    check_order(order)
    check_basis(basis)
    fname = name or f"sh_glyph_o{order}_{basis}"

    @parametric(u=(0, sp.pi), v=(0, 2 * sp.pi), params={"coeffs": default_coefficients(order)}, name=fname,
                periodic="v")
    def glyph(u, v, coeffs):
        """SH glyph: signed radius r(theta=u, phi=v) from even-band real SH coefficients."""
        r = sh_radius(coeffs, u, v, order, basis)
        rs = let(r * sp.sin(u))
        return rs * sp.cos(v), rs * sp.sin(v), r * sp.cos(u)

    glyph.doc = (f"SH glyph, order {order}, {basis} basis (dipy non-legacy): u = theta from +z, v = phi "
                 f"from +x; coeffs ({coefficient_count(order)} floats, dipy order).")
    return glyph


sh_glyph = make_sh_glyph(12, "descoteaux07", "sh_glyph")
sh_glyph_tournier = make_sh_glyph(12, "tournier07", "sh_glyph_tournier")
