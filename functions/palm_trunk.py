"""Palm tree trunk: a pipe around a cubic Bezier centreline whose radius follows a sawtooth of
stacked leaf-base rings (reference implementation's function library, anchors.md section 1;
dissertation Figure 5.21d/e).

Each ring widens slowly over most of its length and narrows steeply over the last ``drop``
fraction: a sawtooth made continuous (the reference's profile jumps, which leaves gaps between
point samples; ours has a steep flank instead, so points and tessellation agree).
The cross-section frame uses the world z axis as reference (N = z projected normal to the tangent,
B = T x N), which stays stable for any trunk that does not run along z, unlike the Frenet frame
that flips at inflections.

Domain: u in [0, 1] from the base to the crown, v in [0, 2 pi) around the trunk.
Parameters: ``control`` (12 floats) the four Bezier control points x0, y0, z0, ..., x3, y3, z3
(default: a 4-unit trunk leaning towards +x); ``radius_base`` (0.35) and ``radius_top`` (0.22)
the radius at both ends; ``rings`` (22) number of rings; ``ring_depth`` (0.18) how much a ring
widens, relative to the radius; ``drop`` (0.12) the fraction of a ring taken by its steep flank.
"""
from sympy import cos, pi, sin

from paramlod import parametric
from paramlod.dsl import bezier, bezier_derivative, cross, fract, normalize, vec3, where

CONTROL = [0.0, 0.0, 0.0, 0.15, 1.5, 0.0, 0.55, 2.9, 0.0, 1.3, 4.0, 0.0]


def sawtooth(x, drop):
    """Continuous sawtooth in [0, 1] with period 1: rises over 1 - drop, falls over drop."""
    f = fract(x)
    return where(f < 1 - drop, f / (1 - drop), (1 - f) / drop)


@parametric(u=(0, 1), v=(0, 2 * pi),
            params={"control": CONTROL, "radius_base": 0.35, "radius_top": 0.22, "rings": 22.0,
                    "ring_depth": 0.18, "drop": 0.12}, periodic="v")
def palm_trunk(u, v, control, radius_base, radius_top, rings, ring_depth, drop):
    """Palm trunk: Bezier pipe with a sawtooth ring profile; control points, radii, rings, ring_depth, drop."""
    pts = [vec3(*control[3 * i:3 * i + 3]) for i in range(4)]
    c = bezier(pts, u)
    tangent = normalize(bezier_derivative(pts, u))
    n = normalize(vec3(0, 0, 1) - tangent * tangent[2])
    b = cross(tangent, n)
    r = (radius_base + (radius_top - radius_base) * u) * (1 + ring_depth * sawtooth(rings * u, drop))
    # cos v N - sin v B: df/du x df/dv points outward
    p = c + (n * cos(v) - b * sin(v)) * r
    return p[0], p[1], p[2]
