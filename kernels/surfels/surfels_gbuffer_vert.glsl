#version 450 core
// G-buffer pass of the surfel sampler: one orthographic view of a triangle soup. Only the corners'
// positions go through the pipeline; the fragment stage reads its triangle's corners itself.
uniform mat4 u_mvp;
in vec3 in_pos;

void main() {
    gl_Position = u_mvp * vec4(in_pos, 1.0);
}
