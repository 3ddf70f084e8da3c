"""Code generation: sympy expressions -> GLSL 4.50 for the tessellation renderer.

The GLSL twin of ``codegen.py``: the same sympy expressions (and the same common-subexpression
elimination) become, for each function index i,

    vec3 pl_pos_i(float u, float v, uint P)
    void pl_surf_i(float u, float v, uint P, out vec3 pos, out vec3 du, out vec3 dv)

and two dispatchers ``pl_position(func, u, v, P)`` / ``pl_surface(func, u, v, P, pos, du, dv)``
that switch on the function index. ``P`` is the instance's offset into the shader storage buffer
``float pl_params[]`` that ``kernels/tess_common.glsl`` declares (the scene's flat parameter array,
``Scene.instance_buffers()[2]``), so array parameters such as 91 SH coefficients cost nothing extra.

The printer derives from ``codegen.CLPrinter`` so that print methods added there for helper
functions are inherited; everything that differs between OpenCL C and GLSL (literals, constants,
``fmin``/``fabs``/``atan2``/``rsqrt``/``cbrt``, the floored ``Mod``) is overridden here. Names that
GLSL lacks but OpenCL snippets commonly use are also given as small functions in
``kernels/tess_common.glsl`` (a compatibility prelude).
"""
from __future__ import annotations

import math

import sympy as sp
from sympy.printing.codeprinter import PrintMethodNotImplementedError

from .codegen import CLPrinter
from .errors import FunctionError
from .function import ParametricFunction

# sympy function name -> GLSL built-in (all take and return float).
GLSL_FUNCTIONS = {
    "sin": "sin", "cos": "cos", "tan": "tan", "asin": "asin", "acos": "acos", "atan": "atan",
    "sinh": "sinh", "cosh": "cosh", "tanh": "tanh", "asinh": "asinh", "acosh": "acosh", "atanh": "atanh",
    "exp": "exp", "log": "log", "sqrt": "sqrt", "floor": "floor", "ceiling": "ceil",
    "Abs": "abs", "sign": "sign", "frac": "fract",
}


def _literal(x: float) -> str:
    if math.isnan(x):
        raise ValueError("NaN constant")
    if math.isinf(x):
        return "(1.0 / 0.0)" if x > 0 else "(-1.0 / 0.0)"
    s = repr(float(x))
    if "e" in s or "E" in s:
        mant, exp = s.lower().split("e")
        if "." not in mant:
            mant += ".0"
        return f"{mant}e{exp}"
    return s


class GLSLPrinter(CLPrinter):
    """sympy -> GLSL 4.50 expressions, single precision."""

    _kf = GLSL_FUNCTIONS
    # an impossible key: never print C math macros (M_LN10, M_SQRT2 ...), which GLSL lacks
    math_macros = {sp.Symbol("__pl_never__"): "__pl_never__"}
    language = "GLSL"

    def __init__(self, settings=None):
        super().__init__(settings)
        self.known_functions = dict(GLSL_FUNCTIONS)

    # --- numbers and constants ------------------------------------------------------------------
    def _print_Float(self, expr):
        return _literal(float(expr))

    def _print_Rational(self, expr):
        return _literal(float(expr))

    def _print_Integer(self, expr):
        return f"{int(expr)}.0"

    def _print_Pi(self, expr):
        return _literal(math.pi)

    def _print_Exp1(self, expr):
        return _literal(math.e)

    def _print_NumberSymbol(self, expr):
        return _literal(float(expr))

    def _print_Infinity(self, expr):
        return "(1.0 / 0.0)"

    def _print_NegativeInfinity(self, expr):
        return "(-1.0 / 0.0)"

    def _print_BooleanTrue(self, expr):
        return "true"

    def _print_BooleanFalse(self, expr):
        return "false"

    # --- operators and functions ----------------------------------------------------------------
    def _print_Pow(self, expr):
        base, ex = expr.as_base_exp()
        b = self.parenthesize(base, 100)
        if ex.is_Integer:
            n = int(ex)
            if n == 0:
                return "1.0"
            mag = "*".join([b] * abs(n)) if abs(n) <= 4 else f"pl_pown({self._print(base)}, {abs(n)})"
            return f"({mag})" if n > 0 else f"(1.0/({mag}))"
        if ex == sp.Rational(1, 2):
            return f"sqrt({self._print(base)})"
        if ex == -sp.Rational(1, 2):
            return f"inversesqrt({self._print(base)})"
        if ex == sp.Rational(1, 3):
            return f"pl_cbrt({self._print(base)})"
        # like C's pow, a negative base with a non-integer exponent is NaN in GLSL too
        return f"pow({self._print(base)}, {self._print(ex)})"

    def _print_Mod(self, expr):
        # sympy's Mod is floored (the sign of the divisor), which is GLSL's mod()
        a, b = expr.args
        return f"mod({self._print(a)}, {self._print(b)})"

    def _print_atan2(self, expr):
        y, x = expr.args
        return f"atan({self._print(y)}, {self._print(x)})"

    def _print_Abs(self, expr):
        return f"abs({self._print(expr.args[0])})"

    def _print_sign(self, expr):
        return f"sign({self._print(expr.args[0])})"

    def _print_Min(self, expr):
        args = [self._print(a) for a in expr.args]
        out = args[0]
        for a in args[1:]:
            out = f"min({out}, {a})"
        return out

    def _print_Max(self, expr):
        args = [self._print(a) for a in expr.args]
        out = args[0]
        for a in args[1:]:
            out = f"max({out}, {a})"
        return out

    def _print_Heaviside(self, expr):
        x = self._print(expr.args[0])
        h0 = expr.args[1] if len(expr.args) > 1 else sp.Rational(1, 2)
        return f"(({x}) < 0.0 ? 0.0 : (({x}) > 0.0 ? 1.0 : {self._print(h0)}))"

    def _print_Relational(self, expr):
        return f"({self._print(expr.lhs)} {expr.rel_op} {self._print(expr.rhs)})"

    def _print_And(self, expr):
        return "(" + " && ".join(self._print(a) for a in expr.args) + ")"

    def _print_Or(self, expr):
        return "(" + " || ".join(self._print(a) for a in expr.args) + ")"

    def _print_Not(self, expr):
        return f"(!{self.parenthesize(expr.args[0], 100)})"


