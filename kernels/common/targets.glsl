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
// table (paramlod.core.color.linear_to_srgb8_buckets, a vec2 per bucket of [0, 1]: the code of
// the bucket's start and the one threshold inside it), not the shader's pow, whose rounding
// differs from numpy's. A storage buffer: on llvmpipe a load is cheaper than a texel fetch.
layout(std430, binding = 5) readonly buffer PlSrgb8Buckets { vec2 pl_srgb8_buckets[]; };

uint srgb8_code(float x) {
    x = clamp(x, 0.0, 1.0);
    int n = pl_srgb8_buckets.length();
    vec2 b = pl_srgb8_buckets[min(int(x * float(n)), n - 1)];
    return uint(b.x) + (x >= b.y ? 1u : 0u);
}

uvec4 srgb8_image(vec3 rgb) {
    return uvec4(srgb8_code(rgb.r), srgb8_code(rgb.g), srgb8_code(rgb.b), 255u);
}
