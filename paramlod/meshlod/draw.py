"""The meshlets-gl draw: the clusters the cut selected, drawn by OpenGL 4.5 with indirect draws, into
the renderers kit's GL targets (paramlod.renderers.gl_targets: noAA, MSAA, SSAA or both, resolved
to a Frame like the tess variant's, so paramlod.pipeline.composite merges the two).

Driven per scene state: ``MeshDraw.upload(arrays, instances)`` when the scene's meshes or instances
change, then ``MeshDraw.draw(selection, camera, ...)`` every frame with the cut's (instance,
cluster) pairs read back from the device. Its OpenCL counterpart is the meshlets rasterizer; both
draw the same selection with the same shading body (kernels/common/shading.cl) and debug colours
(kernels/common/debug_color.cl).

One draw command per selected pair k: (count = 3 * the cluster's triangles, instanceCount = 1,
firstIndex = 3 * its first triangle, baseVertex = 0, baseInstance = k), all issued by one
glMultiDrawElementsIndirect over the scene's global index buffer. baseInstance = k rather than
the instance index because an instanced attribute of divisor 1 over the selection buffer then
reads the command's own (instance, cluster) pair in core GL >= 4.2, with no extension (llvmpipe
and NVIDIA both have ARB_shader_draw_parameters, but a per-draw cluster index would still need a
second lookup); the instance's records and the cluster's level come from storage buffers.
Shaders: kernels/meshlod/mesh_{common,vertex,fragment}.glsl.

Hand-off weights (paramlod.scene.handoff) reach the fragment stage per object id (a storage buffer
of MAX_OBJECT_IDS floats): a hand-off mesh is one instance of its own object, so per object is per
instance; the fragment stage keeps the pixels whose dither is below the weight, on the target's
own grid (subsamples with SSAA). The pixels complement the surfels' exactly when the surfels' key
buffers have that grid too (noAA or MSAA with points supersample 1; 4xSS on both).

Multi-view frames (``MeshDraw.draw_views``): the same indirect draw of the one selection, with the
cut's view masks as a second instanced attribute, is amplified at the latest stage: the vertex
stage works in world space (kernels/meshlod/mesh_views_vertex.glsl) and an instanced geometry
stage (mesh_views_geometry.glsl, VIEWS_PER_DRAW invocations, one draw per chunk of that many views)
projects each triangle into view ``base + gl_InvocationID``, skips the views the mask leaves out
and those whose frustum it misses, and sets ``gl_Layer``; the targets are layered (a layer per
view, paramlod.renderers.gl_targets.LayeredGLTargets) and resolved and read back layer by layer
into one Frame per view. One view is ``draw``, with its programs unchanged.
"""
from __future__ import annotations

import math
import time
import warnings

import moderngl
import numpy as np

from paramlod import kernels
from paramlod.core.camera import Camera
from paramlod.core.frame import Frame, FrameStats
from paramlod.core.layouts import INSTANCE_U, glsl_prelude
from paramlod.core.views import MAX_VIEWS, Views
from paramlod.device.context import gl_cache, gl_context
from paramlod.device.programs import GLSL_LINE, check_block, context_lines, set_uniform
from paramlod.errors import DeviceError, MeshError
from paramlod.meshlod.buffers import MeshArrays, MeshInstances
from paramlod.renderers.gl_targets import (GLTargets, GrowBuffer, LayeredGLTargets, effective_aa, gl_matrix,
                                           srgb8_defines, targets_for)
from paramlod.renderers.shading import LIGHT

COLOR_BY = {0: "material", 1: "cluster", 2: "level"}
MAX_OBJECT_IDS = 4096   # object ids are 12 bits (paramlod.scene.scene.MAX_OBJECTS + 1)
COMMAND_DTYPE = np.dtype([("count", np.uint32), ("instances", np.uint32), ("first", np.uint32),
                          ("base_vertex", np.int32), ("base_instance", np.uint32)])   # DrawElementsIndirectCommand
