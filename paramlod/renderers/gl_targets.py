"""OpenGL render targets and their resolve into a Frame's arrays (part of the renderers kit): what
every OpenGL renderer draws into, whatever it draws (the tess variant's patches, the meshlets-gl
variant's clusters).

Driven by ``paramlod.renderers.tess.TessRenderer`` and ``paramlod.meshlod.draw.MeshDraw``, each
frame: ``targets_for`` (make or reuse targets for (size, supersampling, multisamples)),
``GLTargets.begin`` (bind and clear for drawing), the renderer's draw calls, ``GLTargets.resolve``
and ``GLTargets.frame`` (a Frame read back lazily; ``read`` copies every array at once). The
OpenCL renderers' counterpart is ``paramlod.renderers.targets``.

Targets, at the supersampled size, multisampled or not: colour (linear RGB, alpha 1 where drawn),
linear view depth R32F, world normal, object id R32UI, a depth renderbuffer; colour and normal in
half floats where a pixel has several samples (``half_floats``), float32 otherwise. A fragment
shader writes them at locations 0-3 (kernels/common/targets.glsl). The resolve
(kernels/tess/tess_resolve_*.glsl, with the prelude and tess_common.glsl for its counter buffer):
the hardware multisample resolve of the colour, box-averaged over the SSAA block (straight alpha =
covered fraction); depth, normal and id of the nearest covered sample of the block, +inf / 0 / 0
where none is; the 8-bit sRGB image over the background, the host's encoding bit for bit. Then
the count pass (kernels/tess/tess_count_fragment.glsl): an occlusion query of the resolved pixels
that show something, the pixels written.

noAA targets of one view (``GLTargets.direct``) have no draw targets of their own: the fragments
write an output set, the image (location 4) included. ``begin`` clears only its object ids and
its image (to the background's code); its colour, depth and normal are blanked where the object
id is 0 when they are read. In place of the resolve, the background pass
(kernels/tess/tess_background_fragment.glsl) counts the pixels nothing was drawn into.

Hybrid anti-aliasing (the tess renderer's ``aa = "hybrid"``): each tier draws into its own
targets, coarse to fine; a finer tier's targets start from a per-sample copy of a coarser tier's
(``GLTargets.carry``, kernels/tess/tess_carry_fragment.glsl), whose depth buffer is then a depth
texture (``depth_texture``) so that the copy can read it.

Multi-view frames (``LayeredGLTargets``, the tess renderer's ``draw_views``): the same targets as
2D texture arrays with one layer per view (multisampled arrays for MSAA), drawn in one pass whose
last geometry stage picks the layer; the resolve and the readback then run layer by layer into the
same single-layer output targets. moderngl makes neither multisampled texture arrays nor layered
framebuffers, so these are made through the GL 4.5 direct-state-access entry points (``raw_gl``).
"""
from __future__ import annotations

import ctypes
import math
import weakref

import moderngl
import numpy as np

from paramlod import kernels
from paramlod.core.color import SRGB8_BUCKETS, linear_to_srgb8, linear_to_srgb8_buckets
from paramlod.core.frame import Frame
from paramlod.core.layouts import glsl_prelude
from paramlod.device.context import gl_cache
from paramlod.device.programs import GLSL_LINE, context_lines, set_uniform
from paramlod.errors import DeviceError, ParamlodError, SceneError
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


def _full_screen_program(ctx, defs: dict, common: list[str], fragment: str, what: str, encodes: bool = False):
    """A program of the full-screen triangle (tess_resolve_vertex.glsl) and ``fragment``, each
    stage "#version", the ``defs``, ``common`` and its file (``encodes``: the fragment stage
    encodes the image, with ``srgb8_defines``); a DeviceError naming ``what`` if it does not compile."""
    head = "#version 450 core\n" + "".join(f"#define {k} {v}\n" for k, v in defs.items())
    encoder = srgb8_defines(ctx) if encodes else ""
    stages = {"vertex_shader": head + "\n".join([*common, kernels.source("tess/tess_resolve_vertex.glsl")]),
              "fragment_shader": head + encoder + "\n".join([*common, kernels.source(f"tess/{fragment}.glsl")])}
    try:
        return ctx.program(**stages)
    except moderngl.Error as exc:
        log = str(exc)
        stage = next((k for k in stages if k in log), "fragment_shader")
        raise DeviceError(f"the OpenGL {what} shader does not compile on {ctx.info.get('GL_RENDERER')}:\n"
                          f"{context_lines(stages[stage], log, GLSL_LINE)}\ncompiler said:\n{log[-2000:]}") from None


def _pass_common() -> list[str]:
    """What the resolve and background passes put before their file: the prelude and
    tess_common.glsl (PL_INF, and the counter buffer the resolve reports into)."""
    return [glsl_prelude(), kernels.source("tess/tess_common.glsl")]


def half_floats(ss: int, samples: int, depth_texture: bool = False) -> bool:
    """Whether draw targets keep colour and normal in half floats: where a pixel has several
    samples (memory: 4xSS+8xMS at 1080p holds 265 M samples), and in hybrid tiers (carried into
    such targets). Targets of one sample a pixel keep float32, as the output sets do, so that a
    view of a multi-view frame equals the single-view frame drawn directly bit for bit."""
    return ss * max(samples, 1) > 1 or depth_texture


