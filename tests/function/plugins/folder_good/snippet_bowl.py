"""Test plugin: a bowl written as a dialect snippet, with its numpy reference.

Domain: u in [0, 1] from the centre to the rim, v in [0, 2 pi) around.
Parameters: ``depth`` (0.5) of the bowl.
"""
import numpy as np

from paramlod import parametric


@parametric(u=(0, 1), v=(0, 2 * np.pi), params={"depth": 0.5}, snippet="""
    float z = 0.0f;
    for (int k = 0; k < 3; k++) {
        z -= depth * pow(u, FLOAT(k + 2)) / 3.0f;
    }
    return VEC3(u * cos(v), u * sin(v), z);
""")
def snippet_bowl(u, v, depth):
    """A bowl as a snippet; depth (0.5)."""
    z = -depth * (u ** 2 + u ** 3 + u ** 4) / 3
    return u * np.cos(v), u * np.sin(v), z
