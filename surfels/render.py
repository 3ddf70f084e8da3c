"""The surfel prefix renderer (kernels/surfels_splat.cl).

Render law (Brandt et al. 2019): a prefix of n surfels has a spacing of r = sqrt(packing / n), so
for a wanted spacing r the prefix is n = packing / r^2. A surfel size of s pixels at the object's
distance d gives r = s * pixel(d) / 2, where pixel(d) is the world size of one pixel at view depth d
(2 d / (P[1,1] H) for a perspective camera, 2 / (P[1,1] H) for an orthographic one). Discs are drawn
with radius r, so a size of 2 px means discs 2 px across whose centres are 1 px apart. When the law
asks for more surfels than the set has, the whole set is drawn with its own spacing (larger discs).

Several views (``paramlod.render_views``: a Views, layered key buffers): the object draws the
longest prefix any view that sees it asks for (a view that draws none of it, outside its frustum
or left wholly to the hand-off mesh, asks for nothing), and each surfel, read once, is splatted
into every view whose frustum holds it with that view's own disc radius. A view's discs are then
those of its single-view frame plus more of the same size: never less coverage, and the same keys
where its own law asks for the same prefix.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

import pyopencl as cl

# pixel_world_size: the law's pixel size, re-exported (its home is paramlod.core.camera)
from paramlod.core.camera import Camera, pixel_world_size, sphere_depth, transform_scale  # noqa: F401
from paramlod.core.color import srgb_to_linear
from paramlod.core.frame import FrameStats
from paramlod.core.layouts import SURFEL_COUNTER, SURFEL_VIEW
from paramlod.core.views import Views, as_views
from paramlod.device.context import cl_device
from paramlod.device.programs import kernel
from paramlod.renderers.registry import ObjectKind, RendererSpec, register_kind, register_renderer
from paramlod.renderers.shading import LIGHT
from paramlod.renderers.targets import KeyBuffer
from paramlod.scene.handoff import DEFAULT_SIZE_PX, mesh_weight, prefix_radius
from paramlod.scene.loaders import register_loader

from paramlod.errors import SurfelError
from paramlod.surfels.format import SurfelSet, load_surfels

LOCAL = 64
# IEEE float division and sqrt, as numpy does: the splat kernel's coverage and depth keys must match
# its numpy twin bit for bit, and NVIDIA's default division is not correctly rounded
EXACT_DIVISION = ("-cl-fp32-correctly-rounded-divide-sqrt",)
COUNTERS = tuple(f.name for f in SURFEL_COUNTER.fields)   # per view
VIEW_FLOATS = SURFEL_VIEW.length   # the splat's draw record per view


@dataclass
class FixedSize:
    """Surfels of ``size_px`` pixels at the object's distance (the default strategy)."""
    size_px: float = DEFAULT_SIZE_PX

    def __post_init__(self):
        if not (np.isfinite(self.size_px) and 0.1 <= self.size_px <= 256):
            raise SurfelError(f"surfel size must be between 0.1 and 256 pixels, got {self.size_px}")

    def size(self) -> float:
        return float(self.size_px)

    def observe(self, elapsed_ms: float):
        pass


@dataclass
class FixedCount:
    """Always the first ``count`` surfels, each disc sized to the prefix spacing."""
    count: int

    def __post_init__(self):
        if int(self.count) != self.count or self.count <= 0:
            raise SurfelError(f"surfel count must be a positive integer, got {self.count!r}")

    def observe(self, elapsed_ms: float):
        pass


