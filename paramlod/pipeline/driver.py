"""One frame: instance buffers -> LOD stage -> renderer -> resolve -> Frame."""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from paramlod.core.camera import Camera
from paramlod.device.context import cl_device
from paramlod.errors import SceneError
from paramlod.renderers.targets import Downsample, KeyBuffer
from paramlod.lod.stage import LOD_RENDER_TOTAL, LodSettings, LodStage
from paramlod.renderers.points import COUNTERS, DirectPointRenderer, PointSettings
from paramlod.renderers.points_lfb import LocalFramebufferRenderer, SsaaSettings
from paramlod.scene.scene import Scene
from paramlod.renderers.tess import TessSettings, parse_aa

VARIANTS = ("points", "points-ssaa", "tess")
# Key light in view space (towards the light: upper left, in front) and the ambient share.
LIGHT = np.array([*(np.array([-0.35, 0.5, 1.0]) / np.linalg.norm([-0.35, 0.5, 1.0])), 0.12], np.float32)


@dataclass
class RenderSettings:
    lod: LodSettings = field(default_factory=LodSettings)
    points: PointSettings = field(default_factory=PointSettings)
    ssaa: SsaaSettings = field(default_factory=SsaaSettings)   # the local-framebuffer variant
    tess: TessSettings = field(default_factory=TessSettings)   # levels, spacing, AA mode

    def apply_aa(self, mode, points_only: bool = False):
        """Anti-aliasing ``mode`` (e.g. "4xSS+8xMS") for both renderers: tess takes it whole, the
        points variant its supersampling. ``points_only``: the frame is drawn by the points
        variant alone, so multisampling is an error. Returns the parsed AAMode."""
        self.tess.aa = mode
        self.tess.validate()
        aa = parse_aa(mode)
        if points_only and aa.msaa > 1:
            raise SceneError(f"anti-aliasing {mode!r}: the points variant supersamples only (4xSS, 9xSS, "
                             f"16xSS); multisampling is a mode of the tess variant")
        self.points.supersample = aa.ss
        return aa


def camera_record(camera: Camera) -> np.ndarray:
    rec = np.zeros(36, np.float32)
    rec[0:16] = camera.view.reshape(-1)
    rec[16:32] = camera.projection.reshape(-1)
    rec[32:36] = [camera.width, camera.height, camera.near, camera.far]
    return rec


