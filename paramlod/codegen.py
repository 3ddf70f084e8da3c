"""Code generation: sympy expressions -> OpenCL C (single precision, with common-subexpression
elimination). The numpy side is sympy.lambdify (see ``function.py``).

For each function index i the generated source defines

    float3 pl_pos_i(float u, float v, __global const float* P)
    void   pl_surf_i(float u, float v, __global const float* P, float3* pos, float3* du, float3* dv)

and two dispatchers ``pl_position(func, ...)`` / ``pl_surface(func, ...)`` that switch on the index,
which the kernels in ``kernels/`` call.
"""
from __future__ import annotations

import sympy as sp
from sympy.printing.c import C99CodePrinter

from .function import ParametricFunction


class CLPrinter(C99CodePrinter):
    """C99 printer that keeps everything in float: f-suffixed literals, no double constants."""

    def _print_Float(self, expr):
        return f"{float(expr)!r}f"

    def _print_Rational(self, expr):
        return f"{float(expr)!r}f"

    def _print_Integer(self, expr):
        return f"{int(expr)}.0f"

    def _print_Pi(self, expr):
        return "M_PI_F"

    def _print_Exp1(self, expr):
        return "M_E_F"

    def _print_Pow(self, expr):
        base, ex = expr.as_base_exp()
        b = self.parenthesize(base, 100)
        if ex.is_Integer:
            n = int(ex)
            if n == 0:
                return "1.0f"
            mag = "*".join([b] * abs(n)) if abs(n) <= 4 else f"pown({self._print(base)}, {abs(n)})"
            return f"({mag})" if n > 0 else f"(1.0f/({mag}))"
        if ex == sp.Rational(1, 2):
            return f"sqrt({self._print(base)})"
        if ex == -sp.Rational(1, 2):
            return f"rsqrt({self._print(base)})"
        if ex == sp.Rational(1, 3):
            return f"cbrt({self._print(base)})"
        return f"pow({self._print(base)}, {self._print(ex)})"

    def _print_Piecewise(self, expr):
        # nested ternaries on one line; the last condition must be True (sympy guarantees a default)
        out = self._print(expr.args[-1].expr)
        for e, c in reversed(expr.args[:-1]):
            out = f"(({self._print(c)}) ? ({self._print(e)}) : ({out}))"
        return out

    def _print_sign(self, expr):
        return f"sign({self._print(expr.args[0])})"

    def _print_Min(self, expr):
        args = [self._print(a) for a in expr.args]
        out = args[0]
        for a in args[1:]:
            out = f"fmin({out}, {a})"
        return out

    def _print_Max(self, expr):
        args = [self._print(a) for a in expr.args]
        out = args[0]
        for a in args[1:]:
            out = f"fmax({out}, {a})"
        return out


_printer = CLPrinter()


def cl_expr(expr) -> str:
    return _printer.doprint(expr)


def _cl_body(fn: ParametricFunction, exprs) -> tuple[list[str], list[str]]:
    """Lines that load parameters and compute CSE temporaries, and the final expressions."""
    lines = [f"    const float {_printer.doprint(s)} = P[{i}];" for i, s in enumerate(fn.param_symbols)]
    replacements, reduced = sp.cse(list(exprs), symbols=sp.numbered_symbols("t"), optimizations="basic")
    for sym, e in replacements:
        lines.append(f"    const float {sym} = {cl_expr(e)};")
    return lines, [cl_expr(e) for e in reduced]


def cl_function_source(fn: ParametricFunction, index: int) -> str:
    """OpenCL C for one function: position-only and position-with-partials entry points."""
    head = f"// {fn.name} (from {fn.source})\n"
    lines, (x, y, z) = _cl_body(fn, fn.exprs)
    pos = (f"inline float3 pl_pos_{index}(float u, float v, __global const float* P) {{\n"
           + "\n".join(lines) + f"\n    return (float3)({x}, {y}, {z});\n}}\n")
    lines, r = _cl_body(fn, [*fn.exprs, *fn.du, *fn.dv])
    surf = (f"inline void pl_surf_{index}(float u, float v, __global const float* P,"
            f" float3* pos, float3* du, float3* dv) {{\n" + "\n".join(lines)
            + f"\n    *pos = (float3)({r[0]}, {r[1]}, {r[2]});"
            + f"\n    *du = (float3)({r[3]}, {r[4]}, {r[5]});"
            + f"\n    *dv = (float3)({r[6]}, {r[7]}, {r[8]});\n}}\n")
    return head + pos + surf


def cl_dispatch_source(functions: list[ParametricFunction]) -> str:
    """All functions of a scene plus the dispatchers the kernels call."""
    parts = [cl_function_source(f, i) for i, f in enumerate(functions)]
    cases_p = "".join(f"        case {i}: return pl_pos_{i}(u, v, P);\n" for i in range(len(functions)))
    cases_s = "".join(f"        case {i}: pl_surf_{i}(u, v, P, pos, du, dv); return;\n"
                      for i in range(len(functions)))
    parts.append(
        "inline float3 pl_position(uint func, float u, float v, __global const float* P) {\n"
        f"    switch (func) {{\n{cases_p}    }}\n    return (float3)(NAN, NAN, NAN);\n}}\n")
    parts.append(
        "inline void pl_surface(uint func, float u, float v, __global const float* P,"
        " float3* pos, float3* du, float3* dv) {\n"
        f"    switch (func) {{\n{cases_s}    }}\n"
        "    *pos = *du = *dv = (float3)(NAN, NAN, NAN);\n}\n")
    return "\n".join(parts)
