"""Parametric functions f(u, v) -> R^3 defined with sympy, and their numpy evaluation.

A function is written once as sympy expressions; code generation (``codegen_cl``) turns the same
expressions into OpenCL C for the kernels and into numpy for the references, and the analytic
partial derivatives give the normals.

Two extras:

* the escape hatch: ``@parametric(..., snippet=CODE)`` takes the body as a snippet in the shared
  OpenCL/GLSL dialect (``kernels/README.md``); the decorated Python function is then its numpy
  reference and normals come from central differences;
* composite objects: ``parts=[Part(...)]`` places child functions in the parent's surface frame at
  given (u, v); ``ParametricFunction.expand_parts`` gives their transforms for one set of parameters.

Implicit time: a function argument named ``t`` that is not listed in ``params`` becomes a scalar
parameter ``t`` with default 0.0 (animate by changing it per frame).

Bindings: ``paramlod.dsl.let`` names intermediate results while the body runs. They are kept as an
ordered list of (symbol, expression) next to the three output expressions; derivatives are taken
in forward mode through them, and every backend prints them as local variables
(``ParametricFunction.program``). Large functions (SH glyphs of order 12, frames of curves) stay
small this way, instead of becoming one expression tree with many copies of shared pieces.
"""
from __future__ import annotations

import difflib
import inspect
import math
import re
import traceback
from contextlib import contextmanager
from dataclasses import dataclass, field
from functools import cached_property
from typing import Callable, Mapping, Sequence

import numpy as np
import sympy as sp

from paramlod.errors import FunctionError
from paramlod.function.bindings import collect_bindings

TIME = "t"            # the implicit time parameter's name
MAX_PART_DEPTH = 8    # parts of parts of ... (guards against a part that contains its parent)


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


@dataclass(frozen=True)
class Snippet:
    """A function body in the shared dialect (kernels/README.md) that returns the position."""

    code: str
    fd_step: tuple[float, float]  # central-difference steps in u and v for the partials


@dataclass(frozen=True, eq=False)
class Part:
    """A child object placed on its parent.

    ``function`` (a ParametricFunction or a registered name) is drawn with ``params`` and the
    4x4 ``transform`` given in the parent's surface frame at parameter ``at = (u, v)``: origin
    f(u, v), x = normalize(df/du), z = normalize(df/du x df/dv), y = z x x. Parent parameters named
    in ``inherit`` (default: the time ``t``) are passed on when the child has them and ``params``
    does not set them, so an animated parent animates its parts. ``color`` (linear RGB) overrides
    the parent's material colour; None keeps it.
    """

    function: object
    at: tuple[float, float]
    params: Mapping = field(default_factory=dict)
    transform: object = None
    color: tuple[float, float, float] | None = None
    inherit: tuple[str, ...] = (TIME,)
    name: str | None = None

    def __post_init__(self):
        try:
            m = np.eye(4) if self.transform is None else np.asarray(self.transform, dtype=np.float64)
        except (TypeError, ValueError):
            m = np.full((1,), np.nan)  # reported by the decorator with the plugin's name
        object.__setattr__(self, "transform", m)
        object.__setattr__(self, "params", dict(self.params))
        object.__setattr__(self, "inherit", tuple(self.inherit))

    @property
    def label(self) -> str:
        if self.name:
            return self.name
        f = self.function
        return f if isinstance(f, str) else getattr(f, "name", repr(f))


@dataclass
class PlacedPart:
    """One expanded part: what the scene draws for it this frame."""

    function: "ParametricFunction"
    params: dict
    transform: np.ndarray   # 4x4, parent's object space (or world, if a world transform was given)
    color: tuple[float, float, float] | None
    path: str               # e.g. "giant_worm/jaw_inner[1]/tooth[4]"


PERIODIC_LINES = 33         # points per edge compared by ParametricFunction.edge_gaps
PERIODIC_TOLERANCE = 1e-6   # of the largest coordinate on those edges (float32 rounding is 6e-8)
_periodic_checked = [True]   # False while the registry loads the built-ins (built_in_definitions)


@contextmanager
def built_in_definitions():
    """Definitions made inside do not check their periodic axes at the defaults: the registry's
    built-ins, whose claims tests/function/test_library.py checks, and wrap_flags again with each
    scene's values. Checking them at every start lambdified all fifteen (0.35 s on a 2-core EPYC)."""
    _periodic_checked[0] = False
    try:
        yield
    finally:
        _periodic_checked[0] = True


