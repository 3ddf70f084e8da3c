// The instance records' 3x4 affine rows in GLSL (tess stages, the meshlets-gl draw): rows of 4
// floats starting at pl_inst_f[base], applied to a point / a direction. The includer declares the
// pl_inst_f storage buffer. One order of operations for both, so a mesh and a parametric object of
// one transform agree.
vec3 pl_rows_point(uint base, vec3 p) {
    return vec3(pl_inst_f[base + 0u] * p.x + pl_inst_f[base + 1u] * p.y + pl_inst_f[base + 2u] * p.z + pl_inst_f[base + 3u],
                pl_inst_f[base + 4u] * p.x + pl_inst_f[base + 5u] * p.y + pl_inst_f[base + 6u] * p.z + pl_inst_f[base + 7u],
                pl_inst_f[base + 8u] * p.x + pl_inst_f[base + 9u] * p.y + pl_inst_f[base + 10u] * p.z + pl_inst_f[base + 11u]);
}

vec3 pl_rows_dir(uint base, vec3 d) {
    return vec3(pl_inst_f[base + 0u] * d.x + pl_inst_f[base + 1u] * d.y + pl_inst_f[base + 2u] * d.z,
                pl_inst_f[base + 4u] * d.x + pl_inst_f[base + 5u] * d.y + pl_inst_f[base + 6u] * d.z,
                pl_inst_f[base + 8u] * d.x + pl_inst_f[base + 9u] * d.y + pl_inst_f[base + 10u] * d.z);
}
