"""Parametric functions f(u, v) -> R^3 defined with sympy, and their numpy evaluation.

A function is written once as sympy expressions; code generation (``codegen``) turns the same
expressions into OpenCL C for the kernels and into numpy for the references, and the analytic
partial derivatives give the normals.
"""
from __future__ import annotations

import inspect
import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import Callable, Sequence

import numpy as np
import sympy as sp

from .errors import FunctionError


@dataclass(frozen=True)
class Param:
    """One parameter: a scalar, or an array of ``size`` floats (flattened into the parameter block)."""

    name: str
    default: np.ndarray  # float64, shape () for scalars or (size,)

    @property
    def size(self) -> int:
        return int(self.default.size)

    @property
    def is_array(self) -> bool:
        return self.default.ndim == 1


@dataclass
class ParametricFunction:
    """A surface f(u, v) over a rectangular domain, with named parameters."""

    name: str
    u_range: tuple[float, float]
    v_range: tuple[float, float]
    params: tuple[Param, ...]
    exprs: tuple[sp.Expr, sp.Expr, sp.Expr]
    u: sp.Symbol
    v: sp.Symbol
    param_symbols: tuple[sp.Symbol, ...]  # flattened, in parameter-block order
    source: str = "<unknown>"
    doc: str = ""
    python_function: Callable | None = field(default=None, repr=False)

    # --- parameters --------------------------------------------------------------------------
    @property
    def param_count(self) -> int:
        """Number of floats in this function's parameter block."""
        return len(self.param_symbols)

    def param_block(self, values: dict | None = None) -> np.ndarray:
        """Flatten ``values`` (missing names take their defaults) into a float32 parameter block."""
        values = dict(values or {})
        unknown = sorted(set(values) - {p.name for p in self.params})
        if unknown:
            known = ", ".join(p.name for p in self.params) or "none"
            raise FunctionError(
                f"function '{self.name}' has no parameter {', '.join(map(repr, unknown))} "
                f"(its parameters: {known})")
        out = []
        for p in self.params:
            val = values.get(p.name, p.default)
            arr = np.asarray(val, dtype=np.float64)
            if arr.shape != p.default.shape:
                want = "a number" if not p.is_array else f"{p.size} numbers"
                raise FunctionError(
                    f"function '{self.name}': parameter '{p.name}' needs {want}, got shape {arr.shape}")
            if not np.all(np.isfinite(arr)):
                raise FunctionError(f"function '{self.name}': parameter '{p.name}' is not finite: {val!r}")
            out.append(arr.reshape(-1))
        if not out:
            return np.zeros(0, np.float32)
        return np.concatenate(out).astype(np.float32)

    # --- symbolic derivatives ----------------------------------------------------------------
    @cached_property
    def du(self) -> tuple[sp.Expr, ...]:
        return tuple(sp.diff(e, self.u) for e in self.exprs)

    @cached_property
    def dv(self) -> tuple[sp.Expr, ...]:
        return tuple(sp.diff(e, self.v) for e in self.exprs)

    # --- numpy evaluation --------------------------------------------------------------------
    @cached_property
    def _np_position(self):
        return sp.lambdify((self.u, self.v, *self.param_symbols), list(self.exprs), "numpy", cse=True)

    @cached_property
    def _np_surface(self):
        return sp.lambdify((self.u, self.v, *self.param_symbols),
                           [*self.exprs, *self.du, *self.dv], "numpy", cse=True)

    def _call(self, fn, u, v, block):
        u = np.asarray(u, dtype=np.float64)
        v = np.asarray(v, dtype=np.float64)
        shape = np.broadcast_shapes(u.shape, v.shape)
        with np.errstate(all="ignore"):
            vals = fn(u, v, *[float(x) for x in np.asarray(block, np.float64)])
        return np.stack([np.broadcast_to(np.asarray(c, np.float64), shape) for c in vals], axis=-1)

    def evaluate(self, u, v, block: np.ndarray | None = None, **params) -> np.ndarray:
        """Positions f(u, v) with shape broadcast(u, v) + (3,), float64."""
        if block is None:
            block = self.param_block(params)
        return self._call(self._np_position, u, v, block)

    def surface(self, u, v, block: np.ndarray | None = None, **params):
        """(position, df/du, df/dv), each broadcast(u, v) + (3,), float64."""
        if block is None:
            block = self.param_block(params)
        out = self._call(self._np_surface, u, v, block)
        return out[..., 0:3], out[..., 3:6], out[..., 6:9]

    def normals(self, u, v, block: np.ndarray | None = None, **params) -> np.ndarray:
        """Unit normals df/du x df/dv (NaN where the surface is degenerate)."""
        _, fu, fv = self.surface(u, v, block, **params)
        n = np.cross(fu, fv)
        with np.errstate(all="ignore"):
            return n / np.linalg.norm(n, axis=-1, keepdims=True)


