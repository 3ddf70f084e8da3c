"""Spiky heart: Johi's heart (``johis_heart``) with a grid of spikes on its middle band.

Reference: the "spiky heart" of the reference implementation's function library (anchors.md
section 1); this construction is our own. Each spike is a smooth periodic bump
exp(k (cos(n_u u') - 1)) * exp(k (cos(n_v v) - 1)) (a von Mises profile: one peak per period,
smooth everywhere, no floor or round), so the surface and its normals stay continuous. The band
u in (pi/8, 3 pi/4) fades in and out with smoothstep, keeping the top dip and the tip clean.

Domain: u in [0, pi] from the top to the tip, v in [0, 2 pi) around the y axis.
Parameters: ``size`` (1) uniform scale; ``spikes_u`` (10) spikes per pi along u; ``spikes_v`` (20)
spikes around; ``height`` (0.3) spike height relative to the surface; ``sharpness`` (5) how narrow
each spike is (larger = narrower).
"""
from sympy import cos, exp, pi

from paramlod import parametric
from paramlod.dsl import smoothstep

from .johis_heart import heart_shape


@parametric(u=(0, pi), v=(0, 2 * pi),
            params={"size": 1.0, "spikes_u": 10.0, "spikes_v": 20.0, "height": 0.3, "sharpness": 5.0}, periodic="v")
def spiky_heart(u, v, size, spikes_u, spikes_v, height, sharpness):
    """Johi's heart with smooth spikes on its middle band; size, spikes_u, spikes_v, height, sharpness."""
    x, y, z = heart_shape(u, v)
    bump = exp(sharpness * (cos(2 * spikes_u * u) - 1)) * exp(sharpness * (cos(spikes_v * v) - 1))
    band = smoothstep(pi / 8, pi / 4, u) * (1 - smoothstep(5 * pi / 8, 3 * pi / 4, u))
    r = size * (1 + height * band * bump)
    return r * x, r * y, r * z
