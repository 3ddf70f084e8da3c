"""A tiny third-party package that ships a parametric function through the entry-point group
``paramlod.functions`` (see ../paramlod_test_shapes-0.1.dist-info/entry_points.txt).

Domain: u in [0, 2 pi), v in [-1, 1]. Parameters: ``radius`` (0.6), ``height`` (1.2).
"""
from sympy import cos, pi, sin

from paramlod import parametric


@parametric(u=(0, 2 * pi), v=(-1, 1), params={"radius": 0.6, "height": 1.2})
def ep_barrel(u, v, radius, height):
    """A barrel (bulging cylinder) from an entry point; radius, height."""
    r = radius * (1 + 0.25 * (1 - v ** 2))
    return r * cos(u), height / 2 * v, r * sin(u)