def _check_range(fname: str, axis: str, rng) -> tuple[float, float]:
    try:
        lo, hi = (float(sp.N(x)) for x in rng)
    except (TypeError, ValueError) as exc:
        raise FunctionError(f"function '{fname}': {axis} domain must be (lo, hi), got {rng!r}") from exc
    if not (math.isfinite(lo) and math.isfinite(hi)) or not lo < hi:
        raise FunctionError(f"function '{fname}': {axis} domain ({lo}, {hi}) is empty, reversed or not finite")
    return lo, hi


def _source_of(fn) -> str:
    try:
        return inspect.getsourcefile(fn) or fn.__module__
    except TypeError:
        return getattr(fn, "__module__", "<unknown>")


def parametric(u: Sequence[float] = (0.0, 1.0), v: Sequence[float] = (0.0, 1.0),
               params: dict | None = None, name: str | None = None):
    """Decorator: turn ``fn(u, v, **params) -> (x, y, z)`` of sympy symbols into a ParametricFunction.

    ``params`` maps each parameter name to its default: a number, or a sequence of numbers for an
    array parameter (the function then receives a list of symbols).
    """
    params = dict(params or {})

    def wrap(fn) -> ParametricFunction:
        fname = name or fn.__name__
        where = _source_of(fn)
        u_rng = _check_range(fname, "u", u)
        v_rng = _check_range(fname, "v", v)
        sig = inspect.signature(fn)
        names = list(sig.parameters)
        if len(names) < 2:
            raise FunctionError(f"function '{fname}' ({where}): signature must start with (u, v), got ({', '.join(names)})")
        extra = names[2:]
        missing = [n for n in extra if n not in params]
        if missing:
            raise FunctionError(f"function '{fname}' ({where}): parameter(s) {', '.join(missing)} have no default in params={{...}}")
        unused = [n for n in params if n not in extra]
        if unused:
            raise FunctionError(f"function '{fname}' ({where}): params {', '.join(unused)} are not arguments of the function")

        usym, vsym = sp.symbols("u v", real=True)
        plist, flat, kwargs = [], [], {}
        for pname in extra:
            default = np.asarray(params[pname], dtype=np.float64)
            if default.ndim > 1 or default.size == 0:
                raise FunctionError(f"function '{fname}' ({where}): parameter '{pname}' must be a number or a flat list")
            plist.append(Param(pname, default))
            if default.ndim == 0:
                sym = sp.Symbol(f"p_{pname}", real=True)
                flat.append(sym)
                kwargs[pname] = sym
            else:
                syms = [sp.Symbol(f"p_{pname}_{i}", real=True) for i in range(default.size)]
                flat.extend(syms)
                kwargs[pname] = syms
        try:
            result = fn(usym, vsym, **kwargs)
        except Exception as exc:  # the user's body failed while building expressions
            raise FunctionError(f"function '{fname}' ({where}): building its expressions failed: {exc}") from exc
        if not isinstance(result, (tuple, list, sp.Matrix)) or len(result) != 3:
            raise FunctionError(f"function '{fname}' ({where}) must return three expressions (x, y, z), got {result!r}")
        exprs = []
        for i, e in enumerate(result):
            try:
                e = sp.sympify(e)
            except sp.SympifyError as exc:
                raise FunctionError(f"function '{fname}' ({where}): component {'xyz'[i]} is not an expression: {e!r}") from exc
            if not isinstance(e, sp.Expr):
                raise FunctionError(f"function '{fname}' ({where}): component {'xyz'[i]} is not a scalar expression: {e!r}")
            stray = e.free_symbols - {usym, vsym, *flat}
            if stray:
                raise FunctionError(f"function '{fname}' ({where}): component {'xyz'[i]} uses unknown symbol(s) {sorted(map(str, stray))}")
            exprs.append(e)
        return ParametricFunction(
            name=fname, u_range=u_rng, v_range=v_rng, params=tuple(plist), exprs=tuple(exprs),
            u=usym, v=vsym, param_symbols=tuple(flat), source=where,
            doc=inspect.getdoc(fn) or "", python_function=fn)

    return wrap


def evaluate(fn_or_name, u, v, **params) -> np.ndarray:
    """Evaluate a parametric function (object or registered name) with numpy: shape (..., 3)."""
    from .registry import get_function

    fn = get_function(fn_or_name)
    return fn.evaluate(u, v, **params)
