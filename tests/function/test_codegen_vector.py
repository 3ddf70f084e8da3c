"""The generated code on vector lanes (paramlod.function.codegen_vector, the quad sampler's corners
on CPU devices): its twin is the scalar code, lane for lane, for every built-in and SH order; a
function it cannot vectorize goes lane by lane through the scalar code. The frames it draws:
tests/renderers/test_points_quads.py."""
import numpy as np
import pyopencl.array as cla
import sympy as sp

import paramlod as pl
from paramlod.device.context import cl_device
from paramlod.function.codegen_cl import SPLIT_U, SPLIT_V, surface_split
from paramlod.function.codegen_vector import VECTOR_WIDTH, cl_vector_source, vector_ready
from paramlod.function.programs import POLY_TRIG, VECTOR, kernel
from paramlod.function.registry import builtin_functions
from paramlod.functions.sh_glyph import make_sh_glyph


@pl.parametric(u=(-2, 2), v=(-2, 2), params={"k": 1.5})
def bell(u, v, k):   # erf has no vector form in VECTOR_NODES: lane by lane
    return u, v, sp.erf(k * u) * sp.cos(v)


FUNCS = [f for f in builtin_functions().values()] + [make_sh_glyph(o) for o in (4, 8, 12)] + [bell]


def _lanes(fns, seed=3, groups=300):
    """Per function, vector and scalar (pos, du, dv) at the same samples: PL_VW lanes a group that
    share the split's axis coordinate, as a quad run's corners share their grid line."""
    q = cl_device().queue
    defines = {VECTOR: 1, POLY_TRIG: 1}   # as the quad sampler builds them on CPUs
    k_scalar = kernel("eval_samples", ["common/eval.cl"], fns, defines)
    k_vector = kernel("eval_vector", ["common/eval.cl"], fns, defines)
    rng = np.random.default_rng(seed)
    out = {}
    for i, fn in enumerate(fns):
        (u0, u1), (v0, v1) = fn.u_range, fn.v_range
        u = rng.uniform(u0, u1, (groups, VECTOR_WIDTH)).astype(np.float32)
        v = rng.uniform(v0, v1, (groups, VECTOR_WIDTH)).astype(np.float32)
        split = surface_split(fn)
        if split is not None:
            (u if split.axis == SPLIT_U else v)[:] = (u if split.axis == SPLIT_U else v)[:, :1]
        n = groups * VECTOR_WIDTH
        params = cla.to_device(q, np.concatenate([fn.device_blocks(fn.param_block({}).reshape(-1)),
                                                  np.zeros(1, np.float32)]).astype(np.float32))
        d_vec = cla.empty(q, n * 9, np.float32)
        k_vector(q, (groups,), None, np.uint32(i), cla.to_device(q, np.concatenate([u, v], axis=1)).data,
                 np.uint32(groups), params.data, d_vec.data)
        d_sc = cla.empty(q, n * 24, np.float32)
        k_scalar(q, (n,), None, np.uint32(i), cla.to_device(q, np.stack([u.ravel(), v.ravel()], 1)).data,
                 np.uint32(n), params.data, d_sc.data)
        scalar = d_sc.get().reshape(n, 24)
        # the scalar twin: pl_surface_rest (the split's code, what the vector code's steps are) where
        # the function has a split, pl_surface where not
        out[fn.name] = d_vec.get().reshape(n, 9), scalar[:, 12:21] if split is not None else scalar[:, :9]
    return out


def test_vector_code_equals_the_scalar_code_lane_for_lane():
    results = _lanes(FUNCS)
    exact = 0
    for fn in FUNCS:
        vec, ref = results[fn.name]
        assert np.array_equal(np.isnan(vec), np.isnan(ref)), fn.name
        scale = np.nanmax(np.abs(ref), axis=0) + 1e-6
        # the same steps in the same order: equal, or an ulp or two where a vector builtin (exp, pow)
        # rounds differently from its scalar form (the seashells)
        assert np.nanmax(np.abs(vec - ref) / scale) < 1e-6, fn.name
        exact += np.array_equal(vec, ref, equal_nan=True)
    assert exact >= len(FUNCS) - 6   # most bit for bit


def test_functions_without_vector_forms_go_lane_by_lane():
    assert not vector_ready(bell)
    source = cl_vector_source([bell, FUNCS[0]])
    assert "pl_vsurf_0" not in source and "pl_vrest_0" not in source and "pl_vsurf_1(" in source
    assert all(vector_ready(f) for f in FUNCS if f is not bell and not f.is_snippet)
    vec, ref = _lanes([bell])["bell"]
    assert np.array_equal(vec, ref, equal_nan=True)   # the scalar code itself, lane by lane
