"""Code generation: sympy expressions -> OpenCL C (single precision, with common-subexpression
elimination). The numpy side is sympy.lambdify (see ``define.py``).

For each function index i the generated source defines

    float3 pl_pos_i(float u, float v, __global const float* P)
    void   pl_surf_i(float u, float v, __global const float* P, float3* pos, float3* du, float3* dv)

and two dispatchers ``pl_position(func, ...)`` / ``pl_surface(func, ...)`` that switch on the index,
which the kernels in ``kernels/`` call.

Snippet functions (``@parametric(..., snippet=...)``) are emitted as ``pl_snip_i`` with the
dialect macros of ``kernels/dialect.cl`` in front; their partials are central differences.

The printer is meant to be reused: a GLSL printer subclasses ``CLPrinter`` and overrides the
``names`` table, ``local_decl`` and ``param_read`` (see ``function_body``).
"""
from __future__ import annotations

import weakref

import sympy as sp
from sympy.printing.c import C99CodePrinter
from sympy.printing.codeprinter import PrintMethodNotImplementedError

from paramlod import kernels
from paramlod.errors import FunctionError
from paramlod.function.define import ParametricFunction


class CLPrinter(C99CodePrinter):
    """C99 printer that keeps everything in float: f-suffixed literals, no double constants.

    Backend-specific spellings live in ``names`` so that a subclass can retarget the printer.
    """

    names = {
        "min": "fmin", "max": "fmax", "abs": "fabs", "pown": "pown", "rsqrt": "rsqrt", "cbrt": "cbrt",
        "atan2": "atan2", "floor": "floor", "ceil": "ceil", "sign": "sign", "pow": "pow", "sqrt": "sqrt",
    }
    float_suffix = "f"
    local_decl = "const float"   # declaration of generated temporaries
    bool_decl = "const int"      # ... of temporaries that hold a condition (GLSL: "const bool")
    param_read = "P[{}]"         # expression that reads float k of the parameter block

    def __init__(self, settings=None):
        # no math macros (M_PI_2, M_SQRT2, ...): they are double constants in C, absent in GLSL
        super().__init__({"strict": True, "math_macros": {}, **(settings or {})})

    def _lit(self, x: float) -> str:
        return f"{float(x)!r}{self.float_suffix}"

    def _print_Float(self, expr):
        return self._lit(expr)

    def _print_Rational(self, expr):
        return self._lit(expr)

    def _print_Integer(self, expr):
        return f"{int(expr)}.0{self.float_suffix}"

    def _print_NumberSymbol(self, expr):  # pi, E, GoldenRatio, ...: literals work on every backend
        return self._lit(expr.evalf(20))

    _print_Pi = _print_Exp1 = _print_NumberSymbol

    def _print_Pow(self, expr):
        base, ex = expr.as_base_exp()
        b = self.parenthesize(base, 100)
        n_ = self.names
        if ex.is_Integer:
            n = int(ex)
            if n == 0:
                return self._lit(1.0)
            mag = "*".join([b] * abs(n)) if abs(n) <= 4 else f"{n_['pown']}({self._print(base)}, {abs(n)})"
            return f"({mag})" if n > 0 else f"({self._lit(1.0)}/({mag}))"
        if ex == sp.Rational(1, 2):
            return f"{n_['sqrt']}({self._print(base)})"
        if ex == -sp.Rational(1, 2):
            return f"{n_['rsqrt']}({self._print(base)})"
        if ex == sp.Rational(1, 3):
            return f"{n_['cbrt']}({self._print(base)})"
        return f"{n_['pow']}({self._print(base)}, {self._print(ex)})"

    def _print_Piecewise(self, expr):
        # nested ternaries on one line; a Piecewise without a True default gives NaN where no branch holds
        args = list(expr.args)
        if args[-1].cond == sp.true:
            out = self._print(args.pop().expr)
        else:
            out = "NAN"
        for e, c in reversed(args):
            out = f"(({self._print(c)}) ? ({self._print(e)}) : ({out}))"
        return out

    def _print_Abs(self, expr):
        return f"{self.names['abs']}({self._print(expr.args[0])})"

    def _print_floor(self, expr):
        return f"{self.names['floor']}({self._print(expr.args[0])})"

    def _print_ceiling(self, expr):
        return f"{self.names['ceil']}({self._print(expr.args[0])})"

    def _print_sign(self, expr):
        return f"{self.names['sign']}({self._print(expr.args[0])})"

    def _print_atan2(self, expr):
        y, x = expr.args
        return f"{self.names['atan2']}({self._print(y)}, {self._print(x)})"

    def _print_Heaviside(self, expr):
        x = self._print(expr.args[0])
        h0 = expr.args[1] if len(expr.args) > 1 else sp.Rational(1, 2)
        return (f"(({x}) > {self._lit(0)} ? {self._lit(1)} : "
                f"(({x}) < {self._lit(0)} ? {self._lit(0)} : {self._print(h0)}))")

    def _print_Mod(self, expr):  # Python/GLSL semantics: the result has the sign of the divisor
        a, b = (self._print(x) for x in expr.args)
        return f"(({a}) - ({b}) * {self.names['floor']}(({a}) / ({b})))"

    def _print_frac(self, expr):
        a = self._print(expr.args[0])
        return f"(({a}) - {self.names['floor']}({a}))"

    def _minmax(self, expr, which):
        args = [self._print(a) for a in expr.args]
        out = args[0]
        for a in args[1:]:
            out = f"{self.names[which]}({out}, {a})"
        return out

    def _print_Min(self, expr):
        return self._minmax(expr, "min")

    def _print_Max(self, expr):
        return self._minmax(expr, "max")


