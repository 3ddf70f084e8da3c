// Shared by the tessellation renderer's shader stages (paramlod/renderers/tess.py) and the GLSL
// probe (paramlod/function/probes.py). They prepend "#version 450 core", the stage's PL_* defines
// and the prelude (paramlod.core.layouts.glsl_prelude: the records' PL_INST_*, PL_MAT_*, ... offsets
// and sizes, the patch structs, PL_SPECULAR_EXPONENT); the tessellation stages then get this file,
// the generated function code (paramlod/function/codegen_glsl.py: pl_position, pl_surface) and
// their own file.

#define PL_NAN uintBitsToFloat(0x7fc00000u)
#define PL_INF uintBitsToFloat(0x7f800000u)
#define NAN PL_NAN          // generated code: a Piecewise without a default branch
#define INFINITY PL_INF

// Scene data (Scene.instance_buffers(), Scene.materials()), read-only shader storage buffers.
layout(std430, binding = 0) readonly buffer PlParams { float pl_params[]; };   // flat parameter blocks
layout(std430, binding = 1) readonly buffer PlInstF { float pl_inst_f[]; };    // [n][PL_INST_F] floats
layout(std430, binding = 2) readonly buffer PlInstU { uint pl_inst_u[]; };     // [n][PL_INST_U] uints
layout(std430, binding = 3) readonly buffer PlMaterials { vec4 pl_materials[]; };  // material record: rgb, specular
// Counters read back into Frame.stats: NaN vertices (evaluation stage), the device's real sample
// count per pixel of the multisampled targets (resolve pass; the pixels written are counted by the
// count pass, tess_count_fragment.glsl).
layout(std430, binding = 4) buffer PlCounters { uint pl_nan_vertices; uint pl_device_samples; };

uniform mat4 u_view;        // world -> view
uniform mat4 u_proj;        // view -> clip
uniform vec2 u_screen;      // output width, height in pixels (the LOD stage's pixels)

#include "common/rows.glsl"

vec4 pl_domain(uint inst) {
    uint b = inst * PL_INST_F + PL_INST_DOMAIN;
    return vec4(pl_inst_f[b], pl_inst_f[b + 1u], pl_inst_f[b + 2u], pl_inst_f[b + 3u]);
}

bool pl_bad3(vec3 p) {
    return any(isnan(p)) || any(isinf(p));
}

// a + (b - a) t, exact at both ends, so that neighbouring patches evaluate a shared edge at the
// very same parameters
float pl_lerp(float a, float b, float t) {
    return t >= 1.0 ? b : a + (b - a) * t;
}

// --- helpers the generated code calls (GLSLPrinter.names) --------------------------------------
float pl_pown(float x, int n) {
    float r = 1.0, b = x;
    for (int k = n; k > 0; k >>= 1) { if ((k & 1) != 0) r *= b; b *= b; }
    return r;
}
float pl_cbrt(float x) { return sign(x) * pow(abs(x), 1.0 / 3.0); }
