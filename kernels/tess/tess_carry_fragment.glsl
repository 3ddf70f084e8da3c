// Carry pass of hybrid anti-aliasing (thesis section 5.5.7; GLTargets.carry in
// paramlod/renderers/gl_targets.py, driven by TessRenderer's hybrid draw in
// paramlod/renderers/tess.py): a full-screen triangle (tess_resolve_vertex.glsl) over a finer
// tier's targets, which start from the coarser tier's. Each sample of the finer targets takes the
// colour, linear depth, normal, object id and hardware depth (gl_FragDepth) of the coarse sample
// of the same index in the coarse pixel it lies in (PL_RATIO fine pixels per coarse pixel side):
// every coarse sample is copied into the same number of fine samples, so the finer target's
// resolve of what was carried equals the coarse target's resolve. With a multisampled coarse
// target (PL_MS) gl_SampleID makes the pass run once per sample; a single-sampled one is read once
// per pixel, and the fragment's outputs go to every sample of the pixel.
// Uncovered coarse samples (alpha 0) are discarded: the fine sample keeps the cleared colour and
// depth, and its other attachments are never read (the resolve skips alpha 0).
#ifdef PL_MS
uniform sampler2DMS u_color;
uniform sampler2DMS u_depth;
uniform sampler2DMS u_normal;
uniform usampler2DMS u_object;
uniform sampler2DMS u_zbuf;      // the coarse hardware depth buffer (a depth texture)
// the same sample index; wrapped, should the coarse target hold fewer samples than the fine one
#define PL_FETCH(t, q) texelFetch(t, q, gl_SampleID % textureSamples(t))
#else
uniform sampler2D u_color;
uniform sampler2D u_depth;
uniform sampler2D u_normal;
uniform usampler2D u_object;
uniform sampler2D u_zbuf;
#define PL_FETCH(t, q) texelFetch(t, q, 0)
#endif

#include "common/targets.glsl"

void main() {
    ivec2 q = ivec2(gl_FragCoord.xy) / PL_RATIO;
    vec4 c = PL_FETCH(u_color, q);
    if (c.a == 0.0) discard;
    out_color = c;
    out_depth = PL_FETCH(u_depth, q).r;
    out_normal = PL_FETCH(u_normal, q);
    out_object = PL_FETCH(u_object, q).r;
    gl_FragDepth = PL_FETCH(u_zbuf, q).r;
}
