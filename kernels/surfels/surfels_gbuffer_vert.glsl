#version 450 core
// G-buffer pass of the surfel sampler: one orthographic view of a triangle soup.
uniform mat4 u_mvp;
in vec3 in_pos;
in vec3 in_nrm;
in vec4 in_col;
out vec3 g_pos;
out vec3 g_nrm;
out vec4 g_col;

void main() {
    g_pos = in_pos;
    g_nrm = in_nrm;
    g_col = in_col;
    gl_Position = u_mvp * vec4(in_pos, 1.0);
}
