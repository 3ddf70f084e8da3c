"""Test plugin with parts: a post carrying a built-in cone and a disc from this same folder.

Domain: u in [0, 1] up the post, v in [0, 2 pi) around. Parameters: ``t`` (time), ``lean`` (0.3).
"""
from sympy import cos, pi, sin

from paramlod import Part, parametric, translate


@parametric(u=(0, 1), v=(0, 2 * pi), params={"lean": 0.3}, parts=[
    Part("cone", at=(0.5, 0.0), params={"radius": 0.05, "height": 0.2}, color=(0.9, 0.9, 0.8)),
    Part("wavy_disc", at=(1.0, 0.0), params={"radius": 0.3}, transform=translate(0, 0, 0.05)),
])
def signpost(u, v, t, lean):
    """A leaning post that sways with t, with a spike and a rippled disc; lean (0.3)."""
    return lean * sin(t) * u ** 2 + 0.05 * cos(v), 0.05 * sin(v), u
