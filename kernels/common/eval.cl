// Evaluates parametric functions at given (u, v): the bridge between the generated OpenCL code and
// the numpy references (tests, `check_compiles`, throughput benchmarks). One work-item per sample.
// out: 24 floats per sample = position and partials from pl_surface (pos, du, dv), the position
// from pl_position, position and partials from the surface split (pl_surface_axis, then
// pl_surface_rest) and the position from the position split (pl_position_axis, then
// pl_position_rest; every entry point is checked). Twins: ParametricFunction.evaluate and
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
    float C[PL_SPLIT_FLOATS];
    uint split = pl_split(func);
    if (split) pl_surface_axis(func, split == PL_SPLIT_U ? u : v, params, C);
    float3 spos, sdu, sdv;
    pl_surface_rest(func, u, v, params, C, &spos, &sdu, &sdv);
    uint psplit = pl_position_split(func);
    if (psplit) pl_position_axis(func, psplit == PL_SPLIT_U ? u : v, params, C);
    float3 ppos = pl_position_rest(func, u, v, params, C);
    __global float* o = out + 24 * i;
    o[0] = pos.x; o[1] = pos.y; o[2] = pos.z;
    o[3] = du.x;  o[4] = du.y;  o[5] = du.z;
    o[6] = dv.x;  o[7] = dv.y;  o[8] = dv.z;
    o[9] = p.x;   o[10] = p.y;  o[11] = p.z;
    o[12] = spos.x; o[13] = spos.y; o[14] = spos.z;
    o[15] = sdu.x;  o[16] = sdu.y;  o[17] = sdu.z;
    o[18] = sdv.x;  o[19] = sdv.y;  o[20] = sdv.z;
    o[21] = ppos.x; o[22] = ppos.y; o[23] = ppos.z;
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

// Throughput of the surface split as points_direct evaluates it (points.cl patch_runs): a work-item
// takes one grid line of the split's axis (a = a0 + da * i) and a run of `run` samples down it
// (b = b0 + db * j), pl_surface_axis once and then pl_surface_rest and the normal per sample,
// summed. The host passes u as a and v as b for a split along u, the other way round along v;
// without a split, pl_surface_rest is pl_surface. Driven by paramlod/app/bench/functions.py.
__kernel void eval_split_throughput(uint func, float a0, float da, float b0, float db, uint na, uint run,
                                    __global const float* params, __global float* out)
{
    uint i = get_global_id(0), j0 = get_global_id(1) * run;
    uint split = pl_split(func);
    float a = a0 + da * (float)i;
    float C[PL_SPLIT_FLOATS];
    if (split) pl_surface_axis(func, a, params, C);
    float sum = 0.0f;
    for (uint j = j0; j < j0 + run; ++j) {
        float b = b0 + db * (float)j;
        float3 pos, fu, fv;
        pl_surface_rest(func, split == PL_SPLIT_V ? b : a, split == PL_SPLIT_V ? a : b, params, C, &pos, &fu, &fv);
        float3 n = cross(fu, fv);
        sum += pos.x + pos.y + pos.z + n.x + n.y + n.z;
    }
    if (i < na) out[get_global_id(1) * na + i] = sum;
}

#ifdef PL_VECTOR
// The vector code (pl_vsurface_rest, paramlod.function.codegen_vector) on PL_VW samples a
// work-item: uv holds 2 PL_VW floats a group (u then v per lane), whose lanes share the split's
// axis coordinate (the carried values are lane 0's, as points.cl's runs share a grid line).
// out: 9 floats a sample, position and partials. Twin: pl_surface (eval_samples above).
__kernel void eval_vector(uint func, __global const float* uv, uint n_groups,
                          __global const float* params, __global float* out)
{
    uint g = get_global_id(0);
    if (g >= n_groups) return;
    plv u = pl_vload(0, uv + 2 * PL_VW * g), v = pl_vload(0, uv + 2 * PL_VW * g + PL_VW);
    float C[PL_SPLIT_FLOATS];
    uint split = pl_split(func);
    if (split) pl_surface_axis(func, split == PL_SPLIT_U ? u.s0 : v.s0, params, C);
    plv o[9];
    pl_vsurface_rest(func, u, v, params, C, o);
    for (int k = 0; k < 9; ++k)
        for (int lane = 0; lane < PL_VW; ++lane) out[(PL_VW * g + lane) * 9 + k] = o[k][lane];
}
#endif