class Renderer:
    """Compiled programs and reusable buffers for one set of functions."""

    def __init__(self, functions, record: bool = False):
        self.functions = list(functions)
        # a scene of surfels only has no functions and needs no LOD stage
        self.lod = LodStage(self.functions) if self.functions else None
        self.points = DirectPointRenderer(self.functions, record=record) if self.functions else None
        self.ssaa: LocalFramebufferRenderer | None = None   # built on first use
        self._tess = None
        self.keys: KeyBuffer | None = None      # the frame's key buffers
        self.keys_ss: KeyBuffer | None = None   # supersampled ones of the direct variant
        self._downsample: dict[int, Downsample] = {}
        self._scene_key, self._scene_dev = None, None
        self._cam_buf = None   # the camera record, rewritten every frame
        self._cam_host = None

    def tess_renderer(self):
        """The tessellation renderer for these functions (OpenGL), created on first use."""
        if self._tess is None:
            from paramlod.renderers.tess import TessRenderer

            self._tess = TessRenderer(self.functions)
        return self._tess

    def upload(self, scene: Scene, camera: Camera):
        """Device copies of the scene's buffers (re-sent only when the scene or its time changed)
        and of this frame's camera (the camera the samples are projected with)."""
        import pyopencl as cl
        import pyopencl.array as cla

        q = cl_device().queue
        key = (scene._version, scene.time)
        if key != self._scene_key and self.lod is None:
            self._scene_dev = {"light": cla.to_device(q, LIGHT).data}
            self._scene_key = key
        if key != self._scene_key:
            inst_f, inst_u, params = scene.instance_buffers()
            self._scene_dev = {
                "inst": tuple(cla.to_device(q, a).data for a in (inst_f, inst_u, params)),
                "materials": cla.to_device(q, scene.materials()).data,
                "light": cla.to_device(q, LIGHT).data,
                "domains": inst_f[:, 28:32],
            }
            self._scene_key = key
        if self._cam_buf is None:
            self._cam_buf = cl.Buffer(cl_device().context, cl.mem_flags.READ_ONLY, 36 * 4)
        # not waited for: every frame ends with a wait, so the host copy is free to change then
        self._cam_host = camera_record(camera)
        cl.enqueue_copy(q, self._cam_buf, self._cam_host, is_blocking=False)
        return dict(self._scene_dev, cam=self._cam_buf)

    def targets(self, camera: Camera, ss: int) -> tuple[Camera, KeyBuffer]:
        """The camera to project with and the key buffers to draw into: the frame's, or with
        ``ss`` > 1 supersampled ones ``ss`` times its size (downsampled into the frame's)."""
        if self.keys is None or (self.keys.width, self.keys.height) != camera.size:
            self.keys = KeyBuffer(*camera.size)
        if ss == 1:
            return camera, self.keys
        size = (camera.width * ss, camera.height * ss)
        if max(size) > 16384:
            raise SceneError(f"points supersample {ss} at {camera.width}x{camera.height} needs "
                             f"{size[0]}x{size[1]} subsamples, more than 16384 a side; use a smaller "
                             f"factor or frame")
        if self.keys_ss is None or (self.keys_ss.width, self.keys_ss.height) != size:
            self.keys_ss = None   # free the old buffers before allocating the new ones
            self.keys_ss = KeyBuffer(*size)
        if ss not in self._downsample:
            self._downsample[ss] = Downsample(ss)
        return camera.with_size(size), self.keys_ss

    def render(self, scene: Scene, camera: Camera, settings: RenderSettings, variant: str = "points"):
        """One frame, copied to the host as a Frame (``render_on_device`` plus the read-back)."""
        stats = self.render_on_device(scene, camera, settings, variant)
        t0 = time.perf_counter()
        frame = self.keys.read_frame()
        readback = (time.perf_counter() - t0) * 1e3
        written = int(np.count_nonzero(np.isfinite(frame.depth)))
        stats["pixels_written"] = written
        drawn = written
        ss = stats["supersample"]
        if ss > 1:   # supersampled direct points: overdraw per covered subsample (alpha = coverage)
            drawn = stats["covered_subsamples"] = int(np.rint(frame.color[..., 3] * (ss * ss)).sum())
        stats["overdraw"] = stats["atomics"] / drawn if drawn else 0.0
        stats["ms"].update(readback=readback, total=stats["ms"]["frame"] + readback)
        frame.stats = stats
        frame.background = scene.background
        return frame

    def render_on_device(self, scene: Scene, camera: Camera, settings: RenderSettings,
                         variant: str = "points") -> dict:
        """One frame up to the resolved buffers on the device (``self.keys``), what an interactive
        viewer pays; returns its stats. The direct point variant enqueues the whole frame (LOD
        stage, render, resolve) and waits once at its end: the renderer reads the patch count on
        the device. If a LOD buffer overflowed, it grew and the frame is enqueued again.

        With ``settings.points.supersample`` > 1 the points variant (and surfels) draw into key
        buffers that many times the frame's size, seen by the same camera, which are then
        resolved block by block into the frame's (``framebuffer.Downsample``)."""
        t0 = time.perf_counter()
        settings.points.validate()
        ss = settings.points.supersample if variant == "points" else 1
        cam, target = self.targets(camera, ss)
        dev = self.upload(scene, cam)
        t_upload = time.perf_counter()
        host = 0.0   # Python time spent enqueueing (the rest of the frame is waiting)
        direct = self.lod is not None and variant == "points"
        while True:
            t1 = time.perf_counter()
            target.clear()
            if direct:
                self.lod.enqueue(dev["inst"], dev["domains"], dev["cam"], settings.lod)
                self.points.enqueue(self.lod.render.buf, self.lod.counters, LOD_RENDER_TOTAL,
                                    self.lod.render.capacity, dev["inst"], dev["materials"], dev["cam"],
                                    dev["light"], target, settings.points)
            elif self.lod is not None:   # points-ssaa needs the patch count on the host
                self.lod.enqueue(dev["inst"], dev["domains"], dev["cam"], settings.lod,
                                 t_div=settings.ssaa.lod_divisor)
                host += time.perf_counter() - t1
                self.lod.read_counters()
                t1 = time.perf_counter()
                if self.lod.grow(settings.lod):
                    continue
                if self.ssaa is None:
                    self.ssaa = LocalFramebufferRenderer(self.functions)
                ssaa_t0 = time.perf_counter()
                counters = self.ssaa.draw(self.lod.render.buf, self.lod.result()[0], dev["inst"],
                                          dev["materials"], dev["cam"], dev["light"], self.keys, settings.ssaa)
                ssaa_ms = (time.perf_counter() - ssaa_t0) * 1e3   # it waits for its scan and bins
            surfel_stats = self.draw_surfels(scene, cam, target)
            downsampled = self._downsample[ss].enqueue(target, self.keys) if ss > 1 else None
            resolved = self.keys.resolve_on_device()
            host += time.perf_counter() - t1
            if direct:
                self.lod.read_counters()   # the frame's one wait
            resolved.wait()
            if not (direct and self.lod.grow(settings.lod)):
                break
        n_render, steps, render_ms = 0, [], 0.0
        if direct:
            counters, render_ms = self.points.counts(), self.points.device_ms()
        elif self.lod is not None:
            render_ms = ssaa_ms
        else:
            counters = {k: 0 for k in COUNTERS}
        if self.lod is not None:
            n_render, steps = self.lod.result()
        t4 = time.perf_counter()
        lod_ms = self.lod.device_ms() if self.lod is not None else 0.0
        return {
            "device": cl_device().name,
            "variant": variant,
            "size": list(camera.size),
            "supersample": ss,
            "lod_steps": steps,
            "render_patches": n_render,
            "forced_patches": sum(s["forced"] for s in steps),
            **counters,
            "surfels": surfel_stats,
            # "frame" is the work of a frame up to resolved buffers on the device (what an
            # interactive viewer pays); render() adds "readback", the copy to the host.
            # "lod", "resolve" and the direct variant's "render" are device times of those
            # kernels (points-ssaa's "render" is wall time: it waits inside); "host" is the
            # Python time spent preparing and enqueueing the frame.
            "ms": {"upload": (t_upload - t0) * 1e3, "lod": lod_ms, "render": render_ms,
                   "resolve": _event_ms(resolved) + (_event_ms(downsampled) if ss > 1 else 0.0),
                   "host": (t_upload - t0 + host) * 1e3,
                   "frame": (t4 - t0) * 1e3},
        }

    def draw_surfels(self, scene: Scene, camera: Camera, keys: KeyBuffer) -> list[dict]:
        """Splat each surfel object's prefix into the same key buffer (composed by depth)."""
        if not scene.surfels:
            return []
        from paramlod.surfels.render import draw_surfels

        return [draw_surfels(keys, camera, so.surfels, so.strategy, so.transform, so.object_id, so.specular)
                for so in scene.surfels]


