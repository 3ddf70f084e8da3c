"""Small test meshes for the mesh-LOD tests, as (vertices float32 [V,3], faces uint32 [F,3]).

Used by tests/meshlod (build, cut, raster, GL) and any test that needs a triangle mesh. Every
mesh here is deterministic: the same arguments give the same arrays.
"""
from __future__ import annotations

import os

import numpy as np


def grid(n: int = 32, bump: float = 0.15):
    """A bumpy height field over [-1, 1]^2 with (n+1)^2 vertices and 2 n^2 triangles (an open
    mesh: its border is the square's edge). Faces wind counter-clockwise seen from +z."""
    n = int(n)
    if n < 1:
        raise ValueError(f"grid: n must be >= 1, got {n}")
    t = np.linspace(-1.0, 1.0, n + 1)
    x, y = np.meshgrid(t, t, indexing="xy")
    z = bump * (np.sin(3.1 * x) * np.cos(2.3 * y) + 0.5 * np.sin(7.0 * x + 5.0 * y))
    vertices = np.stack([x, y, z], axis=-1).reshape(-1, 3).astype(np.float32)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="xy")
    v00 = (j * (n + 1) + i).ravel()
    v10 = v00 + 1
    v01 = v00 + (n + 1)
    v11 = v01 + 1
    faces = np.empty((2 * n * n, 3), np.uint32)
    faces[0::2] = np.stack([v00, v10, v11], axis=1)
    faces[1::2] = np.stack([v00, v11, v01], axis=1)
    return vertices, faces


def sphere(subdiv: int = 3, radius: float = 1.0):
    """An icosphere (trimesh.creation.icosphere): 20 * 4^subdiv triangles, closed, outward."""
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=int(subdiv), radius=float(radius))
    return np.asarray(m.vertices, np.float32), np.asarray(m.faces, np.uint32)


def scattered_parts(k: int = 100, seed: int = 0, subdiv: int = 0, box: float = 10.0):
    """``k`` disconnected closed parts (icospheres of ``subdiv``: 20 * 4^subdiv triangles each;
    no vertex shared between parts) of random radius 0.05..0.2 scattered in [-box/2, box/2]^3.
    The case where edge-only clustering of a DAG build never reaches one root."""
    import trimesh

    rng = np.random.default_rng(int(seed))
    unit = trimesh.creation.icosphere(subdivisions=int(subdiv), radius=1.0)
    uv = np.asarray(unit.vertices, np.float64)
    uf = np.asarray(unit.faces, np.int64)
    centres = rng.uniform(-box / 2, box / 2, size=(int(k), 3))
    radii = rng.uniform(0.05, 0.2, size=(int(k), 1, 1))
    vertices = (uv[None] * radii + centres[:, None, :]).reshape(-1, 3).astype(np.float32)
    faces = (uf[None] + (np.arange(int(k)) * len(uv))[:, None, None]).reshape(-1, 3).astype(np.uint32)
    return vertices, faces


def bunny_path() -> str:
    """Path of pymeshfix's examples/StanfordBunny.ply (99,785 triangles in 67 parts); pymeshfix is
    a test dependency."""
    import pymeshfix

    path = os.path.join(os.path.dirname(pymeshfix.__file__), "examples", "StanfordBunny.ply")
    if not os.path.exists(path):
        raise FileNotFoundError(f"bunny_path: {path} is missing (reinstall pymeshfix)")
    return path


def load_bunny():
    """The bunny as (vertices float32, faces uint32), read with trimesh (no processing)."""
    import trimesh

    m = trimesh.load(bunny_path(), process=False, force="mesh")
    return np.asarray(m.vertices, np.float32), np.asarray(m.faces, np.uint32)