def resolve_program(ctx, ss: int, samples: int, layered: bool = False, half: bool = True):
    """The resolve program for ``ss`` x ``ss`` supersampling and ``samples`` multisamples (of one
    layer ``u_layer`` of texture arrays when ``layered``) of targets with half-float normals
    (``half``: renormalized) or float32 ones (copied), cached."""
    programs = gl_cache(ctx).setdefault("gl_resolve_programs", {})
    key = (ss, samples, layered, half)
    prog = programs.get(key)
    if prog is None:
        defs = {"PL_SS": ss, "PL_SAMPLES": samples}
        if samples > 1:
            defs["PL_MS"] = 1
        if layered:
            defs["PL_LAYERED"] = 1
        if half:
            defs["PL_HALF_NORMALS"] = 1
        prog = programs[key] = _full_screen_program(ctx, defs, _pass_common(), "tess_resolve_fragment", "resolve",
                                                    encodes=True)
    return prog


def count_program(ctx):
    """The count pass after a resolve (kernels/tess/tess_count_fragment.glsl), cached."""
    cache = gl_cache(ctx)
    prog = cache.get("gl_count_program")
    if prog is None:
        prog = cache["gl_count_program"] = _full_screen_program(ctx, {}, [], "tess_count_fragment", "count")
    return prog


def background_program(ctx):
    """The background pass of targets drawn directly (kernels/tess/tess_background_fragment.glsl:
    a full-screen triangle on the far plane that writes nothing), cached."""
    cache = gl_cache(ctx)
    prog = cache.get("gl_background_program")
    if prog is None:
        prog = cache["gl_background_program"] = _full_screen_program(ctx, {"PL_FAR": 1}, _pass_common(),
                                                                     "tess_background_fragment", "background")
    return prog


def is_llvmpipe(ctx) -> bool:
    """Whether ``ctx`` is Mesa's llvmpipe (OpenGL on the CPU)."""
    return "llvmpipe" in str(ctx.info.get("GL_RENDERER", "")).lower()


def srgb8_table() -> np.ndarray:
    """uint32 (SRGB8_BUCKETS, 2): per bucket the code of its start and the bits of its threshold
    (paramlod.core.color.linear_to_srgb8_buckets, whose codes and float32 thresholds these are exactly)."""
    buckets = linear_to_srgb8_buckets()
    return np.stack([buckets[:, 0].astype(np.uint32), buckets[:, 1].view(np.uint32)], axis=1)


def srgb8_uniform(ctx) -> bool:
    """Whether fragment stages read the image's encoding table as a uniform block (Mesa's llvmpipe,
    where it fits) rather than a storage buffer. llvmpipe reads a storage buffer at a varying index
    one lane at a time: the framed torus of the peers bench drew in 12.0-16.4 ms instead of
    14.5-20.2 (2-core AMD EPYC, the draw alone, alternating three times). GPUs keep the storage
    buffer, their path when measured; a uniform block read at varying indices is not measured there."""
    return is_llvmpipe(ctx) and int(ctx.info.get("GL_MAX_UNIFORM_BLOCK_SIZE", 0) or 0) >= SRGB8_BUCKETS * 8


def srgb8_defines(ctx) -> str:
    """The #defines a fragment stage that encodes the image (common/targets.glsl ``srgb8_code``)
    puts before its files: the table's bucket count, and PL_SRGB8_UNIFORM (``srgb8_uniform``)."""
    return (f"#define PL_SRGB8_BUCKETS {SRGB8_BUCKETS}\n"
            + ("#define PL_SRGB8_UNIFORM 1\n" if srgb8_uniform(ctx) else ""))


def bind_srgb8_buckets(ctx):
    """Bind the image's sRGB encoding table (``srgb8_table``; cached) to its binding,
    SRGB8_TABLE_BINDING (common/targets.glsl), as the fragment stages read it (``srgb8_uniform``)."""
    cache = gl_cache(ctx)
    buf = cache.get("srgb8_buckets")
    if buf is None:
        buf = cache["srgb8_buckets"] = ctx.buffer(srgb8_table().tobytes())
    if srgb8_uniform(ctx):
        buf.bind_to_uniform_block(SRGB8_TABLE_BINDING)
    else:
        buf.bind_to_storage_buffer(SRGB8_TABLE_BINDING)


def carry_vao(ctx, ratio: int, coarse_samples: int):
    """The carry pass (``GLTargets.carry``) from targets of ``coarse_samples`` multisamples into
    targets of ``ratio`` x ``ratio`` times their pixels: its vertex array (no buffers), cached."""
    vaos = gl_cache(ctx).setdefault("gl_carry_vaos", {})
    key = (ratio, coarse_samples)
    vao = vaos.get(key)
    if vao is None:
        defs = {"PL_RATIO": ratio, **({"PL_MS": 1} if coarse_samples > 1 else {})}
        vao = vaos[key] = ctx.vertex_array(_full_screen_program(ctx, defs, [], "tess_carry_fragment", "carry"), [])
    return vao


# what a set drawn into directly reads where nothing was drawn (its object id is 0)
BLANK = {"color": 0.0, "depth": np.inf, "normal": 0.0}
SRGB8_TABLE_BINDING = 5   # the image encoding table's binding, storage buffer or uniform block (common/targets.glsl)
LENT_SETS = 3   # output sets that lent Frames may hold at once before the oldest is copied to the host
# the resolve's counter buffer (tess_common.glsl PlCounters): NaN vertices, device samples
RESOLVE_COUNTERS_BYTES = 8


