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
divided by ``lod_divisor(mode)``: the supersampling factor per axis (``msaa_lod = True`` adds sqrt(MSAA)).

Hybrid anti-aliasing (``aa = "hybrid"``, thesis section 5.5.7, docs/hybrid.md): the LOD stage sends
each patch with sub-pixel detail or a silhouette to a finer tier (``render_tiers``); the render list is ordered by
tier and each tier drawn into its own targets (``hybrid_tiers``: noAA, 8xMS, 4xSS+8xMS,
multisampling capped to the device), coarse to fine, with the thresholds of its tier
(``tier_divisors``: by default sqrt(8) and sqrt(32), the thesis's guideline that issue #21 names;
those of the tiers' uniform modes, 1 and 2, with ``msaa_lod = False``). A finer tier's
targets start from a per-sample copy of the last tier drawn (``GLTargets.carry``), so its patches
are depth-tested per sample against the coarser ones, and the finest tier drawn is resolved; tiers
without patches are skipped (a frame of tier-0 patches only is a noAA frame). One view at a
time. ``TessSettings.hybrid_targets = "finest"`` draws every tier into the finest one's targets
instead; ``TessSettings.color_by = "tier"`` shades each patch with its tier's debug colour.

Targets and their resolve: ``paramlod.renderers.gl_targets`` (colour RGBA16F, hardware multisample
resolve, then a box downsample of the SSAA block; linear view depth R32F, world normal RGBA16F and
object id R32UI, resolved to the nearest covered sample of the pixel). ``docs/tessellation.md`` has
the details, including how cracks between patches are avoided.

Multi-view frames (``draw_views``, ``paramlod.render_views``): the render list of one LOD pass for
all views is uploaded once and drawn ``TessSettings.views_per_pass`` views a pass. One (the
default): each view is a pass of the single-view program into the single-view targets, resolved
and read back before the next, so each view is tessellated for itself and equals a single-view
frame of its camera. More: the views are drawn into layered targets (``LayeredGLTargets``, a
layer per view) by a program with a geometry stage after the evaluation stage, which then hands
on world-space vertices; an instanced geometry shader
(``kernels/tess/tess_geometry.glsl``, up to 32 invocations, GL's guaranteed minimum) projects each
triangle into one view per invocation, drops it where it lies outside that view's frustum and
picks the view's layer, and more views than that take several passes (view chunks); the views
share the tessellation, whose adaptive outer levels are the largest any view that sees the edge
needs. On the H200 the pass per view is the faster (see TessSettings).
"""
from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, replace
from functools import cached_property

import moderngl
import numpy as np

from paramlod import kernels
from paramlod.core.camera import Camera
from paramlod.core.frame import Frame
from paramlod.core.views import MAX_VIEWS, Views, as_views
from paramlod.core.layouts import GRID_VERTEX, RENDER_PATCH, glsl_prelude, vertex_format
from paramlod.core.transforms import in_range
from paramlod.device.context import cl_device, gl_cache, gl_context
from paramlod.device.programs import GLSL_LINE, check_block, context_lines, set_uniform
from paramlod.errors import FunctionError, SceneError
from paramlod.function.codegen_glsl import glsl_dispatch_source
from paramlod.lod.patches import RENDER_DTYPE, render_tiers
from paramlod.lod.stage import LodStage
from paramlod.lod.uploads import SceneBuffers
from paramlod.renderers.aa import AAMode, lod_divisor, parse_aa  # noqa: F401  (AAMode, lod_divisor re-exported)
from paramlod.renderers.aa import hybrid_tiers, tier_divisors
from paramlod.renderers.gl_targets import (GL_MAX_GEOMETRY_SHADER_INVOCATIONS, GLTargets, GrowBuffer, LayeredGLTargets,
                                           effective_aa, gl_limit, gl_matrix, is_llvmpipe, max_samples,
                                           srgb8_defines, targets_for)
from paramlod.renderers.registry import RendererSpec, register_renderer
from paramlod.renderers.shading import LIGHT
from paramlod.renderers.tess_grid import GridTessellator
from paramlod.scene.scene import Scene

# Highest tessellation level allowed: GL_MAX_TESS_GEN_LEVEL is at least 64 on every GL 4.x device.
MAX_LEVEL = 64.0
# llvmpipe: most vertices a draw call may generate, bounded from above per patch (draw_batches).
# Below 65,536, past which Mesa's llvmpipe silently drops triangles; and small, because llvmpipe's
# draw module resets every vertex of the draw each time it flushes clipped triangles, a cost that
# grows with the square of the draw's vertices: the close-up torus (peers bench, 640 x 640, 2-core
# AMD EPYC, Mesa 22.3) drew in 1,248 ms with 60,000 (9 draws) and in 103 ms with 4,000 (138); the
# framed torus and the glyph fields, mostly unclipped, drew as fast with either
LLVMPIPE_VERTEX_BUDGET = 4000
SPACINGS = {"equal": "equal_spacing", "fractional_odd": "fractional_odd_spacing"}
# the render list's records as vertex attributes: range, ext and inst of each RenderPatch
PATCH_ATTRIBUTES = ("range", "ext", "inst")
PATCH_FORMAT = vertex_format(RENDER_PATCH, PATCH_ATTRIBUTES)   # "4f 16x 4f 1u 12x"
# views per geometry-shader invocation set: GL's guaranteed minimum of MAX_GEOMETRY_SHADER_INVOCATIONS
MAX_INVOCATIONS = 32
VIEW_FLOATS = 36   # a PlViews record (kernels/tess/tess_views.glsl, std140): view, proj, near (vec4)
COLOR_BY = ("material", "tier")   # TessSettings.color_by
HYBRID_TARGETS = ("tiers", "pair", "finest")   # TessSettings.hybrid_targets
TESSELLATORS = ("auto", "hardware", "grid")     # TessSettings.tessellator
LEVEL_MODES = ("fixed", "adaptive", "chord")    # TessSettings.mode, by the control stage's u_adaptive
INNER_MEASURES = ("detail", "extent", "segment")   # TessSettings.inner_measure
GRID_FORMAT = vertex_format(GRID_VERTEX, ("pos", "normal", "inst"))   # "4f 3f 1u"
# TessSettings.detail_levels: the threshold divisors of the spot check's tiers 0, 1, 2 (the pixel of
# 8xMS and of 4xSS+8xMS: the detail each tier's spot check looks for)
DETAIL_DIVISORS = (1.0, math.sqrt(8.0), math.sqrt(32.0))
# hybrid: how far, in output pixels, a tier carried into a finer tier's targets reaches past its
# patches' edges (tess_control.glsl): its coverage is copied to samples up to a pixel from where it
# was decided (0.71 from a noAA pixel's centre), so the seam with a finer tier's patch must be
# covered that far on both sides. Measured on llvmpipe, seashell3 at 128 x 96: without it 17 pixels
# inside the shell kept an uncovered sample, with it none
CARRY_OVERLAP_PX = 1.0
HYBRID_VIEWS = ('anti-aliasing "hybrid" draws one view at a time (its tiers carry one view\'s targets into the '
                'next); render each camera with render(), or use another mode for render_views')


# --- settings -----------------------------------------------------------------------------------
@dataclass
class TessSettings:
    """How render patches are tessellated and sampled.

    mode "adaptive": l = clamp(e * L / min(t, L), l_min, l_max) per level, with L = ``base_level``,
    t the effective LOD threshold and e the patch's measured extent (inner levels) or the screen
    length of the edge itself (outer levels). mode "fixed": ``levels`` = (inner, outer). mode
    "chord" (one view a pass): as few equal segments as keep every chord within ``chord_px``
    pixels of the surface on the screen, from how far 8 samples of each edge (outer levels) and of
    the 6 parameter lines between two edges (inner levels, at least the edges') bend, clamped to
    [l_min, l_max]: a smooth surface gets a few large triangles where "adaptive" makes them a
    pixel long (the framed torus of the peers bench: 6,000 triangles instead of 900,000 at the
    same silhouette, docs/tessellation.md).
    ``overlap``: each patch's parameter range is widened by this fraction per side (within the
    domain), which covers T-junctions between patches of different size.

    ``views_per_pass`` (multi-view frames): the views one pass of the pipeline draws. 1: a pass
    per view, the single-view program drawing into the single-view targets (each view tessellated
    for itself, so it equals a single-view frame of its camera). 2..32: a geometry stage draws that
    many views a pass into layered targets, the views sharing one tessellation whose levels are the largest any view
    needs (thesis chapter 2 found 4 best on consumer NVIDIA GPUs). On the H200 a pass per view
    was the fastest in every case measured (1080p, 2, 6 and 48 views): its draw 2.5x to 7x faster
    than the geometry stage's for a sphere, 1.9x to 2.4x for 19,600 glyphs.

    ``color_by``: "material" (each object's colour) or "tier" (a debug view of ``aa = "hybrid"``:
    each patch shaded with its tier's colour, ``pl_tier_color``: 0 blue, 1 green, 2 red; without
    hybrid every patch is tier 0).

    ``hybrid_targets`` (``aa = "hybrid"``): "tiers", the thesis's scheme, each tier drawn into
    targets of its own mode, coarsest first, each finer one started from a per-sample copy of the
    coarser (``GLTargets.carry``); "pair", tier 0 into its noAA targets and tiers 1 and 2 into the
    finest drawn tier's, one copy from a single-sampled target (per pixel, not per sample: the
    cheap one); or "finest", every tier drawn with its own thresholds straight into the finest
    drawn tier's targets (no copies; the coarser tiers' patches are multisampled too). The tiers
    then differ only in the patches and levels the LOD gives them.

    ``detail_levels`` (other modes than hybrid, one view): the LOD stage's spot check also runs,
    and a patch with detail finer than a pixel is measured again at the threshold divided by
    sqrt(8), then sqrt(32) (``DETAIL_DIVISORS``), and tessellated for that threshold in the same
    targets: a thin SH lobe on a glyph of 20 pixels gets the segments it needs (docs/hybrid.md,
    "Detail levels"). Off by default: a field of thousands of small glyphs sends nearly every
    patch on, measured up to three times and tessellated up to 5.7 times as finely.

    ``inner_measure`` (mode "adaptive"): "extent", the thesis's inner levels from the measured
    extents e_u, e_v (the longest of the LOD stage's polylines across the patch); "segment", from
    s_u, s_v where larger (7 times the longest single LOD segment, what the point renderer
    samples by), so the fastest-moving part of a patch gets pixel-long segments too: a thin SH
    lobe that the polylines pass beside is no longer cut short (order-12 glyphs of 60 px: IoU
    0.89-0.90 -> 0.97), at about 4x the triangles of a glyph field (docs/tessellation.md);
    "detail" (default): "segment" for the patches the spot check sent on (the hybrid's tiers 1
    and 2, ``detail_levels``' finer levels), "extent" for the rest, so every other frame is the
    thesis's (20-px order-12 glyphs, hybrid: IoU 0.73 -> 0.91; docs/hybrid.md).

    ``tessellator``: "hardware", GL's tessellation stages; "grid", the patches tessellated in
    OpenCL with the same levels rounded up to whole segments (equal spacing, so ``spacing`` does
    not apply) and drawn as triangles (``paramlod.renderers.tess_grid``; one view a pass, so not
    with ``views_per_pass`` above 1); "auto" (default): the grid on Mesa's llvmpipe for mode
    "chord", hardware otherwise. llvmpipe runs the tessellation stages on one thread, so the
    grid pays where evaluating the function is the cost (the peers bench's glyph fields drew
    1.4x faster with "adaptive", 2x with "chord"), but where a pixel-sized tessellation makes
    rasterizing the cost it adds its copies to the same raster time (the framed torus with
    "adaptive": 147 ms a frame in hardware, 214 ms with the grid; docs/tessellation.md).
    """

    mode: str = "adaptive"
    levels: tuple[float, float] = (16.0, 16.0)
    base_level: float = 64.0
    l_min: float = 8.0
    l_max: float = 64.0
    spacing: str = "fractional_odd"
    aa: str = "noAA"
    overlap: float = 0.005
    msaa_lod: bool | None = None   # divide the LOD threshold by sqrt(msaa) too; None: for hybrid only (msaa_lod_for)
    views_per_pass: int = 1
    color_by: str = "material"
    hybrid_targets: str = "tiers"
    detail_levels: bool = False
    tessellator: str = "auto"
    chord_px: float = 0.25
    inner_measure: str = "detail"

    def inner_levels_for(self, detail: bool) -> str:
        """The inner measure ("extent" or "segment") of patches that the spot check sent on
        (``detail``) or not. A frame's draw lists pass the concrete measure on
        (``TessRenderer._draw_list``); a list drawn or bounded outside a frame
        (``vertex_bound``, the grid tessellator) is taken as not sent on."""
        if self.inner_measure == "detail":
            return "segment" if detail else "extent"
        return self.inner_measure

    def msaa_lod_for(self, aa: AAMode) -> bool:
        """Whether the LOD thresholds of AA mode ``aa`` are divided by sqrt(multisamples) too:
        ``msaa_lod`` where set; unset, for hybrid tiers (8xMS sqrt(8), 4xSS+8xMS sqrt(32), the
        thesis's guideline for them) and not for the uniform modes (its non-hybrid figures)."""
        return bool(aa.hybrid) if self.msaa_lod is None else bool(self.msaa_lod)

    def validate(self):
        if self.mode not in LEVEL_MODES:
            raise SceneError(f"tess mode must be one of {', '.join(LEVEL_MODES)}, got {self.mode!r}")
        if not (isinstance(self.chord_px, (int, float)) and 0.01 <= self.chord_px <= 100):
            raise SceneError(f"tess chord_px must be a number of pixels in [0.01, 100], got {self.chord_px!r}")
        if not isinstance(self.spacing, str) or self.spacing not in SPACINGS:
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
        if not in_range(self.overlap, 0, 0.25):
            raise SceneError(f"tess overlap must be in [0, 0.25] of a patch's range per side, got {self.overlap!r}")
        parse_aa(self.aa)
        k = self.views_per_pass
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 1 <= k <= MAX_INVOCATIONS:
            raise SceneError(f"tess views_per_pass must be a whole number in 1..{MAX_INVOCATIONS}, got {k!r}")
        if self.color_by not in COLOR_BY:
            raise SceneError(f"tess color_by must be one of {', '.join(COLOR_BY)}, got {self.color_by!r}")
        if self.msaa_lod is not None and not isinstance(self.msaa_lod, (bool, np.bool_)):
            raise SceneError(f"tess msaa_lod must be true, false or unset, got {self.msaa_lod!r}")
        if not isinstance(self.detail_levels, (bool, np.bool_)):
            raise SceneError(f"tess detail_levels must be true or false, got {self.detail_levels!r}")
        if self.inner_measure not in INNER_MEASURES:
            raise SceneError(f"tess inner_measure must be one of {', '.join(INNER_MEASURES)}, got {self.inner_measure!r}")
        if self.tessellator not in TESSELLATORS:
            raise SceneError(f"tess tessellator must be one of {', '.join(TESSELLATORS)}, got {self.tessellator!r}")
        if self.tessellator == "grid" and k > 1:
            raise SceneError("tess tessellator 'grid' draws one view a pass; set views_per_pass to 1 or the "
                             "tessellator to 'hardware'")
        if self.mode == "chord" and k > 1:
            raise SceneError("tess mode 'chord' measures one view a pass; set views_per_pass to 1 or the mode to "
                             "'adaptive'")
        if self.hybrid_targets not in HYBRID_TARGETS:
            raise SceneError(f"tess hybrid_targets must be one of {', '.join(HYBRID_TARGETS)}, "
                             f"got {self.hybrid_targets!r}")


# --- shader programs ----------------------------------------------------------------------------
def _stage(defines: dict, body: list[str], encoder: str = "") -> str:
    """A GLSL stage: ``#version``, the ``defines``, ``encoder`` (a fragment stage's
    ``srgb8_defines``), the records' prelude, tess_common.glsl, ``body``."""
    head = "#version 450 core\n" + "".join(f"#define {k} {v}\n" for k, v in defines.items()) + encoder
    return head + "\n".join([glsl_prelude(), kernels.source("tess/tess_common.glsl"), *body])


def _program(ctx, stages: dict, functions) -> object:
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


def build_programs(ctx, functions, spacing: str, invocations: int = 0, grid: bool = False):
    """The tessellation program for ``functions``, cached: the single-view one, or with
    ``invocations`` > 0 the multi-view one whose geometry stage draws that many views a draw; with
    ``grid`` the grid tessellator's (a vertex and the fragment stage, for triangles made in OpenCL)."""
    functions = list(functions)
    # keyed by the function objects: generating the GLSL again just to look it up cost ~150 ms a
    # frame for an order-12 SH glyph
    programs = gl_cache(ctx).setdefault("tess_programs", {})
    if grid:   # no generated code in it: one program whatever the functions
        key = "grid"
        if key not in programs:
            programs[key] = _program(ctx, {"vertex_shader": _stage({}, [kernels.source("tess/grid_vertex.glsl")]),
                                           "fragment_shader": _stage({}, [kernels.source("tess/tess_fragment.glsl")],
                                                                     srgb8_defines(ctx))},
                                     functions)
        return programs[key]
    key = (tuple(functions), spacing) if not invocations else (tuple(functions), spacing, invocations)
    progs = programs.get(key)
    if progs is None:
        gen_pos = glsl_dispatch_source(functions, position=True, surface=False)
        gen_surf = glsl_dispatch_source(functions, position=False, surface=True)
        tess_defs = {"PL_SPACING": SPACINGS[spacing]}
        views = []
        if invocations:
            tess_defs.update(PL_VIEWS=1, PL_MAX_VIEWS=MAX_VIEWS, PL_GS_INVOCATIONS=invocations)
            views = [kernels.source("tess/tess_views.glsl")]
        stages = {
            "vertex_shader": _stage(tess_defs, [kernels.source("tess/tess_vertex.glsl")]),
            "tess_control_shader": _stage(tess_defs, [*views, gen_pos, kernels.source("tess/tess_control.glsl")]),
            "tess_evaluation_shader": _stage(tess_defs, [gen_surf, kernels.source("tess/tess_eval.glsl")]),
            "fragment_shader": _stage(tess_defs, [*views, kernels.source("tess/tess_fragment.glsl")],
                                      srgb8_defines(ctx)),
        }
        if invocations:
            stages["geometry_shader"] = _stage(tess_defs, [*views, kernels.source("tess/tess_geometry.glsl")])
        progs = programs[key] = _program(ctx, stages, functions)
        check_block(progs, "PlViews", MAX_VIEWS * VIEW_FLOATS * 4, "kernels/tess/tess_views.glsl")
    return progs


def view_chunks(n_views: int, most: int = MAX_INVOCATIONS) -> tuple[int, int]:
    """(geometry-shader invocations, draws) for ``n_views`` views, at most ``most`` a draw: the
    views spread evenly over the fewest draws, so that few invocations idle (40 views: 2 x 20)."""
    draws = -(-n_views // most)
    return -(-n_views // draws), draws


def vertex_bound(ext: np.ndarray, settings: TessSettings, threshold) -> np.ndarray:
    """An upper bound on the vertices the tessellator generates for each patch, from its
    measures ``ext`` (the render records' e_u, e_v, s_u, s_v): the control stage's inner levels, each
    rounded up to the next integer and one more (fractional odd spacing rounds up to odd), on a
    grid of that many segments per side, and four outer edges of at most ``l_max``."""
    if settings.mode == "fixed":
        inner, outer = (np.full(len(ext), float(x)) for x in settings.levels)
        lu = lv = inner
    elif settings.mode == "chord":
        lu = lv = outer = np.full(len(ext), float(settings.l_max))
    else:
        L = float(settings.base_level)
        if settings.inner_levels_for(False) == "segment":
            ext = np.maximum(ext[:, :2], ext[:, 2:4])
        lu, lv = (np.clip(np.nan_to_num(ext[:, a] * L / min(float(t), L), nan=settings.l_min),
                          settings.l_min, settings.l_max) for a, t in ((0, threshold[0]), (1, threshold[1])))
        outer = np.full(len(ext), float(settings.l_max))
    su, sv, so = (np.ceil(x) + 1.0 for x in (lu, lv, outer))
    return ((su + 1.0) * (sv + 1.0) + 4.0 * (so + 1.0)).astype(np.int64)


# --- the renderer -------------------------------------------------------------------------------
class TessRenderer:
    """Compiled programs and reusable GL buffers and targets for one set of functions."""

    def __init__(self, functions):
        self.functions = list(functions)
        self.ctx = gl_context()
        glsl_dispatch_source(self.functions, position=True, surface=False)  # fails early, naming the function
        self._targets: GLTargets | None = None
        # hybrid frames: the targets of the tiers below the finest (which uses _targets)
        self._coarse: list[GLTargets | None] = [None] * (len(hybrid_tiers("tess")) - 1)
        c = self.ctx
        self._patches = GrowBuffer(c, 64 * 1024)
        self._params = GrowBuffer(c, 1024)
        self._inst_f = GrowBuffer(c, 1024)
        self._inst_u = GrowBuffer(c, 1024)
        self._materials = GrowBuffer(c, 1024)
        self._counters = c.buffer(reserve=16)
        self._vaos: dict = {}
        # multi-view frames: their layered targets and the views' records (geometry-stage passes)
        self._layered: LayeredGLTargets | None = None
        self._views = c.buffer(reserve=MAX_VIEWS * VIEW_FLOATS * 4)
        # the grid tessellator (TessSettings.tessellator): made when first used; its triangles
        self._grid: GridTessellator | None = None
        self._grid_vertices = GrowBuffer(c, 1 << 20)
        self._grid_indices = GrowBuffer(c, 1 << 20)

    @property
    def max_samples(self) -> int:
        return max_samples(self.ctx)

    @cached_property
    def max_invocations(self) -> int:
        """Views a multi-view draw covers: MAX_INVOCATIONS, or fewer where the device has fewer."""
        return min(MAX_INVOCATIONS, gl_limit(GL_MAX_GEOMETRY_SHADER_INVOCATIONS) or MAX_INVOCATIONS)

    def effective_aa(self, mode) -> tuple[AAMode, AAMode, list[str]]:
        """(requested, effective, warnings): the multisample count capped to the device."""
        return effective_aa(self.ctx, mode)

    @cached_property
    def llvmpipe(self) -> bool:
        return is_llvmpipe(self.ctx)

    def tessellator(self, settings: TessSettings) -> str:
        """The tessellator a draw with ``settings`` uses: "hardware" or "grid"."""
        if settings.tessellator == "auto":
            return "grid" if self.llvmpipe and settings.mode == "chord" else "hardware"
        return settings.tessellator

    def draw_batches(self, patches: np.ndarray, settings: TessSettings, threshold) -> list[tuple[int, int]]:
        """(first, count) of each draw call for the render records ``patches``, drawn with the
        effective thresholds ``threshold``. One call draws everything, except on Mesa's llvmpipe
        (see LLVMPIPE_VERTEX_BUDGET): there consecutive runs of patches whose bound on generated
        vertices (``vertex_bound``) stays within the budget, one patch at least."""
        n = len(patches)
        if not n:
            return []
        if not self.llvmpipe:
            return [(0, n)]
        ends = np.cumsum(vertex_bound(patches["ext"], settings, threshold))
        batches, first = [], 0
        while first < n:
            base = ends[first - 1] if first else 0
            last = max(first + 1, int(np.searchsorted(ends, base + LLVMPIPE_VERTEX_BUDGET, side="right")))
            batches.append((first, last - first))
            first = last
        return batches

    def _targets_for(self, size, ss, samples) -> GLTargets:
        t, self._targets = self._targets, None   # not kept when making new ones fails
        self._targets = targets_for(t, self.ctx, size, ss, samples, "tessellation")
        return self._targets

    def _tier_targets_for(self, tier, size, modes) -> GLTargets:
        """The targets of hybrid tier ``tier`` of ``modes``: the finest shares the single-view
        targets (a 4xSS+8xMS frame's); the coarser ones keep their own, with a depth texture the
        carry into the next tier reads."""
        if tier == len(modes) - 1:
            return self._targets_for(size, modes[tier].ss, modes[tier].msaa)
        t, self._coarse[tier] = self._coarse[tier], None   # not kept when making new ones fails
        self._coarse[tier] = targets_for(t, self.ctx, size, modes[tier].ss, modes[tier].msaa, "tessellation",
                                         depth_texture=True)
        return self._coarse[tier]

    def _layered_for(self, size, ss, samples, layers) -> LayeredGLTargets:
        t, self._layered = self._layered, None   # not kept when making new ones fails
        self._layered = targets_for(t, self.ctx, size, ss, samples, "tessellation", layers=layers)
        return self._layered

    def _vao(self, prog):
        key = (id(prog), self._patches.generation)
        vao = self._vaos.get(key)
        if vao is None:
            for k in [k for k in self._vaos if k[0] == id(prog)]:  # made for a released buffer
                self._vaos.pop(k).release()
            vao = self._vaos[key] = self.ctx.vertex_array(
                prog, [(self._patches.buf, PATCH_FORMAT, *(f"in_{a}" for a in PATCH_ATTRIBUTES))])
        return vao

    def _inputs(self, render_list, n, scene, settings, threshold):
        """The checked inputs of a draw: (settings, render_list, n, requested AA, effective AA,
        warnings, (t_u, t_v))."""
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
        inst_f = scene.instance_buffers()[0]
        if n and int(render_list["inst"][:n].max()) >= len(inst_f):
            raise SceneError("render_list refers to an instance the scene does not have; was it made for this scene?")

        req, aa, notes = self.effective_aa(settings.aa)
        for msg in notes:
            warnings.warn(msg, RuntimeWarning, stacklevel=3)
        if threshold is None:
            div = aa.divisor(settings.msaa_lod_for(aa))
            threshold = (84.0 / div, 84.0 / div)
        tu, tv = (float(x) for x in threshold)
        if not (tu > 0 and tv > 0):
            raise SceneError(f"tess threshold must be positive pixels, got {threshold}")
        return settings, render_list, n, req, aa, notes, (tu, tv)

    def _upload(self, render_list, n, scene, patches_only: bool = False):
        """The render list, the scene's instance data (when it changed) and zeroed counters
        (``patches_only``: the render list alone)."""
        # CL -> GL through host memory: the render list records go into the vertex buffer
        self._patches.write(np.ascontiguousarray(render_list[:n]).tobytes())
        if patches_only:
            return
        scene_key = (scene._version, scene.time)
        if scene_key != getattr(self, "_scene_key", None):   # instance data only when it changed
            inst_f, inst_u, params = scene.instance_buffers()
            self._params.write(params.tobytes())
            self._inst_f.write(inst_f.tobytes())
            self._inst_u.write(inst_u.tobytes())
            self._materials.write(scene.materials().tobytes())
            self._scene_key = scene_key
        self._counters.write(np.zeros(4, np.uint32).tobytes())

    def _set_uniforms(self, prog, settings, size, threshold):
        """The uniforms and buffers every view shares."""
        w, h = size
        set_uniform(prog, "u_screen", (float(w), float(h)))
        set_uniform(prog, "u_threshold", threshold)
        if settings.mode == "fixed":
            set_uniform(prog, "u_level", tuple(float(x) for x in settings.levels))
        else:
            set_uniform(prog, "u_level", (float(settings.base_level), float(settings.base_level)))
        set_uniform(prog, "u_adaptive", LEVEL_MODES.index(settings.mode))
        set_uniform(prog, "u_chord", float(settings.chord_px))
        set_uniform(prog, "u_clamp", (float(settings.l_min), float(settings.l_max)))
        set_uniform(prog, "u_overlap", float(settings.overlap))
        set_uniform(prog, "u_light", tuple(float(x) for x in LIGHT))
        set_uniform(prog, "u_tier", 0 if settings.color_by == "tier" else -1)   # -1: the material's colour
        for binding, b in enumerate((self._params, self._inst_f, self._inst_u, self._materials)):
            b.buf.bind_to_storage_buffer(binding)
        self._counters.bind_to_storage_buffer(4)

    def _stats(self, ctx, size, req, aa, settings, threshold, n, notes) -> dict:
        """The stats of a draw that do not depend on what it drew."""
        return {
            "device": ctx.info.get("GL_RENDERER"),
            "variant": "tess",
            "size": list(size),
            "aa": req.name,
            "aa_effective": aa.name,
            "msaa_requested": req.msaa,
            "msaa_samples": aa.msaa,
            "ssaa": aa.ss,
            "samples_per_pixel": aa.samples_per_pixel,
            "lod_divisor": aa.divisor(settings.msaa_lod_for(aa)),
            "threshold": list(threshold),
            "tessellator": self.tessellator(settings),
            "tess": {"mode": settings.mode, "spacing": settings.spacing, "levels": list(settings.levels),
                     "base_level": settings.base_level, "l_min": settings.l_min, "l_max": settings.l_max,
                     "overlap": settings.overlap, "color_by": settings.color_by, "chord_px": settings.chord_px,
                     "inner_measure": settings.inner_measure},
            "render_patches": n,
            "warnings": notes,
        }

    def _draw_list(self, prog, patches, settings, threshold, passes=(None,), before=None, start=0, camera=None,
                   scene=None, chord=None, overlap_px: float = 0.0, detail: bool = False):
        """Draw the uploaded records ``patches`` (from record ``start`` on) with ``prog`` and the
        thresholds ``threshold`` once per pass (``before(pass)`` sets each up); returns (a
        primitives query per pass, none without patches; draw calls). ``chord``: mode "chord"'s
        error in output pixels for these patches (the targets' pixel, as the thresholds are
        divided; default ``settings.chord_px``). ``overlap_px``: how far the patches reach past
        their edges in output pixels (CARRY_OVERLAP_PX for a hybrid tier whose targets are
        carried; 0: ``settings.overlap`` alone). ``detail``: the spot check sent these patches on
        (their inner measure, ``TessSettings.inner_levels_for``). With the grid tessellator (one view: the
        ``scene`` seen by ``camera``) ``prog`` is the grid program and the records are
        tessellated in OpenCL first."""
        if chord is not None:
            set_uniform(prog, "u_chord", float(chord))
            settings = replace(settings, chord_px=float(chord))
        set_uniform(prog, "u_overlap_px", float(overlap_px))
        settings = replace(settings, inner_measure=settings.inner_levels_for(detail))
        set_uniform(prog, "u_inner_segment", int(settings.inner_measure == "segment"))
        if camera is not None and self.tessellator(settings) == "grid":
            return self._draw_grid(prog, patches, settings, threshold, scene, camera, overlap_px)
        queries, draw_calls = [], 0
        batches = self.draw_batches(patches, settings, threshold)
        if batches:
            self.ctx.patch_vertices = 1
            vao = self._vao(prog)
            for p in passes:
                if before is not None:
                    before(p)
                queries.append(self.ctx.query(primitives=True))
                with queries[-1]:
                    for first, count in batches:
                        vao.render(mode=moderngl.PATCHES, vertices=count, first=start + first)
                        draw_calls += 1
        return queries, draw_calls

    def _draw_grid(self, prog, patches, settings, threshold, scene, camera, overlap_px: float):
        """``_draw_list`` with the grid tessellator: the triangles of ``patches`` in one draw; the
        NaN vertices it found are added to the counters the evaluation stage would have counted."""
        if not len(patches):
            return [], 0
        if self._grid is None:
            self._grid = GridTessellator(self.functions)
        grid = self._grid.tessellate(patches, scene, camera, settings, threshold, overlap_px=overlap_px)
        self._grid_vertices.write(grid.vertices)   # contiguous arrays: no copy on the host
        self._grid_indices.write(grid.indices)
        if grid.nan_vertices:
            counted = np.frombuffer(self._counters.read(4), np.uint32)[0]
            self._counters.write(np.uint32(counted + grid.nan_vertices).tobytes())
        key = ("grid", id(prog), self._grid_vertices.generation, self._grid_indices.generation)
        vao = self._vaos.get(key)
        if vao is None:
            for k in [k for k in self._vaos if k[:2] == key[:2]]:   # made for a released buffer
                self._vaos.pop(k).release()
            vao = self._vaos[key] = self.ctx.vertex_array(
                prog, [(self._grid_vertices.buf, GRID_FORMAT, "in_pos", "in_normal", "in_inst")],
                index_buffer=self._grid_indices.buf, index_element_size=4)
        query = self.ctx.query(primitives=True)
        with query:
            vao.render(mode=moderngl.TRIANGLES, vertices=len(grid.indices))
        return [query], 1

    def _read_frame(self, tg, scene, msaa, notes) -> tuple[Frame, int, int, float]:
        """Resolve ``tg`` into a Frame that reads it back lazily (``GLTargets.frame``; its
        read-back is paid on access): (Frame, the samples per pixel the device allocated, pixels
        written, resolve ms); a line in ``notes`` when the device allocated other than ``msaa``
        samples."""
        t0 = time.perf_counter()
        # the hardware multisample resolve, then the SSAA block in a shader (targets drawn directly:
        # the background pass)
        device_samples = tg.resolve(scene.background)
        t1 = time.perf_counter()
        if device_samples != msaa:
            notes.append(f"the device allocated {device_samples} samples per pixel for a {msaa}-sample "
                         "request; coverage and the depth/id resolve use all of them")
        return tg.frame(), device_samples, tg.pixels_written, (t1 - t0) * 1e3

    def draw(self, render_list: np.ndarray, n: int | None, scene: Scene, camera: Camera,
             settings: TessSettings | None = None, threshold=None) -> Frame:
        """Draw ``n`` records of ``render_list`` (RENDER_DTYPE, from LodStage.read_render_list).

        ``threshold``: the effective LOD thresholds (t_u, t_v) in output pixels that made the list,
        used by adaptive levels; default 84 px divided by ``lod_divisor`` of the AA mode. With
        aa "hybrid" they are tier 0's, and the list's patches are drawn by tier (``_draw_hybrid``).
        """
        checked = self._inputs(render_list, n, scene, settings, threshold)
        if checked[4].hybrid:
            return self._draw_hybrid(checked, scene, camera)
        return self._draw_one(checked, scene, camera)

    def _draw_one(self, checked, scene, camera, upload="all") -> Frame:
        """``draw`` with checked inputs (``_inputs``); ``upload``: "all" (the render list, the
        scene's data, zeroed counters), "patches" (the render list alone) or None (what the last
        draw sent): a multi-view frame sends the scene's data for its first view only."""
        settings, render_list, n, req, aa, notes, (tu, tv) = checked
        notes = list(notes)   # this draw's own (a multi-view frame draws several)
        ctx = self.ctx
        t0 = time.perf_counter()
        grid = self.tessellator(settings) == "grid"
        prog = build_programs(ctx, self.functions, settings.spacing, grid=grid)
        w, h = camera.size
        tg = self._targets_for((w, h), aa.ss, aa.msaa)
        # detail_levels: the patches the spot check sent on, drawn last with their finer thresholds
        tier = render_tiers(render_list[:n])
        counts = np.bincount(tier, minlength=len(DETAIL_DIVISORS))
        if counts[0] != n:
            render_list = render_list[:n][np.argsort(tier, kind="stable")]
        t1 = time.perf_counter()
        if upload:
            self._upload(render_list, n, scene, patches_only=upload == "patches")
        t2 = time.perf_counter()

        set_uniform(prog, "u_view", gl_matrix(camera.view))
        set_uniform(prog, "u_proj", gl_matrix(camera.projection))
        set_uniform(prog, "u_near", float(camera.near))
        self._set_uniforms(prog, settings, (w, h), (tu, tv))

        tg.begin(prog, scene.background)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)
        queries, draw_calls, start = [], 0, 0
        div = aa.divisor(settings.msaa_lod_for(aa))
        for k, count in enumerate(counts):
            thr = (tu / DETAIL_DIVISORS[k], tv / DETAIL_DIVISORS[k])
            if k:
                set_uniform(prog, "u_threshold", thr)
            q, calls = self._draw_list(prog, render_list[start:start + int(count)], settings, thr, start=start,
                                       camera=camera, scene=scene, chord=settings.chord_px / (div * DETAIL_DIVISORS[k]),
                                       detail=k > 0)
            queries, draw_calls, start = queries + q, draw_calls + calls, start + int(count)
        triangles = sum(int(q.primitives) for q in queries)
        ctx.finish()
        t3 = time.perf_counter()

        frame, device_samples, written, resolve_ms = self._read_frame(tg, scene, aa.msaa, notes)
        nan_vertices = int(np.frombuffer(self._counters.read(4), np.uint32)[0])
        frame.stats = self._stats(ctx, (w, h), req, aa, settings, (tu, tv), n, list(notes))
        frame.stats.update({
            "msaa_samples_device": device_samples,
            "triangles": triangles,
            "detail_patches": [int(c) for c in counts],
            "draw_calls": draw_calls,
            "nan_vertices": nan_vertices,
            "pixels_written": written,
            "ms": {"setup": (t1 - t0) * 1e3, "render_list_upload": (t2 - t1) * 1e3, "draw": (t3 - t2) * 1e3,
                   "carry": 0.0, "resolve": resolve_ms, "readback": 0.0,   # paid on access
                   "total": (time.perf_counter() - t0) * 1e3},
        })
        return frame

    def _draw_hybrid(self, checked, scene, camera) -> Frame:
        """``draw`` of aa "hybrid" (docs/tessellation.md, "Hybrid anti-aliasing"): the render
        list ordered by tier (stable), then, coarse to fine, each tier's patches drawn into its
        targets with its thresholds, each finer tier's targets started from a per-sample copy of
        the last tier drawn (``GLTargets.carry``; with ``hybrid_targets`` "finest" every tier
        draws into the finest drawn tier's targets, without copies); the finest tier drawn is
        resolved. Tiers without patches are skipped, carries and targets included, so a frame
        whose patches are all tier 0 is the noAA frame.

        Stats: ``draw``'s, with "aa" and "aa_effective" "hybrid", samples per pixel, SSAA, MSAA
        and LOD divisor of the finest tier drawn (``tier_resolved``), and ``tiers``: per tier its
        "aa", "patches", "triangles" and "threshold"; ``ms["carry"]``: the carries (0 in other
        frames)."""
        settings, render_list, n, req, aa, notes, (tu, tv) = checked
        notes = list(notes)
        ctx = self.ctx
        t0 = time.perf_counter()
        modes = hybrid_tiers("tess", self.max_samples)
        divisors = (1.0, *(d for d, _ in tier_divisors(modes, settings.msaa_lod_for(aa))))
        tier = render_tiers(render_list[:n])
        counts = np.bincount(tier, minlength=len(modes))
        starts = np.cumsum(counts) - counts   # each tier's first record in the ordered list
        drawn = [k for k in range(len(modes)) if counts[k]] or [0]
        grid = self.tessellator(settings) == "grid"
        prog = build_programs(ctx, self.functions, settings.spacing, grid=grid)
        w, h = camera.size
        # each tier drawn into its own targets, or (hybrid_targets) into the finest drawn tier's
        shared = {"tiers": (), "pair": tuple(drawn[1:]), "finest": tuple(drawn)}[settings.hybrid_targets]
        finest = self._tier_targets_for(drawn[-1], (w, h), modes)
        targets = {k: finest if k in shared else self._tier_targets_for(k, (w, h), modes) for k in drawn}
        t1 = time.perf_counter()
        ordered = render_list[:n][np.argsort(tier, kind="stable")]
        self._upload(ordered, n, scene)
        t2 = time.perf_counter()

        set_uniform(prog, "u_view", gl_matrix(camera.view))
        set_uniform(prog, "u_proj", gl_matrix(camera.projection))
        set_uniform(prog, "u_near", float(camera.near))
        self._set_uniforms(prog, settings, (w, h), (tu, tv))
        tiers = [{"aa": m.name, "patches": int(c), "triangles": 0, "threshold": [tu / d, tv / d]}
                 for m, c, d in zip(modes, counts, divisors)]
        draw_calls, carry_s, draw_s, coarse = 0, 0.0, 0.0, None
        for k in drawn:
            tg = targets[k]
            if coarse is None:
                tg.begin(prog, scene.background)
            elif tg is not coarse:
                ta = time.perf_counter()
                tg.carry(coarse)
                ctx.finish()
                carry_s += time.perf_counter() - ta
            tb = time.perf_counter()
            set_uniform(prog, "u_threshold", tuple(tiers[k]["threshold"]))
            if settings.color_by == "tier":
                set_uniform(prog, "u_tier", k)
            ctx.enable(moderngl.DEPTH_TEST)
            ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)
            first = int(starts[k])
            queries, calls = self._draw_list(prog, ordered[first:first + int(counts[k])], settings,
                                             tuple(tiers[k]["threshold"]), start=first, camera=camera, scene=scene,
                                             chord=settings.chord_px / divisors[k],
                                             overlap_px=CARRY_OVERLAP_PX if tg is not finest else 0.0, detail=k > 0)
            tiers[k]["triangles"] = sum(int(q.primitives) for q in queries)
            draw_calls += calls
            ctx.finish()
            draw_s += time.perf_counter() - tb
            coarse = tg

        top = drawn[-1]
        frame, device_samples, written, resolve_ms = self._read_frame(coarse, scene, modes[top].msaa, notes)
        nan_vertices = int(np.frombuffer(self._counters.read(4), np.uint32)[0])
        frame.stats = self._stats(ctx, (w, h), modes[top], modes[top], settings, (tu, tv), n, notes)
        frame.stats.update({
            "aa": req.name,
            "aa_effective": aa.name,
            "lod_divisor": divisors[top],
            "tier_resolved": top,
            "tiers": tiers,
            "msaa_samples_device": device_samples,
            "triangles": sum(t["triangles"] for t in tiers),
            "draw_calls": draw_calls,
            "nan_vertices": nan_vertices,
            "pixels_written": written,
            "ms": {"setup": (t1 - t0) * 1e3, "render_list_upload": (t2 - t1) * 1e3, "draw": draw_s * 1e3,
                   "carry": carry_s * 1e3, "resolve": resolve_ms, "readback": 0.0,   # paid on access
                   "total": (time.perf_counter() - t0) * 1e3},
        })
        return frame

    def draw_views(self, render_list: np.ndarray, n: int | None, scene: Scene, views,
                   settings: TessSettings | None = None, threshold=None, view_masks=None) -> list[Frame]:
        """Draw ``n`` records of ``render_list`` (one LOD pass's list for all views) into every
        view of ``views`` (a Views, or Cameras of one size): one Frame per view, in order.
        ``settings.views_per_pass`` picks how (see TessSettings): a pass of the single-view
        program per view, or geometry-stage passes of up to 32 views each into layered targets.
        ``view_masks``: the views that see each patch (uint64, bit v: view v; the LOD stage's
        ``read_render_views``): with a pass per view, each view draws only the patches it sees.

        Each Frame's stats are ``draw``'s, with ``view`` (its index), ``views`` (their count),
        its own ``pixels_written`` and ``view_ms`` (its resolve and readback), and with a pass
        per view its own ``view_triangles`` (what its pass tessellated). ``triangles`` are the
        triangles sent to the rasterizer, summed over the views (past the geometry stage's
        per-view frustum cull when it draws several views a pass); ``render_patches``,
        ``nan_vertices`` (over all passes) and ``ms`` are the whole frame's.
        """
        views = as_views(views)
        checked = self._inputs(render_list, n, scene, settings, threshold)
        settings, render_list, n, req, aa, notes, (tu, tv) = checked
        if aa.hybrid:
            raise SceneError(HYBRID_VIEWS)
        ctx = self.ctx
        n_views = len(views)
        invocations, passes = view_chunks(n_views, min(settings.views_per_pass, self.max_invocations))
        if invocations == 1:
            return self._views_one_by_one(checked, scene, views, view_masks)
        t0 = time.perf_counter()
        prog = build_programs(ctx, self.functions, settings.spacing, invocations)
        w, h = views.size
        tg = self._layered_for((w, h), aa.ss, aa.msaa, n_views)
        t1 = time.perf_counter()
        self._upload(render_list, n, scene)
        records = np.zeros((MAX_VIEWS, VIEW_FLOATS), np.float32)
        for v, cam in enumerate(views):
            records[v, :16] = gl_matrix(cam.view).reshape(-1)
            records[v, 16:32] = gl_matrix(cam.projection).reshape(-1)
            records[v, 32] = cam.near
        self._views.write(records.tobytes())
        t2 = time.perf_counter()

        self._set_uniforms(prog, settings, (w, h), (tu, tv))
        tg.begin(prog)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)
        set_uniform(prog, "u_n_views", n_views)
        self._views.bind_to_uniform_block(0)
        queries, draw_calls = self._draw_list(prog, render_list[:n], settings, (tu, tv), range(0, n_views, invocations),
                                              lambda base: set_uniform(prog, "u_view_base", base))
        ctx.finish()
        t3 = time.perf_counter()

        drawn = [int(q.primitives) for q in queries]
        nan_vertices = int(np.frombuffer(self._counters.read(4), np.uint32)[0])
        shared = self._stats(ctx, (w, h), req, aa, settings, (tu, tv), n, notes)
        shared["tessellator"] = "hardware"   # a geometry stage after GL's tessellation stages
        shared.update({"triangles": sum(drawn), "draw_calls": draw_calls, "nan_vertices": nan_vertices,
                       "views": n_views, "views_per_pass": invocations, "passes": passes})
        frames, per_view = [], []
        for v in range(n_views):
            t4 = time.perf_counter()
            tg.resolve(v, scene.background)
            device_samples = tg.device_samples()   # waits; the layer's pixels written, by the count pass
            if v == 0 and device_samples != aa.msaa:
                notes.append(f"the device allocated {device_samples} samples per pixel for a {aa.msaa}-sample "
                             "request; coverage and the depth/id resolve use all of them")
            t5 = time.perf_counter()
            color, depth, normal, ids = tg.read()
            frame = Frame(color=color, depth=depth, normal=normal, object_id=ids)
            frame.background = scene.background
            t6 = time.perf_counter()   # readback, as draw's: to host arrays
            frames.append(frame)
            per_view.append({"view": v, "pixels_written": tg.pixels_written,
                             "view_ms": {"resolve": (t5 - t4) * 1e3, "readback": (t6 - t5) * 1e3}})
        t7 = time.perf_counter()
        ms = {"setup": (t1 - t0) * 1e3, "render_list_upload": (t2 - t1) * 1e3, "draw": (t3 - t2) * 1e3,
              "carry": 0.0, "resolve": sum(p["view_ms"]["resolve"] for p in per_view),
              "readback": sum(p["view_ms"]["readback"] for p in per_view), "total": (t7 - t0) * 1e3}
        shared["msaa_samples_device"] = device_samples
        for frame, own in zip(frames, per_view):
            frame.stats = dict(shared, **own, warnings=list(notes), ms=dict(ms))
        return frames

    def _views_one_by_one(self, checked, scene, views, view_masks=None) -> list[Frame]:
        """A pass of the single-view program per view, each drawn into the single-view targets,
        resolved and read back before the next; the scene's data are sent once. ``view_masks``
        (the LOD stage's render_views): each view draws only the patches it sees, so a cube face
        tessellates its own side. (A pass per view into layered targets made the multi-view
        frame slower than separate frames on the H200, 0.2-0.56x of their speed.)"""
        settings, render_list, n, req, aa, notes, thr = checked
        frames, sent = [], None
        for v, cam in enumerate(views):
            sees = None if view_masks is None else ((view_masks[:n] >> np.uint64(v)) & np.uint64(1)).astype(bool)
            whole = sees is None or sees.all()
            own = render_list[:n] if whole else render_list[:n][sees]
            key = "all" if whole else v   # which list the vertex buffer holds
            upload = "all" if sent is None else None if key == sent else "patches"
            frames.append(self._draw_one((settings, own, len(own), req, aa, notes, thr), scene, cam, upload))
            frames[-1].stats["view_patches"] = len(own)
            sent = key
        ms = {k: sum(f.stats["ms"][k] for f in frames) for k in frames[0].stats["ms"]}
        shared = {"views": len(frames), "views_per_pass": 1, "passes": len(frames), "render_patches": n,
                  "triangles": sum(f.stats["triangles"] for f in frames),
                  "draw_calls": sum(f.stats["draw_calls"] for f in frames),
                  # zeroed with the first upload, so the last view's count is every pass's
                  "nan_vertices": frames[-1].stats["nan_vertices"]}
        for v, f in enumerate(frames):
            own = f.stats["ms"]
            f.stats.update(shared, view=v, view_triangles=f.stats["triangles"], ms=dict(ms),
                           view_ms={"resolve": own["resolve"], "readback": own["readback"]})
        return frames


class Tessellation:
    """Per-scene state of the "tess" variant: the scene's device buffers, its LOD stage (thresholds
    divided by the effective AA mode's ``lod_divisor``; with aa "hybrid" they are tier 0's, and
    the stage sorts the patches into tiers) and the TessRenderer. CL -> GL goes through host
    memory, so a frame waits for the render list; the Frame is read back from GL."""

    def __init__(self, functions, record: bool = False):
        self.buffers = SceneBuffers(LIGHT)
        self.lod = LodStage(functions)
        self.tess = TessRenderer(functions)
        self.scene = self.dev = None

    def prepare(self, scene, camera, settings):
        """``camera``: a Camera, or a Views for a multi-view frame (a camera record per view)."""
        settings.tess.validate()
        settings.lod.validate()
        if isinstance(camera, Views) and parse_aa(settings.tess.aa).hybrid:
            raise SceneError(HYBRID_VIEWS)
        self.scene = scene
        t0 = time.perf_counter()
        self.dev = self.buffers.upload(scene, camera)
        self._upload_ms = (time.perf_counter() - t0) * 1e3

    def enqueue(self, camera, settings):
        """The Frame of ``camera``, or for a Views one Frame per view from one LOD pass for all."""
        t0 = time.perf_counter()
        _, aa, _ = self.tess.effective_aa(settings.tess.aa)
        div = aa.divisor(settings.tess.msaa_lod_for(aa))   # hybrid: 1, tier 0 is measured in output pixels
        d = self.dev
        multi = isinstance(camera, Views)
        if multi:
            _, n, steps, lod_ms = self.lod.run(d["inst"], d["domains"], d["cam"], settings.lod, t_div=div,
                                               n_views=len(camera), one_sided=d["one_sided"])
        else:
            tiers, lod = None, settings.lod
            if aa.hybrid:   # tiers 1 and 2's (threshold divisor, spot-check scale)
                tiers = tier_divisors(hybrid_tiers("tess", self.tess.max_samples), settings.tess.msaa_lod_for(aa))
            elif settings.tess.detail_levels:   # the spot check's tiers in this mode's targets
                tiers = tuple((div * d, d) for d in DETAIL_DIVISORS[1:])
                lod = replace(lod, spot_silhouettes=False)   # edges: a matter of anti-aliasing, not levels
            _, n, steps, lod_ms = self.lod.run(d["inst"], d["domains"], d["cam"], lod, t_div=div, tiers=tiers,
                                               one_sided=d["one_sided"])
        t1 = time.perf_counter()
        records = self.lod.read_render_list(n)
        masks = self.lod.read_render_views(n) if multi else None   # the views that see each patch
        t2 = time.perf_counter()
        tu, tv = (t / div for t in settings.lod.threshold)
        if multi:
            frames = self.tess.draw_views(records, n, self.scene, camera, settings.tess, threshold=(tu, tv),
                                          view_masks=masks)
        else:
            frames = [self.tess.draw(records, n, self.scene, camera, settings.tess, threshold=(tu, tv))]
        t3 = time.perf_counter()
        for frame in frames:
            ms = frame.stats["ms"]
            ms["render_list_read"] = (t2 - t1) * 1e3
            ms["render_list"] = ms["render_list_read"] + ms["render_list_upload"]
            ms["upload"] = self._upload_ms
            ms["lod"] = lod_ms
            ms["render"] = ms["draw"] + ms["carry"]   # carry: a hybrid frame's copies between tiers
            ms["frame"] = (t3 - t0) * 1e3 + self._upload_ms - ms["readback"]
            ms["total"] = (t3 - t0) * 1e3 + self._upload_ms
            frame.stats.update({
                "lod_device": cl_device().name,
                "lod_steps": steps,
                "forced_patches": sum(s["forced"] for s in steps),
                "render_list_bytes": int(n) * RENDER_DTYPE.itemsize,
            })
        return frames if multi else frames[0]


register_renderer(RendererSpec("tess", "parametric", Tessellation, "tess", "gl", TessSettings,
                               "OpenGL 4.5 hardware tessellation of the render patches, noAA/MSAA/SSAA/hybrid",
                               takes_aa="all", multiview=True))
