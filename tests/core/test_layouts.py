"""The CPU<->GPU records of paramlod.core.layouts: each prelude compiles on its device (OpenCL,
OpenGL 4.5), and the sizes and offsets the devices see are the host's -- sizeof/offsetof of the
OpenCL structs, the std430 layout of the GLSL structs and of the tessellation renderer's storage
buffers and vertex format, every emitted #define -- and the generated sRGB table is bit for bit
the host's."""
from __future__ import annotations

import numpy as np
import pyopencl as cl
import pytest

import paramlod as pl
from paramlod import kernels
from paramlod.core import color, layouts, shading
from paramlod.core.layouts import (CAMERA, EVAL_PATCH, INSTANCE_F, INSTANCE_U, LIGHT, LOD_COUNTER, MATERIAL,
                                   RECORDS, RENDER_PATCH, camera_record, cl_prelude, glsl_prelude)
from paramlod.device.context import cl_device, gl_context
from paramlod.device.programs import build
from paramlod.function.registry import get_function
from paramlod.lod.patches import EVAL_DTYPE, RENDER_DTYPE
from paramlod.meshlod import raster
from paramlod.renderers import points, points_lfb
from paramlod.renderers.tess import PATCH_ATTRIBUTES, PATCH_FORMAT, _stage

STRUCTS = [r for r in RECORDS if r.struct]
FLAT = [r for r in RECORDS if not r.struct]


def expected_values(glsl: bool) -> list[tuple[str, int]]:
    """(macro, value) of every #define a prelude emits for the records and launch constants."""
    pre = "PL_" if glsl else ""
    out = []
    for r in FLAT:
        out.append((pre + r.size_macro, r.length))
        out += [(pre + r.macro(f.name), r.offset(f.name)) for f in r.fields]
    out += [(pre + c.name, c.value) for r in RECORDS for c in r.constants]
    out += [(pre + c.name, c.value) for c in layouts.LAUNCH]
    out.append(("PL_SPECULAR_EXPONENT", shading.SPECULAR_EXPONENT))
    return out


def struct_members(r) -> list[tuple[str, int, int]]:
    """(C member, byte offset, bytes) of a struct record: pad of 3 uints is pad0, pad1, pad2."""
    out = []
    for f in r.fields:
        base = r.offset(f.name)
        if f.count == 1 or (f.type == layouts.FLOAT and f.count in (2, 4)):
            out.append((f.name, base, 4 * f.count))
        else:
            out += [(f"{f.name}{i}", base + 4 * i, 4) for i in range(f.count)]
    return out


# --- host side ------------------------------------------------------------------------------------
def test_host_names_derive_from_the_declarations():
    from paramlod.lod import stage
    from paramlod.scene import scene

    assert EVAL_DTYPE == EVAL_PATCH.dtype and EVAL_DTYPE.itemsize == 32
    assert RENDER_DTYPE == RENDER_PATCH.dtype and RENDER_DTYPE.itemsize == 64
    assert (scene.INST_FLOATS, scene.INST_UINTS) == (INSTANCE_F.length, INSTANCE_U.length) == (32, 4)
    assert layouts.CAMERA_FLOATS == CAMERA.length == 36
    assert (stage.LOD_COUNTERS, stage.LOD_RENDER_TOTAL, stage.LOD_LOCAL) == (10, 1, 32)
    assert [stage.C_CHILDREN, stage.C_SPLIT, stage.C_CULLED, stage.C_RENDERED, stage.C_FORCED] == [0, 1, 2, 3, 4]
    # the render kernels' counters: what the host reads by name is the record's (PTS_*, LFB_*, RS_*)
    assert [layouts.POINTS_COUNTER.offset(k) for k in points.COUNTERS] == [0, 1, 2, 3]
    assert (points.SCHED_WORD, points.UNITS_WORD, points.COUNTER_WORDS) == (4, 5, 6)
    assert points_lfb.LFB_COUNTERS[0] == "tile_patch_pairs" and len(points_lfb.LFB_COUNTERS) == 12
    assert raster.COUNTERS[-1] == "atomics" and layouts.RASTER_COUNTER.length == 8
    assert layouts.RASTER_COUNTER.size == 8 * layouts.RASTER_COUNTER.length   # ulong words
    # the light record is what the renderers upload, and GLSL reads it as vec4 u_light (xyz, w)
    assert shading.LIGHT.shape == (LIGHT.length,) and LIGHT.slice("towards") == slice(0, 3)
    assert LIGHT.offset("ambient") == 3 and shading.LIGHT[3] == np.float32(shading.AMBIENT)
    # the material record is read as float4 / vec4 (rgb, specular)
    assert MATERIAL.size == 16 and MATERIAL.slice("color") == slice(0, 3) and MATERIAL.offset("specular") == 3