# views per draw of a multi-view frame: the geometry stage's invocations (GL allows 32), more views
# taking a draw per chunk of this many. On an H200 (1080p, 48 views of 0.5 M triangles) 16 per draw
# drew in 200 ms, 8 in 207, 4 in 213 and 32 in 309
VIEWS_PER_DRAW = 16
VIEW_RECORD = 2 * 16 * 4   # std140 PlView (kernels/meshlod/mesh_common.glsl): view, proj matrices


def draw_program(ctx, color_by: int, views_per_draw: int = 0):
    """The draw program for debug colouring ``color_by`` (and ``views_per_draw`` geometry-stage
    invocations for a multi-view draw; 0: the one-view program), cached with the GL context."""
    programs = gl_cache(ctx).setdefault("meshlod_draw_programs", {})
    key = color_by if not views_per_draw else (color_by, views_per_draw)
    prog = programs.get(key)
    if prog is None:
        head = f"#version 450 core\n#define PL_COLOR_BY {color_by}\n"
        if views_per_draw:
            head += f"#define PL_VIEWS 1\n#define PL_VIEWS_PER_DRAW {views_per_draw}\n#define PL_MAX_VIEWS {MAX_VIEWS}\n"
        common = [glsl_prelude(), kernels.source("meshlod/mesh_common.glsl")]
        # the debug colours are snippet dialect: the dialect first, then them, then the stage
        debug = [kernels.source("common/dialect.glsl"), kernels.source("common/debug_color.cl")] if color_by else []
        vertex = "meshlod/mesh_views_vertex.glsl" if views_per_draw else "meshlod/mesh_vertex.glsl"
        stages = {"vertex_shader": head + "\n".join([*common, kernels.source(vertex)]),
                  "fragment_shader": head + srgb8_defines(ctx) + "\n".join([*common, *debug,
                                                                             kernels.source("meshlod/mesh_fragment.glsl")])}
        if views_per_draw:
            stages["geometry_shader"] = head + "\n".join([*common, kernels.source("meshlod/mesh_views_geometry.glsl")])
        try:
            prog = ctx.program(**stages)
        except moderngl.Error as exc:
            log = str(exc)
            stage = next((k for k in stages if k in log), "fragment_shader")
            raise DeviceError(f"the mesh draw's shaders do not compile on {ctx.info.get('GL_RENDERER')} "
                              f"({stage}):\n{context_lines(stages[stage], log, GLSL_LINE)}\n"
                              f"compiler said:\n{log[-2000:]}") from None
        check_block(prog, "PlViews", MAX_VIEWS * VIEW_RECORD, "kernels/meshlod/mesh_common.glsl")
        programs[key] = prog
    return prog


