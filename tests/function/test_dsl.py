"""The helpers of paramlod.dsl and the code generation behind them: every helper's expressions
compile to single-precision OpenCL C that matches numpy; vectors, Bezier curves, Frenet frames,
tubes and noise against independent numpy formulas; implicit time, array parameters, ``let``;
snippet functions on OpenCL, against their numpy reference, and as GLSL."""
import re

import numpy as np
import pytest
import sympy as sp
from sympy import Abs, Max, Min, Mod, atan2, cos, exp, floor, frac, log, pi, sign, sin, sqrt

import paramlod as pl
from paramlod import dsl
from paramlod.function.codegen_cl import cl_function_source
from paramlod.function.plugins import evaluate_cl


# --- functions used by several tests (defined once, compiled together once) ----------------------
@pl.parametric(u=(-2, 2), v=(-2, 2), params={"k": 1.5})
def kitchen_sink(u, v, k):
    """Every construct the printer must handle."""
    x = dsl.where((u > 0) & (v < 1), u * k, -u / 3) + dsl.clamp(v, -1, 1) + dsl.step(0.5, u)
    y = dsl.smoothstep(-1, 1, u) + dsl.mix(u, v, 0.25) + dsl.fract(u * 2.5) + dsl.mod(v, 0.7) + Mod(u, 1.3)
    z = (atan2(v, u + 3) + Abs(u - v) + Min(u, v, 0.5) + Max(u * v, -1) + floor(u * v) + frac(v)
         + sign(u) + exp(-u * u) + log(u + 3) + sqrt(v + 3) + (u + 3) ** sp.Rational(1, 3)
         + (v + 3) ** -sp.Rational(1, 2) + u ** 5 + pi * sp.E + sp.Rational(2, 7) * v)
    return x, y, z


@pl.parametric(u=(-20, 20), v=(-20, 20), params={"scale": 0.37})
def noisy(u, v, scale):
    """Value noise and fbm on a plane."""
    return u, v, dsl.noise(u * scale, v * scale, 0.3) + 0.5 * dsl.fbm(u, v, octaves=3)


@pl.parametric(u=(-3, 3), v=(0, 1))
def noise_line(u, v):
    """Noise along one line (noise builds large trees outside a body: use it inside one)."""
    return u, v, dsl.noise(u, 0.5, 0.25)


@pl.parametric(u=(0, 1), v=(0, 2 * pi), params={"amp": 0.2, "waves": 3.0}, snippet="""
    float h = 0.0f;
    for (int k = 1; k <= 3; k++) {
        h += amp / FLOAT(k) * sin(waves * FLOAT(k) * 2.0f * PI * u);
    }
    vec3 ring = VEC3(cos(v), sin(v), 0.0f) * (1.0f + h);
    return ring + VEC3(0.0f, 0.0f, MOD(u * 3.0f, 1.0f) * 0.1f + ABS(h) + ATAN2(u, 1.0f) * 0.01f);
""")
def ripple_snippet(u, v, amp, waves):
    """Snippet function and its numpy reference."""
    h = sum(amp / k * np.sin(waves * k * 2 * np.pi * u) for k in (1, 2, 3))
    r = 1 + h
    return r * np.cos(v), r * np.sin(v), np.mod(u * 3, 1) * 0.1 + np.abs(h) + np.arctan2(u, 1) * 0.01


@pl.parametric(u=(0, 1), v=(0, 2 * pi), params={"amp": 0.2, "waves": 3.0})
def ripple_sympy(u, v, amp, waves):
    """The snippet's surface without the MOD/ABS/ATAN2 term, in sympy (for its exact normals)."""
    h = sum(amp / k * sin(waves * k * 2 * pi * u) for k in (1, 2, 3))
    return (1 + h) * cos(v), (1 + h) * sin(v), 0


@pl.parametric(u=(0, 1), v=(0, 2 * pi), params={"amp": 0.2, "waves": 3.0}, snippet="""
    float h = 0.0f;
    for (int k = 1; k <= 3; k++) {
        h += amp / FLOAT(k) * sin(waves * FLOAT(k) * 2.0f * PI * u);
    }
    return VEC3(cos(v), sin(v), 0.0f) * (1.0f + h);
""")
def ripple_plain_snippet(u, v, amp, waves):
    h = sum(amp / k * np.sin(waves * k * 2 * np.pi * u) for k in (1, 2, 3))
    return (1 + h) * np.cos(v), (1 + h) * np.sin(v), 0 * u


