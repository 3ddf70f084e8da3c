"""Probes: the generated GLSL of a function evaluated on the GL device, for tests and debugging.

``glsl_surface`` is the GLSL twin of ``ParametricFunction.surface`` (numpy), as
``plugins.evaluate_cl`` is the OpenCL one: ``kernels/tess/tess_probe.glsl`` calls the generated
``pl_surface`` in a vertex shader and the results come back through transform feedback.
"""
from __future__ import annotations

import numpy as np

from paramlod import kernels
from paramlod.core.layouts import glsl_prelude
from paramlod.device.context import gl_context
from paramlod.device.programs import GLSL_LINE, context_lines, set_uniform
from paramlod.errors import FunctionError
from paramlod.function.codegen_glsl import glsl_dispatch_source
from paramlod.function.registry import get_function

# The process has one GL context (``gl_context()``), so what the probe keeps is not keyed by it:
# compiled programs by their vertex shader's source (which holds the generated code, so it names
# the functions exactly), and one 1x1 framebuffer (a draw needs a complete framebuffer even with
# rasterization off, and the EGL context has none; its default one cannot be bound again).
_programs: dict[str, object] = {}
_target = None


def _glsl_source(body: list[str], defines: dict | None = None) -> str:
    """A GLSL 4.50 stage: ``#version``, the ``defines``, the records' prelude
    (``paramlod.core.layouts.glsl_prelude``), ``tess/tess_common.glsl``, then ``body``."""
    head = "#version 450 core\n" + "".join(f"#define {k} {v}\n" for k, v in (defines or {}).items())
    return head + "\n".join([glsl_prelude(), kernels.source("tess/tess_common.glsl"), *body])




def _framebuffer(ctx):
    global _target
    if _target is None:
        _target = ctx.framebuffer([ctx.renderbuffer((1, 1))])
    return _target


def _probe_program(ctx, fn):
    import moderngl

    gen = glsl_dispatch_source([fn], position=False, surface=True)
    src = _glsl_source([gen, kernels.source("tess/tess_probe.glsl")])
    prog = _programs.get(src)
    if prog is None:
        try:
            prog = ctx.program(vertex_shader=src, varyings=["out_pos", "out_du", "out_dv"])
        except moderngl.Error as exc:
            raise FunctionError(f"the generated GLSL of '{fn.name}' ({fn.source}) does not compile.\n"
                                f"{context_lines(src, str(exc), GLSL_LINE)}\ncompiler said:\n{str(exc)[-2000:]}") from None
        _programs[src] = prog
    return prog


def glsl_surface(fn, u, v, block=None, **params):
    """(position, df/du, df/dv) of ``fn`` (a function or a registered name) evaluated by the
    generated GLSL on the GL device, each float32 broadcast(u, v) + (3,): the twin of
    ``fn.surface`` (numpy) for tests and debugging."""
    import moderngl

    fn = get_function(fn)
    u = np.asarray(u, np.float32)
    v = np.asarray(v, np.float32)
    shape = np.broadcast_shapes(u.shape, v.shape)
    uv = np.stack([np.broadcast_to(u, shape).reshape(-1), np.broadcast_to(v, shape).reshape(-1)], axis=1)
    if block is None:
        block = fn.param_block(params)
    block = np.concatenate([fn.device_blocks(np.asarray(block, np.float32).reshape(-1)), np.zeros(1, np.float32)])
    ctx = gl_context()
    prog = _probe_program(ctx, fn)
    n = len(uv)
    if n == 0:
        empty = np.zeros((*shape, 3), np.float32)
        return empty, empty.copy(), empty.copy()
    vbo = ctx.buffer(np.ascontiguousarray(uv).tobytes())
    out = ctx.buffer(reserve=n * 36)
    pbuf = ctx.buffer(block.tobytes())
    try:
        pbuf.bind_to_storage_buffer(0)
        set_uniform(prog, "u_func", 0)
        set_uniform(prog, "u_param_offset", 0)
        vao = ctx.vertex_array(prog, [(vbo, "2f", "in_uv")])
        _framebuffer(ctx).use()
        vao.transform(out, mode=moderngl.POINTS, vertices=n)
        res = np.frombuffer(out.read(), np.float32).reshape(n, 3, 3)
        vao.release()
    finally:
        for b in (vbo, out, pbuf):
            b.release()
    return tuple(np.ascontiguousarray(res[:, k].reshape(*shape, 3)) for k in range(3))
