// Vertex stage: one vertex per render patch (GL_PATCHES with 1 control point); passes the patch
// record (RENDER_DTYPE: parameter range, measured extents, instance) on to the control stage.
in vec4 in_range;   // u0, u1, v0, v1
in vec4 in_ext;     // e_u, e_v, s_u, s_v (pixels)
in uint in_inst;

out vec4 vs_range;
out vec4 vs_ext;
flat out uint vs_inst;

void main() {
    vs_range = in_range;
    vs_ext = in_ext;
    vs_inst = in_inst;
    gl_Position = vec4(0.0, 0.0, 0.0, 1.0);
}
