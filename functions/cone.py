"""Cone with its base circle in the xy plane at the origin and its tip on +z.

Reference: the teeth of the dissertation's "giant worm" (section 5.7) are small cones.
Domain: u in [0, 1] from the base (u = 0) to the tip (u = 1), v in [0, 2 pi) around the z axis;
f(u, v) = (radius (1 - u) sin v, radius (1 - u) cos v, height u), normals point outward.
The tip (u = 1) is a single point where the normal is undefined.
Parameters: ``radius`` (default 0.5) of the base; ``height`` (default 1).
"""
from sympy import cos, pi, sin

from paramlod import parametric


@parametric(u=(0, 1), v=(0, 2 * pi), params={"radius": 0.5, "height": 1.0}, periodic="v")
def cone(u, v, radius, height):
    """Cone, base circle at z = 0, tip at z = height; u base->tip, v around; radius (0.5), height (1)."""
    r = radius * (1 - u)
    return r * sin(v), r * cos(v), height * u
