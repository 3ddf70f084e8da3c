// Resolve, count, carry and background passes (tess_resolve_fragment.glsl, tess_count_fragment.glsl,
// tess_carry_fragment.glsl, tess_background_fragment.glsl): one full-screen triangle; on the far
// plane with PL_FAR.
void main() {
    vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
#ifdef PL_FAR
    gl_Position = vec4(p * 2.0 - 1.0, 1.0, 1.0);
#else
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
#endif
}
