// The colour attachments of GLTargets (paramlod/renderers/gl_targets.py), written by every
// fragment stage that draws into them (tess, mesh, carry, resolve, background): 0 colour (linear
// RGB; alpha 0 = nothing drawn), 1 linear view depth R32F, 2 world-space normal, 3 object id
// R32UI, 4 the 8-bit sRGB image RGBA8UI (output targets only: the resolve's, or a draw's into
// targets drawn directly, GLTargets.direct; targets without it drop what is written there).
layout(location = 0) out vec4 out_color;
layout(location = 1) out float out_depth;
layout(location = 2) out vec4 out_normal;
layout(location = 3) out uint out_object;
layout(location = 4) out uvec4 out_image;

// The image's code of a linear value, bit for bit the host's linear_to_srgb8: from the encoder's
// table (paramlod.core.color.linear_to_srgb8_buckets: per bucket of [0, 1] the code of the
// bucket's start and the one threshold inside it, here as uint pairs, the threshold's float bits),
// not the shader's pow, whose rounding differs from numpy's. Only in the stages that the host
// gives PL_SRGB8_BUCKETS (paramlod/renderers/gl_targets.py srgb8_defines). The table is one
// buffer, read as a storage buffer or, with PL_SRGB8_UNIFORM (Mesa's llvmpipe), as a uniform
// block of the same bytes: llvmpipe reads a storage buffer at a varying index one lane at a time,
// which cost a third of a tess draw (a texel fetch cost more).
#ifdef PL_SRGB8_BUCKETS
#ifdef PL_SRGB8_UNIFORM
layout(std140, binding = 5) uniform PlSrgb8Table { uvec4 pl_srgb8_pairs[PL_SRGB8_BUCKETS / 2]; };

uvec2 srgb8_bucket(int i) {
    uvec4 pair = pl_srgb8_pairs[i >> 1];
    return (i & 1) != 0 ? pair.zw : pair.xy;
}
#else
layout(std430, binding = 5) readonly buffer PlSrgb8Table { uvec2 pl_srgb8_buckets[]; };

uvec2 srgb8_bucket(int i) {
    return pl_srgb8_buckets[i];
}
#endif

uint srgb8_code(float x) {
    x = clamp(x, 0.0, 1.0);
    uvec2 b = srgb8_bucket(min(int(x * float(PL_SRGB8_BUCKETS)), PL_SRGB8_BUCKETS - 1));
    return b.x + (x >= uintBitsToFloat(b.y) ? 1u : 0u);
}

uvec4 srgb8_image(vec3 rgb) {
    return uvec4(srgb8_code(rgb.r), srgb8_code(rgb.g), srgb8_code(rgb.b), 255u);
}
#endif
