#version 450 core
// Writes world position (w = 1 marks a covered pixel), the unit normal turned towards the viewer,
// and the linear colour. No face culling: open meshes are seen from both sides. The fragment reads
// its triangle's three corners (gl_PrimitiveID) and takes barycentric coordinates of the pixel
// centre from their projections, clamped to the triangle, so every written position lies on the
// mesh: rasterizers snap vertices to a sub-pixel grid, and at a pixel of an almost edge-on triangle
// interpolated attributes can extrapolate far off the surface. (A geometry stage handing the
// corners on as flat attributes did the same at 1.3-1.4x the time on Mesa's llvmpipe.)
struct Triangle { vec4 p[3]; vec4 n[3]; vec4 c[3]; };   // corners' positions, normals, colours
layout(std430, binding = 0) readonly buffer Triangles { Triangle triangles[]; };
uniform mat4 u_mvp;
uniform vec2 u_size;  // the target's pixels
uniform vec3 u_dir;   // viewing direction (camera towards the object)
layout(location = 0) out vec4 o_pos;
layout(location = 1) out vec4 o_nrm;
layout(location = 2) out vec4 o_col;

vec2 window_xy(vec3 p) {
    vec4 c = u_mvp * vec4(p, 1.0);
    return (c.xy / c.w * 0.5 + 0.5) * u_size;
}

void main() {
    Triangle t = triangles[gl_PrimitiveID];
    vec2 a = window_xy(t.p[0].xyz), b = window_xy(t.p[1].xyz), c = window_xy(t.p[2].xyz);
    vec2 q = gl_FragCoord.xy;
    float area = (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
    vec3 w = vec3((c.x - b.x) * (q.y - b.y) - (c.y - b.y) * (q.x - b.x),
                  (a.x - c.x) * (q.y - c.y) - (a.y - c.y) * (q.x - c.x),
                  (b.x - a.x) * (q.y - a.y) - (b.y - a.y) * (q.x - a.x));
    vec3 bary = area != 0.0 ? max(w / area, vec3(0.0)) : vec3(1.0 / 3.0);
    float s = bary.x + bary.y + bary.z;
    bary = (s > 0.0) ? bary / s : vec3(1.0 / 3.0);
    vec3 p = bary.x * t.p[0].xyz + bary.y * t.p[1].xyz + bary.z * t.p[2].xyz;
    vec3 nn = bary.x * t.n[0].xyz + bary.y * t.n[1].xyz + bary.z * t.n[2].xyz;
    float len = length(nn);
    vec3 n = (len > 1e-20) ? nn / len : -u_dir;
    if (dot(n, u_dir) > 0.0) n = -n;
    o_pos = vec4(p, 1.0);
    o_nrm = vec4(n, 0.0);
    o_col = bary.x * t.c[0] + bary.y * t.c[1] + bary.z * t.c[2];
}