_printer = GLSLPrinter()


def glsl_expr(expr, fn: ParametricFunction | None = None) -> str:
    """One sympy expression as GLSL; an unsupported construct is a FunctionError naming ``fn``."""
    try:
        return _printer.doprint(expr)
    except (PrintMethodNotImplementedError, KeyError, ValueError, TypeError) as exc:
        who = f"function '{fn.name}' ({fn.source})" if fn is not None else "an expression"
        bad = sorted({type(f).__name__ for f in sp.preorder_traversal(expr)
                      if isinstance(f, sp.Function) and type(f).__name__ not in GLSL_FUNCTIONS
                      and not hasattr(_printer, f"_print_{type(f).__name__}")})
        what = f"uses {', '.join(bad)}, which has no GLSL form" if bad else f"cannot be printed as GLSL: {exc}"
        raise FunctionError(f"{who} {what}; the tessellation renderer cannot draw it "
                            "(rewrite it with elementary functions, or render it with variant='points')") from None


def _glsl_body(fn: ParametricFunction, exprs) -> tuple[list[str], list[str]]:
    """Lines that load the parameters and compute CSE temporaries, and the final expressions."""
    lines = [f"    const float {_printer.doprint(s)} = pl_params[P + {i}u];"
             for i, s in enumerate(fn.param_symbols)]
    replacements, reduced = sp.cse(list(exprs), symbols=sp.numbered_symbols("t"), optimizations="basic")
    for sym, e in replacements:
        lines.append(f"    const float {sym} = {glsl_expr(e, fn)};")
    return lines, [glsl_expr(e, fn) for e in reduced]


def glsl_function_source(fn: ParametricFunction, index: int) -> str:
    """GLSL for one function: position-only and position-with-partials entry points."""
    head = f"// {fn.name} (from {fn.source})\n"
    lines, (x, y, z) = _glsl_body(fn, fn.exprs)
    pos = (f"vec3 pl_pos_{index}(float u, float v, uint P) {{\n"
           + "\n".join(lines) + f"\n    return vec3({x}, {y}, {z});\n}}\n")
    lines, r = _glsl_body(fn, [*fn.exprs, *fn.du, *fn.dv])
    surf = (f"void pl_surf_{index}(float u, float v, uint P, out vec3 pos, out vec3 du, out vec3 dv) {{\n"
            + "\n".join(lines)
            + f"\n    pos = vec3({r[0]}, {r[1]}, {r[2]});"
            + f"\n    du = vec3({r[3]}, {r[4]}, {r[5]});"
            + f"\n    dv = vec3({r[6]}, {r[7]}, {r[8]});\n}}\n")
    return head + pos + surf


def glsl_dispatch_source(functions: list[ParametricFunction]) -> str:
    """All functions of a scene plus the dispatchers the shaders call."""
    functions = list(functions)
    parts = [glsl_function_source(f, i) for i, f in enumerate(functions)]
    cases_p = "".join(f"        case {i}u: return pl_pos_{i}(u, v, P);\n" for i in range(len(functions)))
    cases_s = "".join(f"        case {i}u: pl_surf_{i}(u, v, P, pos, du, dv); return;\n"
                      for i in range(len(functions)))
    parts.append(
        "vec3 pl_position(uint func, float u, float v, uint P) {\n"
        f"    switch (func) {{\n{cases_p}        default: break;\n    }}\n"
        "    return vec3(PL_NAN);\n}\n")
    parts.append(
        "void pl_surface(uint func, float u, float v, uint P, out vec3 pos, out vec3 du, out vec3 dv) {\n"
        f"    switch (func) {{\n{cases_s}        default: break;\n    }}\n"
        "    pos = vec3(PL_NAN); du = vec3(PL_NAN); dv = vec3(PL_NAN);\n}\n")
    return "\n".join(parts)
