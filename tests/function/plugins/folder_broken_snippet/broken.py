"""Test plugin whose snippet does not compile. Domain: u, v in [0, 1]. No parameters."""
import numpy as np

from paramlod import parametric


@parametric(snippet="""
    vec3 p = VEC3(u, v, 0.0f);
    return p + undefined_offset;
""")
def broken_snippet(u, v):
    """Uses a name the dialect does not have."""
    return u, v, np.zeros_like(u)
