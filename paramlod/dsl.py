"""Helpers for writing parametric functions: each builds sympy expressions, so whatever a plugin
writes with them compiles to every backend (OpenCL C, GLSL, numpy) and can be differentiated.

Scalars are sympy expressions (or numbers). Vectors are 3x1 ``sympy.Matrix`` objects; every helper
also accepts a plain 3-tuple or a numpy array of 3 numbers. Plain Python loops over a fixed range unroll while the function's
expressions are built, so ``sum(c[i] * u**i for i in range(4))`` is fine.

Branches: Python ``if`` on an expression that depends on u, v or a parameter cannot work (its truth
is only known at run time); use ``where(cond, a, b)`` instead.
"""
from __future__ import annotations

from math import comb
from typing import Callable, Sequence

import numpy as np
import sympy as sp

from paramlod.function.bindings import current_bindings, suspend_bindings
from paramlod.function.define import DSL_HELPERS

# the list lives with the definition code, whose error hints name these helpers
__all__ = list(DSL_HELPERS)


# --- named intermediate values ---------------------------------------------------------------------
def let(expr, name: str | None = None):
    """Compute ``expr`` once and refer to it by a new symbol (a local variable in the generated code).

    Inside a @parametric body, large functions built from shared pieces (recurrences, frames,
    normalized vectors) stay small: code generation, the numpy reference and the derivatives
    (forward mode, through each binding) all work on the bound pieces instead of one huge
    expression tree. Outside a body it returns ``expr`` unchanged. Vectors bind per component.
    """
    if _is_vec(expr):
        return sp.Matrix([let(e, name) for e in _vec(expr)])
    e = sp.sympify(expr)
    ctx = current_bindings()
    if ctx is None or e.is_Atom:
        return e
    suffix = f"_{name}" if name and name.isidentifier() else ""
    sym = sp.Symbol(f"b{len(ctx)}{suffix}", real=True)
    ctx.append((sym, e))
    return sym


# --- scalars -------------------------------------------------------------------------------------
def _elementwise(fn, *args):
    """Apply a scalar helper to vectors component by component (any argument may be a vector)."""
    vecs = [a for a in args if _is_vec(a)]
    if not vecs:
        return fn(*args)
    return sp.Matrix([fn(*[_vec(a)[i] if _is_vec(a) else a for a in args]) for i in range(3)])


def where(cond, a, b):
    """``a`` where ``cond`` holds, else ``b`` (a sympy Piecewise; prints as ``cond ? a : b``).

    ``cond`` is a relation such as ``u < pi / 2``; combine relations with ``&``, ``|`` and ``~``.
    """
    if cond is True or cond == sp.true:
        return a
    if cond is False or cond == sp.false:
        return b
    return _elementwise(lambda x, y: sp.Piecewise((x, cond), (y, True)), a, b)


def step(edge, x):
    """0 where x < edge, else 1 (GLSL's step)."""
    return _elementwise(lambda e, y: sp.Piecewise((sp.Integer(0), y < e), (sp.Integer(1), True)), edge, x)


def clamp(x, lo, hi):
    """x limited to [lo, hi]."""
    return _elementwise(lambda y, a, b: sp.Min(sp.Max(y, a), b), x, lo, hi)


def saturate(x):
    """x limited to [0, 1]."""
    return clamp(x, 0, 1)


def smoothstep(edge0, edge1, x):
    """Hermite step from 0 at ``edge0`` to 1 at ``edge1`` (GLSL's smoothstep)."""
    def one(e0, e1, y):
        s = clamp((y - e0) / (e1 - e0), 0, 1)
        return s * s * (3 - 2 * s)
    return _elementwise(one, edge0, edge1, x)


def mix(a, b, t):
    """Linear blend a*(1-t) + b*t of scalars or vectors."""
    if _is_vec(a) or _is_vec(b):
        a, b = _vec(a) if _is_vec(a) else sp.Matrix([a] * 3), _vec(b) if _is_vec(b) else sp.Matrix([b] * 3)
        return a + (b - a) * t
    return a + (b - a) * t


def fract(x):
    """x - floor(x), in [0, 1)."""
    return _elementwise(lambda y: y - sp.floor(y), x)


def mod(x, y):
    """x - y*floor(x/y): the result has the sign of y (GLSL's mod, Python's %)."""
    return _elementwise(lambda a, b: a - b * sp.floor(a / b), x, y)


