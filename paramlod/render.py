"""One frame: instance buffers -> LOD stage -> renderer -> resolve -> Frame."""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .camera import Camera
from .device import cl_device
from .errors import SceneError
from .framebuffer import KeyBuffer
from .lod import LodSettings, LodStage
from .points import DirectPointRenderer, PointSettings
from .scene import Scene

VARIANTS = ("points",)
# Key light in view space (towards the light: upper left, in front) and the ambient share.
LIGHT = np.array([*(np.array([-0.35, 0.5, 1.0]) / np.linalg.norm([-0.35, 0.5, 1.0])), 0.12], np.float32)


@dataclass
class RenderSettings:
    lod: LodSettings = field(default_factory=LodSettings)
    points: PointSettings = field(default_factory=PointSettings)


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
        self.lod = LodStage(self.functions)
        self.points = DirectPointRenderer(self.functions, record=record)
        self.keys: KeyBuffer | None = None
        self._scene_key, self._scene_dev = None, None

    def upload(self, scene: Scene, camera: Camera):
        """Device copies of the scene's buffers (re-sent only when the scene or its time changed)
        and of this frame's camera."""
        import pyopencl.array as cla

        q = cl_device().queue
        key = (id(scene), scene._version, scene.time)
        if key != self._scene_key:
            inst_f, inst_u, params = scene.instance_buffers()
            self._scene_dev = {
                "inst": tuple(cla.to_device(q, a).data for a in (inst_f, inst_u, params)),
                "materials": cla.to_device(q, scene.materials()).data,
                "light": cla.to_device(q, LIGHT).data,
                "domains": inst_f[:, 28:32],
                "count": len(inst_f),
            }
            self._scene_key = key
        dev = dict(self._scene_dev, cam=cla.to_device(q, camera_record(camera)).data)
        if self.keys is None or (self.keys.width, self.keys.height) != camera.size:
            self.keys = KeyBuffer(*camera.size)
        return dev

    def render(self, scene: Scene, camera: Camera, settings: RenderSettings):
        t0 = time.perf_counter()
        dev = self.upload(scene, camera)
        t1 = time.perf_counter()
        rbuf, n_render, steps, lod_ms = self.lod.run(dev["inst"], dev["count"], dev["domains"],
                                                     dev["cam"], settings.lod)
        t2 = time.perf_counter()
        self.keys.clear()
        counters = self.points.draw(rbuf, n_render, dev["inst"], dev["materials"], dev["cam"],
                                    dev["light"], self.keys, settings.points)
        cl_device().queue.finish()
        t3 = time.perf_counter()
        self.keys.resolve_on_device()
        cl_device().queue.finish()
        t4 = time.perf_counter()
        frame = self.keys.read_frame()
        t5 = time.perf_counter()
        written = int(np.count_nonzero(np.isfinite(frame.depth)))
        frame.stats = {
            "device": cl_device().name,
            "variant": "points",
            "size": list(camera.size),
            "lod_steps": steps,
            "render_patches": n_render,
            "forced_patches": sum(s["forced"] for s in steps),
            **counters,
            "pixels_written": written,
            "overdraw": counters["atomics"] / written if written else 0.0,
            # "frame" is the work of a frame up to resolved buffers on the device (what an
            # interactive viewer pays); "readback" copies them to the host for the Frame.
            "ms": {"upload": (t1 - t0) * 1e3, "lod": lod_ms, "render": (t3 - t2) * 1e3,
                   "resolve": (t4 - t3) * 1e3, "frame": (t4 - t0) * 1e3, "readback": (t5 - t4) * 1e3,
                   "total": (t5 - t0) * 1e3},
        }
        frame.background = scene.background
        return frame


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
    if not scene.objects:
        raise SceneError("the scene has no objects; add one with scene.add(...)")
    if time is not None:
        scene.time = float(time)
    return renderer_for(scene).render(scene, camera, settings or RenderSettings())
