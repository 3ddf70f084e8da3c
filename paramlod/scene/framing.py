"""Cameras that frame a scene: bounds from numpy samples of its functions, surfels and mesh boxes."""
from __future__ import annotations

import numpy as np

from paramlod.core.camera import Camera
from paramlod.core.transforms import PLACE_LIMIT
from paramlod.errors import SceneError

GRID = 24            # samples per side of each probed instance
MAX_PROBED = 64      # instances sampled per group; the others are bounded through their origins


def _samples(fn, block) -> np.ndarray:
    uu, vv = np.meshgrid(np.linspace(*fn.u_range, GRID), np.linspace(*fn.v_range, GRID), indexing="ij")
    p = fn.evaluate(uu, vv, block).reshape(-1, 3)
    return p[np.all(np.isfinite(p), axis=1)]


def scene_box(scene) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) corners of a box around every instance of ``scene`` (NaN samples ignored).

    Groups of up to MAX_PROBED instances are sampled exactly; larger groups (curtains, glyph
    fields) are bounded by spheres around every instance's origin whose radius is the largest
    extent of an evenly chosen subset of MAX_PROBED instances."""
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for fn, models, blocks, _, _ in scene._expanded():
        n = len(models)
        pick = np.unique(np.linspace(0, n - 1, min(n, MAX_PROBED)).astype(int))
        world = [_samples(fn, blocks[k]) @ models[k][:3, :3].T + models[k][:3, 3] for k in pick]
        world = [w for w in world if len(w)]
        if not world:
            continue
        if n <= MAX_PROBED:
            pts = np.concatenate(world)
            lo, hi = np.minimum(lo, pts.min(axis=0)), np.maximum(hi, pts.max(axis=0))
        else:
            r = max(float(np.linalg.norm(w - models[k][:3, 3], axis=1).max()) for k, w in zip(pick, world))
            origins = models[:, :3, 3]
            lo, hi = np.minimum(lo, origins.min(axis=0) - r), np.maximum(hi, origins.max(axis=0) + r)
    for so in scene.surfels:
        w = so.surfels.positions @ so.transform[:3, :3].T + so.transform[:3, 3]
        lo, hi = np.minimum(lo, w.min(axis=0)), np.maximum(hi, w.max(axis=0))
    for mo in scene.meshes:
        v = mo.mesh.vertices
        a, b = v.min(axis=0).astype(np.float64), v.max(axis=0).astype(np.float64)
        corners = np.array([[x, y, z, 1.0] for x in (a[0], b[0]) for y in (a[1], b[1]) for z in (a[2], b[2])])
        models = [mo.transform] if mo.transforms is None else mo.transform @ mo.transforms
        w = (np.asarray(models) @ corners.T)[:, :3].transpose(0, 2, 1).reshape(-1, 3)  # every copy's box corners
        lo, hi = np.minimum(lo, w.min(axis=0)), np.maximum(hi, w.max(axis=0))
    if not np.all(np.isfinite(lo)):
        return -np.ones(3), np.ones(3)
    return lo, hi


def framing_camera(scene, direction=(0.6, 0.45, 1.0), up=(0, 1, 0), fov_y=40.0, size=(960, 540),
                   margin=1.1) -> Camera:
    """A camera looking at the centre of the scene's box from ``direction``, as close as it can be
    with every corner of the box inside the frame (``margin`` > 1 leaves a border)."""
    lo, hi = scene_box(scene)
    big = float(np.abs(np.concatenate([lo, hi])).max())
    if big > PLACE_LIMIT:   # the camera would be refused anyway; say which box made it
        raise SceneError(f"framing camera: the scene's bounding box reaches {big:.3g}, beyond {PLACE_LIMIT:.0e}, "
                         "where float32 cannot place geometry (check the transforms and what the functions return)")
    centre = (lo + hi) / 2
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]) - centre
    d = np.asarray(direction, float)
    length = float(np.linalg.norm(d)) if d.shape == (3,) else 0.0
    if not (np.isfinite(length) and length > 0):
        raise SceneError(f"framing camera: direction must be a finite non-zero vector [x, y, z], got {direction!r}")
    d /= length
    probe = Camera.look_at(centre + d, centre, up, fov_y, size)   # only for its axes
    right, upv = probe.view[0, :3], probe.view[1, :3]
    w, h = size
    ty = np.tan(np.radians(fov_y) / 2) / margin
    tx = ty * w / h
    # corner k is in the frame when |x_k| <= tx * depth_k and |y_k| <= ty * depth_k,
    # with depth_k = dist - corner_k . d
    need = corners @ d + np.maximum(np.abs(corners @ right) / tx, np.abs(corners @ upv) / ty)
    dist = float(need.max())
    radius = float(np.linalg.norm(hi - lo) / 2) or 1.0
    dist = max(dist, 1e-3 * radius)
    return Camera.look_at(centre + d * dist, centre, up, fov_y, size,
                          near=max(dist - 1.2 * radius, dist * 1e-3), far=dist + 1.2 * radius)
