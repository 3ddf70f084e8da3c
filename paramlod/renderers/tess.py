"""Tessellation renderer (thesis sections 5.5.2, 5.5.4-5.5.6): the LOD stage's render patches drawn
with OpenGL 4.5 hardware tessellation through moderngl, with noAA, MSAA, SSAA or both.

One quad patch per render patch (a single control point carrying the parameter range, the
measured extents and the instance); the evaluation stage positions each generated vertex with
the function's generated GLSL (``codegen_glsl``) and its analytic normal; per-instance parameters
live in a shader storage buffer. Shading is the point renderer's (``kernels/keys.cl`` shade()).

Anti-aliasing modes (``parse_aa``): ``noAA``; ``2xMS``/``4xMS``/``8xMS`` (aliases ``msaa2`` ...);
``4xSS``/``9xSS``/``16xSS`` (2x2, 3x3, 4x4 supersampling; aliases ``ssaa2x2`` ...); and
combinations such as ``4xSS+8xMS`` (32 depth samples per pixel). A multisample request above what
the device supports is capped, with a warning and ``stats["warnings"]``. The LOD thresholds are
divided by ``lod_divisor(mode)``: the supersampling factor per axis (``msaa_lod`` adds sqrt(MSAA)).

Targets: colour RGBA16F (hardware multisample resolve, then a box downsample of the SSAA block),
linear view depth R32F, world normal RGBA16F and object id R32UI (resolved to the nearest covered
sample of the pixel; ``kernels/tess_resolve_fragment.glsl``). ``docs/tessellation.md`` has the
details, including how cracks between patches are avoided.
"""
from __future__ import annotations

import math
import re
import time
import warnings
from dataclasses import dataclass

import numpy as np

from paramlod import kernels

from paramlod.core.camera import Camera
from paramlod.function.codegen_glsl import glsl_dispatch_source
from paramlod.device.context import gl_context
from paramlod.errors import DeviceError, FunctionError, SceneError
from paramlod.core.frame import Frame
from paramlod.lod.patches import RENDER_DTYPE
from paramlod.device.programs import GLSL_LINE, context_lines
from paramlod.scene.scene import Scene

# Highest tessellation level allowed: GL_MAX_TESS_GEN_LEVEL is at least 64 on every GL 4.x device.
MAX_LEVEL = 64.0
# llvmpipe: worst-case generated vertices per draw call (see TessRenderer.patches_per_draw)
LLVMPIPE_VERTEX_BUDGET = 60000
SPACINGS = {"equal": "equal_spacing", "fractional_odd": "fractional_odd_spacing"}
_MS_ALIASES = {f"msaa{n}": n for n in (2, 4, 8)}
_SS_ALIASES = {f"ssaa{n}x{n}": n for n in (2, 3, 4)}


# --- anti-aliasing modes ------------------------------------------------------------------------
@dataclass(frozen=True)
class AAMode:
    """``ss`` x ``ss`` supersampling (1 = none) combined with ``msaa`` multisamples (1 = none)."""

    ss: int = 1
    msaa: int = 1

    @property
    def samples_per_pixel(self) -> int:
        return self.ss * self.ss * self.msaa

    def divisor(self, msaa_lod: bool = False) -> float:
        """LOD threshold divisor: ``ss``, so the LOD stage measures patches in the supersampled
        target's pixels (the thesis's 4xSS+8xMS figures: 4x the patches of noAA "due to 4xSS");
        with ``msaa_lod`` also sqrt(msaa), the hybrid scheme's guideline (sqrt(32) for 4xSS+8xMS)."""
        return self.ss * (math.sqrt(self.msaa) if msaa_lod else 1.0)

    @property
    def name(self) -> str:
        parts = []
        if self.ss > 1:
            parts.append(f"{self.ss * self.ss}xSS")
        if self.msaa > 1:
            parts.append(f"{self.msaa}xMS")
        return "+".join(parts) or "noAA"


