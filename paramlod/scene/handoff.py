"""The surfel -> mesh hand-off ("blend to the original mesh past the stored prefix", Brandt et al.
2019; PADrend): when the render law asks a surfel object for more surfels than its set holds, its
mesh (a MeshObject with ``handoff`` set, made by ``Scene.add_surfels(..., mesh=...)``) takes over,
blended over a short range by a screen-door dither. docs/surfels.md, "Hand-off to the mesh".

Pure functions of the scene room, so that both renderers use the same numbers without importing
each other: the surfel renderer (paramlod.surfels.render) skips pixels whose dither is below the
weight, the mesh renderers (paramlod.meshlod.render: the cut, the raster, the GL draw) skip those
at or above it. Each computes ``mesh_weight`` for the camera of its own pass.

  demand = packing / (r^2 N)       how many times more surfels the law wants than the set holds
                                   (r: the prefix radius of the strategy's size, as choose_prefix)
  weight = clamp((demand - 1) / blend, 0, 1)      (FixedCount, no size in pixels: 0)

The dither is kernels/common/hash.cl ``pl_dither`` (OpenCL and GLSL); its numpy twin,
paramlod.core.hashing.dither, serves both kernel twins (surfels/build/reference.py splat_discs,
paramlod/meshlod/raster_reference.py).
"""
from __future__ import annotations

import math

import numpy as np

from paramlod.core.camera import pixel_world_size, sphere_depth, transform_scale
from paramlod.core.transforms import is_number
from paramlod.errors import SceneError

DEFAULT_SIZE_PX = 2.0   # the surfel size of the default strategy (paramlod.surfels.FixedSize)
DEFAULT_BLEND = 0.5     # the hand-off completes when the law asks for 1.5 times the set


def check_blend(blend, what: str = "add_surfels") -> float:
    """``blend`` as a float, or a SceneError naming it and the fix."""
    if not is_number(blend):
        raise SceneError(f"{what}: blend must be a number > 0 (the demand range over which the mesh takes "
                         f"over, e.g. 0.5), got {blend!r}")
    b = float(blend)
    if not (math.isfinite(b) and b > 0):
        raise SceneError(f"{what}: blend must be a finite number > 0 (e.g. 0.5: the mesh has taken over when "
                         f"the surfel law asks for 1.5 times the set), got {b}")
    return b


def prefix_radius(camera, surfels, size_px: float, transform) -> tuple[float, float]:
    """(r, depth): the disc radius in object units that a surfel size of ``size_px`` pixels asks
    for at the object's depth (the nearest point of the set's bounding sphere), and that depth.
    r = size_px * pixel(depth) / 2 / scale(transform)."""
    c, rad = surfels.bounding_sphere()
    depth = sphere_depth(camera, c, rad, transform)
    r_world = size_px * pixel_world_size(camera, depth) / 2.0
    return r_world / transform_scale(transform), depth


def demand(camera, surfel_object) -> float:
    """packing / (r^2 N) for the object's strategy; 0 for a strategy without a size in pixels
    (FixedCount). Above 1, the prefix the law asks for has run out."""
    strategy = surfel_object.strategy
    size = getattr(strategy, "size", None) if strategy is not None else (lambda: DEFAULT_SIZE_PX)
    if size is None:
        return 0.0
    s = surfel_object.surfels
    r, _ = prefix_radius(camera, s, float(size()), surfel_object.transform)
    if not r > 0:
        return math.inf
    return float(s.packing / (r * r * len(s)))


def mesh_weight(camera, surfel_object) -> float:
    """The share of the object's pixels its mesh draws, in [0, 1]: clamp((demand - 1) / blend, 0, 1);
    0 when the object has no mesh."""
    if getattr(surfel_object, "mesh", None) is None:
        return 0.0
    d = demand(camera, surfel_object)
    return float(min(max((d - 1.0) / surfel_object.blend, 0.0), 1.0))
