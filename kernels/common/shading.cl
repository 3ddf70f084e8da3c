// The shading model, one body for both paths: two-sided Blinn-Phong in view space. Written in the
// snippet dialect (kernels/README.md; VEC3 and the vec3 type come from common/dialect.cl or
// common/dialect.glsl, which the includer includes first), so the same text compiles as OpenCL C
// (included by common/keys.cl: shade(), the point and surfel kernels) and as GLSL 4.50 (included
// by tess/tess_fragment.glsl). The constants are paramlod.core.shading's: PL_SPECULAR_EXPONENT
// from the prelude, the light and ambient share as data (the light record).
//
// The two sides differ only where the compiled arithmetic has always differed (renders stay
// bit-identical): OpenCL raises to the exponent by squaring (pow dominated the point renderer's
// per-sample cost on CPUs) and takes fmax (IEEE maxNum for NaN); GLSL calls pow and max.
#ifndef PL_SHADING
#define PL_SHADING

#ifdef __OPENCL_VERSION__
#include "common/builtins.cl"
#define PL_SHADE_FN inline
#define PL_SHADE_MAX(a, b) pl_fmaxf((a), (b))
#define PL_DOT(a, b) pl_dot3((a), (b))
#define PL_LENGTH(a) pl_length3(a)
#define PL_NORMALIZE(a) pl_normalize3(a)
#define PL_ISNAN(a) ((a) != (a))
#if PL_SPECULAR_EXPONENT != 48
#error "common/shading.cl raises to the specular exponent by squaring, written for 48 (paramlod/core/shading.py)"
#endif
// ks * c^48: c^4, c^16, then three factors of c^16
inline float pl_specular(float ks, float c) {
    float c4 = (c * c) * (c * c), c16 = (c4 * c4) * (c4 * c4);
    return ks * c16 * c16 * c16;
}
#else
#define PL_SHADE_FN
#define PL_SHADE_MAX(a, b) max((a), (b))
#define PL_DOT(a, b) dot((a), (b))
#define PL_LENGTH(a) length(a)
#define PL_NORMALIZE(a) normalize(a)
#define PL_ISNAN(a) isnan(a)
float pl_specular(float ks, float c) {
    return ks * pow(c, float(PL_SPECULAR_EXPONENT));
}
#endif

// The unit normal facing the viewer: n_view normalized (ev where it degenerates: poles), turned
// towards ev, the unit vector from the point towards the viewer.
PL_SHADE_FN vec3 pl_facing_normal(vec3 n_view, vec3 ev) {
    float ln = PL_LENGTH(n_view);
    vec3 n = (ln > 1e-30f && !PL_ISNAN(ln)) ? n_view / ln : ev;
    if (PL_DOT(n, ev) < 0.0f) n = -n;
    return n;
}

// Linear RGB (not clamped) for the facing unit normal n, the view vector ev, the material's
// colour and specular weight ks, and the light record's towards-the-light L and ambient share.
PL_SHADE_FN vec3 pl_shade_rgb(vec3 n, vec3 ev, vec3 color, float ks, vec3 L, float ambient) {
    float diff = PL_SHADE_MAX(PL_DOT(n, L), 0.0f);
    float spec = pl_specular(ks, PL_SHADE_MAX(PL_DOT(n, PL_NORMALIZE(L + ev)), 0.0f));
    return color * (ambient + (1.0f - ambient) * diff) + VEC3(spec, spec, spec);
}
#endif
