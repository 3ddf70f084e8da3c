"""Errors of the surfel tools: user mistakes with a message naming the bad input."""
from paramlod.errors import ParamlodError


class SurfelError(ParamlodError):
    """A mesh, scene, sampling parameter or .surfels file that cannot be used."""
