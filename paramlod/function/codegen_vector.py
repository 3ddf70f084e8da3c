"""Code generation for CPU lanes: each function's surface code (position and partials) on
``PL_VW`` samples at once, in OpenCL vector types, for the direct point sampler's runs on CPU
devices (kernels/points/points.cl ``surface_lanes``, compiled with ``PL_VECTOR``).

Why: PoCL compiles a work-item's scalar code as it stands; the long chains of an SH glyph or a
fibre evaluate at one sample per instruction. The same steps on ``float8`` fill the CPU's vector
registers (2-core AMD EPYC, PoCL 3: the order-8 glyph field's points frame 1.9x faster,
docs/points.md "Vector lanes").

For each function index i the source defines, from the same lowered steps as the scalar code
(``paramlod.function.codegen_cl.surface_lowered`` and its surface split):

    void pl_vsurf_i(plv u, plv v, __global const float* P, plv* o)                     (no split)
    void pl_vrest_i(plv u, plv v, __global const float* P, const float* C, plv* o)     (split)

and the dispatcher ``pl_vsurface_rest(func, u, v, P, C, o)``, which the kernels call as they call
``pl_surface_rest`` (C: the split's carried values of the lanes' shared axis line, from the scalar
``pl_surface_axis``; ignored without a split). ``o``: position, df/du, df/dv, 9 vectors. Every
value is a vector (parameters and carried values splatted), so each builtin gets arguments of one
type. Snippets and functions using operations outside ``VECTOR_NODES`` go lane by lane through
the scalar ``pl_surface_rest``. The twin is the scalar code (tests/function/test_codegen_vector.py).
"""
from __future__ import annotations

import sympy as sp

from paramlod.function.codegen_cl import (CLPrinter, SinCos, print_checked, RsqrtOf, SqrtOf, param_lines, step_lines,
                                          surface_lowered, surface_split)
from paramlod.function.define import ParametricFunction

VECTOR_WIDTH = 8
PRELUDE = (f"#define PL_VW {VECTOR_WIDTH}\n#define pl_vload vload{VECTOR_WIDTH}\n"
           f"typedef float{VECTOR_WIDTH} plv;   // PL_VW lanes of the generated code\n"
           f"typedef int{VECTOR_WIDTH} plvi;    // its conditions (-1 true, 0 false per lane)\n")


class VectorPrinter(CLPrinter):
    """``CLPrinter`` on ``plv`` lanes: literals are vectors, so that every builtin's arguments
    share one type (pow, atan2 and fmin have no mixed scalar-vector forms for every argument)."""

    local_type = "plv"
    local_decl = "const plv"
    bool_decl = "const plvi"

    def _lit(self, x: float) -> str:
        return f"((plv){float(x)!r}f)"

    def _int(self, n: int) -> str:
        return f"((plvi){n})"


_vprinter = VectorPrinter()

# the expression nodes the vector printer prints to vector builtins (others: lane by lane)
VECTOR_NODES = (sp.Symbol, sp.Number, sp.NumberSymbol, sp.Add, sp.Mul, sp.Pow, sp.sin, sp.cos, sp.tan,
                sp.asin, sp.acos, sp.atan, sp.atan2, sp.sinh, sp.cosh, sp.tanh, sp.exp, sp.log, sp.Abs,
                sp.Min, sp.Max, sp.floor, sp.ceiling, sp.sign, sp.Piecewise, sp.functions.elementary.piecewise.ExprCondPair,
                sp.core.relational.Relational, sp.And, sp.Or, sp.Not, sp.logic.boolalg.BooleanAtom,
                sp.Heaviside, sp.Mod, sp.frac, SqrtOf, RsqrtOf)


def _vector_ready(fn: ParametricFunction, steps, outputs) -> bool:
    exprs = [st.arg if isinstance(st, SinCos) else st[1] for st in steps] + list(outputs)
    return all(isinstance(node, VECTOR_NODES) for e in exprs for node in sp.preorder_traversal(e))


def _outputs(fn: ParametricFunction, outputs) -> str:
    return "".join(f"\n    o[{k}] = {print_checked(_vprinter, e, fn)};" for k, e in enumerate(outputs))


def _vector_function(fn: ParametricFunction, index: int) -> tuple[str, bool] | None:
    """(source, split) of ``pl_vrest_i`` or ``pl_vsurf_i``; None when ``fn`` goes lane by lane."""
    if fn.is_snippet:
        return None
    loads = param_lines(fn, _vprinter)
    split = surface_split(fn)
    if split is None:
        low = surface_lowered(fn)
        if not _vector_ready(fn, low.steps, low.outputs):
            return None
        return (f"inline void pl_vsurf_{index}(plv u, plv v, __global const float* P, plv* o) {{\n"
                + "\n".join(loads + step_lines(fn, low.steps, _vprinter)) + _outputs(fn, low.outputs) + "\n}\n"), False
    if not _vector_ready(fn, split.rest_steps, split.outputs):
        return None
    conditions = {st[0] for st in split.axis_steps
                  if not isinstance(st, SinCos) and isinstance(st[1], sp.logic.boolalg.Boolean)}
    carried = []
    for k, sym in enumerate(split.carried):   # as codegen_cl._split_source stores them
        name = _vprinter.doprint(sym)
        carried.append(f"    const plvi {name} = (plvi)(C[{k}] != 0.0f ? -1 : 0);" if sym in conditions
                       else f"    const plv {name} = C[{k}];")
    lines = loads + carried + step_lines(fn, split.rest_steps, _vprinter)
    return (f"inline void pl_vrest_{index}(plv u, plv v, __global const float* P, const float* C, plv* o) {{\n"
            + "\n".join(lines) + _outputs(fn, split.outputs) + "\n}\n"), True


def vector_ready(fn: ParametricFunction) -> bool:
    """Whether ``fn`` evaluates as vectors (else lane by lane through the scalar code)."""
    return _vector_function(fn, 0) is not None


def cl_vector_source(functions: list[ParametricFunction]) -> str:
    """PRELUDE, the vector functions and ``pl_vsurface_rest``; goes after
    ``codegen_cl.cl_dispatch_source`` (it calls pl_surface_rest for the lanes of the others)."""
    parts, cases = [PRELUDE], []
    for i, fn in enumerate(functions):
        made = _vector_function(fn, i)
        if made is None:
            continue
        src, split = made
        parts.append(src)
        call = f"pl_vrest_{i}(u, v, P, C, o)" if split else f"pl_vsurf_{i}(u, v, P, o)"
        cases.append(f"        case {i}: {call}; return;\n")
    parts.append(
        "inline void pl_vsurface_rest(uint func, plv u, plv v, __global const float* P, const float* C, plv* o) {\n"
        f"    switch (func) {{\n{''.join(cases)}    }}\n"
        "    for (int k = 0; k < PL_VW; ++k) {   // lane by lane: snippets, operations without vector forms\n"
        "        float3 pos, du, dv;\n"
        "        pl_surface_rest(func, u[k], v[k], P, C, &pos, &du, &dv);\n"
        "        o[0][k] = pos.x; o[1][k] = pos.y; o[2][k] = pos.z;\n"
        "        o[3][k] = du.x; o[4][k] = du.y; o[5][k] = du.z;\n"
        "        o[6][k] = dv.x; o[7][k] = dv.y; o[8][k] = dv.z;\n"
        "    }\n}\n")
    return "\n".join(parts)
