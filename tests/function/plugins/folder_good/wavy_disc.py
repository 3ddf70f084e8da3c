"""Test plugin: a disc with animated ripples (an array parameter gives the ripple amplitudes).

Domain: u in [0, 1] from the centre to the rim, v in [0, 2 pi) around.
Parameters: ``radius`` (1), ``amps`` (3 ripple amplitudes), ``t`` (time).
"""
from sympy import cos, pi, sin

from paramlod import parametric
from paramlod.dsl import let


@parametric(u=(0, 1), v=(0, 2 * pi), params={"radius": 1.0, "amps": [0.05, 0.03, 0.02]})
def wavy_disc(u, v, t, radius, amps):
    """Disc with ripples moving outward with t; radius, amps (3)."""
    r = let(radius * u)
    z = sum(a * sin(2 * pi * (k + 2) * u - t) for k, a in enumerate(amps))
    return r * cos(v), r * sin(v), z