def parse_aa(mode) -> AAMode:
    """``"noAA"``, ``"8xMS"``, ``"4xSS"``, ``"4xSS+8xMS"``, ``"msaa4"``, ``"ssaa3x3"`` ... -> AAMode."""
    if isinstance(mode, AAMode):
        return mode
    if not isinstance(mode, str) or not mode.strip():
        raise SceneError(f"anti-aliasing mode must be a string such as 'noAA', '8xMS', '4xSS' or "
                         f"'4xSS+8xMS', got {mode!r}")
    text = mode.strip()
    if text.lower() in ("noaa", "none", "off"):
        return AAMode()
    ss, ms = 1, 1
    for part in (p.strip().lower() for p in text.split("+")):
        m_ms = re.fullmatch(r"(\d+)x?ms(?:aa)?", part)
        m_ss = re.fullmatch(r"(\d+)x?ss(?:aa)?", part)
        if part in _MS_ALIASES or m_ms:
            n = _MS_ALIASES.get(part) or int(m_ms.group(1))
            if n not in (2, 4, 8) or ms != 1:
                raise SceneError(f"anti-aliasing mode {mode!r}: multisampling must be given once, as 2xMS, "
                                 "4xMS or 8xMS")
            ms = n
        elif part in _SS_ALIASES or m_ss:
            if part in _SS_ALIASES:
                n = _SS_ALIASES[part]
            else:
                total = int(m_ss.group(1))
                n = math.isqrt(total)
                if n * n != total or n not in (2, 3, 4):
                    raise SceneError(f"anti-aliasing mode {mode!r}: supersampling must be 4xSS, 9xSS or 16xSS "
                                     "(2x2, 3x3, 4x4 samples per pixel)")
            if ss != 1:
                raise SceneError(f"anti-aliasing mode {mode!r}: supersampling must be given once")
            ss = n
        else:
            raise SceneError(f"unknown anti-aliasing mode {mode!r}: use noAA, 2xMS, 4xMS, 8xMS, 4xSS, 9xSS, "
                             "16xSS or a combination such as 4xSS+8xMS")
    return AAMode(ss, ms)


def lod_divisor(mode, max_samples: int | None = None, msaa_lod: bool = False) -> float:
    """Threshold divisor of an AA mode (``AAMode.divisor``): 2 for 4xSS and 4xSS+8xMS, 1 for 8xMS;
    with ``msaa_lod`` sqrt(samples per pixel): sqrt(8) for 8xMS, sqrt(32) for 4xSS+8xMS. With
    ``max_samples`` the multisample count is first capped to what the device supports."""
    aa = parse_aa(mode)
    if max_samples is not None and aa.msaa > 1:
        aa = AAMode(aa.ss, _cap_samples(aa.msaa, max_samples))
    return aa.divisor(msaa_lod)


def _cap_samples(requested: int, max_samples: int) -> int:
    n = requested
    while n > 1 and n > max_samples:
        n //= 2
    return max(n, 1)


