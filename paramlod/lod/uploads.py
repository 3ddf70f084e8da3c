"""Device copies of a scene's parametric instance buffers and of each frame's camera records:
what the LOD stage and the parametric renderers read (per scene; re-sent only when the scene or
its time changed). A multi-view frame (a ``paramlod.core.views.Views``) sends one camera record
per view, one after another."""
from __future__ import annotations

import pyopencl as cl
import pyopencl.array as cla

from paramlod.core.views import as_views
from paramlod.device.context import cl_device


class SceneBuffers:
    def __init__(self, light):
        self.light = light            # the shading record (paramlod.renderers.shading.LIGHT)
        self._key, self._dev = None, None
        self._cam_buf = self._cam_host = None

    def upload(self, scene, camera) -> dict:
        """{"inst": (floats, uints, params), "materials", "light", "domains" (host), "cam" (the
        camera records), "n_views"}; ``camera``: a Camera or a Views."""
        q = cl_device().queue
        key = (scene._version, scene.time)
        if key != self._key:
            inst_f, inst_u, params = scene.instance_buffers()
            self._dev = {
                "inst": tuple(cla.to_device(q, a).data for a in (inst_f, inst_u, params)),
                "materials": cla.to_device(q, scene.materials()).data,
                "light": cla.to_device(q, self.light).data,
                "domains": inst_f[:, 28:32],
            }
            self._key = key
        views = as_views(camera)
        records = views.records()
        if self._cam_buf is None or self._cam_buf.size < records.nbytes:
            self._cam_buf = cl.Buffer(cl_device().context, cl.mem_flags.READ_ONLY, records.nbytes)
        # not waited for: every frame ends with a wait, so the host copy is free to change then
        # the event is kept with the host copy: a dropped event of a non-blocking copy makes
        # pyopencl wait for it (measured 585 ms behind a running kernel)
        self._cam_host = (records, cl.enqueue_copy(q, self._cam_buf, records, is_blocking=False))
        return dict(self._dev, cam=self._cam_buf, n_views=len(views))
