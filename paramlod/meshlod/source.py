"""Mesh sources -> MeshLod: ``load_mesh(source, lod=...)``, with builds cached by content.

Driven by the scene's "mesh" loader (``Scene.add_mesh``, ``[[objects]] mesh = ...`` in scene files)
and by ``paramlod mesh``. Reading and validating files and arrays is paramlod.scene.meshes'
(read_mesh); building is paramlod.meshlod.build.dag's; the file and the cache are
paramlod.meshlod.format's. No twin (host only).
"""
from __future__ import annotations

import os
from pathlib import Path

from paramlod.errors import MeshError
from paramlod.meshlod.build.dag import BuildSettings, build_dag
from paramlod.meshlod.format import LODS, SUFFIX, MeshLod, cache_key, cache_load, cache_store, load_meshlod
from paramlod.scene.meshes import read_mesh, source_label


def build_settings(settings) -> BuildSettings:
    """None (the defaults), a BuildSettings or a dict of its fields, validated."""
    if settings is None:
        return BuildSettings()
    if isinstance(settings, BuildSettings):
        return settings.validate()
    if isinstance(settings, dict):
        return BuildSettings.from_dict(settings)
    raise MeshError(f"build settings must be a BuildSettings or a dict of its fields, got {type(settings).__name__}")


def load_mesh(source, lod: str = "dag", settings=None, cache: bool = True, progress=None) -> MeshLod:
    """The MeshLod of ``source``: a path (a ``.meshlod`` file is loaded as it is, whatever ``lod``
    says; any other file is read by paramlod.scene.meshes.read_mesh), a ``trimesh.Trimesh``, a
    ``(vertices, faces)`` pair, or a MeshLod (returned unchanged).

    ``lod``: "dag" (the cluster DAG) or "full" (the original triangles only). ``settings``: the
    build's (BuildSettings or a dict; None for the defaults). ``cache``: reuse and store builds in
    the cache (paramlod.meshlod.format.cache_dir). ``progress``: as build_dag's.
    """
    if isinstance(source, MeshLod):
        return source
    if lod not in LODS:
        raise MeshError(f"mesh '{source_label(source)}': lod must be one of {', '.join(map(repr, LODS))}, got {lod!r}")
    s = build_settings(settings)
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
    built = build_dag(mesh.vertices, mesh.faces, mesh.normals, settings=s, lod=lod, progress=progress, name=mesh.name)
    built.info["content_hash"] = digest
    if cache:
        cache_store(built, key)
    return built
