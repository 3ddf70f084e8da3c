// Resolve pass: one invocation per output pixel gathers its PL_SS x PL_SS block of the
// (super-sampled) targets.
//   colour: the hardware multisample resolve (already done into u_color by a framebuffer blit)
//           box-averaged over the block; the average is premultiplied by coverage, so alpha is the
//           covered fraction of all samples and RGB is divided by it (straight alpha, as in Frame).
//   depth, normal, object id: those of the nearest covered sample among all PL_SS^2 x PL_SAMPLES
//           samples (covered: the sample's colour alpha is 1; the draw clears only the colour
//           and depth buffers, so the depth, normal and id of uncovered samples are stale and
//           never read; the loop runs over the samples the device really
//           allocated, which can be more than requested: llvmpipe gives 4 for a 2xMS request), +inf / 0 / 0 where no sample is covered. This matches
//           the point renderer, whose atom_min keeps the nearest sample of a pixel.
#if defined(PL_LAYERED)
// one layer (view) of a multi-view frame's texture arrays; u_color: the hardware resolve of that
// layer (a blit, so a plain texture) or, without multisampling, the colour array itself
uniform int u_layer;
#ifdef PL_MS
uniform sampler2DMSArray u_coverage;
uniform sampler2DMSArray u_depth;
uniform sampler2DMSArray u_normal;
uniform usampler2DMSArray u_object;
#define PL_FETCH(t, q, s) texelFetch(t, ivec3(q, u_layer), s)
#define PL_DEVICE_SAMPLES textureSamples(u_depth)
uniform sampler2D u_color;
#define PL_COLOR(q) texelFetch(u_color, q, 0)
#else
uniform sampler2DArray u_coverage;
uniform sampler2DArray u_depth;
uniform sampler2DArray u_normal;
uniform usampler2DArray u_object;
#define PL_FETCH(t, q, s) texelFetch(t, ivec3(q, u_layer), 0)
#define PL_DEVICE_SAMPLES 1
uniform sampler2DArray u_color;
#define PL_COLOR(q) texelFetch(u_color, ivec3(q, u_layer), 0)
#endif
#else
#ifdef PL_MS
uniform sampler2DMS u_coverage;   // the multisampled colour: alpha 1 where drawn
uniform sampler2DMS u_depth;
uniform sampler2DMS u_normal;
uniform usampler2DMS u_object;
#define PL_FETCH(t, q, s) texelFetch(t, q, s)
#define PL_DEVICE_SAMPLES textureSamples(u_depth)
#else
uniform sampler2D u_coverage;
uniform sampler2D u_depth;
uniform sampler2D u_normal;
uniform usampler2D u_object;
#define PL_FETCH(t, q, s) texelFetch(t, q, 0)
#define PL_DEVICE_SAMPLES 1
#endif
uniform sampler2D u_color;
#define PL_COLOR(q) texelFetch(u_color, q, 0)
#endif

#include "common/targets.glsl"

// The 8-bit sRGB image over u_background that Frame.rgb8 returns (alpha 255), so that a frame
// asked only for its image reads 4 bytes a pixel. Bit for bit the host's
// linear_to_srgb8(rgb * a + background * (1 - a)) of out_color: the composite in float32 as numpy
// computes it (precise: no fused multiply-add), the code from srgb8_code (common/targets.glsl).
uniform vec3 u_background;

void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    int ns = PL_DEVICE_SAMPLES;
    if (p == ivec2(0)) pl_device_samples = uint(ns);
    vec4 c = vec4(0.0);
    float best = PL_INF;
    vec3 n = vec3(0.0);
    uint id = 0u;
    for (int sy = 0; sy < PL_SS; ++sy) {
        for (int sx = 0; sx < PL_SS; ++sx) {
            ivec2 q = p * PL_SS + ivec2(sx, sy);
            c += PL_COLOR(q);
            for (int s = 0; s < ns; ++s) {
                if (PL_FETCH(u_coverage, q, s).a == 0.0) continue;
                float d = PL_FETCH(u_depth, q, s).r;
                if (d < best) {
                    best = d;
                    n = PL_FETCH(u_normal, q, s).xyz;
                    id = PL_FETCH(u_object, q, s).r;
                }
            }
        }
    }
    c /= float(PL_SS * PL_SS);
    precise vec4 straight = c.a > 0.0 ? vec4(c.rgb / c.a, c.a) : vec4(0.0);
    out_color = straight;
    out_depth = best;
#ifdef PL_HALF_NORMALS
    float ln = length(n);   // stored in half floats: no longer of unit length
    out_normal = vec4(ln > 0.0 ? n / ln : vec3(0.0), 0.0);
#else
    out_normal = vec4(n, 0.0);   // float32, as the fragment wrote it (as targets drawn directly keep it)
#endif
    out_object = id;
    precise vec3 over = straight.rgb * straight.a + u_background * (1.0 - straight.a);
    out_image = srgb8_image(over);
}
