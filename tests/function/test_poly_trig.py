"""The inline sin, cos and sincos of the point samplers on CPU devices (kernels/common/poly_trig.cl,
switched on by paramlod.function.programs.POLY_TRIG): accurate to about an ulp of 1, exact
builtins where the reduction would lose bits, NaN where the builtins give NaN, and only inside
the generated function code."""
import numpy as np
import pyopencl as cl

from paramlod.device.context import cl_device
from paramlod.function.programs import POLY_TRIG, _with_trig

# the generated code (here one function) gets the inline forms; the kernel after it the builtins
SOURCE = _with_trig("""
inline float3 generated(float x, float* c) {
    float3 v = sin((float3)(x, 0.5f * x, 1.0f));   // a snippet may take the sine of a vector
    return (float3)(sincos(x, c), sin(x) - cos(x), v.y);
}
""", {POLY_TRIG: 1}) + """
__kernel void probe(__global const float* x, __global float* out) {
    uint i = get_global_id(0);
    float c;
    float3 g = generated(x[i], &c);
    float own = sincos(x[i], &out[6 * i + 5]);   // the kernel's own: the builtin
    out[6 * i] = g.x; out[6 * i + 1] = c; out[6 * i + 2] = g.y; out[6 * i + 3] = g.z; out[6 * i + 4] = own;
}
"""


def _run(x):
    dev = cl_device()
    mf = cl.mem_flags
    x = np.ascontiguousarray(x, np.float32)
    xb = cl.Buffer(dev.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=x)
    ob = cl.Buffer(dev.context, mf.WRITE_ONLY, 6 * x.nbytes)
    cl.Program(dev.context, SOURCE).build().probe(dev.queue, x.shape, None, xb, ob)
    out = np.empty((len(x), 6), np.float32)
    cl.enqueue_copy(dev.queue, out, ob)
    return out


def test_inline_trig_is_accurate_and_the_kernel_keeps_the_builtins():
    rng = np.random.default_rng(7)
    x = np.concatenate([rng.uniform(-8192, 8192, 200_000), rng.uniform(-7, 7, 200_000),
                        np.linspace(-4 * np.pi, 4 * np.pi, 20_001)]).astype(np.float32)
    out = _run(x)
    s, c = np.sin(x.astype(np.float64)), np.cos(x.astype(np.float64))
    ulp1 = 2.0 ** -23
    assert np.max(np.abs(out[:, 0] - s)) <= ulp1 and np.max(np.abs(out[:, 1] - c)) <= ulp1
    assert np.array_equal(out[:, 2], out[:, 0] - out[:, 1])            # sin and cos are sincos's halves
    assert np.max(np.abs(out[:, 3] - np.sin(0.5 * x.astype(np.float64)))) <= 2 * ulp1   # vectors: builtins
    # the builtins after the generated code: within their own error, and not the inline forms
    assert np.max(np.abs(out[:, 4] - s)) <= 2 * ulp1 and np.max(np.abs(out[:, 5] - c)) <= 2 * ulp1
    assert np.count_nonzero(out[:, 4] != out[:, 0]) > 0.01 * len(x)


def test_beyond_the_reduction_and_non_finite_take_the_builtin():
    x = np.float32([8192.5, -8192.5, 1e6, -3e9, 1e20, np.inf, -np.inf, np.nan])
    out = _run(x)
    assert np.array_equal(out[:, 0], out[:, 4], equal_nan=True)   # the builtin's very values
    assert np.array_equal(out[:, 1], out[:, 5], equal_nan=True)
    assert np.all(np.isnan(out[-3:, :2]))


VECTOR_SOURCE = _with_trig("""
inline float8 generated8(float8 x, float8* c) { return sincos(x, c); }
inline float generated1(float x, float* c) { return sincos(x, c); }
""", {POLY_TRIG: 1}) + """
__kernel void probe8(__global const float* x, __global float* out) {
    uint i = get_global_id(0);
    float8 c8;
    float8 s8 = generated8(vload8(i, x), &c8);
    vstore8(s8, 4 * i, out); vstore8(c8, 4 * i + 1, out);
    for (int k = 0; k < 8; ++k) { float c; out[32 * i + 16 + k] = generated1(x[8 * i + k], &c); out[32 * i + 24 + k] = c; }
}
"""


def test_vector_lanes_equal_the_scalar_inline_forms():
    """The generated code on vector lanes (paramlod.function.codegen_vector) takes the float8
    sincos: lane for lane the scalar inline form's bits; a vector with a lane beyond the
    reduction takes the builtin in every lane."""
    dev = cl_device()
    mf = cl.mem_flags
    rng = np.random.default_rng(11)
    x = np.concatenate([rng.uniform(-8192, 8192, 80_000), rng.uniform(-7, 7, 80_000),
                        np.float32([np.nan, 0.0, -0.0, 1e-30, 3.0, 1.5707964, -1.5707964, 8192.0])]).astype(np.float32)
    xb = cl.Buffer(dev.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=x)
    ob = cl.Buffer(dev.context, mf.WRITE_ONLY, 4 * x.nbytes)
    cl.Program(dev.context, VECTOR_SOURCE).build().probe8(dev.queue, (len(x) // 8,), None, xb, ob)
    out = np.empty((len(x) // 8, 4, 8), np.float32)
    cl.enqueue_copy(dev.queue, out, ob)
    assert np.array_equal(out[:, 0], out[:, 2], equal_nan=True) and np.array_equal(out[:, 1], out[:, 3], equal_nan=True)
    far = np.float32([1.0, 2.0, 3.0, 9000.0, 4.0, 5.0, 6.0, 7.0])   # one lane beyond: the builtin in all
    fb = cl.Buffer(dev.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=far)
    cl.Program(dev.context, VECTOR_SOURCE).build().probe8(dev.queue, (1,), None, fb, ob)
    cl.enqueue_copy(dev.queue, out[:1], ob)
    assert np.max(np.abs(out[0, 0] - np.sin(far.astype(np.float64)))) <= 2 * 2.0 ** -23
