"""The shading model as the renderers see it (the kit): the light record ``LIGHT`` (towards the
light in view space, ambient share) that every renderer uploads, and the constants it is made of.
Declared once in ``paramlod.core.shading`` (the preludes of the OpenCL and GLSL sources are
emitted from there, below the renderers); the one shading body is kernels/common/shading.cl,
included by the point kernels' ``shade()`` (kernels/common/keys.cl) and the tessellation
fragment shader."""
from __future__ import annotations

from paramlod.core.shading import AMBIENT, LIGHT, LIGHT_TOWARDS, SPECULAR_EXPONENT

__all__ = ["AMBIENT", "LIGHT", "LIGHT_TOWARDS", "SPECULAR_EXPONENT"]