@dataclass
class FrameTimeAdaptive:
    """Surfel size steered by the last frame's time: factor = elapsed / target; outside [0.9, 1.1]
    the size moves to (3 size + size factor) / 4, clamped to [min_size_px, max_size_px].

    ``draw_surfels`` reports its own draw time through ``observe``; an application that measures
    whole frames sets ``external=True`` and calls ``observe(frame_ms)`` itself."""
    target_ms: float = 16.7
    size_px: float = 2.0
    min_size_px: float = 1.0
    max_size_px: float = 32.0
    external: bool = False

    def __post_init__(self):
        if not (self.target_ms > 0 and np.isfinite(self.target_ms)):
            raise SurfelError(f"target frame time must be positive, got {self.target_ms}")
        if not 0 < self.min_size_px <= self.size_px <= self.max_size_px:
            raise SurfelError(f"need 0 < min_size_px <= size_px <= max_size_px, got "
                              f"{self.min_size_px}, {self.size_px}, {self.max_size_px}")

    def size(self) -> float:
        return float(self.size_px)

    def update(self, elapsed_ms: float) -> float:
        factor = float(elapsed_ms) / self.target_ms
        if factor < 0.9 or factor > 1.1:
            s = (3.0 * self.size_px + self.size_px * factor) / 4.0
            self.size_px = float(min(max(s, self.min_size_px), self.max_size_px))
        return self.size_px

    def observe(self, elapsed_ms: float, external: bool = False):
        if external or not self.external:
            self.update(elapsed_ms)


def object_depth(camera, surfels: SurfelSet, transform) -> float:
    """View depth of the nearest point of the object's bounding sphere (at least the near plane)."""
    c, r = surfels.bounding_sphere()
    return sphere_depth(camera, c, r, transform)


def choose_prefix(surfels: SurfelSet, camera, strategy=None, transform=None, bounds=None) -> dict:
    """The prefix length and disc radius (object units) a strategy asks for. ``bounds``: the set's
    bounding sphere held once (a _Sphere), else it is measured here."""
    strategy = strategy or FixedSize()
    transform = np.eye(4) if transform is None else np.asarray(transform, np.float64)
    N = len(surfels)
    if isinstance(strategy, FixedCount):
        n = min(int(strategy.count), N)
        r = surfels.spacing(n)
        return {"prefix": n, "radius": r, "size_px": None, "saturated": strategy.count > N}
    size = strategy.size()
    r, depth = prefix_radius(camera, bounds or surfels, size, transform)   # object units; the hand-off's weight uses it too
    n = surfels.prefix_for_spacing(r)
    # asking for N (1 + 1e-9) surfels is asking for N: the camera's roundoff must not flip it
    saturated = surfels.packing / (r * r) > N * (1 + 1e-9)
    return {"prefix": n, "radius": max(r, surfels.spacing(n)) if saturated else r, "size_px": size,
            "saturated": bool(saturated), "distance": depth}


class _Sphere:
    """What prefix_radius reads of a set, its bounding sphere, measured once: the measure is a pass
    over every surfel (22 ms for 200k), and a multi-view frame asks for it once per view."""

    def __init__(self, surfels: SurfelSet):
        self._sphere = surfels.bounding_sphere()

    def bounding_sphere(self):
        return self._sphere


def sees(views: Views, centre, radii, transform) -> np.ndarray:
    """bool per view: whether an object-space sphere (``radii``: its radius in each view) placed by
    ``transform`` may reach a pixel of the view: not wholly beyond far or before near, nor wholly
    outside a side of the image widened by 2 pixels (the splat keeps discs up to a pixel outside)."""
    m = np.stack([c.view for c in views]) @ np.asarray(transform, np.float64)
    cv = np.concatenate([m[:, :3, :3] @ np.asarray(centre, np.float64) + m[:, :3, 3], np.ones((len(views), 1))], axis=1)
    rad = np.asarray(radii, np.float64) * transform_scale(transform)
    near, far = np.array([c.near for c in views]), np.array([c.far for c in views])
    p = np.stack([c.projection for c in views])
    kx, ky = 1.0 + 4.0 / views.width, 1.0 + 4.0 / views.height
    planes = np.stack([kx * p[:, 3] + p[:, 0], kx * p[:, 3] - p[:, 0], ky * p[:, 3] + p[:, 1], ky * p[:, 3] - p[:, 1]], axis=1)
    inside = np.einsum("vpk,vk->vp", planes, cv) >= -rad[:, None] * np.linalg.norm(planes[:, :, :3], axis=2)
    return inside.all(axis=1) & ~(-cv[:, 2] - rad > far) & ~(-cv[:, 2] + rad < near)


