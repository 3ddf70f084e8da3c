"""The mesh object kind and its two renderers, registered with the frame plan.

- "meshlets": the cut (kernels/meshlod/cut.cl) then the OpenCL rasterizer
  (kernels/meshlod/raster.cl) into the shared 64-bit key buffers, so meshes composite with
  parametric objects and surfels in one buffer and take the points variant's supersampling.
  Nothing waits between the cut and the raster: the raster reads the cut's count on the device.
- "meshlets-gl": the same cut, its selection read back (about 8 bytes per cluster) and drawn by
  OpenGL with one indirect draw command per cluster (paramlod.meshlod.draw), with the tess
  variant's anti-aliasing modes; composited by depth with the other passes.

The threshold is in pixels of the target drawn into: with supersampling, in subsamples, as the
parametric objects' LOD is (a cluster's error then stays below one subsample).

Meshes that take over from surfel objects (paramlod.scene.handoff) get their weights each frame,
for the camera the surfels are splatted with (the keys pass's; for meshlets-gl, the frame's camera
at settings.points.supersample, the surfels' pass), uploaded without a wait before the cut: the cut
skips instances of weight 0, the raster and the GL fragment stage keep the pixels of dither < w.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from paramlod.device.context import cl_device
from paramlod.errors import MeshError
from paramlod.meshlod.buffers import DeviceMeshes, MeshArrays, MeshInstances
from paramlod.meshlod.cut import ClusterCut, Selection
from paramlod.meshlod.draw import MeshDraw
from paramlod.meshlod.raster import MeshRaster
from paramlod.meshlod.source import load_mesh
from paramlod.renderers.registry import ObjectKind, RendererSpec, register_kind, register_renderer
from paramlod.renderers.shading import LIGHT
from paramlod.scene.loaders import register_loader

COLOR_BY = {"material": 0, "cluster": 1, "level": 2}


@dataclass
class MeshSettings:
    """How meshes are cut and drawn.

    ``threshold_px``: the largest projected error of a drawn cluster, in pixels of the target (0:
    the original triangles); ``cull_frustum``, ``cull_backface``: per-cluster culling;
    ``color_by``: "material", or a debug colour per "cluster" or per LOD "level"."""
    threshold_px: float = 1.0
    cull_frustum: bool = True
    cull_backface: bool = True
    color_by: str = "material"

    def validate(self):
        t = self.threshold_px
        if isinstance(t, bool) or not isinstance(t, (int, float)) or not np.isfinite(t) or t < 0:
            raise MeshError(f"mesh threshold_px must be a finite number of pixels >= 0, got {t!r}")
        if self.color_by not in COLOR_BY:
            raise MeshError(f"mesh color_by must be one of {', '.join(COLOR_BY)}, got {self.color_by!r}")


class _MeshUploads:
    """The scene's meshes and instances on the device, sent again when the scene changed."""

    def __init__(self):
        self._version, self.dev = None, None

    def update(self, scene) -> DeviceMeshes:
        if scene._version != self._version:
            index: dict[int, int] = {}
            meshes = []
            for o in scene.meshes:
                if id(o.mesh) not in index:
                    index[id(o.mesh)] = len(meshes)
                    meshes.append(o.mesh)
            arrays = MeshArrays.pack(meshes)
            instances = MeshInstances.pack(scene.meshes, lambda m: index[id(m)])
            self.dev = DeviceMeshes(arrays, instances)
            self._version = scene._version
        return self.dev


class Meshlets:
    """The "meshlets" renderer's per-scene state: uploads, the cut's selection, the rasterizer."""

    def __init__(self, functions=(), record: bool = False):
        self.uploads, self.cut, self.raster = _MeshUploads(), ClusterCut(), MeshRaster()
        self.selection = Selection()
        self.camera, self.weights = None, None

    def prepare(self, scene, camera, settings):
        settings.mesh.validate()
        self.dev, self.camera = self.uploads.update(scene), camera

    def enqueue(self, target, settings):
        s = settings.mesh
        # here, not in prepare: a redrawn frame sees the surfel strategies as they are now
        self.weights = _weights(self.dev, self.camera)
        self._cut = self.cut.enqueue(self.dev, self.camera, s.threshold_px, self.selection,
                                     cull_frustum=s.cull_frustum, cull_backface=s.cull_backface)
        sel = self.selection
        self.raster.enqueue(target, self.camera, self.dev, sel.pairs, sel.capacity, sel.counters, LIGHT,
                            COLOR_BY[s.color_by])

    def collect(self):
        self.selection.collect()
        self.raster.collect()

    def grow(self, settings) -> bool:
        return any([self.selection.grow(), self.raster.grow()])

    def stats(self) -> dict:
        return _mesh_stats(self.selection, self._cut, self.raster.stats(), self.dev, self.weights)


