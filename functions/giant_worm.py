"""Giant worm (dissertation section 5.7, Figure 5.20): an animated parametric creature made of a
body and child parts placed on it.

Body: a distorted cylinder around a cubic Bezier centreline whose control points sway with the
time ``t``; its thickness is proportional to 1 / (u + o) (o = ``offset`` > 0 keeps it finite),
so the head (u = 0) is (1 + o) / o times thicker than the tail end (u = 1); skin detail is a product
of sines of u and v with integer frequencies around the body (so it closes up). The cross-section
frame uses the world x axis as reference (the worm moves in the yz plane), which stays stable
where a Frenet frame would flip.

Parts (``parts=``, expanded with ``expand_parts`` every frame, so they follow the animation):
3 outer and 3 inner jaw patches at the mouth rim (u = 0, every 120 degrees), a tongue near the axis,
and 19 cone teeth on each inner jaw (57 in all); see ``giant_worm_parts``. Jaws and teeth sit on
the surface, so they follow any parameter; the tongue's inward offset is fixed for the default
``thickness`` and ``offset``.

Domain: u in [0, 1] from the mouth to the tail, v in [0, 2 pi) around the body.
Parameters: ``t`` (time), ``thickness`` (0.35) the radius at the tail end, ``offset`` (0.5) the o
of 1/(u + o), ``sway`` (0.8) how far the head swings sideways, ``bumps`` (0.05) skin relief.
"""
from __future__ import annotations

import math

from sympy import cos, pi, sin

from paramlod import Part, parametric, translate
from paramlod.dsl import bezier, bezier_derivative, cross, let, normalize, vec3

from .giant_worm_parts import giant_worm_jaw_inner, giant_worm_jaw_outer, giant_worm_tongue

INNER_COLOR = (0.55, 0.2, 0.22)
TONGUE_COLOR = (0.75, 0.18, 0.25)
TONGUE_AT = 0.06


def control_points(t, sway):
    """The centreline's Bezier control points (mouth first) at time t."""
    return [vec3(sway * sin(t), 5.0 + 0.3 * sin(1.3 * t), 1.2),
            vec3(0.6 * sway * sin(t - 0.9), 5.5, -1.8),
            vec3(0.3 * sway * sin(t - 1.8), 1.0, -1.6),
            vec3(0, -0.5, -4.5)]


def body_radius(u, thickness, offset):
    """Radius without skin relief: thickness (1 + o) / (u + o)."""
    return thickness * (1 + offset) / (u + offset)


def _tongue_transform(thickness=0.35, offset=0.5):
    """From the rim frame at (TONGUE_AT, 0) to near the body axis (for the default thickness)."""
    return translate(-0.1, 0.0, -0.85 * body_radius(TONGUE_AT, thickness, offset))


def _parts() -> list[Part]:
    parts = []
    for k in range(3):
        v = 2 * math.pi * k / 3
        parts.append(Part(giant_worm_jaw_outer, at=(0.0, v), name="jaw_outer"))
        parts.append(Part(giant_worm_jaw_inner, at=(0.0, v), color=INNER_COLOR, name="jaw_inner"))
    parts.append(Part(giant_worm_tongue, at=(TONGUE_AT, 0.0), transform=_tongue_transform(),
                      color=TONGUE_COLOR, name="tongue"))
    return parts


@parametric(u=(0, 1), v=(0, 2 * pi), params={"thickness": 0.35, "offset": 0.5, "sway": 0.8, "bumps": 0.05},
            parts=_parts(), periodic="v")
def giant_worm(u, v, t, thickness, offset, sway, bumps):
    """Giant worm body (jaws, tongue and 57 teeth as parts): u mouth->tail, v around; t, thickness, offset, sway, bumps."""
    pts = control_points(t, sway)
    c = let(bezier(pts, u), "c")
    tangent = normalize(bezier_derivative(pts, u))
    n = normalize(vec3(1, 0, 0) - tangent * tangent[0])
    b = let(cross(tangent, n), "b")
    skin = 1 + bumps * sin(60 * u) * sin(12 * v) * (0.6 + 0.4 * sin(9 * u + 2 * v))
    r = let(body_radius(u, thickness, offset) * skin, "r")
    p = c + (n * cos(v) - b * sin(v)) * r    # outward normals
    return p[0], p[1], p[2]


def part_count() -> int:
    """Parts of one worm, recursively (3 + 3 jaws, 1 tongue, 57 teeth = 64)."""
    return len(giant_worm.expand_parts())

