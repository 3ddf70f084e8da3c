"""Plain-knit yarn after Keenan Crane, "A Simple Parametric Model of Plain-Knit Yarns" (2023;
github keenancrane/plain-knit-yarn); dissertation section 5.6 (the yarn curves and the blue
curtain of 60k yarns); anchors.md section 3.

Centreline gamma(s) = (s + a sin 2s, h cos s, d cos 2s); one loop spans s in [0, 2 pi] and the next
loop is the same curve shifted by 2 pi along x. Frenet frame in closed form: e1 = gamma'/|gamma'|,
e2 = the part of gamma'' normal to e1, normalized, e3 = e1 x e2, with
gamma' = (1 + 2a cos 2s, -h sin s, -2d sin 2s) and gamma'' = (-4a sin 2s, -h cos s, -4d cos 2s).
The tube is e2 rotated about the tangent by -v (Rodrigues' formula in closed form), i.e.
gamma + radius (cos v e2 - sin v e3); the sign makes df/du x df/dv point outward.

Domain: u = s in [0, 2 pi] along one loop, v in [0, 2 pi) around the yarn.
Parameters (Crane's defaults): ``a`` (1.5) sideways sway of the loop, ``h`` (4) loop height,
``d`` (1) depth of the loop, ``radius`` (0.8, Crane's "snug fit") the yarn's radius.

``yarn_curtain(loops, rows, ...)`` builds the per-instance arrays of a curtain (235 x 254 =
59,690 yarn loops by default) with numpy, without a Python loop per instance.
"""
from __future__ import annotations

import numpy as np
from sympy import cos, pi, sin

from paramlod import parametric
from paramlod.dsl import cross, dot, let, normalize, vec3
from paramlod.errors import FunctionError

CRANE = {"a": 1.5, "h": 4.0, "d": 1.0, "radius": 0.8}
TUWIEN = {"a": 1.354, "h": 3.71, "d": 0.619}   # the constants of the dissertation's curtains
TUWIEN_ROW_SPACING = 5.835
CURTAIN_LOOPS, CURTAIN_ROWS = 235, 254


def yarn_frame(s, a, h, d):
    """(gamma, e1, e2, e3, gamma', gamma'') at s as vectors of sympy expressions (bound with let)."""
    g = vec3(s + a * sin(2 * s), h * cos(s), d * cos(2 * s))
    g1 = let(vec3(1 + 2 * a * cos(2 * s), -h * sin(s), -2 * d * sin(2 * s)), "g1")
    g2 = let(vec3(-4 * a * sin(2 * s), -h * cos(s), -4 * d * cos(2 * s)), "g2")
    e1 = normalize(g1)
    e2 = normalize(g2 - e1 * dot(g2, e1))
    e3 = let(cross(e1, e2), "e3")
    return g, e1, e2, e3, g1, g2


@parametric(u=(0, 2 * pi), v=(0, 2 * pi), params=dict(CRANE), periodic="v")
def yarn(u, v, a, h, d, radius):
    """Crane's plain-knit yarn, one loop: u along the loop in [0, 2pi], v around; a, h, d, radius."""
    g, _, e2, e3, _, _ = yarn_frame(u, a, h, d)
    p = g + (e2 * cos(v) - e3 * sin(v)) * radius
    return p[0], p[1], p[2]


def yarn_centerline(s, a=CRANE["a"], h=CRANE["h"], d=CRANE["d"]) -> np.ndarray:
    """Crane's centreline gamma(s) with numpy: shape s.shape + (3,)."""
    s = np.asarray(s, dtype=np.float64)
    return np.stack([s + a * np.sin(2 * s), h * np.cos(s), d * np.cos(2 * s)], axis=-1)


# instances a curtain may have, as a scene file's instance grid: its transforms alone take 64 bytes
# each (1 GiB at the limit), and the LOD stage holds at most 2^24 patches a buffer
MAX_CURTAIN_INSTANCES = 1 << 24


def check_curtain_size(n: int, what: str) -> None:
    """A FunctionError, before any array is made, when a curtain of ``n`` instances is too large."""
    if n > MAX_CURTAIN_INSTANCES:
        raise FunctionError(f"a curtain of {what} is {n:,} instances, more than {MAX_CURTAIN_INSTANCES:,} (2^24)")


def curtain_layout(loops: int = CURTAIN_LOOPS, rows: int = CURTAIN_ROWS, row_spacing: float = 4.5):
    """(loop index, row index, transforms [n, 4, 4] float32) of a loops x rows grid of loops.

    Loop i of row j is translated by (2 pi i, j row_spacing, 0): the curtain lies in the xy plane,
    loops along x, rows stacked along y. Instance order: row-major (all loops of row 0 first).
    """
    loops, rows = int(loops), int(rows)
    if loops < 1 or rows < 1:
        raise FunctionError(f"a curtain needs at least one loop and one row, got {loops} x {rows}")
    check_curtain_size(loops * rows, f"{loops} x {rows} loops")
    j, i = np.divmod(np.arange(loops * rows), loops)
    m = np.zeros((loops * rows, 4, 4), np.float32)
    m[:, 0, 0] = m[:, 1, 1] = m[:, 2, 2] = m[:, 3, 3] = 1
    m[:, 0, 3] = 2 * np.pi * i
    m[:, 1, 3] = row_spacing * j
    return i, j, m


def yarn_curtain(loops: int = CURTAIN_LOOPS, rows: int = CURTAIN_ROWS, row_spacing: float | None = None,
                 **params) -> dict:
    """Instance arrays for a curtain of ``loops`` x ``rows`` yarn loops (default 235 x 254 = 59,690).

    ``params`` override the yarn's parameters (a, h, d, radius; defaults: Crane's); ``row_spacing``
    defaults to h + 1/2 (Crane). Returns {"count": n, "params": {name: value} (shared by all),
    "per_instance": {} (nothing varies), "transforms": float32[n, 4, 4]}, what
    ``Scene.add_instances(yarn, **result)`` takes.
    """
    values = {**CRANE, **params}
    unknown = set(values) - set(CRANE)
    if unknown:
        raise FunctionError(f"yarn_curtain: unknown yarn parameter(s) {sorted(unknown)} (known: {sorted(CRANE)})")
    spacing = values["h"] + 0.5 if row_spacing is None else float(row_spacing)
    _, _, m = curtain_layout(loops, rows, spacing)
    n = len(m)
    return {"count": n, "params": {k: float(v) for k, v in values.items()}, "per_instance": {}, "transforms": m}


# instance builders that scene files may name (paramlod.function.registry)
BUILDERS = {"yarn_curtain": yarn_curtain}
