// The snippet dialect for GLSL 4.50 (kernels/README.md, "Snippet dialect"); the twin of
// kernels/dialect.cl. The GLSL backend defines PARAM(k), the float k of the instance's parameter
// block, before including this file.
#ifndef PL_DIALECT
#define PL_DIALECT
#define VEC3(x, y, z) vec3((x), (y), (z))
#define VEC2(x, y) vec2((x), (y))
#define PI 3.14159265358979f
#define ABS(x) abs(x)
#define ATAN2(y, x) atan((y), (x))
#define FRACT(x) fract(x)
#define MOD(x, y) mod((x), (y))
#define FLOAT(x) float(x)
#define INT(x) int(x)
#define INVSQRT(x) inversesqrt(x)
#define PARAM_AT(name, i) PARAM((name) + (i))
#endif