class _OutputSet:
    """One set of single-sampled output targets at ``size``: colour RGBA32F, depth R32F, normal
    RGBA32F, object id R32UI and the 8-bit sRGB image RGBA8UI (attachments 0-4 of ``fbo``, with
    the depth buffer ``zbuf`` where the set is drawn into directly).

    A set drawn into directly is cleared by ``clear_direct``: its object ids and image only.
    Clearing the two RGBA32F attachments too cost llvmpipe about as much as drawing a full screen
    into them, so colour, depth and normal keep what an earlier frame left where nothing is drawn,
    and ``read`` blanks them where the object id is 0 (no object; ids are 1-based)."""

    # name: (attribute, attachment, moderngl dtype, components read)
    ARRAYS = {"color": ("color", 0, "f4", 4), "depth": ("depth", 1, "f4", 1), "normal": ("normal", 2, "f4", 3),
              "object_id": ("object", 3, "u4", 1), "image": ("image", 4, "u1", 3)}

    def __init__(self, ctx, size, zbuf=None):
        self.ctx, self.size = ctx, tuple(size)
        self.color = ctx.texture(size, 4, dtype="f4")
        self.depth = ctx.texture(size, 1, dtype="f4")
        self.normal = ctx.texture(size, 4, dtype="f4")
        self.object = ctx.texture(size, 1, dtype="u4")
        self.image = ctx.texture(size, 4, dtype="u1")
        self.fbo = ctx.framebuffer([self.color, self.depth, self.normal, self.object, self.image], zbuf)
        self.background = (0.0, 0.0, 0.0)   # what the last resolve's image is composited over
        self.direct = zbuf is not None
        # drawn directly: where the object id is 0, and the ids read to find it until they are asked for
        self._empty = self._ids = None

    def clear_direct(self, background):
        """Bind this set (drawn into directly) and clear it for a frame over ``background``
        (linear RGB): the depth buffer to 1, the object ids to 0, the image to the background's code."""
        self.fbo.use()
        self.fbo.color_mask = ((False,) * 4,) * 5
        self.fbo.clear(depth=1.0)
        self.fbo.color_mask = ((True,) * 4,) * 5
        self.background = tuple(float(x) for x in background)
        code = (ctypes.c_uint * 4)(*(int(c) for c in linear_to_srgb8(np.float32(self.background))), 255)
        gl = raw_gl()   # moderngl clears integer attachments with floats, which GL leaves undefined
        gl.glClearNamedFramebufferuiv(self.fbo.glo, GL_COLOR, 3, (ctypes.c_uint * 4)())
        gl.glClearNamedFramebufferuiv(self.fbo.glo, GL_COLOR, 4, code)
        self._empty = self._ids = None

    def read(self, name: str) -> np.ndarray:
        """The array ``name`` (a Frame array or "image"), contiguous, row 0 at the top."""
        if name == "object_id" and self._ids is not None:   # read once: a Frame asks for each array once
            a, self._ids = self._ids, None
            return a
        a = self._read(name)
        if self.direct and name == "object_id":
            self._empty = a == 0
        elif self.direct and name in BLANK:
            if self._empty is None:
                self._ids = self._read("object_id")
                self._empty = self._ids == 0
            a[self._empty] = BLANK[name]
        return a

    def _read(self, name: str) -> np.ndarray:
        attr, attachment, dtype, keep = self.ARRAYS[name]
        if getattr(self, attr, None) is None:
            raise ParamlodError(f"this frame's {name} is gone: its OpenGL targets were released before it was read")
        w, h = self.size
        # current, and left so: paramlod's renderers expect their context current (moderngl's
        # ``with ctx`` would leave none current on EGL)
        self.ctx.__enter__()
        # the device drops the channels not kept (RGB of the image: 0.5 ms at 640x640 on llvmpipe,
        # where numpy's slice of RGBA took 1.8); then rows are flipped whole
        data = self.fbo.read(components=keep, dtype=dtype, attachment=attachment)
        a = np.frombuffer(data, np.dtype(dtype)).reshape((h, w, keep) if keep > 1 else (h, w))
        return a[::-1].copy()   # writable, for the blanking in ``read``

    def release(self):
        _release_attributes(self, ("fbo", "color", "depth", "normal", "object", "image"))


def _release_attributes(owner, names):
    """Release the moderngl objects ``owner`` holds as ``names``, those that were made."""
    for name in names:
        obj = owner.__dict__.pop(name, None)
        if obj is not None:
            try:
                obj.release()
            except Exception:
                pass