def test_camera_record_layout():
    cam = pl.Camera.look_at((1, 2, 3), (0, 0, 0), size=(64, 48), near=0.5, far=50)
    rec = camera_record(cam)
    want = np.concatenate([cam.view.reshape(-1), cam.projection.reshape(-1), [64, 48, 0.5, 50]]).astype(np.float32)
    assert rec.dtype == np.float32 and rec.tobytes() == want.tobytes()


def test_scene_buffers_follow_the_instance_records():
    s = pl.Scene()
    s.add("sphere", transform=pl.translate(1, 2, 3))
    inst_f, inst_u, _ = s.instance_buffers()
    assert inst_f.shape == (1, INSTANCE_F.length) and inst_u.shape == (1, INSTANCE_U.length)
    assert inst_f[0, INSTANCE_F.slice("model")].reshape(4, 4)[:3, 3].tolist() == [1, 2, 3]
    fn = get_function("sphere")
    assert inst_u[0, INSTANCE_U.offset("func")] == 0 and inst_u[0, INSTANCE_U.offset("params")] == 0
    assert inst_u[0, INSTANCE_U.offset("object")] == s.objects[0].object_id
    assert inst_f[0, INSTANCE_F.slice("domain")].tolist() == np.float32([*fn.u_range, *fn.v_range]).tolist()
    assert s.materials().shape == (1, MATERIAL.length)


def test_bad_struct_layouts_are_refused():
    F, U = layouts.Field, layouts.UINT
    with pytest.raises(ValueError, match="not a multiple of 16"):
        layouts.Record("x", "", [F("a", U), F("v", layouts.FLOAT, 4)], struct="X")
    with pytest.raises(ValueError, match="alignment"):
        layouts.Record("x", "", [F("v", layouts.FLOAT, 4), F("a", U)], struct="X")
    with pytest.raises(ValueError, match="record order"):
        layouts.vertex_format(RENDER_PATCH, ["ext", "range"])
    assert PATCH_FORMAT == "4f 16x 4f 1u 12x" and PATCH_ATTRIBUTES == ("range", "ext", "inst")


# --- OpenCL -------------------------------------------------------------------------------------
def _cl_run(src: str, n_out: int, dtype=np.uint32, args=()):
    dev = cl_device()
    prog = cl.Program(dev.context, cl_prelude() + "\n" + src).build()
    out = np.zeros(n_out, dtype)
    buf = cl.Buffer(dev.context, cl.mem_flags.WRITE_ONLY, out.nbytes)
    prog.probe(dev.queue, (1,), None, buf, *args)
    cl.enqueue_copy(dev.queue, out, buf)
    return out


def test_cl_prelude_compiles_alone():
    cl.Program(cl_device().context, cl_prelude() + "\n__kernel void probe(__global uint* o) { o[0] = 1u; }\n").build()


def test_a_build_define_the_prelude_has_is_refused():
    """A -D of a macro the prelude defines again would be overridden without an error (the LOD
    stage's first LOD_BACKFACE switch kept the counter index 5): the build names it instead."""
    with pytest.raises(ValueError, match="LOD_BACKFACE is already a macro of the prelude"):
        build(["common/keys.cl"], {"LOD_BACKFACE": 0})


def test_cl_sizes_and_offsets_agree():
    items = [(f"(uint)({m})", v) for m, v in expected_values(glsl=False)]
    for r in STRUCTS:
        items.append((f"(uint)sizeof({r.struct})", r.size))
        for m, off, size in struct_members(r):
            items.append((f"(uint)__builtin_offsetof({r.struct}, {m})", off))
            items.append((f"(uint)sizeof((({r.struct}*)0)->{m})", size))
    body = "\n".join(f"    o[{i}] = {e};" for i, (e, _) in enumerate(items))
    got = _cl_run(f"__kernel void probe(__global uint* o) {{\n{body}\n}}\n", len(items))
    assert dict(zip((e for e, _ in items), got.tolist())) == {e: v for e, v in items}


