"""Surfel sources: triangle meshes loaded with trimesh, turned into the triangle soup the G-buffer
pass rasterizes (per-corner position, normal and linear colour)."""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from paramlod.core.color import srgb_to_linear
from paramlod.errors import SurfelError

MESH_TYPES = (".obj", ".ply", ".stl", ".glb", ".gltf", ".off")
DEFAULT_COLOR = (0.8, 0.8, 0.8, 1.0)
# a corner whose smooth (vertex) normal is further than this from its face normal is a hard edge:
# it takes the face normal (STL and CAD meshes have merged vertices along sharp edges)
HARD_EDGE_COS = np.cos(np.radians(60.0))


@dataclass
class TriangleSoup:
    positions: np.ndarray   # float32 (F, 3, 3)
    normals: np.ndarray     # float32 (F, 3, 3), unit
    colors: np.ndarray      # float32 (F, 3, 4), linear RGB + alpha
    name: str = "mesh"

    @property
    def face_count(self) -> int:
        return len(self.positions)

    @property
    def bounds(self) -> np.ndarray:
        # per coordinate along contiguous rows: numpy reduces (N, 3) along axis 0 about 30x slower
        p = np.ascontiguousarray(self.positions.reshape(-1, 3).T)
        return np.stack([p.min(axis=1), p.max(axis=1)]).astype(np.float64)

    def bounding_sphere(self):
        lo, hi = self.bounds
        c = (lo + hi) / 2.0
        d = self.positions.reshape(-1, 3).astype(np.float64) - c
        r = float(np.sqrt(np.max(np.einsum("ij,ij->i", d, d))))
        return c, r

    @staticmethod
    def concatenate(parts: list["TriangleSoup"], name: str) -> "TriangleSoup":
        return TriangleSoup(np.concatenate([p.positions for p in parts]),
                            np.concatenate([p.normals for p in parts]),
                            np.concatenate([p.colors for p in parts]), name)


def _rgba(colors, n: int) -> np.ndarray:
    """(n, 4) RGBA in [0, 1] from trimesh colours: (n, 3|4) uint8, or one colour for all."""
    c = np.asarray(colors, np.float64)
    if c.ndim == 1:
        c = np.broadcast_to(c, (n, c.shape[0]))
    if c.shape[1] == 3:
        c = np.concatenate([c, np.full((len(c), 1), 255.0)], axis=1)
    return c[:, :4] / 255.0


def _corner_colors(mesh, name: str) -> np.ndarray:
    """Linear RGBA per face corner (F, 3, 4) from vertex colours, face colours, a texture or the
    material's main colour; the default grey when the mesh has none."""
    faces = mesh.faces
    visual = mesh.visual
    kind = getattr(visual, "kind", None)
    try:
        if kind == "texture":
            visual = visual.to_color()  # samples the texture at the UVs, or takes the material colour
            kind = visual.kind
        if kind == "vertex":
            vc = _rgba(visual.vertex_colors, len(mesh.vertices))
            rgba = vc[faces]
        elif kind == "face":
            fc = _rgba(visual.face_colors, len(faces))
            rgba = np.repeat(fc[:, None, :], 3, axis=1)
        else:
            mat = getattr(getattr(mesh.visual, "material", None), "main_color", None)
            base = np.asarray(mat, np.float64)[:4] / 255.0 if mat is not None else None
            if base is None:
                return np.broadcast_to(np.asarray(DEFAULT_COLOR, np.float32), (len(faces), 3, 4)).copy()
            rgba = np.broadcast_to(base, (len(faces), 3, 4))
    except (ValueError, IndexError, TypeError, AttributeError) as exc:
        raise SurfelError(f"mesh '{name}': cannot read its colours ({exc})") from None
    out = np.empty(rgba.shape, np.float32)
    out[..., :3] = srgb_to_linear(rgba[..., :3])
    out[..., 3] = rgba[..., 3]
    return out


