// Resolve: decode the shared colour and aux key buffers (common/keys.cl) into the Frame's arrays,
// the 8-bit sRGB image over the background (what a PNG holds: the only array read back when only
// an image is asked for), and the frame's counters. Built after keys.cl and subsamples.cl (for
// encode_srgb8 and the lin/thr tables). Driven by paramlod.renderers.targets.KeyBuffer; numpy
// twin of the image and counters: paramlod.renderers.points_reference.resolve_image.
//
// counts[2 v]: pixels of layer v written (any sample); counts[2 v + 1]: its covered subsamples,
// rint(alpha * PL_SS_COUNT) summed (alpha = coverage of a supersampled frame; PL_SS_COUNT = 1
// otherwise). Layers (the views of a multi-view frame) follow one another, n pixels each; the host
// launches whole work-groups per layer, so a work-group counts into one layer's record.

#ifndef PL_SS_COUNT
#define PL_SS_COUNT 1
#endif
#define RESOLVE_LOCAL 256

__kernel __attribute__((reqd_work_group_size(RESOLVE_LOCAL, 1, 1)))
void resolve(__global const ulong* color_buf, __global const ulong* aux_buf, uint n,
             __global float4* color, __global float* depth, __global float4* normal,
             __global uint* object_id, __global uchar* image, uint background,
             __global const uint* lin, __global const uint* thr, __global uint* counts)
{
    __local uint written, covered;
    if (get_local_id(0) == 0) { written = 0u; covered = 0u; }
    barrier(CLK_LOCAL_MEM_FENCE);
    uint groups_per_layer = (n + RESOLVE_LOCAL - 1u) / RESOLVE_LOCAL;
    uint layer = get_group_id(0) / groups_per_layer;
    uint in_layer = (get_group_id(0) % groups_per_layer) * RESOLVE_LOCAL + get_local_id(0);
    if (in_layer < n) {
        uint i = layer * n + in_layer;
        ulong k = color_buf[i];
        if (k == 0xFFFFFFFFFFFFFFFFul) {
            color[i] = (float4)(0.0f); depth[i] = INFINITY; normal[i] = (float4)(0.0f); object_id[i] = 0u;
            // packed RGB, 3 bytes a pixel: what the host reads is the image as it is
            image[3 * i] = background >> 24; image[3 * i + 1] = (background >> 16) & 255u;
            image[3 * i + 2] = (background >> 8) & 255u;
        } else {
            uint rgba = (uint)k;
            float alpha = (float)(rgba & 255u) / 255.0f;
            color[i] = (float4)(SRGB8_DECODED[rgba >> 24], SRGB8_DECODED[(rgba >> 16) & 255u],
                                SRGB8_DECODED[(rgba >> 8) & 255u], alpha);
            depth[i] = as_float((uint)(k >> 32));
            ulong a = aux_buf[i];
            uint oct = (uint)(a >> 12) & 0xFFFFFu;
            float2 p = (float2)((float)(oct >> 10) - 511.5f, (float)(oct & 1023u) - 511.5f) / 511.5f;
            float3 nn = (float3)(p.x, p.y, 1.0f - pl_fabsf(p.x) - pl_fabsf(p.y));
            if (nn.z < 0.0f) {
                float2 q = (float2)((1.0f - pl_fabsf(p.y)) * (p.x >= 0.0f ? 1.0f : -1.0f),
                                    (1.0f - pl_fabsf(p.x)) * (p.y >= 0.0f ? 1.0f : -1.0f));
                nn.x = q.x; nn.y = q.y;
            }
            normal[i] = (float4)(pl_normalize3(nn), 0.0f);
            object_id[i] = (uint)a & 0xFFFu;
            // over the background in linear fixed point (integer only: the twin matches exactly)
            uint al = rgba & 255u;
            uint out[3];
            for (uint c = 0; c < 3; ++c) {
                uint code = (rgba >> (24 - 8 * c)) & 255u;
                uint bg = (background >> (24 - 8 * c)) & 255u;
                out[c] = al == 255u ? code
                    : encode_srgb8((uint)(((ulong)lin[code] * al + (ulong)lin[bg] * (255u - al) + 127u) / 255u), thr);
            }
            image[3 * i] = out[0]; image[3 * i + 1] = out[1]; image[3 * i + 2] = out[2];
            atomic_inc(&written);
            // rint(alpha * PL_SS_COUNT) in integers (al / 255 * count is never a half, so rounding
            // to nearest is floor(x + 1/2)): PoCL calls rint out of line, 2/3 of a resolve's time
            atomic_add(&covered, (2u * al * PL_SS_COUNT + 255u) / 510u);
        }
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    if (get_local_id(0) == 0) {
        if (written) atomic_add(&counts[2u * layer], written);
        if (covered) atomic_add(&counts[2u * layer + 1u], covered);
    }
}
