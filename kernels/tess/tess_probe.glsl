// Probe (tests and debugging): evaluates pl_surface at given (u, v) for one function and parameter
// offset in a vertex shader; the results come back through transform feedback
// (paramlod.function.probes.glsl_surface), to compare the generated GLSL with the numpy reference.
in vec2 in_uv;
uniform uint u_func;
uniform uint u_param_offset;
out vec3 out_pos;
out vec3 out_du;
out vec3 out_dv;

void main() {
    pl_surface(u_func, in_uv.x, in_uv.y, u_param_offset, out_pos, out_du, out_dv);
    gl_Position = vec4(0.0, 0.0, 0.0, 1.0);
}