class _Outputs:
    """The output targets the resolve draws into, and their readback: whole (``read``) or lazily
    by the Frame that ``frame`` lends. A lent Frame keeps its set of targets until it is dropped
    (the next resolve takes another set), as the OpenCL key buffer's outputs do; beyond
    ``LENT_SETS`` held at once the oldest is copied to the host and its set reused."""

    def _release(self, *names):
        """Release the moderngl objects ``names`` and the output targets, those that were made
        (lent Frames first copy what they have not read)."""
        lent, free, out = (self.__dict__.pop(k, None) for k in ("_lent", "_free", "out"))
        sets = [out] if out is not None else []
        for key in list(lent or ()):
            sets.append(self._take_back(key, lent))
        for o in {id(o): o for o in (*sets, *(free or ()))}.values():   # the current set may be lent too
            o.release()
        _release_attributes(self, (*names, "resolve_vao", "color_resolved", "samples_buffer", "count_vao",
                                   "count_query", "count_fbo", "count_zbuf"))

    def _failed(self, exc: Exception, what: str):
        """Release what a constructor made before ``exc``, then raise it as a DeviceError naming
        ``what`` (a DeviceError as it is; moderngl.Error: out of memory, an unsupported format)."""
        self.release()
        if isinstance(exc, DeviceError):
            raise exc
        raise DeviceError(f"could not create the {what}: {exc}") from None

    def _outputs(self, prog, zbuf=None):
        """The output sets (each with ``zbuf`` where drawn into directly) and the pass of ``prog``
        that ends a frame: the resolve, or the background pass of targets drawn directly."""
        self._set_zbuf = zbuf
        self.out = _OutputSet(self.ctx, self.size, zbuf)   # the set the next resolve draws into
        self._free: list[_OutputSet] = []            # sets no Frame holds
        # id(set) -> (the set, a weak reference to the Frame that holds it, its finalizer), oldest first
        self._lent: dict[int, tuple] = {}
        if zbuf is None:   # the resolve's counters (tess_common.glsl PlCounters): [1] the device's
            # samples per pixel; the pixels written: the count pass (targets drawn directly count
            # with the background pass's query)
            self.samples_buffer = self.ctx.buffer(reserve=RESOLVE_COUNTERS_BYTES)
            self.count_zbuf = self.ctx.depth_renderbuffer(self.size)   # a framebuffer for the query
            self.count_fbo = self.ctx.framebuffer(depth_attachment=self.count_zbuf)
            self.count_vao = self.ctx.vertex_array(count_program(self.ctx), [])
            self.count_query = self.ctx.query(samples=True)
        self.resolve_vao = self.ctx.vertex_array(prog, [])
        self.pixels_written = 0

    def _count_written(self):
        """The count pass (kernels/tess/tess_count_fragment.glsl) over the resolved depth of the
        current output set, in the occlusion query ``_read_counters`` reads."""
        self.count_fbo.use()
        self.ctx.disable(moderngl.DEPTH_TEST)   # every fragment not discarded passes, and is counted
        self.out.depth.use(location=0)
        set_uniform(self.count_vao.program, "u_depth", 0)
        with self.count_query:
            self.count_vao.render(mode=moderngl.TRIANGLES, vertices=3)

    def _read_counters(self) -> int:
        """The device's samples per pixel from the resolve's counters and ``pixels_written`` from
        the count pass (both wait for the device)."""
        self.pixels_written = int(self.count_query.samples)
        return int(np.frombuffer(self.samples_buffer.read(RESOLVE_COUNTERS_BYTES), np.uint32)[1])

    def _next_set(self) -> _OutputSet:
        """The output set the next frame goes into (``out``): one no Frame holds."""
        if id(self.out) in self._lent:
            if self._free:
                self.out = self._free.pop()
            elif len(self._lent) < LENT_SETS:
                self.out = _OutputSet(self.ctx, self.size, self._set_zbuf)
            else:   # the oldest lent Frame copies its arrays to the host and gives its set back
                self.out = self._take_back(next(iter(self._lent)), self._lent)
        return self.out

    def _bind_resolve(self, background):
        """Bind the output set this resolve draws into (one no Frame holds), its counters, zeroed,
        and the background its image is composited over; returns the resolve program."""
        self._next_set().fbo.use()
        self.out.background = tuple(float(x) for x in background)
        self.samples_buffer.write(bytes(RESOLVE_COUNTERS_BYTES))
        self.samples_buffer.bind_to_storage_buffer(4)
        prog = self.resolve_vao.program
        set_uniform(prog, "u_background", self.out.background)
        bind_srgb8_buckets(self.ctx)
        return prog

    def frame(self) -> Frame:
        """A Frame of the last resolve that reads its arrays and its 8-bit image on request
        (paramlod.core.frame; the image is composited over the resolve's background); it holds
        its output set until it is dropped."""
        out = self.out
        frame = Frame(source=out, size=out.size, background=out.background)
        self._lent[id(out)] = (out, weakref.ref(frame), weakref.finalize(frame, self._given_back, id(out)))
        return frame

    @staticmethod
    def _take_back(key: int, lent: dict) -> _OutputSet:
        """The set ``lent[key]``, its Frame's arrays copied to the host first."""
        out, ref, finalizer = lent.pop(key)
        finalizer.detach()
        frame = ref()
        if frame is not None:
            frame.materialize()
        return out

    def _given_back(self, key: int):
        """A lent Frame was dropped: its set is free again."""
        held = self.__dict__.get("_lent", {}).pop(key, None)
        if held is not None and held[0] is not self.out:   # the current set is never in the free list
            self._free.append(held[0])

    def _check_size(self):
        ctx, (w, h), ss = self.ctx, self.size, self.ss
        limit = min(int(ctx.info.get("GL_MAX_TEXTURE_SIZE", 16384)), int(ctx.info.get("GL_MAX_RENDERBUFFER_SIZE", 16384)))
        if max(w * ss, h * ss) > limit:
            raise SceneError(f"{ss}x{ss} supersampling of {w}x{h} needs {w * ss}x{h * ss} render targets, more than "
                             f"this OpenGL device's limit of {limit} pixels per side; use a smaller size or less supersampling")

    def read(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The resolved (colour [h, w, 4], depth [h, w], normal [h, w, 3], object id [h, w]),
        contiguous host arrays with row 0 at the top."""
        return tuple(self.out.read(name) for name in ("color", "depth", "normal", "object_id"))


class GLTargets(_Outputs):
    """Render targets at the supersampled size (multisampled when ``samples`` > 1) and the
    single-sampled output targets at ``size``; ``what`` names the renderer in errors.
    ``depth_texture``: the depth buffer is a depth texture, so that ``carry`` can read it (a
    renderbuffer otherwise).

    ``direct`` (one sample a pixel, no depth texture): the fragments draw straight into an output
    set, the image included (the draw program's ``u_image``, set by ``begin``), and the resolve
    is the background pass: no full-screen pass reads the targets (on llvmpipe at 640x640 the
    resolve took 9-10 ms of a 20-25 ms frame)."""

    layers = 0   # not layered (LayeredGLTargets)

    def __init__(self, ctx, size: tuple[int, int], ss: int, samples: int, what: str = "OpenGL",
                 depth_texture: bool = False):
        self.ctx = ctx
        self.size, self.ss, self.samples, self.depth_texture = tuple(size), ss, samples, depth_texture
        self.direct = ss == 1 and samples <= 1 and not depth_texture
        w, h = size
        big = (w * ss, h * ss)
        ms = samples if samples > 1 else 0
        self._check_size()
        if self.direct:
            try:
                self.zbuf = ctx.depth_renderbuffer(big)
                self.background_fbo = ctx.framebuffer(depth_attachment=self.zbuf)   # for the background pass
                self.background_query = ctx.query(samples=True)
                self._outputs(background_program(ctx), self.zbuf)
            except Exception as exc:
                self._failed(exc, f"{what} render targets ({w}x{h})")
            return
        try:
            half = half_floats(ss, samples, depth_texture)
            self.color = ctx.texture(big, 4, dtype="f2" if half else "f4", samples=ms)
            self.depth = ctx.texture(big, 1, dtype="f4", samples=ms)
            self.normal = ctx.texture(big, 4, dtype="f2" if half else "f4", samples=ms)
            self.object = ctx.texture(big, 1, dtype="u4", samples=ms)
            if depth_texture:
                self.zbuf = ctx.depth_texture(big, samples=ms)
                if not ms:
                    self.zbuf.compare_func = ""   # read as values (texelFetch), not compared
            else:
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
            if depth_texture and not ms:
                single.append(self.zbuf)
            for t in single:
                t.filter = (ctx.NEAREST, ctx.NEAREST)
            self._outputs(resolve_program(ctx, ss, samples, half=half))
        except Exception as exc:
            self._failed(exc, f"{what} render targets ({w}x{h}, {ss}x{ss} SS, {samples} samples)")

    def begin(self, program=None, background=(0.0, 0.0, 0.0)):
        """Bind the targets for drawing and clear them (colour and depth only; see CLEAR_MASK;
        targets drawn directly: an output set no Frame holds, ``_OutputSet.clear_direct``, its
        image to ``background``, which ``resolve`` must be given too). ``program``, the draw
        program, is told whether to write the image (its ``u_image``): direct targets need it."""
        if self.direct:
            if program is None:
                raise ValueError("targets drawn directly need the draw program, which writes their image")
            self._next_set().clear_direct(background)
            bind_srgb8_buckets(self.ctx)
            set_uniform(program, "u_image", 1)
            return
        if program is not None:
            set_uniform(program, "u_image", 0)
        self.fbo.use()
        self.fbo.color_mask = CLEAR_MASK
        self.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        self.fbo.color_mask = DRAW_MASK

    def carry(self, coarse: GLTargets):
        """Bind these targets for drawing, cleared, and start them from a per-sample copy of
        ``coarse``, a coarser hybrid tier's targets of the same size made with ``depth_texture``
        (kernels/tess/tess_carry_fragment.glsl): each sample takes colour, linear depth, normal,
        object id and hardware depth from the sample of the same index of the coarse pixel it
        lies in, so what is drawn next is depth-tested against the coarse tier per sample."""
        ratio, rest = divmod(self.ss, coarse.ss)
        if rest or coarse.size != self.size or not coarse.depth_texture or coarse.samples > max(self.samples, 1):
            raise ValueError(f"cannot carry {coarse.ss}x{coarse.ss} SS, {coarse.samples} samples "
                             f"(depth texture: {coarse.depth_texture}) at {coarse.size} into {self.ss}x{self.ss} SS, "
                             f"{self.samples} samples at {self.size}")
        ctx = self.ctx
        self.begin()
        vao = carry_vao(ctx, ratio, coarse.samples)
        for unit, (name, tex) in enumerate((("u_color", coarse.color), ("u_depth", coarse.depth),
                                            ("u_normal", coarse.normal), ("u_object", coarse.object),
                                            ("u_zbuf", coarse.zbuf))):
            tex.use(location=unit)
            set_uniform(vao.program, name, unit)
        # GL writes depth only with the test on; every covered coarse sample passes it, being
        # nearer than the cleared 1 (its fragment passed the same test against it)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)
        vao.render(mode=moderngl.TRIANGLES, vertices=3)

    def resolve(self, background=(0.0, 0.0, 0.0)) -> int:
        """Resolve what was drawn into the output targets (waits for the device), the image over
        ``background``; returns the samples per pixel the device really allocated (llvmpipe gives
        4 for a 2xMS request) and sets ``pixels_written``."""
        ctx = self.ctx
        if self.direct:
            return self._count_background(background)
        if self.samples > 1:
            ctx.copy_framebuffer(self.color_resolved_fbo, self.color_ms_fbo)
        ctx.disable(moderngl.DEPTH_TEST)
        prog = self._bind_resolve(background)
        for unit, (name, tex) in enumerate((("u_color", self.color_resolved), ("u_coverage", self.color),
                                            ("u_depth", self.depth), ("u_normal", self.normal),
                                            ("u_object", self.object))):
            tex.use(location=unit)
            set_uniform(prog, name, unit)
        self.resolve_vao.render(mode=moderngl.TRIANGLES, vertices=3)
        self._count_written()
        ctx.finish()
        return self._read_counters()

    def _count_background(self, background) -> int:
        """``resolve`` of targets drawn directly: the background pass, whose occlusion query
        counts the pixels nothing was drawn into (the image has the background since ``begin``)."""
        ctx, out = self.ctx, self.out
        if tuple(float(x) for x in background) != out.background:
            raise ValueError(f"targets drawn directly were begun over the background {out.background}, "
                             f"not {tuple(background)}")
        self.background_fbo.use()   # the depth buffer alone: the pass writes nothing
        self.background_fbo.depth_mask = False
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)
        ctx.depth_func = "<="   # the far plane passes where the cleared depth (1) is left
        with self.background_query:
            self.resolve_vao.render(mode=moderngl.TRIANGLES, vertices=3)
        ctx.depth_func = "<"
        self.background_fbo.depth_mask = True
        out.fbo.use()
        w, h = self.size
        self.pixels_written = w * h - int(self.background_query.samples)   # waits for the pass
        return 1

    def release(self):
        self._release("fbo", "color_ms_fbo", "color_resolved_fbo", "color", "depth", "normal", "object", "zbuf",
                      "background_fbo", "background_query")


# --- layered targets (multi-view frames) --------------------------------------------------------
GL_TEXTURE_2D_ARRAY, GL_TEXTURE_2D_MULTISAMPLE_ARRAY = 0x8C1A, 0x9102
GL_RGBA16F, GL_RGBA32F, GL_R32F, GL_R32UI, GL_DEPTH_COMPONENT24 = 0x881A, 0x8814, 0x822E, 0x8236, 0x81A6
GL_TEXTURE_MIN_FILTER, GL_TEXTURE_MAG_FILTER, GL_NEAREST = 0x2801, 0x2800, 0x2600
GL_FRAMEBUFFER, GL_FRAMEBUFFER_COMPLETE = 0x8D40, 0x8CD5
GL_COLOR_ATTACHMENT0, GL_DEPTH_ATTACHMENT = 0x8CE0, 0x8D00
GL_COLOR, GL_DEPTH, GL_COLOR_BUFFER_BIT, GL_SCISSOR_TEST = 0x1800, 0x1801, 0x4000, 0x0C11
GL_MAX_ARRAY_TEXTURE_LAYERS, GL_MAX_FRAMEBUFFER_LAYERS = 0x88FF, 0x9317
GL_MAX_GEOMETRY_SHADER_INVOCATIONS = 0x8E5A

_U, _I, _B = ctypes.c_uint, ctypes.c_int, ctypes.c_ubyte
_UP, _FP = ctypes.POINTER(ctypes.c_uint), ctypes.POINTER(ctypes.c_float)
_SIGNATURES = {
    "glGetError": (_U, []),
    "glGetIntegerv": (None, [_U, ctypes.POINTER(_I)]),
    "glCreateTextures": (None, [_U, _I, _UP]),
    "glTextureStorage3D": (None, [_U, _I, _U, _I, _I, _I]),
    "glTextureStorage3DMultisample": (None, [_U, _I, _U, _I, _I, _I, _B]),
    "glTextureParameteri": (None, [_U, _U, _I]),
    "glDeleteTextures": (None, [_I, _UP]),
    "glCreateFramebuffers": (None, [_I, _UP]),
    "glDeleteFramebuffers": (None, [_I, _UP]),
    "glNamedFramebufferTexture": (None, [_U, _U, _U, _I]),
    "glNamedFramebufferTextureLayer": (None, [_U, _U, _U, _I, _I]),
    "glNamedFramebufferDrawBuffers": (None, [_U, _I, _UP]),
    "glCheckNamedFramebufferStatus": (_U, [_U, _U]),
    "glClearNamedFramebufferfv": (None, [_U, _U, _I, _FP]),
    "glClearNamedFramebufferuiv": (None, [_U, _U, _I, _UP]),
    "glBlitNamedFramebuffer": (None, [_U, _U] + [_I] * 8 + [_U, _U]),
    "glBindFramebuffer": (None, [_U, _U]),
    "glViewport": (None, [_I] * 4),
    "glColorMaski": (None, [_U, _B, _B, _B, _B]),
    "glDepthMask": (None, [_B]),
    "glDisable": (None, [_U]),
    "glBindTextureUnit": (None, [_U, _U]),
}
_gl_lib = None


def raw_gl():
    """The GL 4.5 entry points moderngl lacks (texture arrays with multisamples, layered
    framebuffers, clearing an integer attachment), called on the current context (gl_context's)
    through the GL library."""
    global _gl_lib
    if _gl_lib is None:
        for name in ("libOpenGL.so.0", "libGL.so.1"):
            try:
                lib = ctypes.CDLL(name)
                break
            except OSError:
                continue
        else:
            raise DeviceError("paramlod's OpenGL renderers need libOpenGL.so.0 or libGL.so.1 (Debian: libopengl0)")
        for fn, (res, args) in _SIGNATURES.items():
            f = getattr(lib, fn)
            f.restype, f.argtypes = res, args
        _gl_lib = lib
    return _gl_lib


def gl_limit(name: int) -> int:
    """glGetIntegerv of a limit moderngl's info dict lacks."""
    value = ctypes.c_int(0)
    raw_gl().glGetIntegerv(name, ctypes.byref(value))
    return value.value


class LayeredGLTargets(_Outputs):
    """GLTargets for a multi-view frame: the draw targets as 2D texture arrays of ``layers``
    layers (view v draws into layer v; multisampled arrays when ``samples`` > 1; the depth buffer
    a depth texture array of the renderbuffer's format), resolved and read back one layer at a
    time into single-layer output targets. Drawn through the layered framebuffer: a geometry
    stage picks each primitive's layer (tess with views_per_pass > 1, meshlets-gl)."""

    depth_texture = False   # hybrid anti-aliasing's carry (GLTargets.carry) draws one view at a time

    def __init__(self, ctx, size: tuple[int, int], ss: int, samples: int, layers: int, what: str = "OpenGL"):
        self.ctx = ctx
        self.size, self.ss, self.samples, self.layers = tuple(size), ss, samples, int(layers)
        w, h = size
        self.big = (w * ss, h * ss)
        self._check_size()
        self.gl = gl = raw_gl()
        most = min(gl_limit(GL_MAX_ARRAY_TEXTURE_LAYERS), gl_limit(GL_MAX_FRAMEBUFFER_LAYERS))
        if not 1 <= self.layers <= most:
            raise SceneError(f"{layers} views need as many layers of {what} render targets; this OpenGL device "
                             f"({ctx.info.get('GL_RENDERER')}) allows 1..{most}")
        self._textures, self._fbos = [], []
        try:
            while gl.glGetError():   # errors left by others are not ours
                pass
            half = half_floats(ss, samples)
            rgba = GL_RGBA16F if half else GL_RGBA32F
            self.color, self.depth, self.normal, self.object, self.zbuf = (
                self._array(f) for f in (rgba, GL_R32F, rgba, GL_R32UI, GL_DEPTH_COMPONENT24))
            draw = [self.color, self.depth, self.normal, self.object]
            self.fbo = self._framebuffer(draw, self.zbuf)
            if samples > 1:
                # the hardware resolve, a layer at a time: that layer of the colour array blitted
                # into a plain texture, which the resolve shader then reads
                self.color_resolved = ctx.texture(self.big, 4, dtype="f2")
                self.color_resolved.filter = (ctx.NEAREST, ctx.NEAREST)
                self.layer_fbo = self._framebuffer([], None)
                self.resolved_fbo = self._framebuffer([], None)
                gl.glNamedFramebufferTexture(self.resolved_fbo, GL_COLOR_ATTACHMENT0, self.color_resolved.glo, 0)
            self._outputs(resolve_program(ctx, ss, samples, layered=True, half=half))
            err = gl.glGetError()
            if err:
                raise DeviceError(f"could not create the {what} render targets ({w}x{h}, {ss}x{ss} SS, {samples} "
                                  f"samples, {layers} layers): OpenGL error 0x{err:04x} (0x0505: out of memory)")
        except Exception as exc:
            self._failed(exc, f"{what} render targets ({w}x{h}, {ss}x{ss} SS, {samples} samples, {layers} layers)")

    def _array(self, fmt: int) -> int:
        gl, (bw, bh) = self.gl, self.big
        glo = ctypes.c_uint(0)
        if self.samples > 1:
            gl.glCreateTextures(GL_TEXTURE_2D_MULTISAMPLE_ARRAY, 1, ctypes.byref(glo))
            gl.glTextureStorage3DMultisample(glo.value, self.samples, fmt, bw, bh, self.layers, 1)
        else:
            gl.glCreateTextures(GL_TEXTURE_2D_ARRAY, 1, ctypes.byref(glo))
            gl.glTextureStorage3D(glo.value, 1, fmt, bw, bh, self.layers)
            # integer textures must be sampled with NEAREST (else incomplete)
            for p in (GL_TEXTURE_MIN_FILTER, GL_TEXTURE_MAG_FILTER):
                gl.glTextureParameteri(glo.value, p, GL_NEAREST)
        self._textures.append(glo.value)
        return glo.value

    def _framebuffer(self, colors: list[int], depth: int | None) -> int:
        """A layered framebuffer of the arrays ``colors`` and ``depth``."""
        gl = self.gl
        glo = ctypes.c_uint(0)
        gl.glCreateFramebuffers(1, ctypes.byref(glo))
        fbo = glo.value
        self._fbos.append(fbo)
        if not colors:
            return fbo
        for att, tex in [(GL_COLOR_ATTACHMENT0 + i, t) for i, t in enumerate(colors)] + [(GL_DEPTH_ATTACHMENT, depth)]:
            gl.glNamedFramebufferTexture(fbo, att, tex, 0)   # the whole array: a layered attachment
        bufs = (ctypes.c_uint * len(colors))(*(GL_COLOR_ATTACHMENT0 + i for i in range(len(colors))))
        gl.glNamedFramebufferDrawBuffers(fbo, len(colors), bufs)
        status = gl.glCheckNamedFramebufferStatus(fbo, GL_FRAMEBUFFER)
        if status != GL_FRAMEBUFFER_COMPLETE:
            raise DeviceError(f"this OpenGL device ({self.ctx.info.get('GL_RENDERER')}) cannot draw into layered "
                              f"targets of {self.samples} samples: framebuffer status 0x{status:04x}")
        return fbo

    def begin(self, program=None):
        """Bind the layered targets for drawing (outside moderngl, which keeps its own binding
        and restores it at its next framebuffer call) and clear every layer's colour and depth
        (see CLEAR_MASK); ``program``, the draw program, is told not to write the image."""
        if program is not None:
            set_uniform(program, "u_image", 0)
        gl, (bw, bh) = self.gl, self.big
        gl.glBindFramebuffer(GL_FRAMEBUFFER, self.fbo)
        gl.glViewport(0, 0, bw, bh)
        gl.glDisable(GL_SCISSOR_TEST)
        for i in range(len(DRAW_MASK)):
            gl.glColorMaski(i, 1, 1, 1, 1)
        gl.glDepthMask(1)
        gl.glClearNamedFramebufferfv(self.fbo, GL_COLOR, 0, (ctypes.c_float * 4)(0.0, 0.0, 0.0, 0.0))
        gl.glClearNamedFramebufferfv(self.fbo, GL_DEPTH, 0, (ctypes.c_float * 1)(1.0))

    def resolve(self, layer: int, background=(0.0, 0.0, 0.0)):
        """Resolve layer ``layer`` into the output targets (not waited for: ``read`` waits)."""
        ctx, gl = self.ctx, self.gl
        if self.samples > 1:
            bw, bh = self.big
            gl.glNamedFramebufferTextureLayer(self.layer_fbo, GL_COLOR_ATTACHMENT0, self.color, 0, layer)
            gl.glBlitNamedFramebuffer(self.layer_fbo, self.resolved_fbo, 0, 0, bw, bh, 0, 0, bw, bh,
                                      GL_COLOR_BUFFER_BIT, GL_NEAREST)
        ctx.disable(moderngl.DEPTH_TEST)
        prog = self._bind_resolve(background)
        color = self.color_resolved.glo if self.samples > 1 else self.color
        for unit, (name, tex) in enumerate((("u_color", color), ("u_coverage", self.color), ("u_depth", self.depth),
                                            ("u_normal", self.normal), ("u_object", self.object))):
            gl.glBindTextureUnit(unit, tex)
            set_uniform(prog, name, unit)
        set_uniform(prog, "u_layer", int(layer))
        self.resolve_vao.render(mode=moderngl.TRIANGLES, vertices=3)
        self._count_written()

    def device_samples(self) -> int:
        """The samples per pixel the device really allocated, as the last resolve saw (waits);
        sets ``pixels_written`` of that layer."""
        self.ctx.finish()   # the resolve's storage write, visible to the read
        return self._read_counters()

    def release(self):
        self._release()
        gl = self.__dict__.get("gl")
        if gl is not None:
            for items, delete in ((self._fbos, gl.glDeleteFramebuffers), (self._textures, gl.glDeleteTextures)):
                if items:
                    delete(len(items), (ctypes.c_uint * len(items))(*items))
                items.clear()


def targets_for(current, ctx, size, ss: int, samples: int, what: str = "OpenGL", layers: int = 0,
                depth_texture: bool = False):
    """``current`` when it fits (size, ss, samples, layers, depth_texture), else new targets
    (``current`` released): GLTargets, or LayeredGLTargets of ``layers`` layers when ``layers`` > 0."""
    if current is not None and (current.size, current.ss, current.samples, current.layers, current.depth_texture) == (
            tuple(size), ss, samples, layers, depth_texture):
        return current
    if current is not None:
        current.release()
    if layers:
        return LayeredGLTargets(ctx, tuple(size), ss, samples, layers, what)
    return GLTargets(ctx, tuple(size), ss, samples, what, depth_texture)


def gl_matrix(m) -> np.ndarray:
    """A row-major 4x4 matrix as GLSL's column-major mat4 (float32)."""
    return np.ascontiguousarray(np.asarray(m, np.float64).T, np.float32)


class GrowBuffer:
    """A GL buffer replaced by a bigger one (a power of two) when data does not fit
    (``generation`` counts the replacements, so vertex arrays that bind it know to rebuild)."""

    def __init__(self, ctx, nbytes: int = 16):
        self.ctx, self.buf, self.generation = ctx, ctx.buffer(reserve=max(16, nbytes)), 0

    def write(self, data):
        """Write ``data`` (bytes, or a C-contiguous array: written without a copy) at the start."""
        nbytes = memoryview(data).nbytes
        if nbytes > self.buf.size:
            self.buf.release()
            self.buf = self.ctx.buffer(reserve=1 << int(math.ceil(math.log2(nbytes))))
            self.generation += 1
        if nbytes:
            self.buf.write(data)
