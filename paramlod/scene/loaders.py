"""File kinds -> scene objects, registered by the subsystems that read them (the surfel room
registers "surfels", the mesh-LOD room "mesh" and "skinned"), so the scene room needs none of them."""
from __future__ import annotations

from typing import Callable

from paramlod.errors import SceneError

LOADERS: dict[str, Callable] = {}
# The package that registers each known kind, for the message when it has not been imported.
PROVIDERS = {"surfels": "paramlod.surfels", "mesh": "paramlod.meshlod", "skinned": "paramlod.meshlod"}


def register_loader(kind: str, load: Callable) -> None:
    """``load(path_or_object, **options)`` returns the data object a scene object of ``kind`` holds
    (a loader that takes no options is called with none)."""
    LOADERS[kind] = load


def load(kind: str, path_or_object, **options):
    """The loaded data of ``path_or_object`` by the loader of ``kind``, given ``options`` as
    keywords (e.g. ``lod="dag"`` for meshes)."""
    loader = LOADERS.get(kind)
    if loader is None:
        raise SceneError(f"no loader for {kind!r} objects is registered (known: {', '.join(LOADERS) or 'none'}); "
                         f"import the package that reads them ({PROVIDERS.get(kind, 'e.g. paramlod.surfels')})")
    return loader(path_or_object, **options)
