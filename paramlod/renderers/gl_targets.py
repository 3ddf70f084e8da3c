"""OpenGL render targets and their resolve into a Frame's arrays (part of the renderers kit): what
every OpenGL renderer draws into, whatever it draws (the tess variant's patches, the meshlets-gl
variant's clusters).

Driven by ``paramlod.renderers.tess.TessRenderer`` and ``paramlod.meshlod.draw.MeshDraw``, each
frame: ``targets_for`` (make or reuse targets for (size, supersampling, multisamples)),
``GLTargets.begin`` (bind and clear for drawing), the renderer's draw calls, ``GLTargets.resolve``
and ``GLTargets.read``. The OpenCL renderers' counterpart is ``paramlod.renderers.targets``.

Targets, at the supersampled size, multisampled or not: colour RGBA16F (linear RGB, alpha 1 where
drawn), linear view depth R32F, world normal RGBA16F, object id R32UI, a depth renderbuffer. A
fragment shader writes them at locations 0-3. The resolve (kernels/tess/tess_resolve_*.glsl, with
the prelude and tess_common.glsl for its counter buffer): the hardware multisample resolve of the
colour, box-averaged over the SSAA block (straight alpha = covered fraction); depth, normal and id of
the nearest covered sample of the block, +inf / 0 / 0 where none is.
"""
from __future__ import annotations

import math

import moderngl
import numpy as np

from paramlod import kernels
from paramlod.core.layouts import glsl_prelude
from paramlod.device.context import gl_cache
from paramlod.device.programs import GLSL_LINE, context_lines, set_uniform
from paramlod.errors import DeviceError, SceneError
from paramlod.renderers.aa import AAMode, cap_samples, parse_aa

DRAW_MASK = ((True,) * 4,) * 4                        # colour, depth, normal, object id
# only the colour (its alpha marks covered samples) and the depth buffer are cleared: the resolve
# never reads the other attachments where nothing was drawn, and on the H200 each cleared
# 4xSS+8xMS attachment costs 5-10 ms (its graphics units are few)
CLEAR_MASK = ((True,) * 4,) + ((False,) * 4,) * 3
_SAMPLE_KEYS = ("GL_MAX_SAMPLES", "GL_MAX_COLOR_TEXTURE_SAMPLES", "GL_MAX_INTEGER_SAMPLES",
                "GL_MAX_DEPTH_TEXTURE_SAMPLES")


def max_samples(ctx) -> int:
    """The most multisamples every target format supports on ``ctx``."""
    info = ctx.info
    vals = [int(info[k]) for k in _SAMPLE_KEYS if info.get(k) is not None]
    return min(vals) if vals else 1


def effective_aa(ctx, mode) -> tuple[AAMode, AAMode, list[str]]:
    """(requested, effective, warnings): the multisample count of ``mode`` capped to ``ctx``."""
    req = parse_aa(mode)
    eff, notes = req, []
    if req.msaa > 1:
        most = max_samples(ctx)
        got = cap_samples(req.msaa, most)
        if got != req.msaa:
            eff = AAMode(req.ss, got)
            notes.append(f"{req.msaa}xMS requested but this OpenGL device ({ctx.info.get('GL_RENDERER')}) "
                         f"supports at most {most} samples: rendering {eff.name} instead of {req.name}")
    return req, eff, notes


def resolve_program(ctx, ss: int, samples: int):
    """The resolve program for ``ss`` x ``ss`` supersampling and ``samples`` multisamples, cached."""
    programs = gl_cache(ctx).setdefault("gl_resolve_programs", {})
    key = (ss, samples)
    prog = programs.get(key)
    if prog is None:
        defs = {"PL_SS": ss, "PL_SAMPLES": samples}
        if samples > 1:
            defs["PL_MS"] = 1
        head = "#version 450 core\n" + "".join(f"#define {k} {v}\n" for k, v in defs.items())
        # the very text the tess renderer compiled before the move (tess_common.glsl declares the
        # counter buffer the resolve reports the device's sample count into)
        common = [glsl_prelude(), kernels.source("tess/tess_common.glsl")]
        stages = {name: head + "\n".join([*common, kernels.source(f"tess/tess_resolve_{part}.glsl")])
                  for name, part in (("vertex_shader", "vertex"), ("fragment_shader", "fragment"))}
        try:
            prog = ctx.program(**stages)
        except moderngl.Error as exc:
            log = str(exc)
            stage = next((k for k in stages if k in log), "fragment_shader")
            raise DeviceError(f"the OpenGL resolve shader does not compile on {ctx.info.get('GL_RENDERER')}:\n"
                              f"{context_lines(stages[stage], log, GLSL_LINE)}\ncompiler said:\n{log[-2000:]}") from None
        programs[key] = prog
    return prog