def member_copies(r, read: str, write: str, as_uint: str) -> list[str]:
    """Statements that copy every member of struct record ``r`` (``read``: the record, e.g.
    "p[i]") as uints to ``write`` (a format with the word index), in declaration order."""
    lines, at = [], 0
    for f in r.fields:
        if f.type == layouts.FLOAT and f.count in (2, 4):
            for k in "xyzw"[:f.count]:
                lines.append(f"{write.format(at)} = {as_uint}({read}.{f.name}.{k});")
                at += 1
        else:
            for m in [f.name] if f.count == 1 else [f"{f.name}{j}" for j in range(f.count)]:
                lines.append(f"{write.format(at)} = {as_uint if f.type == layouts.FLOAT else ''}({read}.{m});")
                at += 1
    assert at == r.size // 4
    return lines


def test_cl_structs_read_the_host_records():
    """A kernel copies every member of 3 host records (arrays of EvalPatch / RenderPatch) out in
    order: the members cover a record exactly, so the copy is the records' bytes (the array
    stride is the dtype's size)."""
    dev = cl_device()
    for r in STRUCTS:
        recs = np.frombuffer(np.arange(3 * r.size // 4, dtype=np.uint32).tobytes(), r.dtype)
        words = r.size // 4
        lines = member_copies(r, "in[i]", f"o[i * {words} + {{}}]", "as_uint")
        src = (f"__kernel void probe(__global uint* o, __global const {r.struct}* in) {{\n"
               "    for (uint i = 0; i < 3u; ++i) {\n" + "\n".join("        " + x for x in lines) + "\n    }\n}\n")
        in_buf = cl.Buffer(dev.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=recs)
        got = _cl_run(src, 3 * words, args=(in_buf,))
        assert got.tobytes() == recs.tobytes(), r.name


def test_cl_srgb_tables_are_the_hosts():
    got = _cl_run("__kernel void probe(__global float* o) {\n"
                  "    for (int i = 0; i < 256; ++i) { o[i] = SRGB8_DECODED[i]; o[256 + i] = SRGB8_THRESHOLDS[i]; }\n}\n",
                  512, np.float32)
    assert got[:256].tobytes() == color.srgb8_decoded().tobytes()
    assert got[256:].tobytes() == color.srgb8_thresholds().tobytes()


# --- GLSL ----------------------------------------------------------------------------------------
def _compute(src: str, buffers: dict, n_out: int, groups: int = 1) -> np.ndarray:
    ctx = gl_context()
    cs = ctx.compute_shader(src)
    out = ctx.buffer(reserve=4 * n_out)
    bufs = [out]
    try:
        out.bind_to_storage_buffer(7)
        for binding, data in buffers.items():
            b = ctx.buffer(np.ascontiguousarray(data).tobytes())
            b.bind_to_storage_buffer(binding)
            bufs.append(b)
        cs.run(group_x=groups)
        ctx.finish()
        return np.frombuffer(out.read(), np.uint32).copy()
    finally:
        for b in bufs:
            b.release()
        cs.release()


_OUT = "layout(std430, binding = 7) buffer PlProbeOut { uint o[]; };\nlayout(local_size_x = 1) in;\n"


def test_glsl_prelude_compiles_alone():
    ctx = gl_context()
    prog = ctx.program(vertex_shader="#version 450 core\n" + glsl_prelude() +
                       "\nvoid main() { gl_Position = vec4(float(PL_INST_F)); }\n")
    prog.release()


def test_glsl_defines_agree():
    items = expected_values(glsl=True)
    body = "\n".join(f"    o[{i}] = uint({m});" for i, (m, _) in enumerate(items))
    got = _compute("#version 450 core\n" + glsl_prelude() + _OUT + "void main() {\n" + body + "\n}\n", {}, len(items))
    assert dict(zip((m for m, _ in items), got.tolist())) == dict(items)


def test_glsl_std430_structs_match_the_dtypes():
    """std430 arrays of the prelude's EvalPatch / RenderPatch structs read the host's records:
    member by member, in order, they give back the records' bytes (stride = the dtype's size)."""
    for r in STRUCTS:
        recs = np.frombuffer(np.arange(3 * r.size // 4, dtype=np.uint32).tobytes(), r.dtype)
        lines = member_copies(r, "p[i]", f"o[i * {r.size // 4}u + {{}}u]", "floatBitsToUint")
        src = ("#version 450 core\n" + glsl_prelude() + _OUT +
               f"layout(std430, binding = 0) readonly buffer PlProbeIn {{ {r.struct} p[]; }};\n"
               "void main() {\n    for (uint i = 0u; i < 3u; ++i) {\n" + "\n".join("        " + x for x in lines) + "\n    }\n}\n")
        got = _compute(src, {0: recs}, 3 * r.size // 4)
        assert got.tobytes() == recs.tobytes(), r.name


def test_tess_storage_buffers_follow_the_records():
    """The tessellation stages' helpers (tess_common.glsl, through the renderer's own stage
    assembly) read the scene's instance, parameter and material buffers where the host wrote them."""
    s = pl.Scene()
    s.add("sphere", transform=pl.translate(1, 2, 3) @ pl.scale(2), material=pl.Material(color=(0.1, 0.2, 0.3)))
    s.add("torus", params={"major": 0.7}, material=pl.Material(color=(0.5, 0.6, 0.7), specular=0.5))
    inst_f, inst_u, params = s.instance_buffers()
    n = len(inst_f)
    per = 4 + 4 + 3 + 4 + 3   # domain, uints, model * (1, 2, 3), material, normal rows * (0, 0, 1)
    body = f"""
layout(std430, binding = 7) buffer PlProbeOut {{ uint o[]; }};
layout(local_size_x = 1) in;
void main() {{
    uint i = gl_WorkGroupID.x, at = i * {per}u;
    vec4 d = pl_domain(i);
    for (uint k = 0u; k < 4u; ++k) o[at + k] = floatBitsToUint(d[k]);
    for (uint k = 0u; k < PL_INST_U; ++k) o[at + 4u + k] = pl_inst_u[i * PL_INST_U + k];
    vec3 p = pl_rows_point(i * PL_INST_F + PL_INST_MODEL, vec3(1.0, 2.0, 3.0));
    for (uint k = 0u; k < 3u; ++k) o[at + 8u + k] = floatBitsToUint(p[k]);
    vec4 m = pl_materials[i];
    for (uint k = 0u; k < 4u; ++k) o[at + 11u + k] = floatBitsToUint(m[k]);
    vec3 q = pl_rows_dir(i * PL_INST_F + PL_INST_NORMAL, vec3(0.0, 0.0, 1.0));
    for (uint k = 0u; k < 3u; ++k) o[at + 15u + k] = floatBitsToUint(q[k]);
}}
"""
    got = _compute(_stage({}, [body]), {0: params, 1: inst_f, 2: inst_u, 3: s.materials()}, n * per, groups=n)
    got = got.view(np.float32).reshape(n, per)
    for i in range(n):
        assert got[i, 0:4].tolist() == inst_f[i, INSTANCE_F.slice("domain")].tolist()
        assert got[i, 4:8].view(np.uint32).tolist() == inst_u[i].tolist()
        model = inst_f[i, INSTANCE_F.slice("model")].reshape(4, 4).astype(np.float64)
        np.testing.assert_allclose(got[i, 8:11], model[:3] @ [1, 2, 3, 1], rtol=1e-6)
        assert got[i, 11:15].tolist() == s.materials()[i].tolist()
        nrm = inst_f[i, INSTANCE_F.slice("normal")].reshape(3, 4)
        np.testing.assert_allclose(got[i, 15:18], nrm[:, 2], rtol=1e-6)


def test_tess_vertex_format_reads_the_render_list():
    """The renderer's vertex format (derived from RENDER_PATCH) hands each record's range, ext and
    inst to the vertex stage: the attributes come back through transform feedback unchanged."""
    ctx = gl_context()
    rng = np.random.default_rng(3)
    recs = np.zeros(5, RENDER_DTYPE)
    for name in ("range", "bbox", "ext"):
        recs[name] = rng.random((5, 4), np.float32)
    recs["inst"] = [3, 1, 4, 1, 5]
    recs["flags"] = 0xFFFF
    vs = ("#version 450 core\n" + glsl_prelude() +
          "in vec4 in_range; in vec4 in_ext; in uint in_inst;\n"
          "out vec4 o_range; out vec4 o_ext; out float o_inst;\n"
          "void main() { o_range = in_range; o_ext = in_ext; o_inst = float(in_inst); gl_Position = vec4(0.0); }\n")
    prog = ctx.program(vertex_shader=vs, varyings=["o_range", "o_ext", "o_inst"])
    vbo = ctx.buffer(recs.tobytes())
    out = ctx.buffer(reserve=len(recs) * 9 * 4)
    vao = ctx.vertex_array(prog, [(vbo, PATCH_FORMAT, *(f"in_{a}" for a in PATCH_ATTRIBUTES))])
    try:
        import moderngl

        fbo = ctx.framebuffer([ctx.renderbuffer((1, 1))])
        fbo.use()
        vao.transform(out, mode=moderngl.POINTS, vertices=len(recs))
        got = np.frombuffer(out.read(), np.float32).reshape(len(recs), 9)
    finally:
        for o in (vao, vbo, out, prog):
            o.release()
    assert got[:, 0:4].tobytes() == recs["range"].tobytes()
    assert got[:, 4:8].tobytes() == recs["ext"].tobytes()
    assert got[:, 8].tolist() == recs["inst"].tolist()


def test_shading_snippet_compiles_on_both():
    """kernels/common/shading.cl, the one shading body, compiles as OpenCL C and as GLSL and gives
    the same colours for ordinary inputs (the specular power differs in how it is computed)."""
    n = np.array([[0.2, 0.3, 0.93], [-0.5, 0.1, 0.86], [0.0, 0.0, -1.0], [0.0, 0.0, 0.0]], np.float32)
    ev = np.array([0.0, 0.0, 1.0], np.float32)
    L = shading.LIGHT
    mat = np.array([0.8, 0.4, 0.2, 0.5], np.float32)
    cl_src = (kernels.source("common/dialect.cl") + "\n" + kernels.source("common/shading.cl") + """
__kernel void probe(__global float* o, __global const float* nv, __global const float* light) {
    for (uint i = 0; i < 4u; ++i) {
        float3 ev = (float3)(0.0f, 0.0f, 1.0f);
        float3 nn = pl_facing_normal(vload3(i, nv), ev);
        float3 c = pl_shade_rgb(nn, ev, (float3)(0.8f, 0.4f, 0.2f), 0.5f,
                                (float3)(light[LIGHT_TOWARDS], light[LIGHT_TOWARDS + 1], light[LIGHT_TOWARDS + 2]),
                                light[LIGHT_AMBIENT]);
        vstore3(c, i, o);
    }
}
""")
    dev = cl_device()
    mk = lambda a: cl.Buffer(dev.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=a)
    got_cl = _cl_run(cl_src, 12, np.float32, args=(mk(n.reshape(-1)), mk(L))).reshape(4, 3)
    gl_src = ("#version 450 core\n" + glsl_prelude() + kernels.source("common/dialect.glsl") + "\n" +
              kernels.source("common/shading.cl") + """
layout(std430, binding = 7) buffer PlProbeOut { float o[]; };
layout(std430, binding = 0) readonly buffer PlN { float nv[]; };
layout(local_size_x = 1) in;
uniform vec4 u_light;
void main() {
    for (uint i = 0u; i < 4u; ++i) {
        vec3 ev = vec3(0.0, 0.0, 1.0);
        vec3 nn = pl_facing_normal(vec3(nv[3u * i], nv[3u * i + 1u], nv[3u * i + 2u]), ev);
        vec3 c = pl_shade_rgb(nn, ev, vec3(0.8, 0.4, 0.2), 0.5, u_light.xyz, u_light.w);
        for (uint k = 0u; k < 3u; ++k) o[3u * i + k] = c[k];
    }
}
""")
    ctx = gl_context()
    cs = ctx.compute_shader(gl_src)
    cs["u_light"].value = tuple(float(x) for x in L)
    out, nb = ctx.buffer(reserve=48), ctx.buffer(n.tobytes())
    try:
        out.bind_to_storage_buffer(7)
        nb.bind_to_storage_buffer(0)
        cs.run(group_x=1)
        ctx.finish()
        got_gl = np.frombuffer(out.read(), np.float32).reshape(4, 3)
    finally:
        for o in (out, nb, cs):
            o.release()
    # float64 reference of the model
    nn = n.astype(np.float64)
    ln = np.linalg.norm(nn, axis=1, keepdims=True)
    nn = np.where(ln > 1e-30, nn / np.where(ln > 0, ln, 1), ev)
    nn = np.where((nn @ ev)[:, None] < 0, -nn, nn)
    Lv = L[:3].astype(np.float64)
    h = (Lv + ev) / np.linalg.norm(Lv + ev)
    spec = mat[3] * np.maximum(nn @ h, 0) ** shading.SPECULAR_EXPONENT
    want = mat[:3] * (L[3] + (1 - L[3]) * np.maximum(nn @ Lv, 0))[:, None] + spec[:, None]
    np.testing.assert_allclose(got_cl, want, rtol=2e-5, atol=1e-6)
    np.testing.assert_allclose(got_gl, want, rtol=2e-5, atol=1e-6)
