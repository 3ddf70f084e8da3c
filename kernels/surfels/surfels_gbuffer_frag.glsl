#version 450 core
// Writes world position (w = 1 marks a covered pixel), the unit normal turned towards the viewer,
// and the linear colour. No face culling: open meshes are seen from both sides. Barycentric
// coordinates are clamped to the triangle, so every written position lies on the mesh.
uniform vec3 u_dir;   // viewing direction (camera towards the object)
in vec3 v_bary;
flat in vec3 v_p0; flat in vec3 v_p1; flat in vec3 v_p2;
flat in vec3 v_n0; flat in vec3 v_n1; flat in vec3 v_n2;
flat in vec4 v_c0; flat in vec4 v_c1; flat in vec4 v_c2;
layout(location = 0) out vec4 o_pos;
layout(location = 1) out vec4 o_nrm;
layout(location = 2) out vec4 o_col;

void main() {
    vec3 b = max(v_bary, vec3(0.0));
    float s = b.x + b.y + b.z;
    b = (s > 0.0) ? b / s : vec3(1.0 / 3.0);
    vec3 p = b.x * v_p0 + b.y * v_p1 + b.z * v_p2;
    vec3 nn = b.x * v_n0 + b.y * v_n1 + b.z * v_n2;
    float len = length(nn);
    vec3 n = (len > 1e-20) ? nn / len : -u_dir;
    if (dot(n, u_dir) > 0.0) n = -n;
    o_pos = vec4(p, 1.0);
    o_nrm = vec4(n, 0.0);
    o_col = b.x * v_c0 + b.y * v_c1 + b.z * v_c2;
}
