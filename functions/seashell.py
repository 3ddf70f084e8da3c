"""Seashells after Brianna Wilson's "Building a Parametric Seashell" (2022), as used in the
dissertation (sections 5.5.7 and 5.6, Figures 5.3d-f; anchors.md section 4).

Construction, with theta = u and the cross-section angle v:

* spiral: R(theta) = A exp(theta cot alpha), centre s R (sin theta sin beta, cos theta sin beta,
  -cos beta), with A = 25 and s = 0.01;
* cross-section: the ellipse (0, b cos v, a sin v), turned by the fixed angles phi = 60.674 deg
  (about x), mu (about y) and omega = 7.584 deg (about z), then by theta about z, and scaled by
  s R / A (1 + E(v) S(theta)), where E and S are the nodule trains along the ellipse and the spiral;
* finally y and z swap, so the shell's axis is y (apex up).

Nodules: each train is a periodic bump with Wilson's parameters (count, width, height,
spikiness): a Gaussian of the phase, exp(-K f^2) with f the offset from the nearest nodule in
periods and K = (width / count)^spikiness. We use the smooth periodic form
exp(K / (2 pi^2) (cos(2 pi f) - 1)), which agrees with it near each nodule and, unlike the
round()-based phase, has no kink half-way between nodules. Nodule heights: 20 nod_height / 20
along the ellipse and 5.674 nod_height / 20 along the spiral; offsets 52.331 and 40.65 degrees;
the spiral train's width is 125.4.

Domain: u = theta in [0, 16 pi] (8 coils; the reference walks it from 16 pi down to 0, which only
flips the orientation: here the apex is at u = 0 and the mouth at u = 16 pi), v in [0, 2 pi) around
the cross-section.
Parameters (degrees for angles): ``alpha`` spiral angle (how fast the shell widens: cot alpha),
``beta`` (how far each coil descends), ``a``, ``b`` the ellipse's radii, ``mu`` its tilt,
``nod_width_e``, ``nod_count_e``, ``spiky_e`` the nodules along the ellipse, ``nod_count_s``,
``spiky_s`` along the spiral, ``nod_height`` the nodule height factor.
Presets (anchors.md): ``seashell1``, ``seashell2`` and ``seashell3`` (many tiny bumps: sub-pixel
detail from a distance).
"""
from __future__ import annotations

import math

from sympy import Matrix, cos, exp, pi, sin, tan

from paramlod import parametric
from paramlod.dsl import let, vec3

A, S = 25.0, 0.01
PHI, OMEGA = math.radians(60.674), math.radians(7.584)
NOD_OFFSET_E, NOD_OFFSET_S = math.radians(52.331), math.radians(40.65)
NOD_WIDTH_S, NOD_HEIGHT_S = 125.4, 5.674
COILS = 8

PARAMS = ("alpha", "beta", "a", "b", "mu", "nod_width_e", "nod_count_e", "nod_count_s", "nod_height",
          "spiky_e", "spiky_s")
PRESETS = {
    "seashell1": (87.0, 29.0, 4.309, 4.7, -39.944, 58.839, 9.0, 20.0, 1.0, 1.5, 2.0),
    "seashell2": (86.5, 10.0, 6.071, 5.153, -39.944, 1.0, 9.0, 11.0, 1.0, 1.5, 1.5),
    "seashell3": (86.5, 10.0, 6.071, 5.153, -39.944, 100.0, 50.0, 70.0, 0.5, 4.0, 5.0),
}


def _rx(t):
    return Matrix([[1, 0, 0], [0, cos(t), -sin(t)], [0, sin(t), cos(t)]])


def _ry(t):
    return Matrix([[cos(t), 0, sin(t)], [0, 1, 0], [-sin(t), 0, cos(t)]])


def _rz(t):
    return Matrix([[cos(t), -sin(t), 0], [sin(t), cos(t), 0], [0, 0, 1]])


def _nodules(phase, count, width, spikiness):
    """Smooth periodic bump train: 1 on each of ``count`` nodules per turn of ``phase``."""
    k = (width / count) ** spikiness / (2 * pi ** 2)
    return exp(k * (cos(count * phase) - 1))


def shell(theta, v, alpha, beta, a, b, mu, nod_width_e, nod_count_e, nod_count_s, nod_height, spiky_e, spiky_s):
    """The seashell point (x, y, z) for angles in degrees (see the module docstring)."""
    deg = pi / 180
    # cot(alpha) as tan(90 deg - alpha): alpha is close to 90 deg, where tan(alpha) in float32 loses digits
    radius = let(A * exp(theta * tan((90 - alpha) * deg)), "R")
    sb = sin(beta * deg)
    spiral = vec3(sin(theta) * sb, cos(theta) * sb, -cos(beta * deg)) * (S * radius)
    # the fixed tilts are constant matrices; mu is a parameter; theta turns it about the shell axis
    tilt = _rz(-OMEGA) * _ry(-mu * deg) * _rx(-PHI)
    section = let(tilt * vec3(0, b * cos(v), a * sin(v)), "section")
    turned = let(_rz(-theta) * section, "turned")
    bumps_e = nod_height * _nodules(v - NOD_OFFSET_E, nod_count_e, nod_width_e, spiky_e)
    bumps_s = (NOD_HEIGHT_S * nod_height / 20) * _nodules(theta - NOD_OFFSET_S, nod_count_s, NOD_WIDTH_S, spiky_s)
    scale = let(S * radius / A * (1 + bumps_e * bumps_s), "scale")
    p = spiral + turned * scale
    return p[0], p[2], p[1]


def make_seashell(name: str, preset: tuple):
    @parametric(u=(0, 2 * COILS * pi), v=(0, 2 * pi), params=dict(zip(PARAMS, preset)), name=name,
                periodic="v")
    def seashell(u, v, alpha, beta, a, b, mu, nod_width_e, nod_count_e, nod_count_s, nod_height,
                 spiky_e, spiky_s):
        """Seashell after Wilson: u = theta in [0, 16pi] apex->mouth, v around; spiral, ellipse, nodules."""
        return shell(u, v, alpha, beta, a, b, mu, nod_width_e, nod_count_e, nod_count_s, nod_height,
                     spiky_e, spiky_s)

    seashell.doc = f"{seashell.doc} Preset {name}: " + ", ".join(f"{k}={v:g}" for k, v in zip(PARAMS, preset))
    return seashell


seashell1 = make_seashell("seashell1", PRESETS["seashell1"])
seashell2 = make_seashell("seashell2", PRESETS["seashell2"])
seashell3 = make_seashell("seashell3", PRESETS["seashell3"])
