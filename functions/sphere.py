"""Sphere of radius ``radius`` centred at the origin.

Domain: u = polar angle theta in [0, pi] from +z, v = azimuth phi in [0, 2 pi) from +x (the same
convention as the SH glyphs), so f(u, v) = radius * (sin u cos v, sin u sin v, cos u).
Parameters: ``radius`` (default 1).
"""
from sympy import cos, pi, sin

from paramlod import parametric


@parametric(u=(0, pi), v=(0, 2 * pi), params={"radius": 1.0}, periodic="v")
def sphere(u, v, radius):
    """Sphere, u = polar angle from +z in [0, pi], v = azimuth from +x in [0, 2pi); radius (1)."""
    return radius * sin(u) * cos(v), radius * sin(u) * sin(v), radius * cos(u)
