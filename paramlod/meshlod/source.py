"""Mesh sources -> MeshLod: ``load_mesh(source, lod=...)``, with builds cached by content.

Driven by the scene's "mesh" loader (``Scene.add_mesh``, ``[[objects]] mesh = ...`` in scene files)
and by ``paramlod mesh``. Reading and validating files and arrays is paramlod.scene.meshes'
(read_mesh); building is paramlod.meshlod.build.dag's (lod "dag", "full") and
paramlod.meshlod.build.chain's (lod "chain"); the file and the cache are paramlod.meshlod.format's.
No twin (host only).

Also the skinned meshes' offline bounds, ``skinned_bounds(mesh)`` (paramlod.meshlod.build.skin_bounds),
cached in the same folder (``<key>.skinbounds.npz``): a full-size mesh's bounds take minutes on a
CPU, so the mesh renderers, the gallery and the bench reuse them across runs. The key covers every
array of the mesh and its rig (the whole clip), the settings and the text of the bounds' module, so
a changed method builds them again.
"""
from __future__ import annotations

import hashlib
import io
import json
import os
import warnings
from dataclasses import fields
from pathlib import Path

import numpy as np

from paramlod.core.files import write_atomically
from paramlod.errors import MeshError, ParamlodError
from paramlod.meshlod.build import skin_bounds as _bounds_module
from paramlod.meshlod.build.skin_bounds import SkinBounds, SkinBoundsSettings, skin_bounds
from paramlod.meshlod.build.chain import ChainSettings, build_chain
from paramlod.meshlod.build.dag import BuildSettings, build_dag
from paramlod.meshlod.format import LODS, SUFFIX, MeshLod, cache_dir, cache_key, cache_load, cache_store, load_meshlod
from paramlod.meshlod.skinned import SkinnedMesh
from paramlod.scene.meshes import read_mesh, source_label


def build_settings(settings, lod: str = "dag"):
    """The build settings of ``lod``, validated: None (the defaults), a dict of their fields, or the
    settings object itself (BuildSettings for "dag" and "full"; ChainSettings for "chain", which
    also takes a BuildSettings and keeps what the two builds share: ChainSettings.like)."""
    cls = ChainSettings if lod == "chain" else BuildSettings
    if settings is None:
        return cls()
    if isinstance(settings, cls):
        return settings.validate()
    if lod == "chain" and isinstance(settings, BuildSettings):
        return ChainSettings.like(settings.validate())
    if isinstance(settings, dict):
        return cls.from_dict(settings)
    raise MeshError(f"build settings for lod {lod!r} must be a {cls.__name__} or a dict of its fields, "
                    f"got {type(settings).__name__}")


def load_mesh(source, lod: str = "dag", settings=None, cache: bool = True, progress=None) -> MeshLod:
    """The MeshLod of ``source``: a path (a ``.meshlod`` file is loaded as it is, whatever ``lod``
    says; any other file is read by paramlod.scene.meshes.read_mesh), a ``trimesh.Trimesh``, a
    ``(vertices, faces)`` pair, or a MeshLod (returned unchanged).

    ``lod``: "dag" (the cluster DAG), "full" (the original triangles only) or "chain" (a discrete
    chain of whole-mesh levels, paramlod.meshlod.build.chain). ``settings``: the build's (see
    build_settings; None for the defaults). ``cache``: reuse and store builds in the cache
    (paramlod.meshlod.format.cache_dir). ``progress``: as build_dag's.
    """
    if isinstance(source, MeshLod):
        return source
    if lod not in LODS:
        raise MeshError(f"mesh '{source_label(source)}': lod must be one of {', '.join(map(repr, LODS))}, got {lod!r}")
    s = build_settings(settings, lod)
    if isinstance(source, (str, os.PathLike)) and Path(source).name.lower().endswith(SUFFIX):
        return load_meshlod(source)
    mesh = read_mesh(source)
    digest = mesh.content_hash()
    key = cache_key(digest, lod, s.as_dict())
    if cache:
        hit = cache_load(key)
        if hit is not None:
            hit.name = mesh.name   # the same content may come under another name
            return hit
    if lod == "chain":
        built = build_chain(mesh.vertices, mesh.faces, mesh.normals, settings=s, progress=progress, name=mesh.name)
    else:
        built = build_dag(mesh.vertices, mesh.faces, mesh.normals, settings=s, lod=lod, progress=progress,
                          name=mesh.name)
    built.info["content_hash"] = digest
    if cache:
        cache_store(built, key)
    return built


# --- skinned meshes' bounds -------------------------------------------------------------------------
BOUNDS_SUFFIX = ".skinbounds.npz"


def _bounds_key(mesh: SkinnedMesh, settings: SkinBoundsSettings) -> str:
    h = hashlib.sha256()
    rig = mesh.rig
    for a in (mesh.vertices, mesh.normals, mesh.triangles, mesh.joints, mesh.weights, mesh.clusters, rig.parents,
              rig.joint_nodes, rig.inverse_bind, rig.root, *rig.rest):
        a = np.ascontiguousarray(a)
        h.update(str((a.dtype.str, a.shape)).encode())
        h.update(a.tobytes())
    for c in rig.channels:
        h.update(f"{c.node}/{c.path}/{c.interpolation}".encode())
        h.update(np.ascontiguousarray(c.times).tobytes())
        h.update(np.ascontiguousarray(c.values).tobytes())
    h.update(json.dumps(settings.as_dict(), sort_keys=True).encode())
    h.update(Path(_bounds_module.__file__).read_bytes())   # a changed method: new bounds
    return h.hexdigest()[:40]


def skinned_bounds(mesh: SkinnedMesh, settings: SkinBoundsSettings | None = None, cache: bool = True,
                   progress=None) -> SkinBounds:
    """The meshlets' conservative bounds over ``mesh``'s clip (skin_bounds), from the cache when it
    holds them; built and stored otherwise (a warning, not an error, when the cache cannot be
    read or written)."""
    if not isinstance(mesh, SkinnedMesh):
        raise MeshError(f"skinned_bounds needs a SkinnedMesh, got {type(mesh).__name__}")
    s = SkinBoundsSettings() if settings is None else settings
    path = cache_dir() / f"{_bounds_key(mesh, s)}{BOUNDS_SUFFIX}" if cache else None
    if path is not None and path.is_file():
        try:
            with np.load(path, allow_pickle=False) as z:
                names = {f.name for f in fields(SkinBounds)}
                if set(z.files) != names:
                    raise ValueError(f"fields {sorted(z.files)}, expected {sorted(names)}")
                d = {k: z[k] for k in names}
            d["radius_scale"] = float(d["radius_scale"])
            d["stats"] = json.loads(str(d["stats"]))
            return SkinBounds(**d)
        except (OSError, ValueError, KeyError, TypeError) as exc:
            warnings.warn(f"skin bounds cache: {path} is unreadable ({exc}); building them again",
                          RuntimeWarning, stacklevel=2)
    b = skin_bounds(mesh, s, progress=progress)
    if path is not None:
        d = {f.name: getattr(b, f.name) for f in fields(SkinBounds)}
        d["stats"] = np.array(json.dumps(d["stats"], default=float))
        buf = io.BytesIO()
        np.savez(buf, **d)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            write_atomically(path, lambda tmp: Path(tmp).write_bytes(buf.getvalue()))
        except (OSError, ParamlodError) as exc:
            warnings.warn(f"skin bounds cache: cannot write {path} ({exc}); the bounds are not cached",
                          RuntimeWarning, stacklevel=2)
    return b
