// Evaluates parametric functions at given (u, v): the bridge between the generated OpenCL code and
// the numpy references (tests, `check_compiles`, throughput benchmarks). One work-item per sample.
// out: 12 floats per sample = position and partials from pl_surface (pos, du, dv), then the
// position from pl_position (both entry points are checked). Twins: ParametricFunction.evaluate and
// .surface (paramlod/function/define.py); the throughput kernels below are driven by
// paramlod/app/bench/functions.py.
__kernel void eval_samples(uint func, __global const float* uv, uint n,
                           __global const float* params, __global float* out)
{
    uint i = get_global_id(0);
    if (i >= n) return;
    float u = uv[2 * i], v = uv[2 * i + 1];
    float3 pos, du, dv;
    pl_surface(func, u, v, params, &pos, &du, &dv);
    float3 p = pl_position(func, u, v, params);
    __global float* o = out + 12 * i;
    o[0] = pos.x; o[1] = pos.y; o[2] = pos.z;
    o[3] = du.x;  o[4] = du.y;  o[5] = du.z;
    o[6] = dv.x;  o[7] = dv.y;  o[8] = dv.z;
    o[9] = p.x;   o[10] = p.y;  o[11] = p.z;
}

// Throughput variant: positions only, summed so that the compiler cannot drop the work.
__kernel void eval_throughput(uint func, float u0, float du, float v0, float dv, uint nu,
                              __global const float* params, __global float* out)
{
    uint i = get_global_id(0), j = get_global_id(1);
    float3 p = pl_position(func, u0 + du * (float)i, v0 + dv * (float)j, params);
    if (i < nu) out[j * nu + i] = p.x + p.y + p.z;
}

// Throughput variant: position, partials and normal (cross(du, dv), as points.cl point_eval forms
// it), summed so that the compiler cannot drop the work. Driven by paramlod/app/bench/functions.py.
__kernel void eval_surface_throughput(uint func, float u0, float du, float v0, float dv, uint nu,
                                      __global const float* params, __global float* out)
{
    uint i = get_global_id(0), j = get_global_id(1);
    float3 pos, fu, fv;
    pl_surface(func, u0 + du * (float)i, v0 + dv * (float)j, params, &pos, &fu, &fv);
    float3 n = cross(fu, fv);
    if (i < nu) out[j * nu + i] = pos.x + pos.y + pos.z + n.x + n.y + n.z;
}
