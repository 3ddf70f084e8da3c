"""One frame, the only driver of a frame (the API, CLI, gallery and bench call it): the plan's
passes, coarsest first -> each keys pass enqueued whole (LOD stages, renderers, downsample,
resolve) and waited for once -> gl passes -> composite by depth when there are several -> Frame,
read back lazily.

A multi-view frame (``render_views``) is the same frame for a ``Views`` of N cameras: each LOD
stage runs once for all of them, each keys pass draws into N layers of key buffers and each gl
pass into N layers of its targets, and the passes of each view are composited into its Frame."""
from __future__ import annotations

import time
import weakref
from dataclasses import replace

import numpy as np

from paramlod.core.camera import Camera, pixel_world_size
from paramlod.core.frame import FrameStats
from paramlod.core.views import Views
from paramlod.device.context import cl_device
from paramlod.errors import SceneError
from paramlod.pipeline.composite import composite
from paramlod.pipeline.passes import SceneState
from paramlod.pipeline.plan import check_variant, multiview_variants
from paramlod.pipeline.settings import RenderSettings
from paramlod.scene.scene import Scene, SceneObject

PROBE_LINES = 9   # undefined_objects: the grid of a domain probed for a finite position

FLOAT32_EPS = float(np.finfo(np.float32).eps)