# --- settings -----------------------------------------------------------------------------------
@dataclass
class TessSettings:
    """How render patches are tessellated and sampled.

    mode "adaptive": l = clamp(e * L / min(t, L), l_min, l_max) per level, with L = ``base_level``,
    t the effective LOD threshold and e the patch's measured extent (inner levels) or the screen
    length of the edge itself (outer levels). mode "fixed": ``levels`` = (inner, outer).
    ``overlap``: each patch's parameter range is widened by this fraction per side (within the
    domain), which covers T-junctions between patches of different size.
    """

    mode: str = "adaptive"
    levels: tuple[float, float] = (16.0, 16.0)
    base_level: float = 64.0
    l_min: float = 8.0
    l_max: float = 64.0
    spacing: str = "fractional_odd"
    aa: str = "noAA"
    overlap: float = 0.005
    msaa_lod: bool = False   # divide the LOD threshold by sqrt(msaa) too (see AAMode.divisor)

    def validate(self):
        if self.mode not in ("adaptive", "fixed"):
            raise SceneError(f"tess mode must be 'adaptive' or 'fixed', got {self.mode!r}")
        if self.spacing not in SPACINGS:
            raise SceneError(f"tess spacing must be one of {', '.join(SPACINGS)}, got {self.spacing!r}")
        try:
            inner, outer = (float(x) for x in self.levels)
        except (TypeError, ValueError):
            raise SceneError(f"tess levels must be (inner, outer), got {self.levels!r}") from None
        for name, val in (("inner level", inner), ("outer level", outer), ("base_level", self.base_level),
                          ("l_min", self.l_min), ("l_max", self.l_max)):
            if not (isinstance(val, (int, float)) and 1 <= val <= MAX_LEVEL):
                raise SceneError(f"tess {name} must be in [1, {MAX_LEVEL:g}], got {val!r}")
        if self.l_min > self.l_max:
            raise SceneError(f"tess l_min ({self.l_min}) is above l_max ({self.l_max})")
        if not 0 <= self.overlap <= 0.25:
            raise SceneError(f"tess overlap must be in [0, 0.25] of a patch's range per side, got {self.overlap!r}")
        parse_aa(self.aa)


# --- shader programs ----------------------------------------------------------------------------
def _stage(defines: dict, body: list[str]) -> str:
    head = "#version 450 core\n" + "".join(f"#define {k} {v}\n" for k, v in defines.items())
    return head + "\n".join([kernels.source("tess/tess_common.glsl"), *body])


def _program(ctx, stages: dict, functions) -> object:
    import moderngl

    try:
        return ctx.program(**stages)
    except moderngl.Error as exc:
        log = str(exc)
        # find the stage the log is about, to show its lines
        stage = next((k for k in stages if k in log), None)   # moderngl names the stage
        shown = context_lines(stages[stage], log, GLSL_LINE) if stage else ""
        names = ", ".join(f"'{f.name}' ({f.source})" for f in functions) or "none"
        raise FunctionError(
            f"the generated GLSL does not compile (functions: {names}"
            f"{', stage: ' + stage if stage else ''}).\n{shown}\ncompiler said:\n{log[-2000:]}") from None


_programs: dict[tuple, object] = {}


def build_programs(ctx, functions, spacing: str):
    """(tessellation program, resolve programs by multisampling) for ``functions``, cached."""
    functions = list(functions)
    # keyed by the function objects: generating the GLSL again just to look it up cost ~150 ms a
    # frame for an order-12 SH glyph
    key = (id(ctx), tuple(id(f) for f in functions), spacing)
    progs = _programs.get(key)
    if progs is None:
        gen_pos = glsl_dispatch_source(functions, position=True, surface=False)
        gen_surf = glsl_dispatch_source(functions, position=False, surface=True)
        tess_defs = {"PL_SPACING": SPACINGS[spacing]}
        stages = {
            "vertex_shader": _stage(tess_defs, [kernels.source("tess/tess_vertex.glsl")]),
            "tess_control_shader": _stage(tess_defs, [gen_pos, kernels.source("tess/tess_control.glsl")]),
            "tess_evaluation_shader": _stage(tess_defs, [gen_surf, kernels.source("tess/tess_eval.glsl")]),
            "fragment_shader": _stage(tess_defs, [kernels.source("tess/tess_fragment.glsl")]),
        }
        progs = _programs[key] = _program(ctx, stages, functions)
    return progs


_resolve_programs: dict[tuple, object] = {}


def _resolve_program(ctx, ss: int, samples: int):
    key = (id(ctx), ss, samples)
    prog = _resolve_programs.get(key)
    if prog is None:
        defs = {"PL_SS": ss, "PL_SAMPLES": samples}
        if samples > 1:
            defs["PL_MS"] = 1
        prog = _resolve_programs[key] = _program(ctx, {
            "vertex_shader": _stage(defs, [kernels.source("tess/tess_resolve_vertex.glsl")]),
            "fragment_shader": _stage(defs, [kernels.source("tess/tess_resolve_fragment.glsl")]),
        }, [])
    return prog