class _DeviceSurfels:
    def __init__(self, s: SurfelSet):
        self.bounds = _Sphere(s)
        n = len(s)
        pos = np.zeros((n, 4), np.float32)
        pos[:, :3] = s.positions
        nrm = np.zeros((n, 4), np.float32)
        nrm[:, :3] = s.normals
        alb = np.zeros((n, 4), np.float32)
        alb[:, :3] = srgb_to_linear(s.colors[:, :3] / 255.0)
        alb[:, 3] = s.colors[:, 3] / 255.0
        ctx = cl_device().context
        mf = cl.mem_flags
        self.host = (pos, nrm, alb)
        self.bufs = [cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=a) for a in self.host]


def draw_records(camera, transform):
    """(xf: model-view rows + normal-matrix rows, float32 (24,); inverse projection, float32 (16,))."""
    mv = camera.view @ transform
    nm = np.linalg.inv(mv[:3, :3]).T
    xf = np.zeros(24, np.float32)
    xf[:12] = mv[:3, :].reshape(-1)
    xf[12:24] = np.hstack([nm, np.zeros((3, 1))]).reshape(-1)
    return xf, np.linalg.inv(camera.projection).astype(np.float32).reshape(-1)


def view_records(views: Views, transform, radii, mesh_weights) -> np.ndarray:
    """float32 (len(views) * VIEW_FLOATS,): per view draw_records, the disc radius in view units and
    the mesh weight (1: the view draws none of the object)."""
    out = np.zeros((len(views), VIEW_FLOATS), np.float32)
    for v, camera in enumerate(views):
        out[v, SURFEL_VIEW.slice("xf")], out[v, SURFEL_VIEW.slice("inv_proj")] = draw_records(camera, transform)
    out[:, SURFEL_VIEW.offset("radius")], out[:, SURFEL_VIEW.offset("mesh_weight")] = radii, mesh_weights
    return out.reshape(-1)


class _Splat:
    """One surfel object's splat in flight: its kernel event and per-view counters. ``choices``:
    each view's own law, ``lead`` the view whose prefix is drawn, ``drawn`` which views it is
    splatted into, ``records`` the kernel's view records."""

    def __init__(self, choices, lead, drawn, n, strategy, n_surfels, records, event, counters, cbuf):
        self.choices, self.lead, self.drawn, self.n = choices, lead, drawn, n
        self.strategy, self.n_surfels, self.records = strategy, n_surfels, records.reshape(-1, VIEW_FLOATS)
        self.event, self.counters, self.cbuf = event, counters, cbuf

    def _per_view(self) -> np.ndarray:
        return self.counters.reshape(-1, len(COUNTERS))

    def stats(self) -> dict:
        """The lead view's law, the counters of all views together."""
        ms = (self.event.profile.end - self.event.profile.start) * 1e-6
        total = self._per_view().sum(axis=0, dtype=np.uint64)
        return {**self.choices[self.lead], "radius_view": float(self.records[self.lead, SURFEL_VIEW.offset("radius")]),
                "surfels": self.n_surfels, "ms": ms, **{k: int(v) for k, v in zip(COUNTERS, total)},
                "views_drawn": int(sum(self.drawn))}

    def view_stats(self, v: int) -> dict:
        """View v: its own law (``view_prefix``: the prefix it asks for), ``prefix`` the prefix
        splatted into it (0 when it draws none of the object) and its counters."""
        ch = self.choices[v]
        return {**ch, "prefix": self.n if self.drawn[v] else 0, "view_prefix": ch["prefix"], "drawn": self.drawn[v],
                "radius_view": float(self.records[v, SURFEL_VIEW.offset("radius")]), "surfels": self.n_surfels,
                **{k: int(c) for k, c in zip(COUNTERS, self._per_view()[v])}}


