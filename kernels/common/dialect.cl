// The snippet dialect for OpenCL C (kernels/README.md, "Snippet dialect"). kernels/dialect.glsl
// defines the same names for GLSL; a snippet that uses only these and the shared built-ins compiles
// on both. paramlod/codegen.py inserts this file before the first snippet function.
#ifndef PL_DIALECT
#define PL_DIALECT
typedef float3 vec3;
typedef float2 vec2;
#define VEC3(x, y, z) ((float3)((x), (y), (z)))
#define VEC2(x, y) ((float2)((x), (y)))
#define PI 3.14159265358979f
#define ABS(x) fabs(x)
#define ATAN2(y, x) atan2((y), (x))
#define FRACT(x) ((x) - floor(x))
#define MOD(x, y) ((x) - (y) * floor((x) / (y)))
#define FLOAT(x) ((float)(x))
#define INT(x) ((int)(x))
#define INVSQRT(x) rsqrt(x)
// float i of an array parameter whose offset the generated code declares as `const int name`
#define PARAM_AT(name, i) P[(name) + (i)]
#endif
