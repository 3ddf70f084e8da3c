// Resolve: decode the shared colour and aux key buffers (keys.cl) into the Frame's arrays.
__kernel void resolve(__global const ulong* color_buf, __global const ulong* aux_buf, uint n,
                      __global float4* color, __global float* depth, __global float4* normal,
                      __global uint* object_id)
{
    uint i = get_global_id(0);
    if (i >= n) return;
    ulong k = color_buf[i];
    if (k == 0xFFFFFFFFFFFFFFFFul) {
        color[i] = (float4)(0.0f); depth[i] = INFINITY; normal[i] = (float4)(0.0f); object_id[i] = 0u;
        return;
    }
    uint rgba = (uint)k;
    float4 s = (float4)((rgba >> 24) & 255u, (rgba >> 16) & 255u, (rgba >> 8) & 255u, rgba & 255u) / 255.0f;
    float3 lin = select(pow((s.xyz + 0.055f) / 1.055f, (float3)(2.4f)), s.xyz / 12.92f,
                        isless(s.xyz, (float3)(0.04045f)));
    color[i] = (float4)(lin, s.w);
    depth[i] = as_float((uint)(k >> 32));
    ulong a = aux_buf[i];
    uint oct = (uint)(a >> 12) & 0xFFFFFu;
    float2 p = (float2)((float)(oct >> 10) - 511.5f, (float)(oct & 1023u) - 511.5f) / 511.5f;
    float3 nn = (float3)(p.x, p.y, 1.0f - fabs(p.x) - fabs(p.y));
    if (nn.z < 0.0f) {
        float2 q = (float2)((1.0f - fabs(p.y)) * (p.x >= 0.0f ? 1.0f : -1.0f),
                            (1.0f - fabs(p.x)) * (p.y >= 0.0f ? 1.0f : -1.0f));
        nn.x = q.x; nn.y = q.y;
    }
    normal[i] = (float4)(normalize(nn), 0.0f);
    object_id[i] = (uint)a & 0xFFFu;
}