class SurfelSplats:
    """The "surfels" renderer: each surfel object's prefix splatted into the shared key buffers
    (composed by depth with the point variants), or, given a Views, view v into layer v.
    Device copies of the sets are kept here, per scene, not on the sets."""

    def __init__(self, functions=(), record: bool = False):
        self._device: dict[int, tuple] = {}   # id(SurfelSet) -> (the set, its device copy)
        self.objects, self.camera, self._splats = [], None, []

    def device_copy(self, surfels: SurfelSet) -> _DeviceSurfels:
        held = self._device.get(id(surfels))
        if held is None or held[0] is not surfels:
            held = self._device[id(surfels)] = (surfels, _DeviceSurfels(surfels))
        return held[1]

    def prepare(self, scene, camera, settings):
        self.objects, self.camera = list(scene.surfels), camera

    def enqueue(self, target, settings=None):
        # computed here, each frame, for this pass's camera: the mesh renderer computes the same
        # weight for its instance (paramlod.scene.handoff), so the two split the pixels
        self._splats = [self.splat(target, self.camera, so.surfels, so.strategy or FixedSize(), so.transform,
                                   so.object_id, so.specular, mesh_weight=self._mesh_weight(so))
                        for so in self.objects]

    def _mesh_weight(self, so):
        if isinstance(self.camera, Views):   # each view's own share, as the mesh renderer's pass of that view
            return [mesh_weight(c, so) for c in self.camera]
        return mesh_weight(self.camera, so)

    def splat(self, keys, camera, surfels, strategy, transform, object_id, specular, light=None,
              mesh_weight=0.0) -> _Splat:
        """Enqueue the splat of one set's prefix into ``keys`` (no wait). ``camera``: a Camera, or
        a Views and ``keys`` of one layer per view. ``mesh_weight`` in [0, 1], one for every view
        or a list of one per view: the hand-off mesh's share; pixels whose dither is below it are
        left out (1: no surfel is splatted)."""
        views = as_views(camera)
        if (keys.width, keys.height) != tuple(views.size):
            raise SurfelError(f"the key buffer is {keys.width}x{keys.height} but the camera is "
                              f"{views.size[0]}x{views.size[1]}")
        if keys.layers != len(views):
            raise SurfelError(f"{len(views)} views need a key buffer of {len(views)} layers, got {keys.layers}")
        if not 0 <= int(object_id) <= 0xFFF:
            raise SurfelError(f"object_id must be in 0..4095 (12 bits of the aux key), got {object_id}")
        transform = np.eye(4) if transform is None else np.asarray(transform, np.float64)
        if transform.shape != (4, 4) or not np.all(np.isfinite(transform)) or abs(np.linalg.det(transform[:3, :3])) < 1e-12:
            raise SurfelError("surfel transform must be a finite, invertible 4x4 matrix")
        weights = _mesh_weights(mesh_weight, len(views))
        dev = self.device_copy(surfels)
        choices = [dict(choose_prefix(surfels, c, strategy, transform, dev.bounds), mesh_weight=w)
                   for c, w in zip(views, weights)]
        centre, rad = dev.bounds.bounding_sphere()
        # a view draws the object if the mesh leaves it pixels (weight 1: the mesh draws them all)
        # and its frustum may hold a disc (the cube around a disc reaches sqrt(3) radii from its centre)
        seen = sees(views, centre, [rad + 2.0 * ch["radius"] for ch in choices], transform)
        drawn = [bool(w < 1.0 and s) for w, s in zip(weights, seen)]
        lead = max(range(len(views)), key=lambda v: (drawn[v], choices[v]["prefix"], -v))
        n = choices[lead]["prefix"] if drawn[lead] else 0
        scale = transform_scale(transform)
        records = view_records(views, transform, [np.float32(ch["radius"] * scale) for ch in choices],
                               [w if d else 1.0 for w, d in zip(weights, drawn)])
        q, ctx = cl_device().queue, cl_device().context
        mf = cl.mem_flags
        view_buf, cam_buf, light_buf = (cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=a) for a in
                                        (records, views.records(), np.asarray(LIGHT if light is None else light, np.float32)))
        counters = np.zeros(len(views) * len(COUNTERS), np.uint64)
        cbuf = cl.Buffer(ctx, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=counters)
        k = kernel("surfels_splat", ["common/keys.cl", "surfels/surfels_splat.cl"], options=EXACT_DIVISION)
        evt = k(q, (_round_up(n, LOCAL),), (LOCAL,), *dev.bufs, np.uint32(n), view_buf, cam_buf,
                np.uint32(len(views)), light_buf, np.float32(specular), np.uint32(object_id),
                keys.color, keys.aux, cbuf)
        return _Splat(choices, lead, drawn, n, strategy, len(surfels), records, evt, counters, cbuf)

    def collect(self):
        for s in self._splats:
            cl.enqueue_copy(cl_device().queue, s.counters, s.cbuf, is_blocking=False)

    def grow(self, settings) -> bool:
        for s in self._splats:   # after the frame's wait: the strategies see their draw times
            s.strategy.observe(s.stats()["ms"])
        return False

    def stats(self) -> dict:
        """{"surfels": one dict per object}; with a Views also "views": per view {"surfels": ...}."""
        out = {"surfels": [s.stats() for s in self._splats]}
        if isinstance(self.camera, Views):
            out["views"] = [{"surfels": [s.view_stats(v) for s in self._splats]} for v in range(len(self.camera))]
        return out