@dataclass(eq=False)
class ParametricFunction:
    """A surface f(u, v) over a rectangular domain, with named parameters."""

    name: str
    u_range: tuple[float, float]
    v_range: tuple[float, float]
    params: tuple[Param, ...]
    exprs: tuple[sp.Expr, sp.Expr, sp.Expr] | None  # None for snippet functions
    u: sp.Symbol
    v: sp.Symbol
    param_symbols: tuple[sp.Symbol, ...]  # flattened, in parameter-block order
    source: str = "<unknown>"
    doc: str = ""
    python_function: Callable | None = field(default=None, repr=False)
    line: int = 0
    parts: tuple[Part, ...] = ()
    # the axes over which f repeats ("u", "v"): f(u0, v) = f(u1, v) for "u"; a sampling grid that
    # spans the domain there skips its last line, a copy of the first (docs/writing-plugins.md)
    periodic: tuple[str, ...] = ()
    snippet: Snippet | None = None
    origin: str = ""  # where the registry found it: "built-in", "plugin folder ...", "entry point ..."
    # named intermediate results from paramlod.dsl.let, in evaluation order: (symbol, expression);
    # exprs (and du, dv) may refer to these symbols, so print them with ``program()``
    bindings: tuple[tuple[sp.Symbol, sp.Expr], ...] = ()

    def __repr__(self) -> str:
        kind = "snippet " if self.snippet is not None else ""
        return f"<{kind}ParametricFunction '{self.name}' from {self.where}>"

    @property
    def where(self) -> str:
        """``file:line`` of the definition, for messages."""
        return f"{self.source}:{self.line}" if self.line else self.source

    @property
    def is_snippet(self) -> bool:
        return self.snippet is not None

    @property
    def summary(self) -> str:
        return self.doc.strip().splitlines()[0] if self.doc.strip() else ""

    # --- parameters --------------------------------------------------------------------------
    @property
    def param_count(self) -> int:
        """Number of floats in this function's parameter block."""
        return len(self.param_symbols)

    def param_offsets(self) -> dict[str, int]:
        """Offset of each parameter in the block."""
        out, k = {}, 0
        for p in self.params:
            out[p.name] = k
            k += p.size
        return out

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
            if np.asarray(val).dtype.kind in "bSU":   # numpy would take "1" and True as numbers
                raise FunctionError(f"function '{self.name}': parameter '{p.name}' must be numbers, got {val!r}")
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

    def param_values(self, block: np.ndarray) -> dict:
        """The inverse of ``param_block``: name -> float or float64 array."""
        block = np.asarray(block, dtype=np.float64).reshape(-1)
        if block.size != self.param_count:
            raise FunctionError(f"function '{self.name}': parameter block has {block.size} floats, "
                                f"expected {self.param_count}")
        out, k = {}, 0
        for p in self.params:
            out[p.name] = block[k:k + p.size].copy() if p.is_array else float(block[k])
            k += p.size
        return out

    # --- symbolic derivatives ----------------------------------------------------------------
    def _need_exprs(self, what: str):
        if self.exprs is None:
            raise FunctionError(f"function '{self.name}' is a snippet function: it has no sympy "
                                f"expressions, so {what} is not available")

    @cached_property
    def _derivatives(self):
        """Forward-mode derivatives through the bindings: (derivative bindings, du, dv).

        For each binding s_k = e_k: ds_k/dx = de_k/dx + sum_j de_k/ds_j * ds_j/dx (x = u or v),
        itself bound to a new symbol, so shared intermediate results are differentiated once.
        """
        self._need_exprs("df/du and df/dv")
        names = {s for s, _ in self.bindings}
        new: list[tuple[sp.Symbol, sp.Expr]] = []
        outs = []
        for x in (self.u, self.v):
            dmap: dict[sp.Symbol, sp.Expr] = {}

            def total(e):
                free = e.free_symbols
                moving = [sj for sj in sorted(free & names, key=sp.default_sort_key) if dmap[sj] != 0]
                d = _diff(e, x, self) if x in free else sp.Integer(0)
                for sj in moving:
                    d = d + _diff(e, sj, self) * dmap[sj]
                return d

            for sk, ek in self.bindings:
                d = total(ek)
                if d.is_Atom:
                    dmap[sk] = d
                else:
                    ds = sp.Symbol(f"d{x}_{sk}", real=True)
                    new.append((ds, d))
                    dmap[sk] = ds
            outs.append(tuple(total(e) for e in self.exprs))
        return tuple(new), outs[0], outs[1]

    @property
    def du(self) -> tuple[sp.Expr, ...]:
        """df/du (may refer to the symbols of ``program("surface")``'s bindings)."""
        return self._derivatives[1]

    @property
    def dv(self) -> tuple[sp.Expr, ...]:
        return self._derivatives[2]

    def program(self, which: str = "position"):
        """(bindings, outputs) to evaluate in order: ``"position"`` gives the 3 coordinates,
        ``"surface"`` the 9 values position, df/du, df/dv. What every backend prints."""
        self._need_exprs("program()")
        if which == "position":
            return self.bindings, tuple(self.exprs)
        if which == "surface":
            dbind, du, dv = self._derivatives
            return self.bindings + dbind, (*self.exprs, *du, *dv)
        raise ValueError(f"program(): which must be 'position' or 'surface', got {which!r}")

    # --- parameter-only subexpressions, hoisted out of the per-sample device code ---------------
    @cached_property
    def hoisted(self) -> tuple:
        """((symbol, expr), ...): the subexpressions of the parameters alone that cost a function
        call, a division or a fractional power (a seashell's tan(alpha) and (a/b)**c). The device
        code reads them from the parameter block, after the parameters, computed once per instance
        on the host (``device_blocks``), instead of evaluating them for every sample
        (``device_program``). Empty for snippets."""
        if self.exprs is None:
            return ()
        params = set(self.param_symbols)
        found = {}

        def visit(e):
            if e.is_Atom or not isinstance(e, sp.Basic):
                return
            if (isinstance(e, sp.Expr) and e.free_symbols and e.free_symbols <= params
                    and any(isinstance(n, sp.Function) or (n.is_Pow and not (n.exp.is_Integer and n.exp > 0))
                            for n in sp.preorder_traversal(e))):
                found.setdefault(e, None)
                return
            for a in e.args:
                visit(a)

        for which in ("position", "surface"):
            bindings, outputs = self.program(which)
            for e in (*(b for _, b in bindings), *outputs):
                visit(e)
        return tuple((sp.Symbol(f"hp{i}", real=True), e) for i, e in enumerate(found))

    @property
    def block_size(self) -> int:
        """Floats of a device parameter block: the parameters, then the hoisted values."""
        return self.param_count + len(self.hoisted)

    def device_program(self, which: str = "position"):
        """``program(which)`` with the hoisted subexpressions replaced by their symbols: what the
        OpenCL and GLSL code evaluate per sample."""
        bindings, outputs = self.program(which)
        if not self.hoisted:
            return bindings, outputs
        sub = {e: sym for sym, e in self.hoisted}
        return (tuple((sym, e.xreplace(sub)) for sym, e in bindings), tuple(e.xreplace(sub) for e in outputs))

    @cached_property
    def _np_hoisted(self):
        return sp.lambdify(self.param_symbols, [e for _, e in self.hoisted], "numpy")

    def device_blocks(self, blocks) -> np.ndarray:
        """float32 device parameter blocks (``block_size`` floats) of parameter blocks (one, or
        [n, param_count]): the hoisted values appended, computed in float64."""
        blocks = np.asarray(blocks, np.float32)
        if not self.hoisted:
            return blocks
        rows = blocks.reshape(-1, self.param_count)
        with np.errstate(all="ignore"):
            vals = self._np_hoisted(*rows.astype(np.float64).T)
        extra = np.stack([np.broadcast_to(np.asarray(x, np.float64), (len(rows),)) for x in vals], axis=1)
        out = np.concatenate([rows, extra.astype(np.float32)], axis=1)
        return out if blocks.ndim == 2 else out.reshape(-1)

    # --- numpy evaluation --------------------------------------------------------------------
    def _lambdify(self, which: str):
        bindings, outputs = self.program(which)

        def cse(exprs):  # bindings first (in order), then sympy's CSE of the outputs
            repl, reduced = sp.cse(exprs, symbols=sp.numbered_symbols("_t"))
            return list(bindings) + repl, reduced

        return sp.lambdify((self.u, self.v, *self.param_symbols), list(outputs), "numpy", cse=cse)

    @cached_property
    def _np_position(self):
        return self._lambdify("position")

    @cached_property
    def _np_surface(self):
        return self._lambdify("surface")

    def _call(self, fn, u, v, block):
        u = np.asarray(u, dtype=np.float64)
        v = np.asarray(v, dtype=np.float64)
        shape = np.broadcast_shapes(u.shape, v.shape)
        with np.errstate(all="ignore"):
            vals = fn(u, v, *[float(x) for x in np.asarray(block, np.float64)])
        return np.stack([np.broadcast_to(np.asarray(c, np.float64), shape) for c in vals], axis=-1)

    def _reference(self, u, v, block):
        """The snippet's numpy reference at (u, v), shape broadcast(u, v) + (3,)."""
        u = np.asarray(u, dtype=np.float64)
        v = np.asarray(v, dtype=np.float64)
        shape = np.broadcast_shapes(u.shape, v.shape)
        with np.errstate(all="ignore"):
            vals = self.python_function(u, v, **self.param_values(block))
        return np.stack([np.broadcast_to(np.asarray(c, np.float64), shape) for c in vals], axis=-1)

    def evaluate(self, u, v, block: np.ndarray | None = None, **params) -> np.ndarray:
        """Positions f(u, v) with shape broadcast(u, v) + (3,), float64."""
        arrays = []   # converted once here; _call and _reference take float64 arrays as they are
        for name, x in (("u", u), ("v", v)):
            try:
                arrays.append(np.asarray(x, dtype=np.float64))
            except (TypeError, ValueError):
                raise FunctionError(f"evaluate '{self.name}': {name} must be numbers (a number or an array), "
                                    f"got {x!r}"[:300]) from None
        u, v = arrays
        if block is None:
            block = self.param_block(params)
        if self.is_snippet:
            return self._reference(u, v, block)
        return self._call(self._np_position, u, v, block)

    def edge_gaps(self, axis: str, blocks: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """How far apart the two edges a periodic ``axis`` joins lie ("v": f(u, v0) against
        f(u, v1)), at PERIODIC_LINES points across, for each parameter block (rows of ``blocks``):
        (gaps [k, PERIODIC_LINES], the most each block's gaps may be [k]: PERIODIC_TOLERANCE of the
        largest coordinate on its edges, the points across). Both NaN: no gap; one NaN: an
        infinite one."""
        blocks = np.atleast_2d(np.asarray(blocks, np.float64))
        t = np.linspace(0.0, 1.0, PERIODIC_LINES)
        (u0, u1), (v0, v1) = self.u_range, self.v_range
        across = (v0 + (v1 - v0) * t) if axis == "u" else (u0 + (u1 - u0) * t)
        ends = [(np.full_like(t, end), across) if axis == "u" else (across, np.full_like(t, end))
                for end in ((u0, u1) if axis == "u" else (v0, v1))]
        if self.is_snippet:   # the numpy reference takes named values: one block at a time
            a, b = (np.stack([self._reference(*e, blk) for blk in blocks]) for e in ends)
        else:                 # the lambdified position broadcasts the parameters' columns
            cols = [c[:, None] for c in blocks.T]
            shape = np.empty((len(blocks), PERIODIC_LINES))
            with np.errstate(all="ignore"):
                a, b = (np.stack(np.broadcast_arrays(*self._np_position(e[0][None], e[1][None], *cols), shape)[:3],
                                 axis=-1) for e in ends)
        with np.errstate(invalid="ignore"):
            gaps = np.linalg.norm(a - b, axis=-1)
            scale = np.nanmax(np.abs(np.concatenate([a, b], axis=1)), axis=(1, 2), initial=0.0)
        both_nan = np.isnan(a).any(-1) & np.isnan(b).any(-1)
        gaps = np.where(both_nan, 0.0, np.where(np.isnan(gaps), np.inf, gaps))
        return gaps, PERIODIC_TOLERANCE * np.maximum(scale, 1e-30), across

    def edges_meet(self, axis: str, blocks: np.ndarray) -> np.ndarray:
        """Per parameter block, whether f closes on itself over ``axis`` (every ``edge_gaps``
        within its limit)."""
        gaps, limit, _ = self.edge_gaps(axis, blocks)
        return np.all(gaps <= limit[:, None], axis=1)

    def surface(self, u, v, block: np.ndarray | None = None, **params):
        """(position, df/du, df/dv), each broadcast(u, v) + (3,), float64.

        Snippet functions use central differences with the snippet's steps (as the kernels do).
        """
        if block is None:
            block = self.param_block(params)
        if self.is_snippet:
            hu, hv = self.snippet.fd_step
            u = np.asarray(u, dtype=np.float64)
            v = np.asarray(v, dtype=np.float64)
            pos = self._reference(u, v, block)
            du = (self._reference(u + hu, v, block) - self._reference(u - hu, v, block)) / (2 * hu)
            dv = (self._reference(u, v + hv, block) - self._reference(u, v - hv, block)) / (2 * hv)
            return pos, du, dv
        out = self._call(self._np_surface, u, v, block)
        return out[..., 0:3], out[..., 3:6], out[..., 6:9]

    def normals(self, u, v, block: np.ndarray | None = None, **params) -> np.ndarray:
        """Unit normals df/du x df/dv (NaN where the surface is degenerate)."""
        _, fu, fv = self.surface(u, v, block, **params)
        n = np.cross(fu, fv)
        with np.errstate(all="ignore"):
            return n / np.linalg.norm(n, axis=-1, keepdims=True)

    def bounds(self, params: dict | None = None, samples: int = 33,
               parts: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounds (lo, hi) of the surface from a samples x samples grid (numpy), for
        framing a camera; NaN samples are ignored. With ``parts``, the parts' bounds are included."""
        uu, vv = np.meshgrid(np.linspace(*self.u_range, samples), np.linspace(*self.v_range, samples),
                             indexing="ij")
        p = self.evaluate(uu, vv, self.param_block(params)).reshape(-1, 3)
        p = p[np.all(np.isfinite(p), axis=1)]
        if not len(p):
            raise FunctionError(f"function '{self.name}' evaluates to NaN or infinity everywhere")
        lo, hi = p.min(axis=0), p.max(axis=0)
        if parts:
            for placed in self.expand_parts(params):
                plo, phi = placed.function.bounds(placed.params, max(5, samples // 3), parts=False)
                corners = np.array([[x, y, z, 1.0] for x in (plo[0], phi[0]) for y in (plo[1], phi[1])
                                    for z in (plo[2], phi[2])]) @ placed.transform.T
                lo, hi = np.minimum(lo, corners[:, :3].min(0)), np.maximum(hi, corners[:, :3].max(0))
        return lo, hi

    # --- composite objects -------------------------------------------------------------------
    def surface_frame(self, u, v, block: np.ndarray | None = None, **params) -> np.ndarray:
        """4x4 local frame(s) at (u, v): columns x, y, z, origin (see ``Part``).

        Shape broadcast(u, v) + (4, 4); NaN where df/du or the normal vanishes.
        """
        p, fu, fv = self.surface(u, v, block, **params)
        with np.errstate(all="ignore"):
            x = fu / np.linalg.norm(fu, axis=-1, keepdims=True)
            z = np.cross(fu, fv)
            z = z / np.linalg.norm(z, axis=-1, keepdims=True)
        y = np.cross(z, x)
        m = np.zeros(p.shape[:-1] + (4, 4))
        m[..., :3, 0], m[..., :3, 1], m[..., :3, 2], m[..., :3, 3] = x, y, z, p
        m[..., 3, 3] = 1.0
        return m

    def expand_parts(self, params: dict | None = None, transform=None, *, _depth: int = 0,
                     _path: str | None = None) -> list[PlacedPart]:
        """All parts (recursively) for one set of this function's parameters, with transforms
        ``transform @ frame(at) @ part.transform`` (``transform`` defaults to the identity).

        Call it every frame: frames are recomputed from the current parameters (for example ``t``).
        """
        if not self.parts:
            return []
        path = _path or self.name
        if _depth >= MAX_PART_DEPTH:
            raise FunctionError(f"plugin '{self.name}' ({self.where}): parts are nested more than "
                                f"{MAX_PART_DEPTH} deep at {path} (does a part contain its parent?)")
        parent = np.eye(4) if transform is None else np.asarray(transform, dtype=np.float64)
        block = self.param_block(params)
        values = self.param_values(block)
        at = np.array([p.at for p in self.parts], dtype=np.float64)
        frames = self.surface_frame(at[:, 0], at[:, 1], block)
        out: list[PlacedPart] = []
        counts: dict[str, int] = {}
        for part, frame in zip(self.parts, frames):
            label = part.label
            idx = counts[label] = counts.get(label, -1) + 1
            here = f"{path}/{label}[{idx}]"
            if not np.all(np.isfinite(frame)):
                raise FunctionError(
                    f"plugin '{self.name}' ({self.where}): part {here} sits at (u, v) = {part.at}, where "
                    f"the surface frame is undefined (df/du or the normal is zero or not finite); "
                    f"move it to another (u, v)")
            child = _resolve(part.function, self, here)
            names = {p.name for p in child.params}
            if set(part.params) - names:   # the child would name neither the plugin nor the part
                raise FunctionError(f"plugin '{self.name}' ({self.where}): part {here}: function '{child.name}' has "
                                    f"no parameter {', '.join(map(repr, sorted(set(part.params) - names)))} "
                                    f"(its parameters: {', '.join(sorted(names)) or 'none'})")
            child_params = dict(part.params)
            for k in part.inherit:
                if k in names and k in values and k not in child_params:
                    child_params[k] = values[k]
            m = parent @ frame @ part.transform
            out.append(PlacedPart(child, child_params, m, part.color, here))
            out.extend(child.expand_parts(child_params, m, _depth=_depth + 1, _path=here))
        return out


# --- functions by name -------------------------------------------------------------------------
# A Part (and ``evaluate``) may name a function instead of holding it. The names belong to the
# registry (``paramlod.function.registry``), which sits above this module: ``paramlod.function``
# (the package) installs the registry's lookup here, so this module never imports the registry.
_name_lookup: Callable[[object], "ParametricFunction"] | None = None


def set_name_lookup(lookup: Callable[[object], "ParametricFunction"] | None) -> None:
    """Install the function that finds a registered function by name (``registry.get_function``)."""
    global _name_lookup
    _name_lookup = lookup


def lookup(fn_or_name) -> "ParametricFunction":
    """``fn_or_name`` itself if it is a ParametricFunction, else the registered function of that name."""
    if isinstance(fn_or_name, ParametricFunction):
        return fn_or_name
    if _name_lookup is None:
        raise FunctionError(f"cannot look up the function {fn_or_name!r}: no function registry is installed "
                            f"(import paramlod.function)")
    return _name_lookup(fn_or_name)


# --- helpers for definition time ---------------------------------------------------------------
# The helpers of ``paramlod.dsl`` (its ``__all__`` is this list), named in the hints of
# ``_body_error``; kept here because dsl sits above this module and may not be imported from it.
DSL_HELPERS = (
    "let", "where", "step", "clamp", "saturate", "smoothstep", "mix", "fract", "mod",
    "vec3", "dot", "cross", "length", "normalize", "rotate",
    "bezier", "bezier_derivative", "frenet_frame", "tube",
    "hash01", "noise", "fbm",
)

_STEP_FUNCTIONS = (sp.floor, sp.ceiling, sp.sign, sp.Heaviside)


def normalize_expr(e: sp.Expr) -> sp.Expr:
    """Rewrite frac and Mod with floor, so every backend prints the same thing."""
    if e.has(sp.frac):
        e = e.replace(sp.frac, lambda a: a - sp.floor(a))
    if e.has(sp.Mod):
        e = e.replace(sp.Mod, lambda a, b: a - b * sp.floor(a / b))
    return e


def _diff(e: sp.Expr, sym: sp.Symbol, fn: ParametricFunction) -> sp.Expr:
    """d e / d sym, treating piecewise-constant functions (floor, ceiling, sign, step) as constants:
    their derivative is 0 almost everywhere, and sympy would otherwise leave it unevaluated."""
    steps = sorted(e.atoms(*_STEP_FUNCTIONS), key=sp.default_sort_key)
    if steps:
        held = {a: sp.Dummy(f"held{i}", real=True) for i, a in enumerate(steps)}
        d = sp.diff(e.xreplace(held), sym).xreplace({h: a for a, h in held.items()})
    else:
        d = sp.diff(e, sym)
    if d.has(sp.Derivative, sp.Subs):
        bad = sorted({str(x.expr.func if isinstance(x, sp.Derivative) else x) for x in d.atoms(sp.Derivative)})
        raise FunctionError(f"plugin '{fn.name}' ({fn.where}): sympy cannot differentiate "
                            f"{', '.join(bad) or 'part of the expression'} with respect to {sym}; "
                            f"use functions with known derivatives or a snippet function")
    return d


def _resolve(function, parent: ParametricFunction, here: str) -> ParametricFunction:
    if isinstance(function, ParametricFunction):
        return function
    try:
        return lookup(function)
    except FunctionError as exc:
        raise FunctionError(f"plugin '{parent.name}' ({parent.where}): part {here}: {exc}") from None


def _check_range(fname: str, where: str, axis: str, rng) -> tuple[float, float]:
    try:
        lo, hi = (float(sp.N(x)) for x in rng)
    except (TypeError, ValueError) as exc:
        raise FunctionError(f"plugin '{fname}' ({where}): the {axis} domain must be (lo, hi), got {rng!r}") from exc
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise FunctionError(f"plugin '{fname}' ({where}): the {axis} domain ({lo}, {hi}) is not finite")
    if lo == hi:
        raise FunctionError(f"plugin '{fname}' ({where}): the {axis} domain ({lo}, {hi}) is empty")
    if lo > hi:
        raise FunctionError(f"plugin '{fname}' ({where}): the {axis} domain ({lo}, {hi}) is reversed; "
                            f"write it as ({hi}, {lo}) (to flip the orientation, use {hi} + {lo} - {axis} "
                            f"inside the function)")
    return lo, hi


def _source_of(fn) -> tuple[str, int]:
    try:
        src = inspect.getsourcefile(fn) or fn.__module__
    except TypeError:
        src = getattr(fn, "__module__", "<unknown>")
    line = getattr(getattr(fn, "__code__", None), "co_firstlineno", 0)
    return src, line


def _failing_line(exc: BaseException, filename: str) -> int | None:
    """Line of the innermost traceback entry in the plugin's own file."""
    line = None
    for fs in traceback.extract_tb(exc.__traceback__):
        if fs.filename == filename:
            line = fs.lineno
    return line


def _body_error(fname: str, where: str, src: str, exc: Exception) -> FunctionError:
    """A clear message for an exception raised while the function body built its expressions."""
    line = _failing_line(exc, src)
    at = f" at line {line}" if line else ""
    if isinstance(exc, FunctionError):
        return exc
    if isinstance(exc, NameError):
        name = getattr(exc, "name", None) or (re.findall(r"'(\w+)'", str(exc)) or ["?"])[0]
        if name in DSL_HELPERS:
            hint = f"; import it: from paramlod.dsl import {name}"
        elif name in dir(sp) and not name.startswith("_"):
            hint = f"; import it: from sympy import {name}"
        else:
            helpers = list(DSL_HELPERS) + ["sin", "cos", "tan", "exp", "log", "sqrt", "pi", "atan2", "Abs", "floor"]
            close = difflib.get_close_matches(name, helpers, n=3)
            hint = (f"; did you mean {', '.join(close)}?" if close else
                    "; helpers such as where, clamp, bezier, tube and noise are in paramlod.dsl, math in sympy")
        return FunctionError(f"plugin '{fname}' ({where}): the body uses the unknown name '{name}'{at} "
                             f"(not an argument and not imported){hint}")
    msg = f"{type(exc).__name__}: {exc}"
    hint = ""
    if "truth value of Relational" in str(exc) or "cannot determine truth value" in str(exc):
        hint = (" - a Python if/and/or/min/max on an expression of u, v or a parameter cannot be decided "
                "while building expressions; use paramlod.dsl.where(cond, a, b), clamp, or sympy Min/Max")
    elif "Cannot convert expression to float" in str(exc) or "loop of ufunc does not support" in str(exc):
        hint = " - use sympy functions (from sympy import sin, ...) or paramlod.dsl helpers, not math or numpy"
    return FunctionError(f"plugin '{fname}' ({where}): building its expressions failed{at}: {msg}{hint}")


def _check_parts(fname: str, where: str, parts, u_rng, v_rng) -> tuple[Part, ...]:
    out = []
    for i, part in enumerate(parts or ()):
        if not isinstance(part, Part):
            raise FunctionError(f"plugin '{fname}' ({where}): parts[{i}] must be a paramlod Part(...), got {part!r}")
        label = f"parts[{i}] ({part.label})"
        if not isinstance(part.function, (ParametricFunction, str)):
            raise FunctionError(f"plugin '{fname}' ({where}): {label}: function must be a @parametric "
                                f"function or a registered name, got {part.function!r}")
        try:
            pu, pv = (float(x) for x in part.at)
        except (TypeError, ValueError):
            raise FunctionError(f"plugin '{fname}' ({where}): {label}: at must be (u, v), got {part.at!r}") from None
        if not (u_rng[0] <= pu <= u_rng[1] and v_rng[0] <= pv <= v_rng[1]):
            raise FunctionError(f"plugin '{fname}' ({where}): {label}: at = ({pu}, {pv}) lies outside the "
                                f"parent's domain u {u_rng}, v {v_rng}")
        if part.transform.shape != (4, 4) or not np.all(np.isfinite(part.transform)):
            raise FunctionError(f"plugin '{fname}' ({where}): {label}: transform must be a finite 4x4 matrix")
        if part.color is not None:
            c = np.asarray(part.color, dtype=np.float64)
            if c.shape != (3,) or not np.all((c >= 0) & (c <= 1)):
                raise FunctionError(f"plugin '{fname}' ({where}): {label}: color must be three numbers in "
                                    f"[0, 1], got {part.color!r}")
        if isinstance(part.function, ParametricFunction):
            try:
                part.function.param_block(part.params)
            except FunctionError as exc:
                raise FunctionError(f"plugin '{fname}' ({where}): {label}: {exc}") from None
        out.append(part)
    return tuple(out)


_SNIPPET_DOUBLE = re.compile(r"(?<![\w.])(\d+\.\d*|\.\d+|\d+[eE][+-]?\d+|\d+\.\d*[eE][+-]?\d+)(?![\w.])")
_RESERVED = {  # names a snippet parameter cannot take: keywords and types of OpenCL C or GLSL, dialect macros
    "int", "uint", "float", "double", "half", "bool", "void", "vec2", "vec3", "vec4", "float2", "float3",
    "float4", "const", "global", "local", "private", "constant", "kernel", "in", "out", "inout", "uniform",
    "buffer", "shared", "sampler", "image", "if", "else", "for", "while", "do", "return", "break", "continue",
    "switch", "case", "default", "struct", "true", "false", "P", "PI", "VEC3", "ABS", "ATAN2", "FRACT", "MOD",
    "PARAM_AT", "PARAM", "mix", "dot", "cross", "length", "normalize", "min", "max", "clamp", "step",
    "smoothstep", "sign", "floor", "ceil", "sqrt", "pow", "exp", "log", "sin", "cos", "tan", "asin", "acos",
    "atan", "u", "v", "discard", "precise", "restrict", "volatile", "inline", "static", "sizeof", "main",
}


def _check_snippet(fname: str, where: str, code: str, param_names) -> str:
    if not isinstance(code, str) or not code.strip():
        raise FunctionError(f"plugin '{fname}' ({where}): snippet must be a non-empty string of dialect code")
    if not re.search(r"\breturn\b", code):
        raise FunctionError(f"plugin '{fname}' ({where}): the snippet never returns; end it with "
                            f"'return VEC3(x, y, z);'")
    for n, text in enumerate(code.splitlines(), 1):
        stripped = re.sub(r"//.*", "", text)
        if re.search(r"\bdouble\b", stripped):
            raise FunctionError(f"plugin '{fname}' ({where}): snippet line {n}: 'double' is not part of the "
                                f"dialect (float only): {text.strip()}")
        cast = re.search(r"\(\s*(float|int|uint)\s*\)|\b(float|int)\s*\((?!\s*\))", stripped)
        if cast and not re.match(r"\s*(float|int)\s+\w+\s*\(", stripped):
            kind = (cast.group(1) or cast.group(2)).upper()
            raise FunctionError(f"plugin '{fname}' ({where}): snippet line {n}: write conversions as "
                                f"{kind if kind != 'UINT' else 'INT'}(x), which works in OpenCL C and GLSL "
                                f"(a C cast is not GLSL, a constructor is not C): {text.strip()}")
        native = re.search(r"\b(fabs|abs|atan2|fract|fmod|mod|rsqrt|inversesqrt)\s*\(", stripped)
        if native:
            macro = {"fabs": "ABS", "abs": "ABS", "atan2": "ATAN2", "fract": "FRACT", "fmod": "MOD",
                     "mod": "MOD", "rsqrt": "INVSQRT", "inversesqrt": "INVSQRT"}[native.group(1)]
            raise FunctionError(f"plugin '{fname}' ({where}): snippet line {n}: '{native.group(1)}' exists in "
                                f"only one of OpenCL C and GLSL (or means different things); use the "
                                f"dialect's {macro}(...): {text.strip()}")
        m = _SNIPPET_DOUBLE.search(stripped)
        if m:
            raise FunctionError(f"plugin '{fname}' ({where}): snippet line {n}: the float literal '{m.group(1)}' "
                                f"needs an f suffix ({m.group(1)}f) so that it stays single precision on "
                                f"every backend: {text.strip()}")
    for p in param_names:
        if p in _RESERVED or p.startswith("pl_"):
            raise FunctionError(f"plugin '{fname}' ({where}): parameter '{p}' cannot be used in a snippet "
                                f"function (it is a keyword, type or dialect name); rename it")
    return code


def parametric(u: Sequence[float] = (0.0, 1.0), v: Sequence[float] = (0.0, 1.0),
               params: dict | None = None, name: str | None = None, parts: Sequence[Part] | None = None,
               snippet: str | None = None, fd_step: tuple[float, float] | None = None, periodic: str = ""):
    """Decorator: turn ``fn(u, v, **params) -> (x, y, z)`` of sympy symbols into a ParametricFunction.

    ``params`` maps each parameter name to its default: a number, or a sequence of numbers for an
    array parameter (the function then receives a list of symbols). An argument named ``t`` that
    is not in ``params`` is the implicit time (a scalar parameter, default 0.0).

    ``parts`` lists child objects (``Part``) placed on this surface. ``snippet`` gives the body in
    the shared dialect instead (``kernels/README.md``); ``fn`` is then the numpy reference,
    called with float64 arrays u, v and the parameter values, and the partials are central
    differences with steps ``fd_step`` (default: 1/1000 of each domain's width).

    ``periodic`` names the axes over which the surface closes on itself ("u", "v" or "uv"): with
    "v", f(u, v0) = f(u, v1) for every u and every parameter value. The point renderers then do not
    sample the last grid line of a patch that spans the domain there (a copy of the first).
    Checked here at the defaults, and with a scene's own values when it is sent to the device
    (paramlod.lod.uploads.wrap_flags: where the edges do not meet, the seam's line is kept).
    """
    params = dict(params or {})

    def wrap(fn) -> ParametricFunction:
        if not callable(fn):
            raise FunctionError(f"@parametric must decorate a function, got {fn!r}")
        fname = name or fn.__name__
        src, line = _source_of(fn)
        where = f"{src}:{line}" if line else src
        u_rng = _check_range(fname, where, "u", u)
        v_rng = _check_range(fname, where, "v", v)
        try:
            sig = inspect.signature(fn)
        except (TypeError, ValueError) as exc:
            raise FunctionError(f"plugin '{fname}' ({where}): cannot read its signature: {exc}") from None
        plist_sig = list(sig.parameters.values())
        bad = [p.name for p in plist_sig if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]
        if bad:
            raise FunctionError(f"plugin '{fname}' ({where}): wrong signature: *args/**kwargs ({', '.join(bad)}) "
                                f"are not allowed; write def {fname}(u, v, param1, ...)")
        names = [p.name for p in plist_sig]
        positional = [p for p in plist_sig[:2] if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
        if len(positional) < 2:
            raise FunctionError(f"plugin '{fname}' ({where}): wrong signature ({', '.join(names)}): it must "
                                f"start with the two surface parameters, as in def {fname}(u, v, ...)")
        extra = names[2:]
        declared = dict(params)
        if TIME in extra and TIME not in declared:
            declared[TIME] = 0.0  # implicit time parameter
        missing = [n for n in extra if n not in declared]
        if missing:
            raise FunctionError(f"plugin '{fname}' ({where}): parameter(s) {', '.join(missing)} have no default; "
                                f"add them to params={{...}}, e.g. params={{'{missing[0]}': 1.0}}")
        unused = [n for n in declared if n not in extra]
        if unused:
            raise FunctionError(f"plugin '{fname}' ({where}): params {', '.join(unused)} are not arguments of "
                                f"the function ({', '.join(names)})")
        checked_parts = _check_parts(fname, where, parts, u_rng, v_rng)
        axes = _check_periodic_axes(fname, where, periodic)

        usym, vsym = sp.symbols("u v", real=True)
        plist, flat, kwargs = [], [], {}
        for pname in extra:
            try:
                default = np.asarray(declared[pname], dtype=np.float64)
            except (TypeError, ValueError):
                default = np.asarray([np.nan])
            if default.ndim > 1 or default.size == 0 or not np.all(np.isfinite(default)):
                raise FunctionError(f"plugin '{fname}' ({where}): the default of parameter '{pname}' must be a "
                                    f"finite number or a flat list of numbers, got {declared[pname]!r}")
            plist.append(Param(pname, default))
            if default.ndim == 0:
                sym = sp.Symbol(f"p_{pname}", real=True)
                flat.append(sym)
                kwargs[pname] = sym
            else:
                syms = [sp.Symbol(f"p_{pname}_{i}", real=True) for i in range(default.size)]
                flat.extend(syms)
                kwargs[pname] = syms
        common = dict(name=fname, u_range=u_rng, v_range=v_rng, params=tuple(plist), u=usym, v=vsym,
                      param_symbols=tuple(flat), source=src, doc=inspect.getdoc(fn) or "",
                      python_function=fn, line=line, parts=checked_parts, periodic=axes)

        if snippet is not None:
            code = _check_snippet(fname, where, snippet, extra)
            steps = fd_step or ((u_rng[1] - u_rng[0]) * 1e-3, (v_rng[1] - v_rng[0]) * 1e-3)
            try:
                steps = tuple(float(s) for s in steps)
            except (TypeError, ValueError):
                steps = (0.0,)
            if len(steps) != 2 or not all(s > 0 and math.isfinite(s) for s in steps):
                raise FunctionError(f"plugin '{fname}' ({where}): fd_step must be two positive numbers, got {fd_step!r}")
            out = ParametricFunction(exprs=None, snippet=Snippet(code, steps), **common)
            _check_reference(out, where)
            _check_periodic(out, where)
            return out

        with collect_bindings() as raw_bindings:   # dsl.let appends to it while the body runs
            try:
                result = fn(usym, vsym, **kwargs)
            except Exception as exc:  # the user's body failed while building expressions
                raise _body_error(fname, where, src, exc) from None
        allowed = {usym, vsym, *flat}
        bindings = []
        for sym, e in raw_bindings:
            bindings.append((sym, _check_expr(fname, where, e, allowed, f"intermediate value {sym}")))
            allowed.add(sym)
        exprs = _check_result(fname, where, result, allowed)
        used = _used_bindings(bindings, exprs)
        out = ParametricFunction(exprs=tuple(exprs), bindings=used, **common)
        _check_periodic(out, where)
        return out

    return wrap


def _check_result(fname: str, where: str, result, allowed: set) -> list[sp.Expr]:
    if isinstance(result, sp.MatrixBase):
        result = list(result)
    if not isinstance(result, (tuple, list)) or len(result) != 3:
        kind = f"{len(result)} values" if isinstance(result, (tuple, list)) else type(result).__name__
        raise FunctionError(f"plugin '{fname}' ({where}) must return three expressions (x, y, z), "
                            f"got {kind}: {result!r}"[:400])
    return [_check_expr(fname, where, e, allowed, f"component {'xyz'[i]}") for i, e in enumerate(result)]


def _check_expr(fname: str, where: str, e, allowed: set, what: str) -> sp.Expr:
    try:
        e = sp.sympify(e)
    except (sp.SympifyError, TypeError) as exc:
        raise FunctionError(f"plugin '{fname}' ({where}): {what} is not an expression: {e!r}") from exc
    if isinstance(e, sp.MatrixBase) or not isinstance(e, sp.Expr):
        raise FunctionError(f"plugin '{fname}' ({where}): {what} is not a scalar expression: {e!r}"[:400])
    if e.has(sp.zoo, sp.nan, sp.oo, -sp.oo):
        raise FunctionError(f"plugin '{fname}' ({where}): {what} is infinite or undefined "
                            f"(a division by zero?): {e}"[:400])
    if e.has(sp.I):   # the generated code is real: it would fail to compile, far from the plugin
        raise FunctionError(f"plugin '{fname}' ({where}): {what} is complex (it holds the imaginary unit I; "
                            f"a square root of a negative constant?): {e}"[:400])
    stray = e.free_symbols - allowed
    if stray:
        # a string ("u") or a Symbol made in the plugin has a known name but is not the symbol passed in
        alike = sorted(str(x) for x in stray if str(x) in {str(a) for a in allowed})
        hint = (f" ({', '.join(alike)}: a string or a sympy Symbol made in the plugin, not the argument the "
                "function is given; use the argument)" if alike else "")
        raise FunctionError(f"plugin '{fname}' ({where}): {what} uses unknown symbol(s) "
                            f"{sorted(map(str, stray))}; use only u, v and the parameters{hint}")
    return normalize_expr(e)


def _used_bindings(bindings, exprs) -> tuple:
    """The bindings the outputs need (directly or through other bindings), in order."""
    need = set().union(*(e.free_symbols for e in exprs)) if exprs else set()
    keep = []
    for sym, e in reversed(bindings):
        if sym in need:
            keep.append((sym, e))
            need |= e.free_symbols
    return tuple(reversed(keep))


def _check_reference(fn: ParametricFunction, where: str) -> None:
    """Run a snippet function's numpy reference on a small grid: it must give three arrays."""
    uu, vv = np.meshgrid(np.linspace(*fn.u_range, 3), np.linspace(*fn.v_range, 3), indexing="ij")
    try:
        with np.errstate(all="ignore"):
            vals = fn.python_function(uu, vv, **fn.param_values(fn.param_block()))
    except Exception as exc:
        raise _body_error(fn.name, where, fn.source, exc) from None
    if not isinstance(vals, (tuple, list)) or len(vals) != 3:
        raise FunctionError(f"plugin '{fn.name}' ({where}): its numpy reference must return three arrays "
                            f"(x, y, z), got {type(vals).__name__}")
    try:
        for c in vals:
            np.broadcast_to(np.asarray(c, np.float64), uu.shape)
    except (ValueError, TypeError) as exc:
        raise FunctionError(f"plugin '{fn.name}' ({where}): its numpy reference returned values that do not "
                            f"broadcast to the shape of u and v: {exc}") from None


def _check_periodic_axes(fname: str, where: str, periodic) -> tuple[str, ...]:
    if not isinstance(periodic, str) or set(periodic) - {"u", "v"} or len(set(periodic)) != len(periodic):
        raise FunctionError(f"plugin '{fname}' ({where}): periodic must name the axes the surface closes over, "
                            f"\"u\", \"v\", \"uv\" or \"\", got {periodic!r}")
    return tuple(a for a in "uv" if a in periodic)


def _check_periodic(fn: ParametricFunction, where: str) -> None:
    """The edges a periodic axis joins must coincide at the defaults: a wrong claim would leave a
    gap of one sample step along the seam."""
    if not _periodic_checked[0]:
        return
    for axis in fn.periodic:
        gaps, limit, across = fn.edge_gaps(axis, fn.param_block())
        bad = gaps[0] > limit[0]
        if bad.any():
            k = int(np.argmax(np.where(bad, gaps[0], -1.0)))
            other, lo, hi = ("v", *fn.u_range) if axis == "u" else ("u", *fn.v_range)
            raise FunctionError(f"plugin '{fn.name}' ({where}): declared periodic in {axis}, but f at {axis} = {lo:g} "
                                f"and {axis} = {hi:g} differ by {gaps[0, k]:.3g} at {other} = {across[k]:.4g} (default "
                                f"parameters); remove '{axis}' from periodic or make the two edges meet")


def evaluate(fn_or_name, u, v, **params) -> np.ndarray:
    """Evaluate a parametric function (object or registered name) with numpy: shape (..., 3)."""
    fn = lookup(fn_or_name)
    return fn.evaluate(u, v, **params)