class MeshletsGL:
    """The "meshlets-gl" renderer's per-scene state: the OpenCL cut and the OpenGL draw."""

    def __init__(self, functions=(), record: bool = False):
        self.uploads, self.cut, self.draw = _MeshUploads(), ClusterCut(), MeshDraw()
        self.selection = Selection()
        self._drawn_version = None

    def prepare(self, scene, camera, settings):
        settings.mesh.validate()
        self.dev, self.background = self.uploads.update(scene), scene.background
        if self.uploads._version != self._drawn_version:
            self.draw.upload(self.dev.arrays, self.dev.instances)
            self._drawn_version = self.uploads._version

    def enqueue(self, camera, settings):
        s = settings.mesh
        ss = settings.points.supersample   # the surfels' keys pass: its camera gives the weights
        weights = _weights(self.dev, camera if ss == 1 else camera.with_size((camera.width * ss, camera.height * ss)))
        while True:
            events = self.cut.enqueue(self.dev, camera, s.threshold_px, self.selection,
                                      cull_frustum=s.cull_frustum, cull_backface=s.cull_backface)
            self.selection.collect()
            cl_device().queue.finish()
            if not self.selection.grow():
                break
        pairs = self.selection.read_pairs(self.selection.counts()["selected"])   # the counters the loop collected
        frame = self.draw.draw(pairs, camera, settings.tess.aa, COLOR_BY[s.color_by], LIGHT, self.background,
                               weights=weights)
        stats = _mesh_stats(self.selection, events, {}, self.dev, weights)
        ms = frame.stats["ms"]
        frame.stats.update({k: v for k, v in stats.items() if k != "ms"}, variant="meshlets-gl")
        frame.stats["ms"] = {**ms, "cut": stats["ms"]["cut"], "render": ms.get("draw", 0.0)}
        return frame

    def collect(self):
        pass

    def grow(self, settings) -> bool:
        return False

    def stats(self) -> dict:
        return {}


def _weights(dev, camera):
    """The instances' hand-off weights for ``camera``, sent to the device (no wait); None when the
    scene has no hand-off (the device's weights stay 1)."""
    if not dev.instances.handoffs:
        return None
    w = dev.instances.weights(camera)
    dev.set_weights(w)
    return w


def _mesh_stats(selection, cut_events, raster: dict, dev, weights=None) -> dict:
    c = selection.counts()
    ms = sum((e.profile.end - e.profile.start) * 1e-6 for e in cut_events)
    out = {"clusters_drawn": c["selected"], "triangles_drawn": c["triangles"],
           "clusters_culled_frustum": c["culled_frustum"], "clusters_culled_backface": c["culled_backface"],
           "cluster_tests": c["tests"], "mesh_device_bytes": dev.nbytes + selection.nbytes,
           **{(k if k == "atomics" else f"raster_{k}"): v for k, v in raster.items() if k != "ms"}}
    if weights is not None:   # the hand-off meshes' shares of their pixels, in scene order
        out["handoff_weights"] = [float(weights[i]) for i, _ in dev.instances.handoffs]
    raster_ms = raster.get("ms", {})
    out["ms"] = {"cut": ms, **raster_ms}
    if raster_ms:
        out["ms"]["render"] = sum(raster_ms.values())
    return out


register_kind(ObjectKind("mesh", "meshlets", "meshes",
                         follows={"tess": "meshlets-gl", "points": "meshlets", "points-ssaa": "meshlets"}))
register_renderer(RendererSpec("meshlets", "mesh", Meshlets, "mesh", "keys", MeshSettings,
                               "mesh clusters cut on the device and rasterized with atom_min into the key buffers"))
register_renderer(RendererSpec("meshlets-gl", "mesh", MeshletsGL, "mesh", "gl", MeshSettings,
                               "the same cut drawn by OpenGL (one indirect draw per cluster), MSAA/SSAA",
                               takes_aa="all"))
register_loader("mesh", load_mesh)
