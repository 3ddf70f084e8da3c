// Inline sin, cos and sincos for the generated function code of the direct point sampler, the
// grid tessellator and the LOD stage on CPU devices (PL_POLY_TRIG, set by
// paramlod/renderers/points.py, tess_grid.py and paramlod/lod/stage.py where cl_device() is not a GPU). PoCL's CPU builtins are calls that are never
// inlined, so a kernel that calls them runs one work-item at a time; written out here, the
// arithmetic inlines and vectorizes. Measured on PoCL
// 3.0 (2-core AMD EPYC, 640 x 640 points frames): the order-8 glyph field's render 354 -> 261 ms,
// the torus 89 -> 69-78 ms. paramlod.function.programs.build puts this file before the generated
// code and gives the three names back after it, so the kernels' own code keeps the builtins, and the
// LOD stage (whose decisions its numpy twin checks bit for bit) never sees it.
//
// Method (facts from Cephes' sinf/cosf): x = j pi/2 + r with j the nearest integer to x 2/pi and
// pi/2 split into three parts (Cody and Waite), so that j times the first two parts is exact for
// |j| < 2^13; sin r and cos r from minimax polynomials on [-pi/4, pi/4], error about 1 ulp of 1;
// the quadrant j mod 4 picks and signs them. Beyond |x| = 8192 (|j| up to 5216) the reduction
// loses bits, so larger arguments, infinities included, take the builtin. NaN stays NaN.
#define PL_TRIG_LIMIT 8192.0f

#define PL_OVERLOAD __attribute__((overloadable))

// The reduction and the two polynomials, one text for a float and for PL_VW lanes (T, its int type
// IT; `half`: 0.5 with x's sign): q the nearest integer to x 2/pi, s and k sin r and cos r
#define PL_SINCOS_CORE(T, IT, x, half) \
    IT q = convert_##IT(x * 0.636619772367581343f + (half)); \
    T j = convert_##T(q); \
    T r = ((x - j * 1.5703125f) - j * 4.837512969970703125e-4f) - j * 7.54978995489188216e-8f; \
    T z = r * r; \
    T s = ((-1.9515295891e-4f * z + 8.3321608736e-3f) * z - 1.6666654611e-1f) * z * r + r; \
    T k = ((2.443315711809948e-5f * z - 1.388731625493765e-3f) * z + 4.166664568298827e-2f) * z * z \
          - 0.5f * z + 1.0f;

inline float PL_OVERLOAD pl_poly_sincos(float x, float* c) {
    if (x > PL_TRIG_LIMIT || x < -PL_TRIG_LIMIT) return sincos(x, c);
    PL_SINCOS_CORE(float, int, x, x < 0.0f ? -0.5f : 0.5f)
    int quadrant = q & 3;
    *c = quadrant == 0 ? k : quadrant == 1 ? -s : quadrant == 2 ? -k : s;
    return quadrant == 0 ? s : quadrant == 1 ? k : quadrant == 2 ? -s : -k;
}

inline float PL_OVERLOAD pl_poly_sin(float x) { float c; return pl_poly_sincos(x, &c); }

inline float PL_OVERLOAD pl_poly_cos(float x) { float c; pl_poly_sincos(x, &c); return c; }

// PL_VW lanes (paramlod.function.codegen_vector): the same arithmetic per lane, the quadrant
// chosen by select; a vector with a lane beyond the limit takes the builtin in every lane
inline float8 PL_OVERLOAD pl_poly_sincos(float8 x, float8* c) {
    if (any(x > PL_TRIG_LIMIT || x < -PL_TRIG_LIMIT)) return sincos(x, c);
    PL_SINCOS_CORE(float8, int8, x, select((float8)0.5f, (float8)-0.5f, x < 0.0f))
    int8 quadrant = q & 3;
    *c = select(select(select(s, -k, quadrant == 2), -s, quadrant == 1), k, quadrant == 0);
    return select(select(select(-k, -s, quadrant == 2), k, quadrant == 1), s, quadrant == 0);
}

inline float8 PL_OVERLOAD pl_poly_sin(float8 x) { float8 c; return pl_poly_sincos(x, &c); }

inline float8 PL_OVERLOAD pl_poly_cos(float8 x) { float8 c; pl_poly_sincos(x, &c); return c; }

// vectors (snippets may take the sine of a vec2 or vec3): the builtins
#define PL_TRIG_VECTOR(T) \
    inline T PL_OVERLOAD pl_poly_sincos(T x, T* c) { return sincos(x, c); } \
    inline T PL_OVERLOAD pl_poly_sin(T x) { return sin(x); } \
    inline T PL_OVERLOAD pl_poly_cos(T x) { return cos(x); }
PL_TRIG_VECTOR(float2)
PL_TRIG_VECTOR(float3)
PL_TRIG_VECTOR(float4)
#undef PL_TRIG_VECTOR

// the OpenCL headers may define these names as macros themselves (PoCL does): kept, and given
// back after the generated code (paramlod.function.programs)
#pragma push_macro("sincos")
#pragma push_macro("sin")
#pragma push_macro("cos")
#undef sincos
#undef sin
#undef cos
#define sincos(x, c) pl_poly_sincos((x), (c))
#define sin(x) pl_poly_sin(x)
#define cos(x) pl_poly_cos(x)