class MeshDraw:
    """GL buffers of one scene's meshes and instances, and the per-frame draw of a selection."""

    def __init__(self):
        self.ctx = gl_context()
        self.arrays: MeshArrays | None = None
        self.instances: MeshInstances | None = None
        self._targets: GLTargets | None = None
        self._layered: LayeredGLTargets | None = None
        self._picks = GrowBuffer(self.ctx, 1024)
        self._commands = GrowBuffer(self.ctx, 1024)
        self._masks = GrowBuffer(self.ctx, 1024)   # the view masks of a multi-view draw
        self._views = self.ctx.buffer(reserve=MAX_VIEWS * VIEW_RECORD)   # its PlViews block
        self._weights_host = np.ones(MAX_OBJECT_IDS, np.float32)
        self._weights = self.ctx.buffer(self._weights_host.tobytes())
        self._static: list = []
        self._vaos: dict = {}

    # --- scene data -------------------------------------------------------------------------
    def upload(self, arrays: MeshArrays, instances: MeshInstances) -> None:
        """Copy the scene's packed meshes and instances into GL buffers (vertex, index and storage
        buffers); call again when they change."""
        if not isinstance(arrays, MeshArrays) or not isinstance(instances, MeshInstances):
            raise MeshError("MeshDraw.upload needs a paramlod.meshlod.buffers.MeshArrays and a MeshInstances "
                            f"(MeshArrays.pack / MeshInstances.pack), got {type(arrays).__name__} and "
                            f"{type(instances).__name__}")
        if len(instances) and int(instances.inst_u[:, INSTANCE_U.offset("func")].max()) >= len(arrays.ranges):
            raise MeshError(f"MeshDraw.upload: an instance names mesh {int(instances.inst_u[:, 0].max())} but the "
                            f"MeshArrays hold {len(arrays.ranges)} meshes; pack both from the same scene")
        self._release_static()
        ctx = self.ctx

        def buf(a):
            a = np.ascontiguousarray(a)
            return ctx.buffer(a.tobytes() if a.nbytes else bytes(16))

        try:
            self._vertices = buf(arrays.vertices.astype(np.float32, copy=False))
            self._normals = buf(arrays.normals.astype(np.float32, copy=False))
            self._indices = buf(arrays.triangles.astype(np.uint32, copy=False).reshape(-1))
            self._inst_f = buf(instances.inst_f.astype(np.float32, copy=False))
            self._inst_u = buf(instances.inst_u.astype(np.uint32, copy=False))
            self._materials = buf(instances.materials.astype(np.float32, copy=False))
            self._clusters = buf(arrays.clusters)
        except Exception as exc:   # moderngl.Error: out of memory
            self._release_static()
            raise MeshError(f"the scene's meshes ({arrays.nbytes / 2**20:.1f} MiB) do not fit the OpenGL device's "
                            f"memory: {exc}; draw fewer or smaller meshes") from None
        self._static = [self._vertices, self._normals, self._indices, self._inst_f, self._inst_u,
                        self._materials, self._clusters]
        # per cluster, the command's index count and first index: a frame only gathers them
        self._index_count = (3 * arrays.clusters["count"]).astype(np.uint32)
        self._index_first = (3 * arrays.clusters["first"]).astype(np.uint32)
        self.arrays, self.instances = arrays, instances

    def write_vertices(self, first: int, vertices: np.ndarray, normals: np.ndarray) -> None:
        """Overwrite vertices [first, first + n) of the uploaded meshes (float32 [n, 4] each): a
        skinned mesh's pose of this frame (paramlod.meshlod.skin)."""
        if self.arrays is None:
            raise MeshError("MeshDraw.write_vertices before upload")
        v = np.ascontiguousarray(vertices, np.float32)
        n = np.ascontiguousarray(normals, np.float32)
        if v.shape != n.shape or v.ndim != 2 or v.shape[1] != 4 or not 0 <= first <= len(self.arrays.vertices) - len(v):
            raise MeshError(f"MeshDraw.write_vertices: {v.shape} vertices at {first} do not fit the "
                            f"{len(self.arrays.vertices)} uploaded")
        if len(v):
            self._vertices.write(v.tobytes(), offset=16 * int(first))
            self._normals.write(n.tobytes(), offset=16 * int(first))

    def _release_static(self):
        for vao in self._vaos.values():
            vao.release()
        self._vaos.clear()
        for b in self._static:
            b.release()
        self._static = []

    def release(self):
        """Give back every GL object (the draw cannot be used afterwards)."""
        self._release_static()
        for b in (self._picks, self._commands, self._masks):
            b.buf.release()
        self._weights.release()
        self._views.release()
        for name in ("_targets", "_layered"):
            if getattr(self, name) is not None:
                getattr(self, name).release()
                setattr(self, name, None)

    def _vao(self, prog, views: bool = False):
        key = (id(prog), self._picks.generation, self._masks.generation if views else -1)
        vao = self._vaos.get(key)
        if vao is None:
            for k in [k for k in self._vaos if k[0] == id(prog)]:   # made for a released pick buffer
                self._vaos.pop(k).release()
            attributes = [(self._vertices, "4f", "in_position"), (self._normals, "4f", "in_normal"),
                          (self._picks.buf, "2u/i", "in_pick")]
            if views:   # the pair's ulong view mask as two uints
                attributes.append((self._masks.buf, "2u/i", "in_views"))
            vao = self._vaos[key] = self.ctx.vertex_array(prog, attributes, index_buffer=self._indices,
                                                          index_element_size=4)
        return vao

    # --- a frame ----------------------------------------------------------------------------
    def _object_weights(self, weights) -> np.ndarray:
        """float32 [MAX_OBJECT_IDS]: the weight of each object id from per-instance ``weights``."""
        table = np.ones(MAX_OBJECT_IDS, np.float32)
        if weights is None:
            return table
        try:
            w = np.asarray(weights, np.float32).reshape(-1)
        except (TypeError, ValueError):
            raise MeshError("MeshDraw.draw: weights must be numbers in [0, 1], one per uploaded instance") from None
        if len(w) != len(self.instances) or not np.all((w >= 0) & (w <= 1)):
            raise MeshError(f"MeshDraw.draw: weights must be {len(self.instances)} numbers in [0, 1] (one per "
                            f"uploaded instance, MeshInstances.weights), got {len(w)}")
        ids = self.instances.inst_u[:, INSTANCE_U.offset("object")] & (MAX_OBJECT_IDS - 1)
        table[ids] = w
        if not np.array_equal(table[ids], w):
            raise MeshError("MeshDraw.draw: instances of one object have different weights; the GL draw takes one "
                            "weight per object (a hand-off mesh is one instance of its own object)")
        return table

    def _check(self, selection, camera, color_by, light, background):
        if self.arrays is None:
            raise MeshError("MeshDraw.draw before MeshDraw.upload: upload the scene's MeshArrays and MeshInstances first")
        if not isinstance(camera, Camera):
            raise MeshError(f"MeshDraw.draw needs a paramlod Camera, got {type(camera).__name__}")
        if color_by not in COLOR_BY:
            raise MeshError(f"color_by must be 0 (material), 1 (per cluster) or 2 (per LOD level), got {color_by!r}")
        sel = np.asarray(selection)
        if sel.size == 0:
            sel = sel.reshape(0, 2)
        if sel.ndim != 2 or sel.shape[1] != 2 or not np.issubdtype(sel.dtype, np.integer):
            raise MeshError(f"the selection must be an integer array of (instance, cluster) pairs, shape [n, 2]; "
                            f"got {sel.dtype} of shape {sel.shape}")
        if sel.size and (sel.min() < 0 or sel.max() >= 2 ** 32):
            raise MeshError("the selection holds negative or over 32-bit indices; it must be the cut's uint32 pairs")
        sel = np.ascontiguousarray(sel, np.uint32)
        inst, clus = sel[:, 0], sel[:, 1]
        if len(sel):
            if int(inst.max()) >= len(self.instances):
                raise MeshError(f"the selection names instance {int(inst.max())} but {len(self.instances)} were "
                                "uploaded; was the cut made for this scene?")
            if int(clus.max()) >= len(self.arrays.clusters):
                raise MeshError(f"the selection names cluster {int(clus.max())} but the meshes have "
                                f"{len(self.arrays.clusters)}; was the cut made for this scene?")
            r = self.arrays.ranges[self.instances.inst_u[inst, INSTANCE_U.offset("func")]]
            wrong = (clus < r[:, 0]) | (clus >= r[:, 0] + r[:, 1])
            if wrong.any():
                k = int(np.flatnonzero(wrong)[0])
                raise MeshError(f"selection pair {k} draws cluster {int(clus[k])} with instance {int(inst[k])}, "
                                "whose mesh does not own that cluster; was the cut made for this scene?")
        light = LIGHT if light is None else tuple(float(x) for x in light)
        if len(light) != 4 or not all(math.isfinite(x) for x in light):
            raise MeshError(f"light must be (towards x, y, z, ambient) as paramlod.renderers.shading.LIGHT, got {light!r}")
        background = tuple(float(x) for x in background)
        if len(background) != 3:
            raise MeshError(f"background must be linear RGB (r, g, b), got {background!r}")
        return sel, light, background

    def _begin(self, selection, camera, aa, color_by, light, background, weights):
        """What every frame does first: check the input and the AA mode. (sel, light, background,
        the weight of each object id, (requested, effective, notes) AA)."""
        sel, light, background = self._check(selection, camera, color_by, light, background)
        table = self._object_weights(weights)
        req, eff, notes = effective_aa(self.ctx, "noAA" if aa is None else aa)
        for msg in notes:
            warnings.warn(msg, RuntimeWarning, stacklevel=3)
        return sel, light, background, table, (req, eff, notes)

    def _upload(self, sel, table) -> np.ndarray:
        """Write the frame's draw commands, picks and object weights; returns the commands."""
        n = len(sel)
        cmd = np.zeros(n, COMMAND_DTYPE)
        cmd["count"] = self._index_count[sel[:, 1]]
        cmd["instances"] = 1
        cmd["first"] = self._index_first[sel[:, 1]]
        cmd["base_instance"] = np.arange(n, dtype=np.uint32)
        self._picks.write(sel.tobytes())
        self._commands.write(cmd.tobytes())
        if not np.array_equal(table, self._weights_host):
            self._weights.write(table.tobytes())
            self._weights_host = table
        return cmd

    def _bind(self, prog, light, rows: int):
        """The uniforms and storage buffers the draw programs share; depth test on, two-sided."""
        ctx = self.ctx
        set_uniform(prog, "u_light", light)
        set_uniform(prog, "u_rows", rows)
        for binding, b in enumerate((self._inst_f, self._inst_u, self._materials, self._clusters, self._weights)):
            b.bind_to_storage_buffer(binding)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)   # two-sided

    def _stats(self, size, aa, color_by, cmd, triangles, written, device_samples, ms) -> dict:
        req, eff, notes = aa
        if device_samples != eff.msaa:
            notes = notes + [f"the device allocated {device_samples} samples per pixel for a {eff.msaa}-sample "
                             "request; coverage and the depth/id resolve use all of them"]
        n = len(cmd)
        return {
            "device": self.ctx.info.get("GL_RENDERER"),
            "variant": "meshlets-gl",
            "size": list(size),
            "aa": req.name,
            "aa_effective": eff.name,
            "msaa_requested": req.msaa,
            "msaa_samples": eff.msaa,
            "msaa_samples_device": device_samples,
            "ssaa": eff.ss,
            "supersample": eff.ss,
            "samples_per_pixel": eff.samples_per_pixel,
            "color_by": COLOR_BY[int(color_by)],
            "clusters": n,
            "triangles_selected": int(cmd["count"].sum(dtype=np.int64)) // 3,
            "triangles": triangles,
            "draw_calls": 1 if n else 0,
            "draw_commands": n,
            "pixels_written": written,
            "warnings": list(notes),
            "ms": ms,
        }

    def draw(self, selection: np.ndarray, camera: Camera, aa: str | None = None, color_by: int = 0,
             light=None, background=(0.0, 0.0, 0.0), weights=None) -> Frame:
        """Draw the (instance, cluster) pairs of ``selection`` (uint32 [n, 2], the cut's output)
        seen by ``camera`` with anti-aliasing ``aa`` (paramlod.renderers.aa.parse_aa; None =
        noAA); ``color_by`` 0/1/2 colours by material, cluster or LOD level; ``light`` is the
        light record (default paramlod.renderers.shading.LIGHT); ``weights``: the instances'
        hand-off weights (MeshInstances.weights; None: all 1). Returns a host Frame."""
        sel, light, background, table, aa_ = self._begin(selection, camera, aa, color_by, light, background, weights)
        eff = aa_[1]
        ctx = self.ctx
        t0 = time.perf_counter()
        prog = draw_program(ctx, int(color_by))
        w, h = camera.size
        tg, self._targets = self._targets, None   # not kept when making new ones fails
        tg = self._targets = targets_for(tg, ctx, (w, h), eff.ss, eff.msaa, "mesh draw")
        t1 = time.perf_counter()
        cmd = self._upload(sel, table)
        t2 = time.perf_counter()

        set_uniform(prog, "u_view", gl_matrix(camera.view))
        set_uniform(prog, "u_proj", gl_matrix(camera.projection))
        self._bind(prog, light, int(h * eff.ss))
        tg.begin(prog, background)
        n = len(sel)
        triangles = 0
        if n:
            query = ctx.query(primitives=True)
            with query:
                self._vao(prog).render_indirect(self._commands.buf, mode=moderngl.TRIANGLES, count=n)
            triangles = int(query.primitives)
        ctx.finish()
        t3 = time.perf_counter()
        device_samples = tg.resolve(background)
        t4 = time.perf_counter()
        frame = tg.frame()   # read back lazily: the image alone when only it is asked for
        ms = {"setup": (t1 - t0) * 1e3, "upload": (t2 - t1) * 1e3, "render": (t3 - t2) * 1e3,
              "draw": (t3 - t2) * 1e3, "resolve": (t4 - t3) * 1e3, "readback": 0.0,
              "frame": (t4 - t0) * 1e3, "total": (t4 - t0) * 1e3}
        frame.stats = FrameStats(self._stats((w, h), aa_, color_by, cmd, triangles, tg.pixels_written,
                                             device_samples, ms))
        return frame

    def draw_views(self, selection: np.ndarray, masks: np.ndarray, views: Views, aa: str | None = None,
                   color_by: int = 0, light=None, background=(0.0, 0.0, 0.0), weights=None) -> list[Frame]:
        """``draw`` for every view of ``views`` (a paramlod.core.views.Views) from one selection:
        ``masks`` (uint64 per pair, the cut's view masks: bit v draws the pair into view v;
        Selection.read_masks). Returns one host Frame per view; its stats are the whole draw's
        (``triangles``: emitted into all views; ``ms`` setup, upload, draw) but for
        ``pixels_written`` and the times of its own resolve and read-back."""
        if not isinstance(views, Views):
            raise MeshError(f"MeshDraw.draw_views needs a paramlod.core.views.Views, got {type(views).__name__}")
        sel, light, background, table, aa_ = self._begin(selection, views[0], aa, color_by, light, background, weights)
        m = np.asarray(masks)
        if m.shape != (len(sel),) or not np.issubdtype(m.dtype, np.unsignedinteger):
            raise MeshError(f"MeshDraw.draw_views: masks must be one unsigned view mask per selected pair "
                            f"({len(sel)}), got {m.dtype} of shape {m.shape}")
        eff = aa_[1]
        ctx = self.ctx
        n_views = len(views)
        per_draw = min(n_views, VIEWS_PER_DRAW)
        t0 = time.perf_counter()
        prog = draw_program(ctx, int(color_by), per_draw)
        w, h = views.size
        tg, self._layered = self._layered, None   # not kept when making new ones fails
        tg = self._layered = targets_for(tg, ctx, (w, h), eff.ss, eff.msaa, "multi-view mesh draw", layers=n_views)
        t1 = time.perf_counter()
        cmd = self._upload(sel, table)
        self._masks.write(np.ascontiguousarray(m, np.uint64).tobytes())
        records = np.zeros((MAX_VIEWS, 2, 4, 4), np.float32)
        for v, cam in enumerate(views):
            records[v] = gl_matrix(cam.view), gl_matrix(cam.projection)
        self._views.write(records.tobytes())
        t2 = time.perf_counter()

        self._bind(prog, light, int(h * eff.ss))
        set_uniform(prog, "u_n_views", n_views)
        self._views.bind_to_uniform_block(0)
        tg.begin(prog)
        n = len(sel)
        triangles = 0
        if n:
            query = ctx.query(primitives=True)
            vao = self._vao(prog, views=True)
            with query:
                for base in range(0, n_views, per_draw):
                    set_uniform(prog, "u_base", base)
                    vao.render_indirect(self._commands.buf, mode=moderngl.TRIANGLES, count=n)
            triangles = int(query.primitives)
        ctx.finish()
        t3 = time.perf_counter()
        frames = []
        for v in range(n_views):
            t4 = time.perf_counter()
            tg.resolve(v, background)
            device_samples = tg.device_samples()   # waits for the resolve
            t5 = time.perf_counter()
            color, depth, normal, ids = tg.read()
            t6 = time.perf_counter()
            ms = {"setup": (t1 - t0) * 1e3, "upload": (t2 - t1) * 1e3, "render": (t3 - t2) * 1e3,
                  "draw": (t3 - t2) * 1e3, "resolve": (t5 - t4) * 1e3, "readback": (t6 - t5) * 1e3,
                  "frame": (t3 - t0 + t5 - t4) * 1e3, "total": (t6 - t0) * 1e3}
            stats = FrameStats(self._stats((w, h), aa_, color_by, cmd, triangles, tg.pixels_written,
                                           device_samples, ms))
            frames.append(Frame(color=color, depth=depth, normal=normal, object_id=ids, stats=stats,
                                background=background))
        return frames