_DRAW_MASK = ((True,) * 4,) * 4                        # colour, depth, normal, object id
_CLEAR_MASK = ((True,) * 4,) + ((False,) * 4,) * 3


def _set(prog, name, value):
    """Set a uniform if the compiler kept it (unused uniforms are optimized away)."""
    try:
        u = prog[name]
    except KeyError:
        return
    if isinstance(value, np.ndarray):
        u.write(np.ascontiguousarray(value, np.float32).tobytes())
    else:
        u.value = value


def _mat(m) -> np.ndarray:
    """A row-major 4x4 matrix as GLSL's column-major mat4 bytes."""
    return np.ascontiguousarray(np.asarray(m, np.float64).T, np.float32)


# --- render targets -----------------------------------------------------------------------------
class _Targets:
    """Multisampled (or not) render targets at the supersampled size, and the resolve targets."""

    def __init__(self, ctx, size: tuple[int, int], ss: int, samples: int):
        self.size, self.ss, self.samples = size, ss, samples
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
        except Exception as exc:  # moderngl.Error: out of memory, unsupported format
            self.release()
            raise DeviceError(f"could not create the tessellation render targets ({w}x{h}, {ss}x{ss} SS, "
                              f"{samples} samples): {exc}") from None

    def release(self):
        for name in ("fbo", "color_ms_fbo", "color_resolved_fbo", "out_fbo", "color", "depth", "normal", "object",
                     "zbuf", "color_resolved", "out_color", "out_depth", "out_normal", "out_object"):
            obj = self.__dict__.pop(name, None)
            if obj is not None:
                try:
                    obj.release()
                except Exception:
                    pass


class _GrowBuffer:
    """A GL buffer that is replaced by a bigger one when data does not fit (``generation`` counts)."""

    def __init__(self, ctx, nbytes: int):
        self.ctx, self.buf, self.generation = ctx, ctx.buffer(reserve=max(16, nbytes)), 0

    def write(self, data: bytes):
        if len(data) > self.buf.size:
            self.buf.release()
            self.buf = self.ctx.buffer(reserve=1 << int(math.ceil(math.log2(len(data)))))
            self.generation += 1
        if data:
            self.buf.write(data)


