"""Mesh sources -> MeshLod: ``load_mesh(source, lod=...)``, with builds cached by content.

Driven by the scene's "mesh" loader (``Scene.add_mesh``, ``[[objects]] mesh = ...`` in scene files)
and by ``paramlod mesh``. Reading and validating files and arrays is paramlod.scene.meshes'
(read_mesh); building is paramlod.meshlod.build.dag's (lod "dag", "full") and
paramlod.meshlod.build.chain's (lod "chain"); the file and the cache are paramlod.meshlod.format's.
No twin (host only).
"""
from __future__ import annotations

import os
from pathlib import Path

from paramlod.errors import MeshError
from paramlod.meshlod.build.chain import ChainSettings, build_chain
from paramlod.meshlod.build.dag import BuildSettings, build_dag
from paramlod.meshlod.format import LODS, SUFFIX, MeshLod, cache_key, cache_load, cache_store, load_meshlod
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
