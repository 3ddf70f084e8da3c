"""Code generation: sympy expressions -> OpenCL C (single precision, with common-subexpression
elimination). The numpy side is sympy.lambdify (see ``define.py``).

For each function index i the generated source defines

    float3 pl_pos_i(float u, float v, __global const float* P)
    void   pl_surf_i(float u, float v, __global const float* P, float3* pos, float3* du, float3* dv)

and two dispatchers ``pl_position(func, ...)`` / ``pl_surface(func, ...)`` that switch on the index,
which the kernels in ``kernels/`` call; and the surface split (``split_surface``): ``pl_axis_i`` /
``pl_rest_i`` with the dispatchers ``pl_split``, ``pl_surface_axis`` and ``pl_surface_rest``; the
same of the position-only code (``position_split``): ``pl_paxis_i`` / ``pl_prest_i`` with
``pl_position_split``, ``pl_position_axis`` and ``pl_position_rest``.

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
    local_type = "float"         # type of generated temporaries (a sincos's cosine is declared apart)
    local_decl = "const float"   # declaration of generated temporaries
    bool_decl = "const int"      # ... of temporaries that hold a condition (GLSL: "const bool")
    param_read = "P[{}]"         # expression that reads float k of the parameter block

    def __init__(self, settings=None):
        # no math macros (M_PI_2, M_SQRT2, ...): they are double constants in C, absent in GLSL
        super().__init__({"strict": True, "math_macros": {}, **(settings or {})})

    def _lit(self, x: float) -> str:
        return f"{float(x)!r}{self.float_suffix}"

    def _int(self, n: int) -> str:   # an integer argument (pown's exponent)
        return str(n)

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
            mag = "*".join([b] * abs(n)) if abs(n) <= 4 else f"{n_['pown']}({self._print(base)}, {self._int(abs(n))})"
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

    def _print_SqrtOf(self, expr):
        return f"{self.names['sqrt']}({self._print(expr.args[0])})"

    def _print_RsqrtOf(self, expr):
        return f"{self.names['rsqrt']}({self._print(expr.args[0])})"

    def _print_Min(self, expr):
        return self._minmax(expr, "min")

    def _print_Max(self, expr):
        return self._minmax(expr, "max")


_printer = CLPrinter()


def cl_expr(expr) -> str:
    return _printer.doprint(expr)


def print_checked(printer: CLPrinter, expr, fn: ParametricFunction) -> str:
    try:
        return printer.doprint(expr)
    except PrintMethodNotImplementedError as exc:
        what = str(exc).split(":")[-1].split("\n")[0].strip() or str(exc)
        raise FunctionError(f"plugin '{fn.name}' ({fn.where}): uses {what}, which has no equivalent in the "
                            f"generated GPU code; rewrite it with elementary functions or use a snippet "
                            f"function") from None


def param_lines(fn: ParametricFunction, printer: CLPrinter = _printer) -> list[str]:
    """Lines that load the device parameter block into the sympy parameter symbols and the
    hoisted values (ParametricFunction.hoisted, after the parameters)."""
    return [f"    {printer.local_decl} {printer.doprint(s)} = {printer.param_read.format(i)};"
            for i, s in enumerate((*fn.param_symbols, *(h for h, _ in fn.hoisted)))]


# --- lowering: one shared program per call --------------------------------------------------------
class SqrtOf(sp.Function):
    """sqrt(x) kept as one node, so that CSE shares it between x**(1/2) and x**(3/2) = x*sqrt(x)."""
    nargs = 1


class RsqrtOf(sp.Function):
    """1/sqrt(x) as one node: x**(-3/2) = rsqrt(x)**3 shares the rsqrt of x**(-1/2) (the derivative
    of a normalisation), where ``pow(x, 1.5f)`` in a denominator costs a pow and a division."""
    nargs = 1


def _half_power(p):
    n = int(p.exp.p)  # exponent n/2, n odd
    if n > 0:
        return p.base ** ((n - 1) // 2) * SqrtOf(p.base)
    return RsqrtOf(p.base) ** (-n)


def _prepare(e):
    """Before CSE: constants as floats (pi*(1/180)*x folds to one literal, pi**-2 to one number)
    and half-integer powers through sqrt/rsqrt nodes."""
    consts = {a: sp.Float(a.evalf(20), 20) for a in e.atoms(sp.NumberSymbol)}
    if consts:
        e = e.xreplace(consts)
    return e.replace(lambda x: x.is_Pow and x.exp.is_Rational and x.exp.q == 2, _half_power)


class SinCos:
    """One sincos(arg) that defines both ``s`` = sin(arg) and ``c`` = cos(arg)."""
    __slots__ = ("s", "c", "arg")

    def __init__(self, s, c, arg):
        self.s, self.c, self.arg = s, c, arg


class Lowered:
    """What one generated call computes: ``steps`` in order (``(symbol, expr)`` definitions and
    ``SinCos`` pairs), then ``outputs`` (expressions over the steps' symbols). Printed by
    ``function_body`` and counted by ``count_flops``, so the count is the count of the printed code."""

    def __init__(self, steps, outputs):
        self.steps, self.outputs = list(steps), list(outputs)


def _lift_power_bases(exprs, gen):
    """x**n with a compound x prints as x*x*...: give x its own temporary, so it is evaluated once."""
    new, cache = [], {}

    def rec(x):
        if x.is_Atom:
            return x
        args = tuple(rec(a) for a in x.args)
        y = x if args == x.args else x.func(*args)
        if y.is_Pow and y.exp.is_Integer and abs(int(y.exp)) >= 2 and not y.base.is_Atom:
            if y.base not in cache:
                cache[y.base] = next(gen)
                new.append((cache[y.base], y.base))
            return sp.Pow(cache[y.base], y.exp, evaluate=False)
        return y

    return [rec(e) for e in exprs], new


def lower(exprs, bindings=(), optimize: bool = True, sincos: bool = False) -> Lowered:
    """The steps that compute ``bindings`` (symbol, expr) and ``exprs``.

    ``optimize``: one CSE over the bindings and outputs together (bindings otherwise repeat their
    shared subexpressions: sin(u) in five of them, the same exp() in position and partials), constants
    folded, half powers through sqrt/rsqrt, compound power bases once, dead steps dropped, and with
    ``sincos`` (OpenCL) sin and cos of one argument from one sincos. ``optimize=False`` is the
    generator before this (bindings verbatim, CSE of the outputs only), kept for the benchmark's
    before/after.
    """
    exprs, bindings = list(exprs), list(bindings)
    gen = sp.numbered_symbols("t")
    if not optimize:
        replacements, reduced = sp.cse(exprs, symbols=gen)
        return Lowered(bindings + list(replacements), reduced)
    names = [s for s, _ in bindings]
    values = [_prepare(e) for _, e in bindings] + [_prepare(sp.sympify(e)) for e in exprs]
    replacements, reduced = sp.cse(values, symbols=gen)
    defs = dict(replacements)
    defs.update(zip(names, reduced[:len(names)]))
    outputs = list(reduced[len(names):])
    order = [s for s, _ in replacements] + names   # temporaries first: they never need a later binding
    keys = list(defs)
    lifted, extra = _lift_power_bases([defs[k] for k in keys] + outputs, gen)
    defs = dict(zip(keys, lifted[:len(keys)]))
    outputs = lifted[len(keys):]
    for k, e in extra:
        defs[k] = e
    order = [k for k, _ in extra] + order
    pairs = {}
    if sincos:
        every = [*defs.values(), *outputs]
        sins = {a.args[0] for e in every for a in e.atoms(sp.sin)}
        coss = {a.args[0] for e in every for a in e.atoms(sp.cos)}
        both = sorted(sins & coss, key=sp.default_sort_key)
        mapping = {}
        for i, arg in enumerate(both):
            s_, c_ = sp.Symbol(f"s{i}", real=True), sp.Symbol(f"c{i}", real=True)
            mapping[sp.sin(arg)], mapping[sp.cos(arg)] = s_, c_
            pairs[s_] = pairs[c_] = (s_, c_, arg)
        if mapping:
            defs = {k: e.xreplace(mapping) for k, e in defs.items()}
            outputs = [e.xreplace(mapping) for e in outputs]
            pairs = {k: (s_, c_, a.xreplace(mapping)) for k, (s_, c_, a) in pairs.items()}
    # aliases (a temporary that is just another symbol or a number, e.g. t3 = sin(x) after sincos)
    alias = {k: e for k, e in defs.items() if e.is_Atom}
    while alias:
        for k in alias:  # chains (b0 = t0, t0 = c0 after sincos) resolve to their end
            while alias[k] in alias:
                alias[k] = alias[alias[k]]
        defs = {k: e.xreplace(alias) for k, e in defs.items() if k not in alias}
        outputs = [e.xreplace(alias) for e in outputs]
        pairs = {k: (s_, c_, a.xreplace(alias)) for k, (s_, c_, a) in pairs.items()}
        alias = {k: e for k, e in defs.items() if e.is_Atom}
    order = [k for k in order if k in defs]

    def deps(k):
        e = pairs[k][2] if k in pairs else defs[k]
        return [d for d in e.free_symbols if d in defs or d in pairs]

    # live steps in an order where each follows what it reads (iterative DFS: SH glyphs chain hundreds)
    rank = {k: i for i, k in enumerate(order)}
    for i, k in enumerate(sorted(pairs, key=str)):
        rank.setdefault(k, len(order) + i)
    steps, done = [], set()
    roots = sorted({d for e in outputs for d in e.free_symbols if d in defs or d in pairs}, key=rank.get)
    for root in roots:
        stack = [(root, False)]
        while stack:
            k, expanded = stack.pop()
            if k in done:
                continue
            if expanded:
                done.add(k)
                if k in pairs:
                    s_, c_, arg = pairs[k]
                    done.update((s_, c_))
                    steps.append(SinCos(s_, c_, arg))
                else:
                    steps.append((k, defs[k]))
                continue
            stack.append((k, True))
            stack.extend((d, False) for d in sorted(deps(k), key=rank.get, reverse=True) if d not in done)
    return Lowered(steps, outputs)


def function_body(fn: ParametricFunction, exprs, printer: CLPrinter = _printer,
                  bindings=(), optimize: bool = True, sincos: bool = False) -> tuple[list[str], list[str]]:
    """Lines that compute ``bindings`` and ``exprs`` (see ``lower``), and the final expressions.
    Backend-neutral apart from the printer and ``sincos`` (OpenCL only): the GLSL printer reuses it
    with ``fn.program("position")`` or ``fn.program("surface")``.
    """
    low = lower(exprs, bindings, optimize=optimize, sincos=sincos)
    return step_lines(fn, low.steps, printer), [print_checked(printer, e, fn) for e in low.outputs]


def step_lines(fn: ParametricFunction, steps, printer: CLPrinter = _printer) -> list[str]:
    """One declaration line per step (two for a SinCos)."""
    lines = []
    for step in steps:
        if isinstance(step, SinCos):
            lines.append(f"    {printer.local_type} {step.c};")
            lines.append(f"    {printer.local_decl} {step.s} = sincos({print_checked(printer, step.arg, fn)}, &{step.c});")
        else:
            sym, e = step
            decl = printer.bool_decl if isinstance(e, sp.logic.boolalg.Boolean) else printer.local_decl
            lines.append(f"    {decl} {printer.doprint(sym)} = {print_checked(printer, e, fn)};")
    return lines


# --- the surface split along one parameter ----------------------------------------------------------
# A point renderer samples a patch on a grid, so the steps that read only one parameter (the
# centreline of a fibre or a yarn: 591 of the fibre's 595 operations; the Legendre terms of an SH
# glyph: 1083 of 1519) are the same along a grid line. ``split_surface`` separates them, so that a
# work-item computes them once per grid line (pl_surface_axis) and then the rest per sample
# (pl_surface_rest) along a run of that line. Both parts are the steps of pl_surf_i, in its order, so
# the values are those of pl_surface.
SPLIT_MIN_OPS = 16   # below this many operations on the axis alone, a split saves less than it costs
SPLIT_NONE, SPLIT_U, SPLIT_V = 0, 1, 2   # pl_split(func): no split, the axis steps read u / read v


class SplitSurface:
    """``axis`` (SPLIT_U / SPLIT_V): the steps of pl_surf_i that read only that parameter
    (``axis_steps``), the ones of them the others read (``carried``, in order), and the others
    (``rest_steps``) with ``outputs``; ``ops``: sympy's operation count of the axis steps."""

    def __init__(self, axis, axis_steps, carried, rest_steps, outputs, ops):
        self.axis, self.axis_steps, self.carried = axis, axis_steps, carried
        self.rest_steps, self.outputs, self.ops = rest_steps, outputs, ops


def _step_symbols(step):
    return (step.s, step.c) if isinstance(step, SinCos) else (step[0],)


def _step_expr(step):
    return step.arg if isinstance(step, SinCos) else step[1]


def split_surface(fn: ParametricFunction, low: Lowered) -> SplitSurface | None:
    """The split of the lowered surface steps along the parameter whose steps alone cost more, or
    None when those cost fewer than SPLIT_MIN_OPS operations."""
    reads = {}   # step symbol -> the parameters (u, v) it reads, directly or through other steps
    for step in low.steps:
        r = set()
        for s in _step_expr(step).free_symbols:
            r |= {s} if s in (fn.u, fn.v) else reads.get(s, set())
        for s in _step_symbols(step):
            reads[s] = r
    best = None
    for axis, param in ((SPLIT_U, fn.u), (SPLIT_V, fn.v)):
        ops = sum(sp.count_ops(_step_expr(st)) + isinstance(st, SinCos)
                  for st in low.steps if reads[_step_symbols(st)[0]] == {param})
        if ops >= SPLIT_MIN_OPS and (best is None or ops > best[2]):
            best = (axis, param, ops)
    if best is None:
        return None
    axis, param, ops = best
    # steps of the function's parameters alone (reading neither u nor v) go into both parts
    axis_steps = [st for st in low.steps if reads[_step_symbols(st)[0]] <= {param}]
    rest = [st for st in low.steps if reads[_step_symbols(st)[0]] != {param}]
    read = set().union(*(_step_expr(st).free_symbols for st in rest), *(e.free_symbols for e in low.outputs))
    carried = [s for st in axis_steps if reads[_step_symbols(st)[0]] for s in _step_symbols(st) if s in read]
    return SplitSurface(axis, axis_steps, carried, rest, list(low.outputs), ops)


def check_printable(fn: ParametricFunction) -> None:
    """Raise a FunctionError naming the plugin when its expressions use a function no backend has."""
    if fn.exprs is None:
        return
    for e in [*fn.exprs, *(e for _, e in fn.bindings)]:
        print_checked(_printer, e, fn)


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


# generated source per function, index and optimize flag: functions never change after definition,
# and every program of a scene (LOD stage, renderers, eval) asks for the same code again
_sources: "weakref.WeakKeyDictionary[ParametricFunction, dict[tuple, str]]" = weakref.WeakKeyDictionary()


def cl_function_source(fn: ParametricFunction, index: int, optimize: bool = True) -> str:
    """OpenCL C for one function: position-only and position-with-partials entry points
    (``optimize=False``: the unoptimised generator, for before/after measurements)."""
    per_fn = _sources.setdefault(fn, {})
    key = (index, optimize)
    if key not in per_fn:
        per_fn[key] = _cl_function_source(fn, index, optimize)
    return per_fn[key]


def _cl_function_source(fn: ParametricFunction, index: int, optimize: bool = True) -> str:
    head = f"// {fn.name} (from {fn.source})\n"
    if fn.is_snippet:
        return head + _snippet_source(fn, index)
    loads = param_lines(fn)
    program = fn.device_program if optimize else fn.program   # unoptimised: parameter terms per sample too
    bindings, outputs = program("position")
    low_pos = lower(outputs, bindings, optimize=optimize, sincos=optimize)
    pos = _position_source(fn, f"pl_pos_{index}(float u, float v, __global const float* P)",
                           loads + step_lines(fn, low_pos.steps), low_pos.outputs)
    bindings, outputs = program("surface")
    low = lower(outputs, bindings, optimize=optimize, sincos=optimize)
    surf = _surface_source(fn, f"pl_surf_{index}(float u, float v, __global const float* P,",
                           loads + step_lines(fn, low.steps), low.outputs)
    if not optimize:
        return head + pos + surf
    _surface_lows[fn] = low
    split = _splits[fn] = split_surface(fn, low)
    split_pos = _position_splits[fn] = split_surface(fn, low_pos)
    return (head + pos + surf + (_split_source(fn, index, loads, split) if split else "")
            + (_split_source(fn, index, loads, split_pos, position=True) if split_pos else ""))


# the lowered surface code of each function and its splits (None: none), filled with its source
_surface_lows: "weakref.WeakKeyDictionary[ParametricFunction, Lowered]" = weakref.WeakKeyDictionary()
_splits: "weakref.WeakKeyDictionary[ParametricFunction, SplitSurface | None]" = weakref.WeakKeyDictionary()
_position_splits: "weakref.WeakKeyDictionary[ParametricFunction, SplitSurface | None]" = weakref.WeakKeyDictionary()


def surface_lowered(fn: ParametricFunction) -> Lowered:
    """The steps of ``pl_surf_i`` (``lower``'s result) as its generated source has them: lowered
    once per function, with its source."""
    if fn not in _surface_lows:
        cl_function_source(fn, 0)
    return _surface_lows[fn]


def surface_split(fn: ParametricFunction) -> SplitSurface | None:
    """The split the generated code of ``fn`` has (None: pl_surface_rest calls pl_surf_i)."""
    if fn.is_snippet:
        return None
    if fn not in _splits:
        cl_function_source(fn, 0)
    return _splits[fn]


def position_split(fn: ParametricFunction) -> SplitSurface | None:
    """The split of the position-only code of ``fn`` (None: pl_position_rest calls pl_pos_i); its
    axis may differ from the surface split's."""
    if fn.is_snippet:
        return None
    if fn not in _position_splits:
        cl_function_source(fn, 0)
    return _position_splits[fn]


def _position_source(fn, head: str, lines, outputs) -> str:
    x, y, z = (print_checked(_printer, e, fn) for e in outputs)
    return f"inline float3 {head} {{\n" + "\n".join(lines) + f"\n    return (float3)({x}, {y}, {z});\n}}\n"


def _surface_source(fn, head: str, lines, outputs) -> str:
    r = [print_checked(_printer, e, fn) for e in outputs]
    return (f"inline void {head} float3* pos, float3* du, float3* dv) {{\n" + "\n".join(lines)
            + f"\n    *pos = (float3)({r[0]}, {r[1]}, {r[2]});"
            + f"\n    *du = (float3)({r[3]}, {r[4]}, {r[5]});"
            + f"\n    *dv = (float3)({r[6]}, {r[7]}, {r[8]});\n}}\n")


def _split_source(fn: ParametricFunction, index: int, loads, split: SplitSurface, position: bool = False) -> str:
    """pl_axis_i (the axis steps; the carried values stored in C) and pl_rest_i (the carried values
    loaded from C, the other steps, the outputs); pl_paxis_i and pl_prest_i for the position-only
    code (``position``)."""
    name = _printer.doprint(fn.u if split.axis == SPLIT_U else fn.v)
    conditions = {st[0] for st in split.axis_steps
                  if not isinstance(st, SinCos) and isinstance(st[1], sp.logic.boolalg.Boolean)}
    store, load = [], []
    for k, sym in enumerate(split.carried):
        name_k = _printer.doprint(sym)
        if sym in conditions:   # a condition travels as 0 or 1
            store.append(f"    C[{k}] = {name_k} ? 1.0f : 0.0f;")
            load.append(f"    {_printer.bool_decl} {name_k} = C[{k}] != 0.0f;")
        else:
            store.append(f"    C[{k}] = {name_k};")
            load.append(f"    const float {name_k} = C[{k}];")
    p = "p" if position else ""
    axis = (f"inline void pl_{p}axis_{index}(float {name}, __global const float* P, float* C) {{\n"
            + "\n".join(loads + step_lines(fn, split.axis_steps) + store) + "\n}\n")
    lines = loads + load + step_lines(fn, split.rest_steps)
    if position:
        return axis + _position_source(fn, f"pl_prest_{index}(float u, float v, __global const float* P, const float* C)",
                                       lines, split.outputs)
    return axis + _surface_source(fn, f"pl_rest_{index}(float u, float v, __global const float* P, const float* C,",
                                  lines, split.outputs)


def cl_dispatch_source(functions: list[ParametricFunction], optimize: bool = True) -> str:
    """All functions of a scene plus the dispatchers the kernels call."""
    parts = []
    if any(f.is_snippet for f in functions):
        parts.append(kernels.source("common/dialect.cl"))
    parts += [cl_function_source(f, i, optimize) for i, f in enumerate(functions)]
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
    parts.append(_split_dispatch(functions, optimize))
    return "\n".join(parts)


def _axis_dispatch(splits, split_name: str, axis_name: str, axis_fn: str) -> str:
    """``split_name``(func), the axis of ``splits`` (one per function, None: none), and
    ``axis_name``(func, a, P, C), which calls ``axis_fn``_i."""
    kinds = "".join(f"        case {i}: return {s.axis}u;\n" for i, s in enumerate(splits) if s)
    axis = "".join(f"        case {i}: {axis_fn}_{i}(a, P, C); return;\n" for i, s in enumerate(splits) if s)
    return (f"inline uint {split_name}(uint func) {{\n    switch (func) {{\n{kinds}    }}\n    return 0u;\n}}\n"
            f"inline void {axis_name}(uint func, float a, __global const float* P, float* C) {{\n"
            f"    switch (func) {{\n{axis}    }}\n}}\n")


def _split_dispatch(functions: list[ParametricFunction], optimize: bool) -> str:
    """pl_split(func) (SPLIT_NONE / SPLIT_U / SPLIT_V), pl_surface_axis and pl_surface_rest; the
    same for the position-only code (pl_position_split, pl_position_axis, pl_position_rest); and
    PL_SPLIT_FLOATS (the carried values of the largest split: the size of C)."""
    splits = [surface_split(f) if optimize else None for f in functions]
    psplits = [position_split(f) if optimize else None for f in functions]
    floats = max([1] + [len(s.carried) for s in splits + psplits if s])
    rest = "".join(f"        case {i}: pl_rest_{i}(u, v, P, C, pos, du, dv); return;\n" if s else
                   f"        case {i}: pl_surf_{i}(u, v, P, pos, du, dv); return;\n" for i, s in enumerate(splits))
    prest = "".join(f"        case {i}: return pl_prest_{i}(u, v, P, C);\n" if s else
                    f"        case {i}: return pl_pos_{i}(u, v, P);\n" for i, s in enumerate(psplits))
    return (f"#define PL_SPLIT_U {SPLIT_U}u\n#define PL_SPLIT_V {SPLIT_V}u\n#define PL_SPLIT_FLOATS {floats}\n"
            + _axis_dispatch(splits, "pl_split", "pl_surface_axis", "pl_axis")
            + "inline void pl_surface_rest(uint func, float u, float v, __global const float* P, const float* C,"
            " float3* pos, float3* du, float3* dv) {\n"
            f"    switch (func) {{\n{rest}    }}\n"
            "    *pos = *du = *dv = (float3)(NAN, NAN, NAN);\n}\n"
            + _axis_dispatch(psplits, "pl_position_split", "pl_position_axis", "pl_paxis")
            + "inline float3 pl_position_rest(uint func, float u, float v, __global const float* P, const float* C) {\n"
            f"    switch (func) {{\n{prest}    }}\n    return (float3)(NAN, NAN, NAN);\n}}\n")