_printer = CLPrinter()


def cl_expr(expr) -> str:
    return _printer.doprint(expr)


def _print_checked(printer: CLPrinter, expr, fn: ParametricFunction) -> str:
    try:
        return printer.doprint(expr)
    except PrintMethodNotImplementedError as exc:
        what = str(exc).split(":")[-1].split("\n")[0].strip() or str(exc)
        raise FunctionError(f"plugin '{fn.name}' ({fn.where}): uses {what}, which has no equivalent in the "
                            f"generated GPU code; rewrite it with elementary functions or use a snippet "
                            f"function") from None


def param_lines(fn: ParametricFunction, printer: CLPrinter = _printer) -> list[str]:
    """Lines that load the parameter block into the sympy parameter symbols."""
    return [f"    {printer.local_decl} {printer.doprint(s)} = {printer.param_read.format(i)};"
            for i, s in enumerate(fn.param_symbols)]


def function_body(fn: ParametricFunction, exprs, printer: CLPrinter = _printer,
                  bindings=()) -> tuple[list[str], list[str]]:
    """Lines that compute ``bindings`` (in order) and the CSE temporaries of ``exprs``, and the final
    expressions. Backend-neutral apart from the printer: the GLSL printer reuses it with
    ``fn.program("position")`` or ``fn.program("surface")``.
    """
    def decl(e):
        return printer.bool_decl if isinstance(e, sp.logic.boolalg.Boolean) else printer.local_decl

    lines = [f"    {decl(e)} {printer.doprint(sym)} = {_print_checked(printer, e, fn)};" for sym, e in bindings]
    replacements, reduced = sp.cse(list(exprs), symbols=sp.numbered_symbols("t"))
    lines += [f"    {decl(e)} {sym} = {_print_checked(printer, e, fn)};" for sym, e in replacements]
    return lines, [_print_checked(printer, e, fn) for e in reduced]


def check_printable(fn: ParametricFunction) -> None:
    """Raise a FunctionError naming the plugin when its expressions use a function no backend has."""
    if fn.exprs is None:
        return
    for e in [*fn.exprs, *(e for _, e in fn.bindings)]:
        _print_checked(_printer, e, fn)