def _event_ms(evt) -> float:
    return (evt.profile.end - evt.profile.start) * 1e-6


_renderers: dict[tuple, Renderer] = {}


def renderer_for(scene: Scene) -> Renderer:
    funcs = scene.functions()
    key = tuple(id(f) for f in funcs)
    r = _renderers.get(key)
    if r is None:
        r = _renderers[key] = Renderer(funcs)
    return r


def render(scene: Scene, camera: Camera, variant: str = "points", settings: RenderSettings | None = None,
           time: float | None = None):
    """Render ``scene`` seen by ``camera``; returns a Frame (colour, depth, normal, ids, stats).

    ``time`` sets ``scene.time``, the value of the implicit parameter ``t`` of animated functions.
    """
    if variant not in VARIANTS:
        raise SceneError(f"unknown variant '{variant}' (available: {', '.join(VARIANTS)})")
    if not scene.objects and not scene.surfels:
        raise SceneError("the scene has no objects; add one with scene.add(...) or scene.add_surfels(...)")
    if time is not None:
        scene.time = float(time)
    settings = settings or RenderSettings()
    if variant == "tess":
        from paramlod.renderers.tess import render_tess

        if not scene.surfels:
            return render_tess(scene, camera, settings.tess, settings.lod)
        # surfels are points: draw them with the point path and composite by depth
        from paramlod.pipeline.composite import composite, subscene

        frames = [render(subscene(scene, [], scene.surfels), camera, "points", settings)]
        if scene.objects:
            parametric = subscene(scene, scene.objects)
            frames.insert(0, render_tess(parametric, camera, settings.tess, settings.lod))
        return composite(frames, background=scene.background)
    return renderer_for(scene).render(scene, camera, settings, variant)