@pl.parametric(u=(0, 1), v=(0, 1), params={"coeffs": [0.5, -0.25, 0.125, 1.0]}, snippet="""
    float s = 0.0f;
    for (int i = 0; i < 4; i++) { s += PARAM_AT(coeffs, i) * pow(u, FLOAT(i)); }
    return VEC3(u, v, s * (1.0f + t));
""")
def poly_snippet(u, v, t, coeffs):
    """Array parameter and implicit time in a snippet."""
    s = sum(c * u ** i for i, c in enumerate(coeffs))
    return u, v, s * (1 + t)


FUNCS = [kitchen_sink, noisy, ripple_snippet, ripple_sympy, ripple_plain_snippet, poly_snippet]


def on_cl(fn, u, v, **params):
    return evaluate_cl(fn, u, v, functions=FUNCS, **params)


def grid(fn, n=41, inset=0.0):
    """A float32 grid; ``inset`` (a fraction of the domain) keeps its lines off round numbers."""
    (u0, u1), (v0, v1) = fn.u_range, fn.v_range
    u = np.linspace(u0 + inset * (u1 - u0), u1 - 0.7 * inset * (u1 - u0), n).astype(np.float32)
    v = np.linspace(v0 + 1.3 * inset * (v1 - v0), v1 - inset * (v1 - v0), n - 4).astype(np.float32)
    return np.meshgrid(u, v, indexing="ij")


# --- code generation ----------------------------------------------------------------------------
def test_every_construct_prints_as_single_precision_opencl():
    src = cl_function_source(kitchen_sink, 0)
    body = "\n".join(line for line in src.splitlines() if not line.startswith("//"))
    doubles = re.findall(r"(?<![\w.])\d+\.\d*(?:[eE][+-]?\d+)?(?![\w.])", body)
    assert not doubles, f"double literals in the generated code: {doubles[:5]}"
    for forbidden in ("M_PI", "M_E", "Heaviside", "Piecewise", "frac(", "Mod(", "fmod("):
        assert forbidden not in body
    for expected in ("fmin(", "fmax(", "floor(", "atan2(", "fabs(", "sign(", " ? "):
        assert expected in body
    u, v = grid(kitchen_sink, inset=0.00731)
    pos, du, dv, _ = on_cl(kitchen_sink, u, v)
    ref, rdu, rdv = kitchen_sink.surface(u.astype(np.float64), v.astype(np.float64))
    # floor/fract/step jump: float32 and float64 may fall on different sides right at a jump
    close = np.abs(pos - ref).max(axis=-1) <= 2e-5 * np.abs(ref).max()
    assert close.mean() > 0.99
    for a, b in ((du, rdu), (dv, rdv)):
        close = np.abs(a - b).max(axis=-1) <= 1e-4 * np.abs(b).max()
        assert close.mean() > 0.95


