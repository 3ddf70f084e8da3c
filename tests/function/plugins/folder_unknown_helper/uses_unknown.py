"""Test plugin that calls a helper it never imported. Domain: u, v in [0, 1]. No parameters."""
from paramlod import parametric


@parametric()
def lumpy(u, v):
    """Calls smoothstep without importing it."""
    return u, v, smoothstep(0, 1, u)  # noqa: F821 - the mistake under test
