"""The shading model's constants, the one copy (numpy only): a key light in view space, the
ambient share and the specular exponent of the two-sided Blinn-Phong that every renderer uses.

The light and the ambient share travel to the device as data, the light record
(``paramlod.core.layouts.LIGHT``: a buffer for the OpenCL kernels, the uniform ``u_light`` for the
tessellation shaders), so a caller may shade with another light (``surfels.render``'s ``light=``).
The exponent is a compile-time constant of both preludes (``PL_SPECULAR_EXPONENT``), read by the
one shading body, kernels/common/shading.cl, which both the OpenCL and the GLSL paths include.
``paramlod.renderers.shading`` is the renderers' face of this module (the kit); the home is here
because the preludes are emitted below the renderers (paramlod.core.layouts, put in front of
every program by paramlod.device.programs).
"""
from __future__ import annotations

import numpy as np

LIGHT_TOWARDS = (-0.35, 0.5, 1.0)   # towards the light: upper left, in front (normalized in LIGHT)
AMBIENT = 0.12                      # ambient share
SPECULAR_EXPONENT = 48              # Blinn-Phong exponent (OpenCL: c^48 by squaring)

_towards = np.array(LIGHT_TOWARDS)
# the light record: towards the light (unit, view space), ambient share (layouts.LIGHT)
LIGHT = np.array([*(_towards / np.linalg.norm(_towards)), AMBIENT], np.float32)


def prelude(glsl: bool) -> str:
    """The shading model's part of the OpenCL / GLSL prelude."""
    return ("// shading model (paramlod/core/shading.py); the light and ambient come as data (light record)\n"
            f"#define PL_SPECULAR_EXPONENT {int(SPECULAR_EXPONENT)}")
