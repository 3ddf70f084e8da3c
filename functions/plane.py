"""Flat rectangle in the xy plane, centred at the origin, facing +z.

Reference: the plane of the reference implementation's function library (anchors.md section 1).
Domain: u in [-1/2, 1/2] along x, v in [-1/2, 1/2] along y, so f(u, v) = (width u, height v, 0)
and the normal df/du x df/dv is +z.
Parameters: ``width`` (default 2) and ``height`` (default 2), the side lengths along x and y.
"""
from paramlod import parametric


@parametric(u=(-0.5, 0.5), v=(-0.5, 0.5), params={"width": 2.0, "height": 2.0})
def plane(u, v, width, height):
    """Rectangle in the xy plane facing +z; width (2) along x, height (2) along y."""
    return width * u, height * v, 0
