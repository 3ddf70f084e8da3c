"""Plain-knit fibre after Keenan Crane (2023; anchors.md section 3): a thin tube around a curve
that winds around the yarn centreline; dissertation section 5.6 (curtain of 358k fibre curves).

Fibre centreline: eta(s) = gamma(s) + r (cos theta e2 + sin theta e3), theta(s) = omega s - 2 cos s
+ phi, with Crane's yarn gamma and its closed-form Frenet frame (e1, e2, e3) (see ``yarn``).
The tube needs eta'(s); it is closed form too, from the Frenet-Serret formulas
e2' = |gamma'| (-kappa e1 + tau e3), e3' = -|gamma'| tau e2 with curvature
kappa = |gamma' x gamma''| / |gamma'|^3 and torsion tau = (gamma' x gamma'') . gamma''' / |gamma' x gamma''|^2,
gamma''' = (-8a cos 2s, h sin s, 8d sin 2s). The tube's cross-section frame: n1 = the direction from
the yarn centre to the fibre, made normal to eta', and n2 = T x n1; point = eta + radius
(cos v n1 - sin v n2) (outward normals).

Domain: u = s in [0, 2 pi] along one loop, v in [0, 2 pi) around the fibre.
Parameters: the yarn's ``a`` (1.5), ``h`` (4), ``d`` (1); ``r`` (0.5) the distance of the fibre from
the yarn centreline; ``omega`` (5) twist, turns per loop; ``phi`` (0) the fibre's phase (fibre k of
n: 2 pi k / n); ``radius`` (0.3) the fibre's own radius.

``fiber_curtain(loops, rows, fibers)`` gives the instance arrays of a curtain (235 x 254 loops x 6
fibres = 358,140 instances by default) without a Python loop per instance.
"""
from __future__ import annotations

import numpy as np
from sympy import cos, pi, sin, sqrt

from paramlod import parametric
from paramlod.dsl import cross, dot, let, normalize, vec3
from paramlod.errors import FunctionError

from .yarn import CRANE, CURTAIN_LOOPS, CURTAIN_ROWS, check_curtain_size, curtain_layout, yarn_frame

FIBER = {"a": CRANE["a"], "h": CRANE["h"], "d": CRANE["d"], "r": 0.5, "omega": 5.0, "phi": 0.0, "radius": 0.3}


def fiber_center(s, a, h, d, r, omega, phi):
    """(eta, eta', w) at s: the fibre centreline, its derivative and the unit offset direction w."""
    g, e1, e2, e3, g1, g2 = yarn_frame(s, a, h, d)
    g3 = vec3(-8 * a * cos(2 * s), h * sin(s), 8 * d * sin(2 * s))
    b = let(cross(g1, g2), "b")
    speed = let(sqrt(dot(g1, g1)), "speed")
    bb = let(dot(b, b))
    kappa = let(sqrt(bb) / speed ** 3, "kappa")
    tau = let(dot(b, g3) / bb, "tau")
    theta = let(omega * s - 2 * cos(s) + phi, "theta")
    ct, st = let(cos(theta)), let(sin(theta))
    w = let(e2 * ct + e3 * st, "w")
    de2 = (e3 * tau - e1 * kappa) * speed
    de3 = e2 * (-tau * speed)
    eta = g + w * r
    deta = let(g1 + (e3 * ct - e2 * st) * (r * (omega + 2 * sin(s))) + (de2 * ct + de3 * st) * r, "deta")
    return eta, deta, w


@parametric(u=(0, 2 * pi), v=(0, 2 * pi), params=dict(FIBER), periodic="v")
def fiber(u, v, a, h, d, r, omega, phi, radius):
    """Crane's fibre around the yarn, one loop: u along, v around; a, h, d, r, omega, phi, radius."""
    eta, deta, w = fiber_center(u, a, h, d, r, omega, phi)
    t = normalize(deta)
    n1 = normalize(w - t * dot(w, t))
    n2 = let(cross(t, n1))
    p = eta + (n1 * cos(v) - n2 * sin(v)) * radius
    return p[0], p[1], p[2]


def fiber_centerline(s, a=FIBER["a"], h=FIBER["h"], d=FIBER["d"], r=FIBER["r"], omega=FIBER["omega"],
                     phi=FIBER["phi"]) -> np.ndarray:
    """Crane's fibre centreline eta(s) with numpy (closed-form Frenet frame): s.shape + (3,)."""
    s = np.asarray(s, dtype=np.float64)
    g = np.stack([s + a * np.sin(2 * s), h * np.cos(s), d * np.cos(2 * s)], axis=-1)
    g1 = np.stack([1 + 2 * a * np.cos(2 * s), -h * np.sin(s), -2 * d * np.sin(2 * s)], axis=-1)
    g2 = np.stack([-4 * a * np.sin(2 * s), -h * np.cos(s), -4 * d * np.cos(2 * s)], axis=-1)
    e1 = g1 / np.linalg.norm(g1, axis=-1, keepdims=True)
    e2 = g2 - e1 * np.sum(g2 * e1, axis=-1, keepdims=True)
    e2 /= np.linalg.norm(e2, axis=-1, keepdims=True)
    e3 = np.cross(e1, e2)
    theta = (omega * s - 2 * np.cos(s) + phi)[..., None]
    return g + r * (np.cos(theta) * e2 + np.sin(theta) * e3)


def fiber_curtain(loops: int = CURTAIN_LOOPS, rows: int = CURTAIN_ROWS, fibers: int = 6,
                  row_spacing: float | None = None, **params) -> dict:
    """Instance arrays for a curtain of ``loops`` x ``rows`` yarn loops with ``fibers`` fibres each
    (default 235 x 254 x 6 = 358,140 instances).

    Fibre k of loop i gets phi = phi0 + 2 pi k / fibers + 2 pi omega i (mod 2 pi): the phase the
    continuous fibre has at the start of loop i, so fibres run on across loops for any omega.
    Returns {"count": n, "params": {name: value} (shared), "per_instance": {"phi": float32[n]},
    "transforms": float32[n, 4, 4]}, what ``Scene.add_instances(fiber, **result)`` takes; instance
    order: the fibres of one loop together, loops row-major.
    """
    values = {**FIBER, **params}
    unknown = set(values) - set(FIBER)
    if unknown:
        raise FunctionError(f"fiber_curtain: unknown fibre parameter(s) {sorted(unknown)} (known: {sorted(FIBER)})")
    fibers = int(fibers)
    if fibers < 1:
        raise FunctionError(f"fiber_curtain: fibers must be at least 1, got {fibers}")
    spacing = values["h"] + 0.5 if row_spacing is None else float(row_spacing)
    check_curtain_size(int(loops) * int(rows) * fibers, f"{int(loops)} x {int(rows)} loops of {fibers} fibres")
    i, _, m = curtain_layout(loops, rows, spacing)
    n = len(m) * fibers
    k = np.tile(np.arange(fibers), len(m))
    loop = np.repeat(i, fibers)
    phi = np.mod(values["phi"] + 2 * np.pi * k / fibers + 2 * np.pi * values["omega"] * loop, 2 * np.pi)
    shared = {name: float(val) for name, val in values.items() if name != "phi"}
    return {"count": n, "params": shared, "per_instance": {"phi": phi.astype(np.float32)},
            "transforms": np.repeat(m, fibers, axis=0)}


# instance builders that scene files may name (paramlod.function.registry)
BUILDERS = {"fiber_curtain": fiber_curtain}