# --- the renderer -------------------------------------------------------------------------------
class TessRenderer:
    """Compiled programs and reusable GL buffers and targets for one set of functions."""

    def __init__(self, functions):
        self.functions = list(functions)
        self.ctx = gl_context()
        glsl_dispatch_source(self.functions, position=True, surface=False)  # fails early, naming the function
        self._targets: _Targets | None = None
        c = self.ctx
        self._patches = _GrowBuffer(c, 64 * 1024)
        self._params = _GrowBuffer(c, 1024)
        self._inst_f = _GrowBuffer(c, 1024)
        self._inst_u = _GrowBuffer(c, 1024)
        self._materials = _GrowBuffer(c, 1024)
        self._counters = c.buffer(reserve=16)
        self._vaos: dict = {}

    @property
    def max_samples(self) -> int:
        info = self.ctx.info
        keys = ("GL_MAX_SAMPLES", "GL_MAX_COLOR_TEXTURE_SAMPLES", "GL_MAX_INTEGER_SAMPLES", "GL_MAX_DEPTH_TEXTURE_SAMPLES")
        vals = [int(info[k]) for k in keys if info.get(k) is not None]
        return min(vals) if vals else 1

    def effective_aa(self, mode) -> tuple[AAMode, AAMode, list[str]]:
        """(requested, effective, warnings): the multisample count capped to the device."""
        req = parse_aa(mode)
        eff, notes = req, []
        if req.msaa > 1:
            got = _cap_samples(req.msaa, self.max_samples)
            if got != req.msaa:
                eff = AAMode(req.ss, got)
                notes.append(f"{req.msaa}xMS requested but this OpenGL device ({self.ctx.info.get('GL_RENDERER')}) "
                             f"supports at most {self.max_samples} samples: rendering {eff.name} instead of {req.name}")
        return req, eff, notes

    def patches_per_draw(self, settings: TessSettings) -> int:
        """Patches per draw call. One call draws everything, except on Mesa's llvmpipe, which
        silently drops triangles once a single tessellated draw generates more than about 65,536
        vertices (seen with Mesa 22.3): there the list is drawn in batches whose worst-case vertex
        count stays below that."""
        if "llvmpipe" not in str(self.ctx.info.get("GL_RENDERER", "")).lower():
            return 1 << 30
        top = max(settings.levels) if settings.mode == "fixed" else settings.l_max
        side = int(math.ceil(top)) + 2           # vertices per row, fractional spacing included
        return max(1, LLVMPIPE_VERTEX_BUDGET // (side * side + 4 * side))

    def _targets_for(self, size, ss, samples) -> _Targets:
        t = self._targets
        if t is None or (t.size, t.ss, t.samples) != (tuple(size), ss, samples):
            if t is not None:
                t.release()
            self._targets = None
            self._targets = _Targets(self.ctx, tuple(size), ss, samples)
        return self._targets

    def _vao(self, prog):
        key = (id(prog), self._patches.generation)
        vao = self._vaos.get(key)
        if vao is None:
            for k in [k for k in self._vaos if k[0] == id(prog)]:  # made for a released buffer
                self._vaos.pop(k).release()
            vao = self._vaos[key] = self.ctx.vertex_array(
                prog, [(self._patches.buf, "4f 16x 4f 1u 12x", "in_range", "in_ext", "in_inst")])
        return vao

    def draw(self, render_list: np.ndarray, n: int | None, scene: Scene, camera: Camera,
             settings: TessSettings | None = None, threshold=None) -> Frame:
        """Draw ``n`` records of ``render_list`` (RENDER_DTYPE, from LodStage.read_render_list).

        ``threshold``: the effective LOD thresholds (t_u, t_v) in output pixels that made the list,
        used by adaptive levels; default 84 px divided by ``lod_divisor`` of the AA mode.
        """
        import moderngl

        settings = settings or TessSettings()
        settings.validate()
        if not isinstance(scene, Scene) or not scene.objects:
            raise SceneError("the scene has no objects; add one with scene.add(...)")
        if [id(f) for f in scene.functions()] != [id(f) for f in self.functions]:
            raise SceneError("this TessRenderer was built for other functions than the scene uses; "
                             "make one with TessRenderer(scene.functions())")
        render_list = np.asarray(render_list)
        if render_list.dtype != RENDER_DTYPE:
            raise SceneError(f"render_list must be a numpy array of paramlod.patches.RENDER_DTYPE records, "
                             f"got dtype {render_list.dtype}")
        n = len(render_list) if n is None else int(n)
        if not 0 <= n <= len(render_list):
            raise SceneError(f"render patch count {n} is outside 0..{len(render_list)} (the list's length)")
        inst_f, inst_u, params = scene.instance_buffers()
        if n and int(render_list["inst"][:n].max()) >= len(inst_f):
            raise SceneError("render_list refers to an instance the scene does not have; was it made for this scene?")

        req, aa, notes = self.effective_aa(settings.aa)
        for msg in notes:
            warnings.warn(msg, RuntimeWarning, stacklevel=2)
        if threshold is None:
            div = aa.divisor(settings.msaa_lod)
            threshold = (84.0 / div, 84.0 / div)
        tu, tv = (float(x) for x in threshold)
        if not (tu > 0 and tv > 0):
            raise SceneError(f"tess threshold must be positive pixels, got {threshold}")

        ctx = self.ctx
        t0 = time.perf_counter()
        prog = build_programs(ctx, self.functions, settings.spacing)
        resolve = _resolve_program(ctx, aa.ss, aa.msaa)
        w, h = camera.size
        tg = self._targets_for((w, h), aa.ss, aa.msaa)
        t1 = time.perf_counter()

        # CL -> GL through host memory: the render list records go into the vertex buffer
        self._patches.write(np.ascontiguousarray(render_list[:n]).tobytes())
        scene_key = (scene._version, scene.time)
        if scene_key != getattr(self, "_scene_key", None):   # instance data only when it changed
            self._params.write(params.tobytes())
            self._inst_f.write(inst_f.tobytes())
            self._inst_u.write(inst_u.tobytes())
            self._materials.write(scene.materials().tobytes())
            self._scene_key = scene_key
        self._counters.write(np.zeros(4, np.uint32).tobytes())
        t2 = time.perf_counter()

        from paramlod.pipeline.driver import LIGHT

        _set(prog, "u_view", _mat(camera.view))
        _set(prog, "u_proj", _mat(camera.projection))
        _set(prog, "u_screen", (float(w), float(h)))
        _set(prog, "u_threshold", (tu, tv))
        if settings.mode == "fixed":
            _set(prog, "u_level", tuple(float(x) for x in settings.levels))
            _set(prog, "u_adaptive", 0)
        else:
            _set(prog, "u_level", (float(settings.base_level), float(settings.base_level)))
            _set(prog, "u_adaptive", 1)
        _set(prog, "u_clamp", (float(settings.l_min), float(settings.l_max)))
        _set(prog, "u_overlap", float(settings.overlap))
        _set(prog, "u_near", float(camera.near))
        _set(prog, "u_light", tuple(float(x) for x in LIGHT))
        for binding, b in enumerate((self._params, self._inst_f, self._inst_u, self._materials)):
            b.buf.bind_to_storage_buffer(binding)
        self._counters.bind_to_storage_buffer(4)

        tg.fbo.use()
        # only the colour (its alpha marks covered samples) and the depth buffer are cleared: the
        # resolve never reads the other attachments where nothing was drawn, and on the H200
        # each cleared 4xSS+8xMS attachment costs 5-10 ms (its graphics units are few)
        tg.fbo.color_mask = _CLEAR_MASK
        tg.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        tg.fbo.color_mask = _DRAW_MASK
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)
        triangles, draw_calls = 0, 0
        if n:
            ctx.patch_vertices = 1
            batch = self.patches_per_draw(settings)
            query = ctx.query(primitives=True)
            vao = self._vao(prog)
            with query:
                for first in range(0, n, batch):
                    vao.render(mode=moderngl.PATCHES, vertices=min(batch, n - first), first=first)
                    draw_calls += 1
            triangles = int(query.primitives)
        ctx.finish()
        t3 = time.perf_counter()

        # resolve: hardware multisample resolve of the colour, then the SSAA block in a shader
        if aa.msaa > 1:
            ctx.copy_framebuffer(tg.color_resolved_fbo, tg.color_ms_fbo)
        ctx.disable(moderngl.DEPTH_TEST)
        tg.out_fbo.use()
        self._counters.bind_to_storage_buffer(4)
        for unit, (name, tex) in enumerate((("u_color", tg.color_resolved), ("u_coverage", tg.color),
                                            ("u_depth", tg.depth), ("u_normal", tg.normal),
                                            ("u_object", tg.object))):
            tex.use(location=unit)
            _set(resolve, name, unit)
        self._resolve_vao(resolve).render(mode=moderngl.TRIANGLES, vertices=3)
        ctx.finish()
        t4 = time.perf_counter()

        color = np.frombuffer(tg.out_color.read(), np.float32).reshape(h, w, 4)[::-1]
        depth = np.frombuffer(tg.out_depth.read(), np.float32).reshape(h, w)[::-1]
        normal = np.frombuffer(tg.out_normal.read(), np.float32).reshape(h, w, 4)[::-1, :, :3]
        ids = np.frombuffer(tg.out_object.read(), np.uint32).reshape(h, w)[::-1]
        nan_vertices, device_samples = (int(x) for x in np.frombuffer(self._counters.read(8), np.uint32))
        if device_samples != aa.msaa:
            notes.append(f"the device allocated {device_samples} samples per pixel for a {aa.msaa}-sample "
                         "request; coverage and the depth/id resolve use all of them")
        frame = Frame(color=np.ascontiguousarray(color), depth=np.ascontiguousarray(depth),
                      normal=np.ascontiguousarray(normal), object_id=np.ascontiguousarray(ids))
        frame.background = scene.background
        written = int(np.count_nonzero(np.isfinite(depth)))
        t5 = time.perf_counter()   # readback: textures to host arrays, flipped to row 0 = top
        frame.stats = {
            "device": ctx.info.get("GL_RENDERER"),
            "variant": "tess",
            "size": [w, h],
            "aa": req.name,
            "aa_effective": aa.name,
            "msaa_requested": req.msaa,
            "msaa_samples": aa.msaa,
            "msaa_samples_device": device_samples,
            "ssaa": aa.ss,
            "samples_per_pixel": aa.samples_per_pixel,
            "lod_divisor": aa.divisor(settings.msaa_lod),
            "threshold": [tu, tv],
            "tess": {"mode": settings.mode, "spacing": settings.spacing, "levels": list(settings.levels),
                     "base_level": settings.base_level, "l_min": settings.l_min, "l_max": settings.l_max,
                     "overlap": settings.overlap},
            "render_patches": n,
            "triangles": triangles,
            "draw_calls": draw_calls,
            "nan_vertices": nan_vertices,
            "pixels_written": written,
            "warnings": list(notes),
            "ms": {"setup": (t1 - t0) * 1e3, "render_list_upload": (t2 - t1) * 1e3, "draw": (t3 - t2) * 1e3,
                   "resolve": (t4 - t3) * 1e3, "readback": (t5 - t4) * 1e3, "total": (t5 - t0) * 1e3},
        }
        return frame

    def _resolve_vao(self, prog):
        key = ("resolve", id(prog))
        vao = self._vaos.get(key)
        if vao is None:
            vao = self._vaos[key] = self.ctx.vertex_array(prog, [])
        return vao


