"""Code generation: sympy expressions (or dialect snippets) -> GLSL 4.50 for the tessellation renderer.

The GLSL twin of ``codegen_cl.py``, built on the same pieces (``CLPrinter`` retargeted through its
``names`` table, ``function_body`` with the same common-subexpression elimination, the snippet
dialect of ``kernels/dialect.glsl``). For each function index i it defines

    vec3 pl_pos_i(float u, float v, uint P)
    void pl_surf_i(float u, float v, uint P, out vec3 pos, out vec3 du, out vec3 dv)

and two dispatchers ``pl_position(func, u, v, P)`` / ``pl_surface(func, u, v, P, pos, du, dv)``
that switch on the function index. ``P`` is the instance's offset into the shader storage buffer
``float pl_params[]`` declared in ``kernels/tess_common.glsl`` (the scene's flat parameter array,
``Scene.instance_buffers()``), so array parameters such as 91 SH coefficients cost nothing extra.
Partials are analytic (sympy) for expression functions and central differences with the
function's steps for snippet functions, exactly as in the OpenCL code.
"""
from __future__ import annotations

import math

from sympy.printing.c import known_functions_C99
from sympy.printing.codeprinter import PrintMethodNotImplementedError

from paramlod import kernels
from paramlod.errors import FunctionError
from paramlod.function.codegen_cl import CLPrinter, function_body, param_lines, snippet_body
from paramlod.function.define import ParametricFunction

# sympy function name -> GLSL 4.50 built-in (float in, float out)
GLSL_FUNCTIONS = {
    "sin": "sin", "cos": "cos", "tan": "tan", "asin": "asin", "acos": "acos", "atan": "atan",
    "sinh": "sinh", "cosh": "cosh", "tanh": "tanh", "asinh": "asinh", "acosh": "acosh", "atanh": "atanh",
    "exp": "exp", "log": "log", "sqrt": "sqrt", "floor": "floor", "ceiling": "ceil",
    "Abs": "abs", "sign": "sign", "exp2": "exp2", "log2": "log2",
}


def glsl_literal(x: float) -> str:
    """A float literal GLSL accepts (no suffix; infinities as 1/0)."""
    x = float(x)
    if math.isnan(x):
        return "uintBitsToFloat(0x7fc00000u)"
    if math.isinf(x):
        return "(1.0 / 0.0)" if x > 0 else "(-1.0 / 0.0)"
    s = repr(x)
    if "e" in s:
        mant, exp = s.split("e")
        return f"{mant if '.' in mant else mant + '.0'}e{exp}"
    return s


class GLSLPrinter(CLPrinter):
    """``CLPrinter`` retargeted to GLSL 4.50 (single precision)."""

    names = {**CLPrinter.names, "min": "min", "max": "max", "abs": "abs", "pown": "pl_pown",
             "rsqrt": "inversesqrt", "cbrt": "pl_cbrt", "atan2": "atan"}
    float_suffix = ""
    local_decl = "const float"
    bool_decl = "const bool"
    param_read = "pl_params[P + {}u]"
    _kf = GLSL_FUNCTIONS
    language = "GLSL"

    def __init__(self, settings=None):
        super().__init__(settings)
        self.known_functions = dict(GLSL_FUNCTIONS)

    def _lit(self, x) -> str:
        return glsl_literal(float(x))

    def _print_BooleanTrue(self, expr):
        return "true"

    def _print_BooleanFalse(self, expr):
        return "false"


def _no_glsl_form(self, expr, **kwargs):
    raise PrintMethodNotImplementedError(f"Unsupported by GLSL: {type(expr).__name__}")


# C99 math functions that GLSL lacks (erf, gamma, hypot, log10 ...): a clear error, not C code
for _name in set(known_functions_C99) - set(GLSL_FUNCTIONS):
    if f"_print_{_name}" not in CLPrinter.__dict__:
        setattr(GLSLPrinter, f"_print_{_name}", _no_glsl_form)

_printer = GLSLPrinter()


def glsl_expr(expr) -> str:
    return _printer.doprint(expr)