# --- vectors -------------------------------------------------------------------------------------
def _is_vec(a) -> bool:
    if isinstance(a, sp.MatrixBase):
        return len(a) == 3
    if isinstance(a, np.ndarray):
        return a.shape == (3,)
    return isinstance(a, (tuple, list)) and len(a) == 3


def _vec(a) -> sp.Matrix:
    if isinstance(a, sp.MatrixBase):
        if len(a) != 3:
            raise ValueError(f"expected a 3-vector, got a {a.shape[0]}x{a.shape[1]} matrix")
        return sp.Matrix(list(a))
    if _is_vec(a):
        return sp.Matrix([sp.sympify(x) for x in (a.tolist() if isinstance(a, np.ndarray) else a)])
    raise ValueError(f"expected a 3-vector (vec3(...), a 3-tuple, a 3x1 Matrix or a numpy array of 3), got {a!r}")


def vec3(x, y=None, z=None) -> sp.Matrix:
    """A 3-vector: ``vec3(x, y, z)``, ``vec3(s)`` = (s, s, s), or ``vec3((x, y, z))``."""
    if y is None and z is None:
        if _is_vec(x):
            return _vec(x)
        return sp.Matrix([x, x, x])
    if y is None or z is None:
        raise ValueError("vec3 takes one value or three")
    return sp.Matrix([x, y, z])


