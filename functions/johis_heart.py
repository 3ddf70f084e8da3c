"""Johi's heart: a sphere whose upper half is pinched into two lobes and whose lower half narrows
to a point (dissertation section 5.4, Listing 5.1; Figure 5.3a).

The listing prints the base sphere as (sin u cos u, cos u, sin u cos v), which is not a sphere (its
x is sin(2u)/2) and does not give the heart of Figure 5.3a. We read it as the unit sphere with
polar angle u measured from +y, written (sin u sin v, cos u, sin u cos v): it keeps the printed y
and z, gives exactly the heart of the figure, and has outward normals (df/du x df/dv).
Then, as in the listing:

* upper half (u < pi/2): y *= 1 - 0.8 cos((0.7 pi |x|)^(1/4)), a dip at x = 0 between two lobes;
* lower half: x *= sin(u)^2, narrowing to the tip at u = pi;
* finally (x, y, z) *= (0.9, 1, 0.4), a flat heart.

Domain: u in [0, pi] from the top (+y) to the tip (-y), v in [0, 2 pi) around the y axis.
Parameters: ``size`` (default 1), a uniform scale.
"""
from sympy import Abs, cos, pi, sin, sqrt

from paramlod import parametric
from paramlod.dsl import where


def heart_shape(u, v):
    """The unscaled heart point at (u, v) as three expressions (shared with spiky_heart)."""
    x, y, z = sin(u) * sin(v), cos(u), sin(u) * cos(v)
    upper = u < pi / 2
    y = where(upper, y * (1 - cos(sqrt(sqrt(Abs(x * pi * 0.7)))) * 0.8), y)
    x = where(upper, x, x * sin(u) ** 2)
    return 0.9 * x, y, 0.4 * z


@parametric(u=(0, pi), v=(0, 2 * pi), params={"size": 1.0}, periodic="v")
def johis_heart(u, v, size):
    """Johi's heart (thesis Listing 5.1, base sphere read as (sin u sin v, cos u, sin u cos v)); size (1)."""
    x, y, z = heart_shape(u, v)
    return size * x, size * y, size * z
