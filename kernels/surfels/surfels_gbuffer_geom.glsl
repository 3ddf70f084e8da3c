#version 450 core
// Hands every fragment its triangle's three corners (flat) and barycentric coordinates, so the
// fragment shader can keep the surface point on the triangle: rasterizers snap vertices to a
// sub-pixel grid, and at a pixel of an almost edge-on triangle the interpolated attributes can
// extrapolate far off the surface.
layout(triangles) in;
layout(triangle_strip, max_vertices = 3) out;
in vec3 g_pos[];
in vec3 g_nrm[];
in vec4 g_col[];
out vec3 v_bary;
flat out vec3 v_p0; flat out vec3 v_p1; flat out vec3 v_p2;
flat out vec3 v_n0; flat out vec3 v_n1; flat out vec3 v_n2;
flat out vec4 v_c0; flat out vec4 v_c1; flat out vec4 v_c2;

void main() {
    for (int i = 0; i < 3; ++i) {
        v_bary = vec3(i == 0 ? 1.0 : 0.0, i == 1 ? 1.0 : 0.0, i == 2 ? 1.0 : 0.0);
        v_p0 = g_pos[0]; v_p1 = g_pos[1]; v_p2 = g_pos[2];
        v_n0 = g_nrm[0]; v_n1 = g_nrm[1]; v_n2 = g_nrm[2];
        v_c0 = g_col[0]; v_c1 = g_col[1]; v_c2 = g_col[2];
        gl_Position = gl_in[i].gl_Position;
        EmitVertex();
    }
    EndPrimitive();
}