def dot(a, b):
    a, b = _vec(a), _vec(b)
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross(a, b) -> sp.Matrix:
    a, b = _vec(a), _vec(b)
    return sp.Matrix([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def length(a):
    return sp.sqrt(dot(a, a))


def normalize(a) -> sp.Matrix:
    a = let(_vec(a))
    return let(a * let(1 / length(a)))


def rotate(v, axis, angle) -> sp.Matrix:
    """``v`` rotated by ``angle`` (radians, right-handed) about ``axis`` (Rodrigues' formula).

    The axis need not be unit length; it is normalized here.
    """
    v, k = let(_vec(v)), normalize(axis)
    c, s = let(sp.cos(angle)), let(sp.sin(angle))
    return v * c + cross(k, v) * s + k * (dot(k, v) * (1 - c))


# --- curves --------------------------------------------------------------------------------------
def _points(points) -> list:
    pts = [(_vec(p) if _is_vec(p) else sp.sympify(p)) for p in points]
    if len(pts) < 2:
        raise ValueError("a Bezier curve needs at least two control points")
    return pts


def bezier(points: Sequence, t):
    """Bezier curve of degree len(points) - 1 at ``t`` in [0, 1] (Bernstein form).

    Control points are scalars or 3-vectors; the result has the same kind.
    """
    pts = _points(points)
    n = len(pts) - 1
    terms = [p * (comb(n, i) * t ** i * (1 - t) ** (n - i)) for i, p in enumerate(pts)]
    out = terms[0]
    for term in terms[1:]:
        out = out + term
    return out


def bezier_derivative(points: Sequence, t, order: int = 1):
    """The ``order``-th derivative d^k/dt^k of ``bezier(points, t)``, as a lower-degree Bezier curve."""
    pts = _points(points)
    for _ in range(order):
        n = len(pts) - 1
        if n == 0:
            return pts[0] * 0
        pts = [(pts[i + 1] - pts[i]) * n for i in range(n)]
    if len(pts) == 1:
        return pts[0]
    return bezier(pts, t)


def _curve_derivatives(curve, t):
    """(c(t), c'(t), c''(t)) for a callable curve or an expression vector in the symbol ``t``."""
    if callable(curve):
        s = sp.Dummy("s", real=True)
        with suspend_bindings():  # the curve's expression is differentiated and rewritten below
            c = _vec(curve(s))
        d1 = c.diff(s)
        d2 = d1.diff(s)
        sub = {s: t}
        return c.xreplace(sub), d1.xreplace(sub), d2.xreplace(sub)
    if not isinstance(t, sp.Symbol):
        raise ValueError("frenet_frame/tube: when the curve is an expression, t must be the symbol it "
                         "depends on; pass a callable curve(s) to evaluate it at an expression")
    c = _vec(curve)
    d1 = c.diff(t)
    return c, d1, d1.diff(t)


def frenet_frame(curve, t):
    """Unit tangent, normal and binormal (T, N, B) of a space curve at ``t``.

    ``curve`` is a callable ``curve(s) -> vec3`` (evaluated at any expression ``t``) or a vector
    expression in the symbol ``t``. Undefined where the curve is straight (c'' parallel to c').
    """
    _, d1, d2 = _curve_derivatives(curve, t)
    d1, d2 = let(d1), let(d2)
    tangent = normalize(d1)
    binormal = normalize(cross(d1, d2))
    return tangent, let(cross(binormal, tangent)), binormal


def tube(curve, t, angle, radius):
    """Point at ``angle`` on the circle of ``radius`` around ``curve`` at ``t`` (Frenet frame):
    c(t) + radius * (cos(angle) N + sin(angle) B). ``radius`` may depend on t or the angle."""
    c, _, _ = _curve_derivatives(curve, t)
    _, n, b = frenet_frame(curve, t)
    return let(c) + (n * sp.cos(angle) + b * sp.sin(angle)) * let(radius)


# --- noise ---------------------------------------------------------------------------------------
# The lattice hash is the permutation polynomial ((34 x + 1) x) mod 289 on integers. Every value stays
# an integer below 2^22 and every reduction mod 289 is exact in float32, so float32 (OpenCL, GLSL)
# and float64 (numpy) give identical hashes; a sin-based hash would not, because it amplifies
# rounding differences. Each reduced value is bound with ``let`` so that sympy cannot fold the
# divisions by 289 into larger, inexact products.
_P = 289


def _mod289(x):
    """x mod 289 for an integer-valued x (|x| < 2^24), exact in float32: the first step may be off by
    one period (x/289 is rounded); the second, on a value in [-289, 578), cannot be (the +1/2 keeps
    the quotient at least 1/578 away from an integer)."""
    r = let(x - _P * sp.floor((x + sp.Rational(1, 2)) / _P))
    return let(r - _P * sp.floor((r + sp.Rational(1, 2)) / _P))


def _permute(x):
    return _mod289((34 * x + 1) * x)   # x in [0, 289): (34 x + 1) x < 2^22


def hash01(i, j=0, k=0):
    """A pseudo-random value in [0, 1) (a multiple of 1/289) for integer lattice coordinates."""
    h = _permute(_mod289(_permute(_mod289(_permute(_mod289(i)) + _mod289(j))) + _mod289(k)))
    return h / _P


def _fade(f):
    return f * f * f * (f * (f * 6 - 15) + 10)  # quintic: C2 continuous across cells


def noise(x, y=0, z=0):
    """Value noise in [-1, 1]: smooth (C2), period 289 in each coordinate, exact same values on every
    backend. Pass a vec3 as ``x`` or up to three scalars. Use it inside a @parametric body, where
    its pieces are bound with ``let``; outside one the plain expression tree is very large."""
    if _is_vec(x):
        x, y, z = _vec(x)
    coords = [let(c) for c in (x, y, z)]
    cells = [let(sp.floor(c)) for c in coords]
    fr = [c - i for c, i in zip(coords, cells)]
    w = [let(_fade(f)) for f in fr]
    # trilinear blend of the 8 corner values; a coordinate that is a constant needs no blend
    def corner(dx, dy, dz):
        return let(hash01(cells[0] + dx, cells[1] + dy, cells[2] + dz))
    def lerp(a, b, s):
        return a + (b - a) * s
    xs = [[lerp(corner(0, dy, dz), corner(1, dy, dz), w[0]) for dy in (0, 1)] for dz in (0, 1)]
    ys = [lerp(xs[dz][0], xs[dz][1], w[1]) for dz in (0, 1)]
    return 2 * lerp(ys[0], ys[1], w[2]) - 1


def fbm(x, y=0, z=0, octaves: int = 4, lacunarity: float = 2.0, gain: float = 0.5):
    """Fractal sum of ``octaves`` noise layers (unrolled), roughly in [-1, 1]."""
    if _is_vec(x):
        x, y, z = _vec(x)
    total, amp, freq, norm = 0, 1.0, 1.0, 0.0
    for o in range(int(octaves)):
        # offset each octave so the layers do not share lattice points
        total = total + amp * noise(x * freq + 17 * o, y * freq + 31 * o, z * freq + 7 * o)
        norm += amp
        amp *= gain
        freq *= lacunarity
    return total / norm


def _curve_helpers() -> dict[str, Callable]:
    """Name -> helper (every name of ``__all__``)."""
    return {n: globals()[n] for n in __all__}
