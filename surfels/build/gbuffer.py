"""G-buffers of K orthographic views (position, normal, colour, valid mask): rasterized in
OpenCL for meshes (raster.py), rendered with paramlod's point renderer for parametric scenes."""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from paramlod.core.transforms import SQUARE_LIMIT
from paramlod.errors import SurfelError
from paramlod.pipeline.driver import render
from paramlod.surfels.build.raster import gbuffer_arrays
from paramlod.surfels.build.sources import TriangleSoup
from paramlod.surfels.build.views import ViewSet, make_views


@dataclass
class GBuffer:
    views: ViewSet
    position: np.ndarray   # float32 (K, H, W, 4): world xyz, w = 1 where the surface was seen
    normal: np.ndarray     # float32 (K, H, W, 3): unit, turned towards the view
    color: np.ndarray      # float32 (K, H, W, 4): linear RGB, alpha
    source: str = ""

    @property
    def valid(self) -> np.ndarray:
        return self.position[..., 3] > 0

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.position.shape[:3]

    @property
    def pixel_count(self) -> int:
        k, h, w = self.shape
        return k * h * w

    def subsample(self, stride: int) -> "GBuffer":
        """Every stride-th pixel of every stride-th row (stride divides the resolution), as the
        G-buffer of views with resolution / stride pixels per side."""
        if stride == 1:
            return self
        res = self.views.resolution
        if res % stride:
            raise SurfelError(f"stride {stride} does not divide the resolution {res}")
        sl = (slice(None), slice(None, None, stride), slice(None, None, stride))
        return GBuffer(replace(self.views, resolution=res // stride), np.ascontiguousarray(self.position[sl]),
                       np.ascontiguousarray(self.normal[sl]), np.ascontiguousarray(self.color[sl]), self.source)

    def check(self):
        n = int(self.valid.sum())
        if n == 0:
            raise SurfelError(f"{self.source or 'the object'} covers no pixel in any of the "
                              f"{self.views.count} views: nothing to sample")
        finite = np.isfinite(self.position[..., :3])
        if finite.all():   # the usual case, without numpy's slow reduction over an axis of 3
            return n
        bad = self.valid & ~np.all(finite, axis=-1)
        if bad.any():
            raise SurfelError(f"{self.source or 'the object'}: {int(bad.sum())} G-buffer pixels have "
                              "non-finite positions")
        return n


def mesh_gbuffer(soup: TriangleSoup, views: int = 16, resolution: int = 512) -> GBuffer:
    lo, hi = soup.bounds
    span = float(np.linalg.norm(hi - lo))
    if span > SQUARE_LIMIT:   # the sampler's keys, float32 squared distances, would give infinite radii
        raise SurfelError(f"mesh '{soup.name}' spans {span:.3g}, beyond {SQUARE_LIMIT:.3g} (the sampler squares "
                          "distances in float32); scale the mesh down")
    centre, radius = soup.bounding_sphere()
    vs = make_views(centre, radius, views, resolution)
    g = GBuffer(vs, *gbuffer_arrays(soup, vs), soup.name)
    g.check()
    return g


def scene_bounds(scene, grid: int = 33) -> np.ndarray:
    """(2, 3) world bounds of a parametric scene: every instance (parts included) evaluated with
    numpy on a grid x grid lattice of its domain (scene_gbuffer adds a margin for what falls between)."""
    inst_f, inst_u, params = scene.instance_buffers()
    funcs = scene.functions()
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    t = np.linspace(0.0, 1.0, grid)
    for i in range(len(inst_f)):
        fn = funcs[int(inst_u[i, 0])]
        off = int(inst_u[i, 1])
        block = params[off:off + fn.param_count]
        u0, u1, v0, v1 = (float(x) for x in inst_f[i, 28:32])
        uu, vv = np.meshgrid(u0 + (u1 - u0) * t, v0 + (v1 - v0) * t, indexing="ij")
        with np.errstate(all="ignore"):
            p = np.asarray(fn.evaluate(uu, vv, block=block), np.float64).reshape(-1, 3)
        p = p[np.all(np.isfinite(p), axis=1)]
        if not len(p):
            raise SurfelError(f"scene object {int(inst_u[i, 2])} ('{fn.name}') has no finite point to sample")
        m = inst_f[i, 0:16].astype(np.float64).reshape(4, 4)
        w = p @ m[:3, :3].T + m[:3, 3]
        lo, hi = np.minimum(lo, w.min(axis=0)), np.maximum(hi, w.max(axis=0))
    return np.stack([lo, hi])


def scene_gbuffer(scene, views: int = 16, resolution: int = 512, margin: float = 1.1, name: str = "scene") -> GBuffer:
    """G-buffers of a parametric scene through paramlod.render on orthographic cameras: position
    from each pixel centre and its linear depth, the Frame's normal, the object's material colour."""
    if not scene.objects:
        raise SurfelError("the scene has no objects to sample")
    lo, hi = scene_bounds(scene)
    centre = (lo + hi) / 2
    radius = float(np.linalg.norm(hi - lo) / 2)
    vs = make_views(centre, radius, views, resolution, margin=margin)
    k, n = vs.count, vs.resolution
    pos = np.zeros((k, n, n, 4), np.float32)
    nrm = np.zeros((k, n, n, 3), np.float32)
    col = np.zeros((k, n, n, 4), np.float32)
    # the albedo of each object id (instances of one object share its material)
    _, inst_u, _ = scene.instance_buffers()
    mats = scene.materials()
    albedo = np.zeros((int(inst_u[:, 2].max()) + 1, 4), np.float32)
    first = {}
    for i, oid in enumerate(inst_u[:, 2]):
        first.setdefault(int(oid), i)
    for oid, i in first.items():
        albedo[oid, :3] = mats[i, :3]
        albedo[oid, 3] = 1.0
    for i in range(k):
        frame = render(scene, vs.camera(i))
        ok = np.isfinite(frame.depth)
        p = vs.pixel_world(i, np.where(ok, frame.depth, 0.0))
        pos[i, ..., :3] = np.where(ok[..., None], p, 0.0)
        pos[i, ..., 3] = ok
        # the renderer turns normals towards the eye point as a perspective camera would; for an
        # orthographic view "towards the viewer" is against the viewing direction
        n = frame.normal.astype(np.float32)
        n = np.where((n @ vs.directions[i].astype(np.float32) > 0)[..., None], -n, n)
        nrm[i] = np.where(ok[..., None], n, 0.0)
        col[i] = albedo[np.where(ok, frame.object_id, 0)]
    g = GBuffer(vs, pos, nrm, col, name)
    g.check()
    return g