def _mesh_weights(mesh_weight, n_views: int) -> list[float]:
    """``mesh_weight`` (one number, or one per view) as n_views floats in [0, 1]."""
    ws = list(mesh_weight) if isinstance(mesh_weight, (list, tuple, np.ndarray)) else [mesh_weight] * n_views
    if len(ws) != n_views:
        raise SurfelError(f"mesh_weight: {n_views} views need one weight each, got {len(ws)}")
    out = []
    for w in ws:
        try:
            w = float(w)
        except (TypeError, ValueError):
            w = float("nan")
        if not 0.0 <= w <= 1.0:
            raise SurfelError(f"mesh_weight must be in [0, 1] (the hand-off mesh's share of the pixels), "
                              f"got {mesh_weight!r}")
        out.append(w)
    return out


def draw_surfels(keys, camera, surfels, strategy=None, transform=None, object_id: int = 1,
                 specular: float = 0.25, light=None) -> dict:
    """Splat the prefix that ``strategy`` (default: FixedSize(2)) asks for into ``keys`` (a cleared
    or partly drawn paramlod.renderers.targets.KeyBuffer; with a Views for ``camera``, one layer
    per view) and wait; returns stats (with a Views also "views": one dict per view). The caller
    resolves."""
    r = SurfelSplats()
    s = r.splat(keys, camera, load_surfels(surfels), strategy or FixedSize(), transform, object_id, specular, light)
    r._splats = [s]
    r.collect()
    cl_device().queue.finish()
    r.grow(None)
    if isinstance(camera, Views):
        return {**s.stats(), "views": [s.view_stats(v) for v in range(len(camera))]}
    return s.stats()