class Pipeline:
    """Per-scene state for the scenes it renders (dropped with the scene)."""

    def __init__(self):
        self._scenes: weakref.WeakKeyDictionary[Scene, SceneState] = weakref.WeakKeyDictionary()

    def state(self, scene: Scene) -> SceneState:
        st = self._scenes.get(scene)
        if st is None:
            st = self._scenes[scene] = SceneState()
        return st

    def render(self, scene: Scene, camera: Camera, variant: str | None = None,
               settings: RenderSettings | None = None, time_: float | None = None):
        """A Frame of ``scene`` seen by ``camera``; see ``paramlod.render``."""
        frames = self.passes(scene, camera, variant, settings, time_)
        frame = frames[0] if len(frames) == 1 else composite(frames, background=scene.background)
        note_nothing_drawn(frame, frames, camera, scene=scene)
        return frame

    def render_views(self, scene: Scene, cameras, variant: str | None = None,
                     settings: RenderSettings | None = None, time_: float | None = None) -> list:
        """One Frame per camera of ``cameras`` from one LOD pass; see ``paramlod.render_views``."""
        views = Views(cameras)
        passes = self.passes(scene, views, variant, settings, time_)   # per pass: a Frame per view
        out = []
        for v, camera in enumerate(views):
            frames = [p[v] for p in passes]
            frame = frames[0] if len(frames) == 1 else composite(frames, background=scene.background)
            note_nothing_drawn(frame, frames, camera, others_drew=any(
                int(q[u].stats.get("pixels_written", 0)) for q in passes for u in range(len(views)) if u != v))
            out.append(frame)
        return out

    def render_on_device(self, scene: Scene, camera: Camera, variant: str | None = None,
                         settings: RenderSettings | None = None) -> FrameStats:
        """One frame up to resolved buffers on the device (what an interactive viewer pays); its stats.
        Several passes are composited on the host, which reads them back."""
        frame = self.render(scene, camera, variant, settings)
        return frame.stats

    def passes(self, scene: Scene, camera: Camera, variant: str | None = None,
               settings: RenderSettings | None = None, time_: float | None = None) -> list:
        """The Frames of the frame's passes, coarsest first, before they are composited; for a
        ``Views``, each pass gives a list of Frames, one per view."""
        if not isinstance(scene, Scene):
            raise SceneError(f"render needs a paramlod.Scene, got {type(scene).__name__}")
        if not isinstance(camera, (Camera, Views)):
            raise SceneError(f"render needs a paramlod.Camera, got {type(camera).__name__}")
        check_variant(variant)
        if not scene.object_count:
            raise SceneError("the scene has no objects; add one with scene.add(...), scene.add_mesh(...) or "
                             "scene.add_surfels(...)")
        if time_ is not None:
            scene.time = time_
        settings = RenderSettings() if settings is None else settings
        if not isinstance(settings, RenderSettings):
            raise SceneError(f"render's settings must be a paramlod.RenderSettings, got {type(settings).__name__}")
        settings.points.validate()
        st = self.state(scene)
        frames = []
        passes = st.update(scene, variant, settings)
        if isinstance(camera, Views):
            check_multiview(passes)
        for p in passes:
            if p.target == "gl":
                frames.append(self._gl_pass(st, p, camera, settings))
            else:
                frames.append(self._keys_pass(st, p, scene, camera, settings))
        return frames

    def _gl_pass(self, st, p, camera, settings):
        group = p.groups[0]
        if group.aa:
            settings = replace(settings, tess=replace(settings.tess, aa=group.aa))
        r = st.renderer(group)
        r.prepare(st.subscenes[group], camera, settings)
        return r.enqueue(camera, settings)

    def _keys_pass(self, st, p, scene, camera, settings):
        t0 = time.perf_counter()
        ss = p.ss
        layers = len(camera) if isinstance(camera, Views) else 1
        frame_keys = st.keys(camera.size, ss, layers)
        # the key buffers drawn into, coarsest first: one, or a hybrid pass's one per tier (its
        # renderers are given the frame's camera and scale each tier's samples themselves)
        tiers = p.tiers or (ss,)
        targets = [frame_keys if t == 1 else st.subsample_keys(camera.size, t, layers) for t in tiers]
        cam = camera.with_size((camera.width * ss, camera.height * ss)) if ss > 1 and not p.tiers else camera
        drawn = [(g, st.renderer(g)) for g in p.groups]
        for g, r in drawn:
            r.prepare(st.subscenes[g], cam, settings)
        t_upload = time.perf_counter()
        q = cl_device().queue
        host = 0.0   # Python time spent enqueueing (the rest of the frame is waiting)
        while True:
            t1 = time.perf_counter()
            targets[0].clear()
            for k, target in enumerate(targets):
                if k:   # a finer tier starts from the coarser tier's samples
                    st.upsample(tiers[k] // tiers[k - 1]).enqueue(targets[k - 1], target)
                for g, r in drawn:
                    if not p.tiers:
                        r.enqueue(target, settings)
                    elif getattr(r, "tiered", False):
                        r.enqueue(target, settings, tier=k)
                    elif k == 0:
                        r.enqueue(target, settings)
            downsampled = st.downsample(ss).enqueue(targets[-1], frame_keys) if ss > 1 else None
            resolved = frame_keys.resolve_on_device(scene.background)
            host += time.perf_counter() - t1
            # the counter copies: into pageable memory NVIDIA's driver waits for them, so they and
            # the finish are the frame's one wait
            for g, r in drawn:
                r.collect()
            frame_keys.read_counts()
            q.finish()
            if not any([r.grow(settings) for _, r in drawn]):
                break
        t_end = time.perf_counter()
        stats = _keys_stats([r.stats() for _, r in drawn], [g.spec.variant for g, _ in drawn])
        counts = frame_keys.counts
        written = counts["pixels_written"] if ss == 1 else counts["covered_subsamples"]
        stats.update({
            "device": cl_device().name,
            "size": list(camera.size),
            "supersample": ss,
            "samples_per_pixel": ss * ss,
            **({"aa": "hybrid", "tiers": [t * t for t in tiers]} if p.tiers else {}),
            "pixels_written": counts["pixels_written"],
            "overdraw": stats.get("atomics", 0) / written if written else 0.0,
        })
        if ss > 1:
            stats["covered_subsamples"] = counts["covered_subsamples"]
        ms = stats["ms"]
        ms.update(upload=(t_upload - t0) * 1e3, resolve=_event_ms(resolved) + _event_ms(downsampled),
                  host=(t_upload - t0 + host) * 1e3, frame=(t_end - t0) * 1e3, readback=0.0,
                  total=(t_end - t0) * 1e3)
        if not isinstance(camera, Views):
            frame = frame_keys.frame()
            frame.stats = FrameStats(stats)
            return frame
        frames = frame_keys.frames()
        for v, frame in enumerate(frames):
            frame.stats = FrameStats(view_stats(stats, v, len(frames), frame_keys.layer_counts(v), ss))
        return frames


def check_multiview(passes) -> None:
    """A SceneError naming the variants of a multi-view frame that draw one view only."""
    single = sorted({g.spec.variant for p in passes for g in p.groups if not g.spec.multiview})
    if single:
        raise SceneError(f"render_views: variant {', '.join(single)} draws one view at a time; use a multi-view variant "
                         f"({', '.join(multiview_variants())}) or render each camera with render()")


def view_stats(stats: dict, view: int, n_views: int, counts: dict, ss: int) -> dict:
    """The stats of view ``view`` of a multi-view keys pass: the frame's (LOD, samples, times: shared
    by every view), with this view's written pixels and, from the renderers' per-view counters
    (``stats["views"]``), this view's share."""
    out = dict(stats, view=view, views=n_views, pixels_written=counts["pixels_written"])
    if ss > 1:
        out["covered_subsamples"] = counts["covered_subsamples"]
    per_view = stats.get("views")
    if per_view:
        out["view_counts"] = per_view[view]
    return out


def undefined_objects(scene: Scene) -> list[str]:
    """The names of the parametric objects whose function (with the object's parameters, its first
    instance's where they vary) has no finite position on a PROBE_LINES x PROBE_LINES grid of
    its domain: the LOD stage culls their patches, which would read as objects out of view."""
    out = []
    for o in scene.objects:
        if not isinstance(o, SceneObject):
            continue
        fn = o.function
        uu, vv = np.meshgrid(np.linspace(*fn.u_range, PROBE_LINES), np.linspace(*fn.v_range, PROBE_LINES))
        params = {**o.params, **{k: np.asarray(a)[0] for k, a in o.per_instance.items()}}
        try:
            with np.errstate(all="ignore"):
                p = fn.evaluate(uu, vv, **params)
        except Exception:   # noqa: BLE001 - a diagnosis only: an object it cannot evaluate is not named
            continue
        if not np.isfinite(p).all(axis=-1).any():
            out.append(f"'{fn.name}'")
    return out


def note_nothing_drawn(frame, frames, camera, others_drew: bool = False, scene: Scene | None = None) -> None:
    """``stats["nothing_drawn"]``: None, or why a frame covers no pixel (also in ``warnings``), so
    an empty image is never taken for a render (objects at 1e10 gave one with exit code 0).
    ``others_drew``: a view of a multi-view frame whose other views drew (a cube face looking away
    from the scene): it only notes that no object lies in this view, without a warning."""
    stats = frame.stats
    reason = None
    if not int(stats.get("pixels_written", 0)) and others_drew:
        stats["nothing_drawn"] = "nothing drawn: no object lies in this view (other views of the frame drew)"
        return
    if not int(stats.get("pixels_written", 0)):
        parts = [f.stats for f in frames]
        patches = sum(int(p.get("render_patches", 0)) for p in parts)
        culled = sum(int(s.get("culled", 0)) for p in parts for s in p.get("lod_steps") or [])
        # the kernels place points in float32: far from the origin its steps outgrow a pixel
        far_off = float(np.linalg.norm(camera.eye))
        depth = float(np.sqrt(camera.near * camera.far))   # a depth between near and far
        step, pixel = far_off * FLOAT32_EPS, pixel_world_size(camera, depth)
        if step > pixel:
            reason = (f"nothing drawn: the camera is {far_off:.3g} from the origin, where float32's steps "
                      f"({step:.3g}) are larger than a pixel at depth {depth:.3g} ({pixel:.3g}); move the scene "
                      "and the camera nearer the origin")
        elif patches == 0 and culled and scene is not None and (bad := undefined_objects(scene)) \
                and len(bad) == sum(isinstance(o, SceneObject) for o in scene.objects):
            reason = (f"nothing drawn: {', '.join(bad)} evaluates to NaN or infinity everywhere on a "
                      f"{PROBE_LINES} x {PROBE_LINES} grid of its domain, and the LOD stage culls such patches "
                      "(check the formula: a square root or logarithm of a negative number, a division by zero)")
        elif patches == 0 and culled:
            reason = (f"nothing drawn: the LOD stage culled every patch ({culled}), every object lies outside "
                      "the camera's view (check the camera's eye, target, near and far)")
        elif patches:
            reason = (f"nothing drawn: {patches} patches reached the renderer but none covered a pixel; the "
                      "objects are too far, too small or too far from the origin for float32 to place")
        else:
            reason = ("nothing drawn: no object covered a pixel; every object is outside the camera's view, "
                      "too far or too small")
        stats["warnings"] = [*stats.get("warnings", []), reason]
    stats["nothing_drawn"] = reason


def _keys_stats(parts: list[dict], names: list[str]) -> dict:
    """The stats of the renderers of one keys pass merged: counters added, LOD steps of the first."""
    parametric = [n for n in names if n != "surfels"]
    out = {"variant": ", ".join(dict.fromkeys(parametric)) if parametric else "surfels",
           "render_patches": 0, "forced_patches": 0, "lod_steps": [], "samples": 0, "atomics": 0,
           "surfels": [], "ms": {"lod": 0.0, "render": 0.0}}
    for part in parts:
        for k, v in part.items():
            if k == "ms":
                for mk, mv in v.items():
                    out["ms"][mk] = out["ms"].get(mk, 0.0) + mv
            elif k == "surfels":
                out["surfels"] += v
            elif k == "lod_steps":
                out["lod_steps"] = out["lod_steps"] or v
            elif k == "views":   # per-view counters: merged view by view
                prev = out.get("views")
                out["views"] = v if prev is None else [_merge_counts(a, b) for a, b in zip(prev, v)]
            elif isinstance(v, (int, float)) and not isinstance(v, bool) and k in out and k != "variant":
                out[k] += v
            else:
                out.setdefault(k, v)
    if len(parts) > 1:
        out["passes"] = [dict(p, variant=n) for p, n in zip(parts, names)]
    return out


def _merge_counts(a: dict, b: dict) -> dict:
    """Two renderers' counters of one view: numbers added, lists (per-object records) joined."""
    out = dict(a)
    for k, v in b.items():
        out[k] = out[k] + v if k in out else v
    return out


def _event_ms(evt) -> float:
    return (evt.profile.end - evt.profile.start) * 1e-6 if evt is not None else 0.0


PIPELINE = Pipeline()


def render(scene: Scene, camera: Camera, variant: str | None = None, settings: RenderSettings | None = None,
           time: float | None = None):
    """Render ``scene`` seen by ``camera``; returns a Frame (colour, depth, normal, ids, stats).

    Each object is drawn by its own ``variant`` and ``aa`` (``scene.add(..., variant=, aa=)``),
    else by ``variant`` (default "points"; see ``paramlod.variants()``) with the AA of
    ``settings``; objects of several variants are composited by depth. ``time`` sets
    ``scene.time``, the value of the implicit parameter ``t`` of animated functions.
    """
    return PIPELINE.render(scene, camera, variant, settings, time)


def render_views(scene: Scene, cameras, variant: str | None = None, settings: RenderSettings | None = None,
                 time: float | None = None) -> list:
    """Render ``scene`` for every camera of ``cameras`` (one size; e.g. ``paramlod.views.stereo``,
    ``cube_faces``, ``quilt``) from one LOD pass; returns one Frame per camera.

    A patch (or mesh cluster, or surfel prefix) is refined as far as the view that needs most
    asks, and culled only when no view sees it; every renderer then draws that shared result into
    each view (docs/multiview.md). ``frame.stats["view"]`` is its index; LOD, sample and time figures are those of
    the whole multi-view frame, ``pixels_written`` the view's own."""
    return PIPELINE.render_views(scene, cameras, variant, settings, time)


def render_on_device(scene: Scene, camera: Camera, variant: str | None = None,
                     settings: RenderSettings | None = None) -> FrameStats:
    """``render`` up to resolved buffers on the device; returns the frame's stats."""
    return PIPELINE.render_on_device(scene, camera, variant, settings)


def render_passes(scene: Scene, camera: Camera, variant: str | None = None,
                  settings: RenderSettings | None = None, time: float | None = None) -> list:
    """The Frames of the passes ``render`` composites (one per key-buffer subsample count and per
    GL group), coarsest first: what a mixed frame is made of."""
    return PIPELINE.passes(scene, camera, variant, settings, time)


def scene_state(scene: Scene) -> SceneState:
    """The pipeline's state for ``scene`` (its passes, renderer states and key buffers)."""
    return PIPELINE.state(scene)


__all__ = ["Pipeline", "PIPELINE", "note_nothing_drawn", "render", "render_on_device", "render_passes",
           "render_views", "scene_state"]
