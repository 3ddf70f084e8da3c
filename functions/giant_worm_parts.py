"""The giant worm's jaws and tongue (dissertation section 5.7, Figure 5.20): child patches placed on
the worm's body (``giant_worm``) and animated by the time ``t`` they inherit from it.

Each jaw is a pointed, curved petal in the body's surface frame at the mouth rim (x along the
body towards the tail, z outward, y around): it reaches forward (-x) ``length`` units, is
``width`` wide at its base, bends around the mouth (cross-section radius ``bend``) and curls
towards the axis at its tip; it opens outward by ``open_deg`` degrees times (1/2 + 1/2 sin(1.5 t)),
a rotation about the frame's y axis. The outer jaw is the skin side; the inner jaw is the same
petal moved ``thickness`` inward with the opposite orientation, so its normals face the mouth
(the frame the teeth stand in). The 19 teeth per inner jaw (57 in all) are ``cone`` parts.

Domains: jaws u in [0, 1] base -> tip, v in [-1, 1] across; tongue u in [0, pi] base -> tip,
v in [0, 2 pi) around.
Parameters: jaws: ``t`` (time), ``length`` (1.6), ``width`` (1.0), ``bend`` (1.05), ``curl`` (0.35),
``open_deg`` (35), inner jaw also ``thickness`` (0.08); tongue: ``t``, ``length`` (1.4),
``width`` (0.35), ``wiggle`` (0.25) the amplitude of its side-to-side motion.
"""
from __future__ import annotations

import numpy as np
from sympy import cos, pi, sin

from paramlod import Part, parametric
from paramlod.dsl import let

from .cone import cone

JAW = {"length": 1.6, "width": 1.0, "bend": 1.05, "curl": 0.35, "open_deg": 35.0}
TOOTH_COLOR = (0.86, 0.82, 0.68)


def jaw_point(u, across, t, length, width, bend, curl, open_deg, inset=0):
    """Point of the jaw petal at u (base -> tip) and ``across`` in [-1, 1], in the rim frame."""
    half = let(width / 2 * (1 - u ** 2), "half")            # pointed tip
    y = half * across
    z = -y ** 2 / (2 * bend) - curl * u ** 2 - inset * (1 - u / 2)   # around the mouth, curling in
    x = -length * u
    angle = let(open_deg * pi / 180 * (1 + sin(1.5 * t)) / 2, "open")
    ca, sa = cos(angle), sin(angle)
    # rotation about y: the tip (-x) swings towards +z (outward) as the jaw opens
    return x * ca + z * sa, y, -x * sa + z * ca


@parametric(u=(0, 1), v=(-1, 1), params=dict(JAW))
def giant_worm_jaw_outer(u, v, t, length, width, bend, curl, open_deg):
    """Giant worm outer jaw (skin side): u base->tip, v across; t, length, width, bend, curl, open_deg."""
    # -v: df/du x df/dv points away from the mouth (outward)
    return jaw_point(u, -v, t, length, width, bend, curl, open_deg)


def _teeth() -> list[Part]:
    """19 cone teeth in rows across the inner jaw, smaller towards the tip."""
    rows = [(0.12, 6, 0.085, 0.30), (0.3, 5, 0.075, 0.26), (0.48, 4, 0.065, 0.22),
            (0.66, 3, 0.055, 0.18), (0.84, 1, 0.045, 0.14)]
    parts = []
    for u, count, radius, height in rows:
        half_span = 0.75 * (1 - u ** 2)  # stay inside the narrowing petal
        for across in np.linspace(-half_span, half_span, count) if count > 1 else [0.0]:
            parts.append(Part(cone, at=(u, float(across)), params={"radius": radius, "height": height},
                              color=TOOTH_COLOR, name="tooth"))
    return parts


@parametric(u=(0, 1), v=(-1, 1), params={**JAW, "thickness": 0.08}, parts=_teeth())
def giant_worm_jaw_inner(u, v, t, length, width, bend, curl, open_deg, thickness):
    """Giant worm inner jaw (mouth side, carries 19 cone teeth); t, length, width, bend, curl, open_deg, thickness."""
    # df/du x df/dv points into the mouth: the teeth stand along it
    return jaw_point(u, v, t, length, width, bend, curl, open_deg, inset=thickness)


@parametric(u=(0, pi), v=(0, 2 * pi), params={"length": 1.4, "width": 0.35, "wiggle": 0.25},
            periodic="v")
def giant_worm_tongue(u, v, t, length, width, wiggle):
    """Giant worm tongue: a stretched, flattened, wiggling sphere; u base->tip, v around; t, length, width, wiggle."""
    along = let((1 - cos(u)) / 2, "along")                 # 0 at the base, 1 at the tip
    x = -length * along
    y = width * sin(u) * cos(v) + wiggle * along ** 2 * sin(3 * along - 2 * t)
    z = 0.45 * width * sin(u) * sin(v) + 0.15 * width * sin(u) ** 2
    return x, y, z