def snippet_body(fn: ParametricFunction, scalar_load: str) -> str:
    """A snippet function's body (shared by the OpenCL and GLSL backends): its parameters as
    locals (scalars loaded with ``scalar_load.format(offset)``, arrays as their offset), then the
    user's code."""
    offs = fn.param_offsets()
    loads = []
    for p in fn.params:
        if p.is_array:
            loads.append(f"    const int {p.name} = {offs[p.name]};  // array: PARAM_AT({p.name}, i)")
        else:
            loads.append(f"    const float {p.name} = {scalar_load.format(offs[p.name])};")
    return ("\n".join(loads) + ("\n" if loads else "")
            + "    // --- snippet ---\n"
            + "\n".join("    " + line for line in fn.snippet.code.strip("\n").splitlines())
            + "\n}\n")


def _snippet_source(fn: ParametricFunction, index: int) -> str:
    hu, hv = fn.snippet.fd_step
    snip = (f"inline float3 pl_snip_{index}(float u, float v, __global const float* P) {{\n"
            + snippet_body(fn, "P[{}]"))
    pos = (f"inline float3 pl_pos_{index}(float u, float v, __global const float* P) {{\n"
           f"    return pl_snip_{index}(u, v, P);\n}}\n")
    # normals of snippet functions: central differences with the function's fd_step
    surf = (f"inline void pl_surf_{index}(float u, float v, __global const float* P,"
            f" float3* pos, float3* du, float3* dv) {{\n"
            f"    const float hu = {_printer._lit(hu)}, hv = {_printer._lit(hv)};\n"
            f"    *pos = pl_snip_{index}(u, v, P);\n"
            f"    *du = (pl_snip_{index}(u + hu, v, P) - pl_snip_{index}(u - hu, v, P)) * (0.5f / hu);\n"
            f"    *dv = (pl_snip_{index}(u, v + hv, P) - pl_snip_{index}(u, v - hv, P)) * (0.5f / hv);\n}}\n")
    return snip + pos + surf


# generated source per function and index: functions never change after definition, and every
# program of a scene (LOD stage, renderers, eval) asks for the same code again
_sources: "weakref.WeakKeyDictionary[ParametricFunction, dict[int, str]]" = weakref.WeakKeyDictionary()


def cl_function_source(fn: ParametricFunction, index: int) -> str:
    """OpenCL C for one function: position-only and position-with-partials entry points."""
    per_fn = _sources.setdefault(fn, {})
    if index not in per_fn:
        per_fn[index] = _cl_function_source(fn, index)
    return per_fn[index]


def _cl_function_source(fn: ParametricFunction, index: int) -> str:
    head = f"// {fn.name} (from {fn.source})\n"
    if fn.is_snippet:
        return head + _snippet_source(fn, index)
    loads = param_lines(fn)
    bindings, outputs = fn.program("position")
    lines, (x, y, z) = function_body(fn, outputs, bindings=bindings)
    pos = (f"inline float3 pl_pos_{index}(float u, float v, __global const float* P) {{\n"
           + "\n".join(loads + lines) + f"\n    return (float3)({x}, {y}, {z});\n}}\n")
    bindings, outputs = fn.program("surface")
    lines, r = function_body(fn, outputs, bindings=bindings)
    surf = (f"inline void pl_surf_{index}(float u, float v, __global const float* P,"
            f" float3* pos, float3* du, float3* dv) {{\n" + "\n".join(loads + lines)
            + f"\n    *pos = (float3)({r[0]}, {r[1]}, {r[2]});"
            + f"\n    *du = (float3)({r[3]}, {r[4]}, {r[5]});"
            + f"\n    *dv = (float3)({r[6]}, {r[7]}, {r[8]});\n}}\n")
    return head + pos + surf


def cl_dispatch_source(functions: list[ParametricFunction]) -> str:
    """All functions of a scene plus the dispatchers the kernels call."""
    parts = []
    if any(f.is_snippet for f in functions):
        parts.append(kernels.source("common/dialect.cl"))
    parts += [cl_function_source(f, i) for i, f in enumerate(functions)]
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