def test_derivatives_of_piecewise_constant_parts_are_zero():
    # floor/fract/sign contribute nothing to df/du; Min/Max pick the active branch
    u, v = 0.37, 0.81
    _, du, dv = kitchen_sink.surface(u, v)
    h = 1e-6
    num_du = (kitchen_sink.evaluate(u + h, v) - kitchen_sink.evaluate(u - h, v)) / (2 * h)
    num_dv = (kitchen_sink.evaluate(u, v + h) - kitchen_sink.evaluate(u, v - h)) / (2 * h)
    np.testing.assert_allclose(du, num_du, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(dv, num_dv, rtol=1e-5, atol=1e-5)


# --- helpers against numpy ----------------------------------------------------------------------
def test_vector_helpers_and_rodrigues_rotation():
    a, b = np.array([0.3, -1.2, 2.0]), np.array([1.5, 0.4, -0.7])
    assert float(dsl.dot(a, b)) == pytest.approx(a @ b)
    np.testing.assert_allclose(np.array(dsl.cross(a, b), float).ravel(), np.cross(a, b))
    assert float(dsl.length(a)) == pytest.approx(np.linalg.norm(a))
    np.testing.assert_allclose(np.array(dsl.normalize(b), float).ravel(), b / np.linalg.norm(b))
    axis, angle = np.array([1.0, 2.0, -0.5]), 0.83
    k = axis / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    R = np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K   # rotation matrix form
    got = np.array(dsl.rotate(a, axis, angle), float).ravel()
    np.testing.assert_allclose(got, R @ a, atol=1e-12)
    np.testing.assert_allclose(np.array(dsl.mix(a, b, 0.25), float).ravel(), 0.75 * a + 0.25 * b)
    assert np.array(dsl.vec3(2), float).ravel().tolist() == [2, 2, 2]


def test_bezier_of_any_degree_and_its_derivatives():
    rng = np.random.default_rng(2)
    t = sp.Symbol("t", real=True)
    for degree in (1, 2, 3, 6):
        pts = rng.normal(size=(degree + 1, 3))
        curve = sp.lambdify(t, dsl.bezier([tuple(p) for p in pts], t), "numpy")
        d1 = sp.lambdify(t, dsl.bezier_derivative([tuple(p) for p in pts], t), "numpy")
        d2 = sp.lambdify(t, dsl.bezier_derivative([tuple(p) for p in pts], t, order=2), "numpy")
        for s in (0.0, 0.3, 0.77, 1.0):
            q = pts.copy()   # de Casteljau
            for r in range(degree):
                q = (1 - s) * q[:-1] + s * q[1:]
            np.testing.assert_allclose(np.ravel(curve(s)), q[0], atol=1e-12)
            h = 1e-5
            num = (np.ravel(curve(s + h)) - np.ravel(curve(s - h))) / (2 * h)
            np.testing.assert_allclose(np.ravel(d1(s)), num, atol=1e-6)
            num2 = (np.ravel(d1(s + h)) - np.ravel(d1(s - h))) / (2 * h)
            np.testing.assert_allclose(np.broadcast_to(np.ravel(d2(s)), (3,)), num2, atol=1e-5)
    # scalar control points give a scalar curve
    assert float(dsl.bezier([0, 1, 1, 0], sp.Rational(1, 2))) == pytest.approx(0.75)


def test_frenet_frame_and_tube_of_a_helix():
    c = 0.4
    helix = lambda s: dsl.vec3(cos(s), sin(s), c * s)  # noqa: E731
    t = sp.Symbol("t", real=True)
    T, N, B = (sp.lambdify(t, e, "numpy") for e in dsl.frenet_frame(helix, t))
    for s in (0.0, 1.1, 2.5):
        tan = np.array([-np.sin(s), np.cos(s), c]) / np.hypot(1, c)
        nrm = np.array([-np.cos(s), -np.sin(s), 0.0])     # towards the axis
        np.testing.assert_allclose(np.ravel(T(s)), tan, atol=1e-12)
        np.testing.assert_allclose(np.ravel(N(s)), nrm, atol=1e-12)
        np.testing.assert_allclose(np.ravel(B(s)), np.cross(tan, nrm), atol=1e-12)

    @pl.parametric(u=(0, 4 * pi), v=(0, 2 * pi), params={"r": 0.15})
    def helix_tube(u, v, r):
        return tuple(dsl.tube(helix, u, v, r))

    s = np.linspace(0, 4 * np.pi, 25)[:, None]
    a = np.linspace(0, 2 * np.pi, 16)[None, :]
    p = helix_tube.evaluate(s, a)
    centre = np.stack([np.cos(s), np.sin(s), c * s], -1)
    np.testing.assert_allclose(np.linalg.norm(p - centre, axis=-1), 0.15, rtol=1e-7)  # 0.15 as float32
    tan = np.stack([-np.sin(s), np.cos(s), np.full_like(s, c)], -1)
    assert np.abs(np.sum((p - centre) * tan, -1)).max() < 1e-9
    assert helix_tube.bindings   # frenet_frame/tube name their pieces with let


def test_noise_is_smooth_bounded_and_identical_on_every_backend():
    u, v = grid(noisy, 61)
    pos, du, dv, _ = on_cl(noisy, u, v)
    ref, rdu, _ = noisy.surface(u.astype(np.float64), v.astype(np.float64))
    assert np.abs(pos - ref).max() < 2e-6   # the lattice hash is exact in float32
    np.testing.assert_allclose(du, rdu, atol=2e-4)
    z = ref[..., 2]
    assert z.std() > 0.1 and np.abs(z).max() <= 1.5
    x = np.linspace(-3, 3, 20001)
    n = noise_line.evaluate(x, 0.0)[..., 2]
    assert np.abs(n).max() <= 1 and np.abs(np.diff(n)).max() < 1e-3   # bounded, continuous
    # the hash: lattice values in [0, 1), multiples of 1/289, periodic with 289
    h = [float(dsl.hash01(i, j, 3)) for i in range(-5, 5) for j in range(3)]
    assert all(0 <= x < 1 and abs(x * 289 - round(x * 289)) < 1e-12 for x in h)
    assert float(dsl.hash01(7, 2, 1)) == float(dsl.hash01(7 + 289, 2, 1))
    assert len(set(h)) > 20


# --- parameters and bindings ----------------------------------------------------------------------
def test_implicit_time_and_array_parameters():
    @pl.parametric(params={"w": [1.0, 2.0, 3.0]})
    def waving(u, v, t, w):
        return u, v, sum(c * sin(u * (i + 1) + t) for i, c in enumerate(w))
    assert [p.name for p in waving.params] == ["t", "w"]
    assert waving.params[0].default == 0.0 and waving.params[1].size == 3
    z0 = waving.evaluate(0.3, 0.0)[2]
    assert z0 == pytest.approx(sum(c * np.sin(0.3 * (i + 1)) for i, c in enumerate([1, 2, 3])))
    assert waving.evaluate(0.3, 0.0, t=1.0)[2] != pytest.approx(z0)
    assert waving.evaluate(0.3, 0.0, w=[0, 0, 1])[2] == pytest.approx(np.sin(0.9))
    with pytest.raises(pl.FunctionError, match="parameter 'w' needs 3 numbers"):
        waving.param_block({"w": [1, 2]})


def test_let_gives_the_same_surface_with_smaller_code():
    def body(u, v, named):
        b = dsl.let if named else (lambda e, name=None: e)
        s = b(sin(3 * u) * cos(2 * v) + u * v)
        g = b(s * s + 1)
        return g * cos(u) + s, g * sin(u) - s, b(g * s)

    @pl.parametric(u=(0, 2), v=(0, 3))
    def with_let(u, v):
        return body(u, v, True)

    @pl.parametric(u=(0, 2), v=(0, 3))
    def without_let(u, v):
        return body(u, v, False)

    assert len(with_let.bindings) == 3 and not without_let.bindings
    u, v = np.meshgrid(np.linspace(0, 2, 9), np.linspace(0, 3, 7))
    for a, b in zip(with_let.surface(u, v), without_let.surface(u, v)):
        np.testing.assert_allclose(a, b, atol=1e-12)
    bindings, outputs = with_let.program("surface")
    assert len(bindings) > 3 and len(outputs) == 9   # derivative bindings follow the value bindings


def test_the_helper_list_is_the_modules_public_functions():
    """``dsl.__all__`` (the list the definition code's hints name) is exactly the public helpers."""
    import inspect

    public = {n for n, f in vars(dsl).items() if not n.startswith("_") and inspect.isfunction(f)
              and f.__module__ == dsl.__name__}
    assert sorted(dsl.__all__) == sorted(public)
    assert len(set(dsl.__all__)) == len(dsl.__all__)


# --- snippets ------------------------------------------------------------------------------------
def test_snippet_functions_match_their_reference_on_opencl():
    u, v = grid(ripple_snippet, 33)
    pos, du, dv, only = on_cl(ripple_snippet, u, v)
    ref, rdu, rdv = ripple_snippet.surface(u.astype(np.float64), v.astype(np.float64))
    np.testing.assert_allclose(pos, ref, atol=2e-6)
    np.testing.assert_allclose(only, pos, atol=1e-7)
    # central differences: close to the exact partials of the same surface (sympy twin)
    _, pdu, pdv, _ = on_cl(ripple_plain_snippet, u, v)
    _, edu, edv = ripple_sympy.surface(u.astype(np.float64), v.astype(np.float64))
    assert np.abs(pdu - edu).max() < 5e-3 * np.abs(edu).max()
    assert np.abs(pdv - edv).max() < 5e-3 * np.abs(edv).max()
    # array parameters (PARAM_AT) and the implicit time
    u, v = grid(poly_snippet, 9)
    pos = on_cl(poly_snippet, u, v, t=0.5, coeffs=[1, 2, 3, 4])[0]
    np.testing.assert_allclose(pos, poly_snippet.evaluate(u, v, t=0.5, coeffs=[1, 2, 3, 4]), atol=1e-5)
    assert [p.name for p in poly_snippet.params] == ["t", "coeffs"]


def test_a_snippet_compiles_as_glsl_too():
    """The dialect's promise: the same snippet text compiles as GLSL 4.50 with dialect.glsl."""
    from paramlod import kernels
    from paramlod.device.context import gl_context

    ctx = gl_context()
    for fn in (ripple_snippet, poly_snippet):
        offs = fn.param_offsets()
        loads = "\n".join(f"    const int {p.name} = {offs[p.name]};" if p.is_array
                          else f"    float {p.name} = PARAM({offs[p.name]});" for p in fn.params)
        src = ("#version 450\nlayout(local_size_x = 1) in;\n"
               "layout(std430, binding = 0) buffer Params { float pl_params[]; };\n"
               "#define PARAM(k) pl_params[k]\n" + kernels.source("common/dialect.glsl") + "\n"
               f"vec3 snip(float u, float v) {{\n{loads}\n{fn.snippet.code}\n}}\n"
               "void main() { vec3 p = snip(0.25, 0.5); pl_params[0] = p.x + p.y + p.z; }\n")
        ctx.compute_shader(src).release()   # raises with the GLSL compiler's log on error