def _round_up(n, m):
    return max(m, (n + m - 1) // m * m)


# The resting-face test of up_axis: a surfel lies on a bounding-box face when it is within this
# fraction of the box's largest extent of it and its normal is within ~14 degrees of the face's.
_FACE_BAND, _FACE_COS = 0.02, 0.97


def up_axis(surfels: SurfelSet) -> np.ndarray:
    """The set's up direction, a unit world axis: opposite the bounding-box face the object rests on
    (scans and models standing on a ground have a flat base: many surfels on one face, facing out of
    it), else +y (the OBJ / glTF convention). Scans are often z-up, so y-up alone lays them on their side."""
    p, n = surfels.positions.astype(np.float64), surfels.normals.astype(np.float64)
    lo, hi = p.min(axis=0), p.max(axis=0)
    band = _FACE_BAND * float(np.max(hi - lo))
    share = {}
    for a in range(3):
        for sign, face in ((-1, lo[a]), (1, hi[a])):
            on = (np.abs(p[:, a] - face) <= band) & (sign * n[:, a] > _FACE_COS)
            share[(a, sign)] = float(on.mean()) if len(p) else 0.0
    ranked = sorted(share, key=share.get, reverse=True)
    (a, sign), runner_up = ranked[0], share[ranked[1]]
    up = np.zeros(3)
    # a base: at least 1% of the surfels and clearly more than any other face (a cube has six)
    if share[(a, sign)] >= 0.01 and share[(a, sign)] >= 3 * runner_up:
        up[a] = -sign
    else:
        up[1] = 1.0
    return up


def principal_frame(surfels: SurfelSet, up=None):
    """(right, up, front) unit vectors: ``up`` (default up_axis), ``right`` the set's major principal
    axis across ``up`` (world axes when the spread across ``up`` is about round: the principal axes of
    a round set are noise), pointing to the set's longer tail along it, ``front = right x up`` (+z for
    y-up, -y for z-up data). The frame turns with the data: a set stored rotated by R gets R times it."""
    up = up_axis(surfels) if up is None else np.asarray(up, np.float64)
    up = up / np.linalg.norm(up)
    p = surfels.positions.astype(np.float64)
    flat = (p - p.mean(axis=0)) - np.outer((p - p.mean(axis=0)) @ up, up)
    w, v = np.linalg.eigh(flat.T @ flat / max(1, len(p)))   # ascending; w[0] ~ 0 along up
    right = v[:, 2]
    if w[2] <= 1.2 * w[1]:
        # about round across up: the world axis most across up (x unless up is x)
        axes = np.eye(3)
        right = axes[int(np.argmin(np.abs(axes @ up)))] if abs(up[0]) > 0.5 else axes[0]
        right = right - (right @ up) * up
    right = right / np.linalg.norm(right)
    # a principal axis has no sign: take the one with the set's longer tail (positive skewness), which
    # turns with the data; a set about symmetric along it points it along +world instead
    x = flat @ right
    sd = float(np.std(x))
    skew = float(np.mean(x ** 3)) / sd ** 3 if sd > 0 else 0.0
    if (skew < 0) if abs(skew) > 0.05 else (right[int(np.argmax(np.abs(right)))] < 0):
        right = -right
    return right, up, np.cross(right, up)


def default_camera(surfels: SurfelSet, size=(512, 512), fov_y: float = 35.0, direction=(1.0, 0.6, 1.4),
                   up=None):
    """A perspective camera that frames the set's bounding sphere from ``direction``, given in the
    set's principal frame (right, up, front; see principal_frame): a 3/4 view of its widest side,
    upright. ``up`` overrides the automatic up axis."""
    right, up, front = principal_frame(surfels, up)
    # the sphere around the box in that frame (not the world box): the same framing however the set is stored
    basis = np.stack([right, up, front], axis=1)
    p = surfels.positions.astype(np.float64)
    q = p @ basis
    mid = (q.min(axis=0) + q.max(axis=0)) / 2
    c = basis @ mid
    r = max(float(np.sqrt(np.max(np.sum((q - mid) ** 2, axis=1)))), float(np.max(surfels.radii)), 1e-12)
    d = np.asarray(direction, np.float64)
    d = d[0] * right + d[1] * up + d[2] * front
    d /= np.linalg.norm(d)
    w, h = size
    half = np.radians(fov_y) / 2
    fit = min(np.tan(half), np.tan(half) * w / h)
    dist = 1.1 * r / np.sin(np.arctan(fit))
    return Camera.look_at(c + d * dist, c, up=up, fov_y=fov_y, size=size,
                          near=max(dist - 2 * r, dist * 1e-3), far=dist + 2 * r)


def render_surfels(path_or_set, camera=None, strategy=None, size=(512, 512), transform=None,
                   background=(0.12, 0.12, 0.14)):
    """Render one surfel set alone: -> paramlod.Frame (stats in frame.stats)."""
    surfels = load_surfels(path_or_set)
    camera = camera or default_camera(surfels, size)
    t0 = time.perf_counter()
    keys = KeyBuffer(*camera.size)
    keys.clear()
    stats = draw_surfels(keys, camera, surfels, strategy, transform)
    frame = keys.resolve(background)
    frame.stats = FrameStats({"device": cl_device().name, "variant": "surfels", "size": list(camera.size),
                              "surfels": stats, "pixels_written": keys.counts["pixels_written"],
                              "ms": {"render": stats["ms"], "total": (time.perf_counter() - t0) * 1e3}})
    return frame


register_kind(ObjectKind("surfels", "surfels", "surfels"))
register_renderer(RendererSpec("surfels", "surfels", SurfelSplats, "points", "keys", object,
                               "prefixes of blue-surfel sets splatted with atom_min into the key buffers",
                               multiview=True))
register_loader("surfels", load_surfels)
