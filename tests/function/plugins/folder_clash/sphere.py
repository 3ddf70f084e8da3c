"""Test plugin that takes a built-in's name. Domain: u, v in [0, 1]. No parameters."""
from paramlod import parametric


@parametric(name="sphere")
def my_sphere(u, v):
    """Not really a sphere."""
    return u, v, 0
