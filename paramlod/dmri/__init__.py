"""Diffusion MRI: SH bookkeeping, SH fields from NIfTI, fits and synthetic fields."""
from paramlod.dmri.field import *  # noqa: F401,F403  (split into sh, field, io, fit, synthetic next)
from paramlod.dmri.field import _SYN_SPHERE  # noqa: F401