def soup_from_trimesh(mesh, name: str = "mesh") -> TriangleSoup:
    """The triangle soup of one ``trimesh.Trimesh`` (checked: faces present, coordinates finite)."""
    v = np.asarray(mesh.vertices, np.float64)
    f = np.asarray(mesh.faces, np.int64)
    if f.ndim != 2 or len(f) == 0:
        raise SurfelError(f"mesh '{name}' has no faces (a point cloud or an empty mesh cannot be sampled)")
    if f.shape[1] != 3:
        raise SurfelError(f"mesh '{name}': faces must be triangles, got {f.shape[1]} corners")
    if len(v) == 0 or f.min() < 0 or f.max() >= len(v):
        raise SurfelError(f"mesh '{name}': face indices refer to missing vertices")
    bad = ~np.all(np.isfinite(v), axis=1)
    if bad.any():
        raise SurfelError(f"mesh '{name}' has {int(bad.sum())} vertices with NaN or infinite coordinates "
                          f"(first: vertex {int(np.argmax(bad))})")
    tri = v[f]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area2 = np.linalg.norm(fn, axis=1)
    if not np.any(area2 > 0):
        raise SurfelError(f"mesh '{name}': all {len(f)} faces have zero area")
    with np.errstate(invalid="ignore", divide="ignore"):
        fn = fn / area2[:, None]
        fn[area2 == 0] = 0.0
        vn = np.zeros_like(v)
        np.add.at(vn, f.reshape(-1), np.repeat(fn * area2[:, None], 3, axis=0))  # area-weighted
        vn /= np.linalg.norm(vn, axis=1, keepdims=True)
    cn = vn[f]
    dots = np.sum(cn * fn[:, None, :], axis=2)
    hard = ~(dots >= HARD_EDGE_COS)  # also NaN (isolated degenerate corners)
    cn[hard] = np.broadcast_to(fn[:, None, :], cn.shape)[hard]
    return TriangleSoup(tri.astype(np.float32), cn.astype(np.float32), _corner_colors(mesh, name), name)


def load_mesh(path) -> TriangleSoup:
    """Load OBJ, PLY, STL, GLB/glTF or OFF with trimesh; all meshes of a scene file are merged
    (their scene transforms applied)."""
    path = Path(path)
    if not path.exists():
        raise SurfelError(f"mesh file {path} does not exist")
    if path.is_dir():
        raise SurfelError(f"mesh file {path} is a folder")
    ext = path.suffix.lower()
    if ext not in MESH_TYPES:
        raise SurfelError(f"mesh file {path}: unknown type '{path.suffix}' (use {', '.join(MESH_TYPES)})")
    if os.path.getsize(path) == 0:
        raise SurfelError(f"mesh file {path} is empty")
    import trimesh

    try:
        loaded = trimesh.load(str(path), file_type=ext[1:], process=False)
    except Exception as exc:  # trimesh and its loaders raise anything from ValueError to struct.error
        raise SurfelError(f"cannot read mesh file {path}: it is corrupt or not a {ext[1:].upper()} file "
                          f"({type(exc).__name__}: {exc})") from None
    if isinstance(loaded, trimesh.Scene):
        try:
            geoms = loaded.dump(concatenate=False)
        except Exception as exc:
            raise SurfelError(f"cannot read the scene in {path} ({type(exc).__name__}: {exc})") from None
    else:
        geoms = [loaded]
    meshes = [g for g in geoms if isinstance(g, trimesh.Trimesh) and len(g.faces)]
    if not meshes:
        raise SurfelError(f"mesh file {path} has no faces (a point cloud or an empty file cannot be sampled)")
    parts = [soup_from_trimesh(m, f"{path.name}" if len(meshes) == 1 else f"{path.name}[{i}]")
             for i, m in enumerate(meshes)]
    return TriangleSoup.concatenate(parts, path.name) if len(parts) > 1 else parts[0]