def _snippet_source(fn: ParametricFunction, index: int, position: bool, surface: bool) -> str:
    hu, hv = fn.snippet.fd_step
    snip = f"vec3 pl_snip_{index}(float u, float v, uint P) {{\n" + snippet_body(fn, "PARAM({})")
    pos = f"vec3 pl_pos_{index}(float u, float v, uint P) {{\n    return pl_snip_{index}(u, v, P);\n}}\n"
    surf = (f"void pl_surf_{index}(float u, float v, uint P, out vec3 pos, out vec3 du, out vec3 dv) {{\n"
            f"    const float hu = {glsl_literal(hu)}, hv = {glsl_literal(hv)};\n"
            f"    pos = pl_snip_{index}(u, v, P);\n"
            f"    du = (pl_snip_{index}(u + hu, v, P) - pl_snip_{index}(u - hu, v, P)) * (0.5 / hu);\n"
            f"    dv = (pl_snip_{index}(u, v + hv, P) - pl_snip_{index}(u, v - hv, P)) * (0.5 / hv);\n}}\n")
    return snip + (pos if position else "") + (surf if surface else "")


def _program_of(fn: ParametricFunction, which: str):
    """(bindings, outputs) of ``fn`` for "position" (3 outputs) or "surface" (9: f, df/du, df/dv),
    the same program the OpenCL code is generated from."""
    return fn.device_program(which)


def glsl_function_source(fn: ParametricFunction, index: int, position: bool = True, surface: bool = True) -> str:
    """GLSL for one function: the position-only and/or the position-with-partials entry point
    (a shader stage gets only what it calls: large functions compile slowly on llvmpipe)."""
    head = f"// {fn.name} (from {fn.source})\n"
    if fn.is_snippet:
        return head + _snippet_source(fn, index, position, surface)
    loads = param_lines(fn, _printer)
    pos = ""
    if position:
        bindings, outputs = _program_of(fn, "position")
        lines, (x, y, z) = function_body(fn, outputs, _printer, bindings=bindings)
        pos = (f"vec3 pl_pos_{index}(float u, float v, uint P) {{\n"
               + "\n".join(loads + lines) + f"\n    return vec3({x}, {y}, {z});\n}}\n")
    if not surface:
        return head + pos
    bindings, outputs = _program_of(fn, "surface")
    lines, r = function_body(fn, outputs, _printer, bindings=bindings)
    surf = (f"void pl_surf_{index}(float u, float v, uint P, out vec3 pos, out vec3 du, out vec3 dv) {{\n"
            + "\n".join(loads + lines)
            + f"\n    pos = vec3({r[0]}, {r[1]}, {r[2]});"
            + f"\n    du = vec3({r[3]}, {r[4]}, {r[5]});"
            + f"\n    dv = vec3({r[6]}, {r[7]}, {r[8]});\n}}\n")
    return head + pos + surf


def glsl_dispatch_source(functions, position: bool = True, surface: bool = True) -> str:
    """All functions of a scene plus the dispatchers the shaders call (``pl_position`` and/or
    ``pl_surface``). A function that uses something GLSL lacks is a FunctionError naming it."""
    functions = list(functions)
    parts = []
    if any(f.is_snippet for f in functions):
        parts.append("#define PARAM(k) pl_params[P + uint(k)]\n" + kernels.source("common/dialect.glsl"))
    try:
        parts += [glsl_function_source(f, i, position, surface) for i, f in enumerate(functions)]
    except FunctionError as exc:
        raise FunctionError(f"{exc} (while generating GLSL for the tessellation renderer; "
                            "variant='points' does not need GLSL)") from None
    cases_p = "".join(f"        case {i}u: return pl_pos_{i}(u, v, P);\n" for i in range(len(functions)))
    cases_s = "".join(f"        case {i}u: pl_surf_{i}(u, v, P, pos, du, dv); return;\n"
                      for i in range(len(functions)))
    if position:
        parts.append(
            "vec3 pl_position(uint func, float u, float v, uint P) {\n"
            f"    switch (func) {{\n{cases_p}        default: break;\n    }}\n"
            "    return vec3(NAN);\n}\n")
    if surface:
        parts.append(
            "void pl_surface(uint func, float u, float v, uint P, out vec3 pos, out vec3 du, out vec3 dv) {\n"
            f"    switch (func) {{\n{cases_s}        default: break;\n    }}\n"
            "    pos = vec3(NAN); du = vec3(NAN); dv = vec3(NAN);\n}\n")
    return "\n".join(parts)
