// Resolve and carry passes (tess_resolve_fragment.glsl, tess_carry_fragment.glsl): one
// full-screen triangle.
void main() {
    vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