# --- the whole frame ----------------------------------------------------------------------------
def render_tess(scene: Scene, camera: Camera, settings: TessSettings | None = None, lod_settings=None,
                lod_stage=None) -> Frame:
    """One frame with the tessellation variant: instance buffers -> LOD stage (thresholds divided
    by ``lod_divisor`` of the effective AA mode) -> render list to host -> tessellation -> Frame.

    The device buffers, the LOD stage and this TessRenderer are those of ``paramlod.render``'s
    Renderer for the scene's functions (instance buffers are sent once per scene change);
    ``lod_stage`` overrides the LOD stage."""
    from paramlod.device.context import cl_device
    from paramlod.lod.stage import LodSettings
    from paramlod.pipeline.driver import renderer_for

    if not isinstance(scene, Scene) or not scene.objects:
        raise SceneError("the scene has no objects; add one with scene.add(...)")
    settings = settings or TessSettings()
    settings.validate()
    lod_settings = lod_settings or LodSettings()
    lod_settings.validate()
    t0 = time.perf_counter()
    r = renderer_for(scene)
    lod_stage = lod_stage or r.lod
    tess = r.tess_renderer()
    _, aa, _ = tess.effective_aa(settings.aa)
    div = aa.divisor(settings.msaa_lod)
    dev = r.upload(scene, camera)
    inst, domains, cam = dev["inst"], dev["domains"], dev["cam"]
    t1 = time.perf_counter()
    _, n, steps, lod_ms = lod_stage.run(inst, domains, cam, lod_settings, t_div=div)
    t2 = time.perf_counter()
    records = lod_stage.read_render_list(n)
    t3 = time.perf_counter()
    tu, tv = (t / div for t in lod_settings.threshold)
    frame = tess.draw(records, n, scene, camera, settings, threshold=(tu, tv))
    t4 = time.perf_counter()
    ms = frame.stats["ms"]
    ms["render_list_read"] = (t3 - t2) * 1e3
    ms["render_list"] = ms["render_list_read"] + ms["render_list_upload"]
    ms["upload"] = (t1 - t0) * 1e3
    ms["lod"] = lod_ms
    ms["total"] = (t4 - t0) * 1e3
    frame.stats.update({
        "lod_device": cl_device().name,
        "lod_steps": steps,
        "forced_patches": sum(s["forced"] for s in steps),
        "render_list_bytes": int(n) * RENDER_DTYPE.itemsize,
    })
    return frame


