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

Skinned meshes (paramlod.meshlod.skinned, ``Scene.add_skinned_mesh``) are meshes of this kind:
each frame the skinning kernel (paramlod.meshlod.skin) writes every skinned object's pose at its
time (its own, or the scene's) into the shared vertex buffers before the cut; their meshlets have
no DAG and are cut by the skinned cull (paramlod.meshlod.skin_cull.SkinCull, bounds that hold for
the whole clip) into the same selection, after the static meshes' cut. For meshlets-gl the posed
vertices are read back and written into the GL vertex buffers (one skinning implementation, the
one the twin checks, for both renderers; the cost is 32 bytes per skinned vertex each way per
frame, measured in docs/skinning.md).

Meshes that take over from surfel objects (paramlod.scene.handoff) get their weights each frame,
for the camera the surfels are splatted with (the keys pass's; for meshlets-gl, the frame's camera
at settings.points.supersample, the surfels' pass), uploaded without a wait before the cut: the cut
skips instances of weight 0, the raster and the GL fragment stage keep the pixels of dither < w.

Multi-view frames (``paramlod.render_views``; both renderers are registered ``multiview=True``):
the renderer is given a paramlod.core.views.Views. One cut serves every view (a cluster as fine as
the finest view that sees it asks, culled only when every view culls it, paramlod.meshlod.cut);
"meshlets" rasterizes each cluster into the layers of the views its mask names, "meshlets-gl"
amplifies each triangle per view in a geometry stage into layered targets and returns one Frame
per view. ``stats()["views"]`` (and each GL frame's ``view_counts``) counts the clusters and
triangles drawn into each view. The hand-off weights of a multi-view frame are each instance's
largest over the views (the mesh draws the share the view that needs it most asks for).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from paramlod.core.views import Views
from paramlod.device.context import cl_device
from paramlod.device.programs import events_ms
from paramlod.errors import MeshError
from paramlod.meshlod.buffers import DeviceMeshes, MeshArrays, MeshInstances
from paramlod.meshlod.cut import ClusterCut, Selection
from paramlod.meshlod.draw import MeshDraw
from paramlod.meshlod.raster import MeshRaster
from paramlod.meshlod.skin import Skinning, pose_records, read_vertices
from paramlod.meshlod.skin_cull import SkinCull
from paramlod.meshlod.skinned import SkinnedMesh, skinned_source
from paramlod.meshlod.source import load_mesh, skinned_bounds
from paramlod.renderers.registry import ObjectKind, RendererSpec, register_kind, register_renderer
from paramlod.renderers.shading import LIGHT
from paramlod.scene.loaders import register_loader

COLOR_BY = {"material": 0, "cluster": 1, "level": 2}


@dataclass
class MeshSettings:
    """How meshes are cut and drawn.

    ``threshold_px``: the largest projected error of a drawn cluster, in pixels of the target (0:
    the original triangles); ``cull_frustum``, ``cull_backface``: per-cluster culling, the
    backface cones only for objects whose material is one-sided (``two_sided`` False: a two-sided
    mesh shows its back faces; skinned meshes' class-0 meshlets likewise, per batch);
    ``color_by``: "material", or a debug colour per "cluster" or per LOD "level"."""
    threshold_px: float = 1.0
    cull_frustum: bool = True
    cull_backface: bool = True
    color_by: str = "material"

    def validate(self):
        t = self.threshold_px
        if isinstance(t, bool) or not isinstance(t, (int, float)) or not np.isfinite(t) or t < 0:
            raise MeshError(f"mesh threshold_px must be a finite number of pixels >= 0, got {t!r}")
        if not isinstance(self.color_by, str) or self.color_by not in COLOR_BY:
            raise MeshError(f"mesh color_by must be one of {', '.join(COLOR_BY)}, got {self.color_by!r}")


class _MeshUploads:
    """The scene's meshes and instances on the device, sent again when the scene changed."""

    def __init__(self):
        self._version, self.dev = None, None
        self.skinned: list = []   # the skinned objects, in their slots' order

    def update(self, scene) -> DeviceMeshes:
        if scene._version != self._version:
            def key(o):   # a skinned object has a pose of its own: its own copy of the vertices
                return ("object", id(o)) if isinstance(o.mesh, SkinnedMesh) else id(o.mesh)

            index: dict = {}
            meshes, skinned = [], []
            for o in scene.meshes:
                if key(o) not in index:
                    index[key(o)] = len(meshes)
                    meshes.append(o.mesh)
                    if isinstance(o.mesh, SkinnedMesh):
                        skinned.append(o)
            arrays = MeshArrays.pack(meshes)
            instances = MeshInstances.pack(scene.meshes, lambda o: index[key(o)])
            self.dev = DeviceMeshes(arrays, instances)
            self.skinned = skinned   # in slot order (mesh order)
            self._version = scene._version
        return self.dev

    def times(self, scene) -> list:
        """The pose time of each skinned slot: its object's own, or the scene's."""
        return [scene.time if getattr(o, "time", None) is None else o.time for o in self.skinned]


class _Cuts:
    """The cut of the static meshes (ClusterCut) and of the skinned ones (SkinCull with their
    bounds over the clip; every meshlet when culling is off), into one selection; and the
    skinning before them."""

    def __init__(self):
        self.cut, self.skinning = ClusterCut(), Skinning()
        self.skin_cull, self._cull_dev = None, None
        self.skin_events: list = []
        self.last_cull = None   # how the last frame cut the skinned meshes: "skin_cull", "none"

    def pose(self, dev, times) -> list:
        self.skin_events = self.skinning.enqueue(dev, pose_records(dev, times)) if dev.skin.slots else []
        return self.skin_events

    def enqueue(self, dev, camera, s, selection) -> list:
        if not dev.skin.slots:
            self.last_cull = None
            return self.cut.enqueue(dev, camera, s.threshold_px, selection, cull_frustum=s.cull_frustum,
                                    cull_backface=s.cull_backface)
        events = self.cut.enqueue(dev.only(False), camera, s.threshold_px, selection, cull_frustum=s.cull_frustum,
                                  cull_backface=s.cull_backface)
        if s.cull_frustum or s.cull_backface:
            events += self._culler(dev).enqueue(dev.skin_matrices, camera, selection, cull_frustum=s.cull_frustum,
                                                cull_backface=s.cull_backface, reset=False)
            self.last_cull = "skin_cull"
        else:
            # no culling: every meshlet (a skinned mesh has no DAG: its clusters are all roots of error
            # 0, so the static cut with its tests off selects them all, with no bounds to build)
            events += self.cut.enqueue(dev.only(True), camera, s.threshold_px, selection, cull_frustum=False,
                                       cull_backface=False, reset=False)
            self.last_cull = "none"
        return events

    def _culler(self, dev) -> SkinCull:
        if self._cull_dev is not dev:
            for slot in dev.skin.slots:   # offline, once per mesh (and cached on disk between runs)
                if slot.mesh.bounds is None:
                    slot.mesh.bounds = skinned_bounds(slot.mesh)
            self.skin_cull = SkinCull(dev, [slot.mesh.bounds for slot in dev.skin.slots])
            self._cull_dev = dev
        return self.skin_cull

    def ms(self) -> float:
        return events_ms(self.skin_events)


class Meshlets:
    """The "meshlets" renderer's per-scene state: uploads, the cut's selection, the rasterizer."""

    def __init__(self, functions=(), record: bool = False):
        self.uploads, self.cuts, self.raster = _MeshUploads(), _Cuts(), MeshRaster()
        self.selection = Selection()
        self.camera, self.weights, self.times = None, None, []

    def prepare(self, scene, camera, settings):
        settings.mesh.validate()
        self.dev, self.camera = self.uploads.update(scene), camera
        self.times = self.uploads.times(scene)

    def enqueue(self, target, settings):
        s = settings.mesh
        # here, not in prepare: a redrawn frame sees the surfel strategies as they are now
        self.weights = _weights(self.dev, self.camera)
        self.cuts.pose(self.dev, self.times)
        self._cut = self.cuts.enqueue(self.dev, self.camera, s, self.selection)
        sel = self.selection
        self.raster.enqueue(target, self.camera, self.dev, sel.pairs, sel.capacity, sel.counters, LIGHT,
                            COLOR_BY[s.color_by], masks=sel.masks)

    def collect(self):
        self.selection.collect()
        self.raster.collect()

    def grow(self, settings) -> bool:
        return any([self.selection.grow(), self.raster.grow()])

    def stats(self) -> dict:
        out = _mesh_stats(self.selection, self._cut, self.raster.stats(), self.dev, self.weights, self.cuts)
        if isinstance(self.camera, Views):
            out["views"] = _view_counts(self.selection)
        return out


class MeshletsGL:
    """The "meshlets-gl" renderer's per-scene state: the OpenCL cut and the OpenGL draw."""

    def __init__(self, functions=(), record: bool = False):
        self.uploads, self.cuts, self.draw = _MeshUploads(), _Cuts(), MeshDraw()
        self.selection = Selection()
        self._drawn_version = None
        self.times = []

    def prepare(self, scene, camera, settings):
        settings.mesh.validate()
        self.dev, self.background = self.uploads.update(scene), scene.background
        if self.uploads._version != self._drawn_version:
            self.draw.upload(self.dev.arrays, self.dev.instances)
            self._drawn_version = self.uploads._version
        self.times = self.uploads.times(scene)

    def enqueue(self, camera, settings):
        s = settings.mesh
        ss = settings.points.supersample   # the surfels' keys pass: its camera gives the weights
        weights = _weights(self.dev, camera if ss == 1 else camera.with_size((camera.width * ss, camera.height * ss)))
        self.cuts.pose(self.dev, self.times)
        while True:
            events = self.cuts.enqueue(self.dev, camera, s, self.selection)
            self.selection.collect()
            cl_device().queue.finish()
            if not self.selection.grow():
                break
        t0 = time.perf_counter()
        for slot in self.dev.skin.slots:   # the GL draw reads the pose the skinning wrote
            v, n = read_vertices(self.dev, slot.dst_first, slot.count)
            self.draw.write_vertices(slot.dst_first, v, n)
        pose_copy_ms = (time.perf_counter() - t0) * 1e3
        n = self.selection.counts()["selected"]   # the counters the loop collected
        pairs = self.selection.read_pairs(n)
        stats = _mesh_stats(self.selection, events, {}, self.dev, weights, self.cuts)
        if not isinstance(camera, Views):
            frame = self.draw.draw(pairs, camera, settings.tess.aa, COLOR_BY[s.color_by], LIGHT, self.background,
                                   weights=weights)
            return self._frame_stats(frame, stats, pose_copy_ms)
        frames = self.draw.draw_views(pairs, self.selection.read_masks(n), camera, settings.tess.aa,
                                      COLOR_BY[s.color_by], LIGHT, self.background, weights=weights)
        per_view = _view_counts(self.selection)
        for v, frame in enumerate(frames):
            self._frame_stats(frame, stats, pose_copy_ms)
            frame.stats.update(view=v, views=len(frames), view_counts=per_view[v])
        return frames

    def _frame_stats(self, frame, stats, pose_copy_ms):
        ms = frame.stats["ms"]
        frame.stats.update({k: v for k, v in stats.items() if k != "ms"}, variant="meshlets-gl")
        frame.stats["ms"] = {**ms, "cut": stats["ms"]["cut"], "render": ms.get("draw", 0.0)}
        if self.dev.skin.slots:   # the skinning's device time, and the pose's CL -> host -> GL copy
            frame.stats["ms"].update(skin=stats["ms"]["skin"], pose_copy=pose_copy_ms)
        return frame

    def collect(self):
        pass

    def grow(self, settings) -> bool:
        return False

    def stats(self) -> dict:
        return {}


def _weights(dev, camera):
    """The instances' hand-off weights for ``camera`` (a Views: each one's largest over the views),
    sent to the device (no wait); None when the scene has no hand-off (the device's weights stay 1)."""
    if not dev.instances.handoffs:
        return None
    cams = camera if isinstance(camera, Views) else [camera]
    w = np.max([dev.instances.weights(c) for c in cams], axis=0)
    dev.set_weights(w)
    return w


def _view_counts(selection) -> list:
    """Per view, {"clusters_drawn", "triangles_drawn"} of the last collected cut."""
    return [{"clusters_drawn": c["clusters"], "triangles_drawn": c["triangles"]} for c in selection.view_counts()]


def _mesh_stats(selection, cut_events, raster: dict, dev, weights, cuts) -> dict:
    c = selection.counts()
    ms = events_ms(cut_events)
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
    if dev.skin.slots:
        out["skinned_objects"] = len(dev.skin.slots)
        out["skinned_vertices"] = int(sum(sl.count for sl in dev.skin.slots))
        out["ms"]["skin"] = cuts.ms()
        out["skin_cull"] = cuts.last_cull   # "skin_cull" (the clip's bounds) or "none" (culling off)
    return out


register_kind(ObjectKind("mesh", "meshlets", "meshes",
                         follows={"tess": "meshlets-gl", "points": "meshlets", "points-ssaa": "meshlets"}))
register_renderer(RendererSpec("meshlets", "mesh", Meshlets, "mesh", "keys", MeshSettings,
                               "mesh clusters cut on the device and rasterized with atom_min into the key buffers",
                               multiview=True))
register_renderer(RendererSpec("meshlets-gl", "mesh", MeshletsGL, "mesh", "gl", MeshSettings,
                               "the same cut drawn by OpenGL (one indirect draw per cluster), MSAA/SSAA",
                               takes_aa="all", multiview=True))
register_loader("mesh", load_mesh)
register_loader("skinned", skinned_source)
