"""Torus around the z axis.

Domain: u in [0, 2 pi) around the central axis (from +x), v in [0, 2 pi) around the tube.
f(u, v) = ((R + r cos v) cos u, (R + r cos v) sin u, r sin v).
Parameters: ``major`` R, distance from the axis to the tube centre (default 1);
``minor`` r, tube radius (default 0.35).
"""
from sympy import cos, pi, sin

from paramlod import parametric


@parametric(u=(0, 2 * pi), v=(0, 2 * pi), params={"major": 1.0, "minor": 0.35}, periodic="uv")
def torus(u, v, major, minor):
    """Torus around z; u around the axis, v around the tube; major (1) and minor (0.35) radii."""
    ring = major + minor * cos(v)
    return ring * cos(u), ring * sin(u), minor * sin(v)