# --- probe: the generated GLSL evaluated on the device ------------------------------------------
_probes: dict[tuple, object] = {}


def glsl_surface(fn, u, v, block=None, **params):
    """(position, df/du, df/dv) of ``fn`` evaluated by the generated GLSL on the GL device, each
    float32 broadcast(u, v) + (3,): the twin of ``fn.surface`` (numpy) for tests and debugging."""
    import moderngl

    from paramlod.function.registry import get_function

    fn = get_function(fn)
    u = np.asarray(u, np.float32)
    v = np.asarray(v, np.float32)
    shape = np.broadcast_shapes(u.shape, v.shape)
    uv = np.stack([np.broadcast_to(u, shape).reshape(-1), np.broadcast_to(v, shape).reshape(-1)], axis=1)
    if block is None:
        block = fn.param_block(params)
    block = np.concatenate([np.asarray(block, np.float32).reshape(-1), np.zeros(1, np.float32)])
    ctx = gl_context()
    gen = glsl_dispatch_source([fn], position=False, surface=True)
    key = (id(ctx), gen)
    prog = _probes.get(key)
    if prog is None:
        src = _stage({}, [gen, kernels.source("tess/tess_probe.glsl")])
        try:
            prog = ctx.program(vertex_shader=src, varyings=["out_pos", "out_du", "out_dv"])
        except moderngl.Error as exc:
            raise FunctionError(f"the generated GLSL of '{fn.name}' ({fn.source}) does not compile.\n"
                                f"{context_lines(src, str(exc), GLSL_LINE)}\ncompiler said:\n{str(exc)[-2000:]}") from None
        _probes[key] = prog
    n = len(uv)
    if n == 0:
        empty = np.zeros((*shape, 3), np.float32)
        return empty, empty.copy(), empty.copy()
    vbo = ctx.buffer(np.ascontiguousarray(uv).tobytes())
    out = ctx.buffer(reserve=n * 36)
    pbuf = ctx.buffer(block.tobytes())
    try:
        pbuf.bind_to_storage_buffer(0)
        _set(prog, "u_func", 0)
        _set(prog, "u_param_offset", 0)
        vao = ctx.vertex_array(prog, [(vbo, "2f", "in_uv")])
        # a draw needs a complete framebuffer even with rasterization off; the EGL context has none
        fbo = _probes.get("fbo")
        if fbo is None:
            fbo = _probes["fbo"] = ctx.framebuffer([ctx.renderbuffer((1, 1))])
        fbo.use()
        vao.transform(out, mode=moderngl.POINTS, vertices=n)
        res = np.frombuffer(out.read(), np.float32).reshape(n, 3, 3)
        vao.release()
    finally:
        for b in (vbo, out, pbuf):
            b.release()
    return tuple(np.ascontiguousarray(res[:, k].reshape(*shape, 3)) for k in range(3))
