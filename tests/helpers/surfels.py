"""The surfel set the surfel renderer's tests share (a fixture: import it into a test module)."""
import numpy as np
import pytest
import trimesh

from paramlod.surfels.build import sample_mesh


@pytest.fixture(scope="module")
def ball():
    """1500 surfels of a unit icosphere with vertex colours."""
    m = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    m.visual.vertex_colors = np.column_stack([
        (m.vertices * 0.5 + 0.5) * 255, np.full(len(m.vertices), 255)]).astype(np.uint8)
    return sample_mesh(m, 1500, views=8, resolution=64)