class GLTargets:
    """Render targets at the supersampled size (multisampled when ``samples`` > 1) and the
    single-sampled output targets at ``size``; ``what`` names the renderer in errors."""

    def __init__(self, ctx, size: tuple[int, int], ss: int, samples: int, what: str = "OpenGL"):
        self.ctx = ctx
        self.size, self.ss, self.samples = tuple(size), ss, samples
        w, h = size
        big = (w * ss, h * ss)
        ms = samples if samples > 1 else 0
        limit = min(int(ctx.info.get("GL_MAX_TEXTURE_SIZE", 16384)), int(ctx.info.get("GL_MAX_RENDERBUFFER_SIZE", 16384)))
        if max(big) > limit:
            raise SceneError(f"{ss}x{ss} supersampling of {w}x{h} needs {big[0]}x{big[1]} render targets, more than "
                             f"this OpenGL device's limit of {limit} pixels per side; use a smaller size or less supersampling")
        try:
            self.color = ctx.texture(big, 4, dtype="f2", samples=ms)
            self.depth = ctx.texture(big, 1, dtype="f4", samples=ms)
            self.normal = ctx.texture(big, 4, dtype="f2", samples=ms)
            self.object = ctx.texture(big, 1, dtype="u4", samples=ms)
            self.zbuf = ctx.depth_renderbuffer(big, samples=ms)
            self.fbo = ctx.framebuffer([self.color, self.depth, self.normal, self.object], self.zbuf)
            if ms:
                self.color_ms_fbo = ctx.framebuffer([self.color])
                self.color_resolved = ctx.texture(big, 4, dtype="f2")
                self.color_resolved_fbo = ctx.framebuffer([self.color_resolved])
            else:
                self.color_resolved = self.color
            # integer textures must be sampled with NEAREST (else incomplete); multisample ones have no filter
            single = [self.color_resolved] + ([] if ms else [self.depth, self.normal, self.object])
            for t in single:
                t.filter = (ctx.NEAREST, ctx.NEAREST)
            self.out_color = ctx.texture(size, 4, dtype="f4")
            self.out_depth = ctx.texture(size, 1, dtype="f4")
            self.out_normal = ctx.texture(size, 4, dtype="f4")
            self.out_object = ctx.texture(size, 1, dtype="u4")
            self.out_fbo = ctx.framebuffer([self.out_color, self.out_depth, self.out_normal, self.out_object])
            self.samples_buffer = ctx.buffer(reserve=8)   # the resolve writes the device's sample count at [1]
            self.resolve_vao = ctx.vertex_array(resolve_program(ctx, ss, samples), [])
        except DeviceError:
            self.release()
            raise
        except Exception as exc:  # moderngl.Error: out of memory, unsupported format
            self.release()
            raise DeviceError(f"could not create the {what} render targets ({w}x{h}, {ss}x{ss} SS, "
                              f"{samples} samples): {exc}") from None

    def begin(self):
        """Bind the targets for drawing and clear them (colour and depth only; see CLEAR_MASK)."""
        self.fbo.use()
        self.fbo.color_mask = CLEAR_MASK
        self.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        self.fbo.color_mask = DRAW_MASK

    def resolve(self) -> int:
        """Resolve what was drawn into the output targets (waits for the device); returns the
        samples per pixel the device really allocated (llvmpipe gives 4 for a 2xMS request)."""
        ctx = self.ctx
        if self.samples > 1:
            ctx.copy_framebuffer(self.color_resolved_fbo, self.color_ms_fbo)
        ctx.disable(moderngl.DEPTH_TEST)
        self.out_fbo.use()
        self.samples_buffer.bind_to_storage_buffer(4)
        prog = self.resolve_vao.program
        for unit, (name, tex) in enumerate((("u_color", self.color_resolved), ("u_coverage", self.color),
                                            ("u_depth", self.depth), ("u_normal", self.normal),
                                            ("u_object", self.object))):
            tex.use(location=unit)
            set_uniform(prog, name, unit)
        self.resolve_vao.render(mode=moderngl.TRIANGLES, vertices=3)
        ctx.finish()
        return int(np.frombuffer(self.samples_buffer.read(8), np.uint32)[1])

    def read(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The resolved (colour [h, w, 4], depth [h, w], normal [h, w, 3], object id [h, w]),
        contiguous host arrays with row 0 at the top."""
        w, h = self.size
        color = np.frombuffer(self.out_color.read(), np.float32).reshape(h, w, 4)[::-1]
        depth = np.frombuffer(self.out_depth.read(), np.float32).reshape(h, w)[::-1]
        normal = np.frombuffer(self.out_normal.read(), np.float32).reshape(h, w, 4)[::-1, :, :3]
        ids = np.frombuffer(self.out_object.read(), np.uint32).reshape(h, w)[::-1]
        return tuple(np.ascontiguousarray(a) for a in (color, depth, normal, ids))

    def release(self):
        for name in ("resolve_vao", "fbo", "color_ms_fbo", "color_resolved_fbo", "out_fbo", "color", "depth",
                     "normal", "object", "zbuf", "color_resolved", "out_color", "out_depth", "out_normal",
                     "out_object", "samples_buffer"):
            obj = self.__dict__.pop(name, None)
            if obj is not None:
                try:
                    obj.release()
                except Exception:
                    pass


def targets_for(current: GLTargets | None, ctx, size, ss: int, samples: int, what: str = "OpenGL") -> GLTargets:
    """``current`` when it fits (size, ss, samples), else new targets (``current`` released)."""
    if current is not None and (current.size, current.ss, current.samples) == (tuple(size), ss, samples):
        return current
    if current is not None:
        current.release()
    return GLTargets(ctx, tuple(size), ss, samples, what)


def gl_matrix(m) -> np.ndarray:
    """A row-major 4x4 matrix as GLSL's column-major mat4 (float32)."""
    return np.ascontiguousarray(np.asarray(m, np.float64).T, np.float32)


class GrowBuffer:
    """A GL buffer replaced by a bigger one (a power of two) when data does not fit
    (``generation`` counts the replacements, so vertex arrays that bind it know to rebuild)."""

    def __init__(self, ctx, nbytes: int = 16):
        self.ctx, self.buf, self.generation = ctx, ctx.buffer(reserve=max(16, nbytes)), 0

    def write(self, data: bytes):
        if len(data) > self.buf.size:
            self.buf.release()
            self.buf = self.ctx.buffer(reserve=1 << int(math.ceil(math.log2(len(data)))))
            self.generation += 1
        if data:
            self.buf.write(data)
