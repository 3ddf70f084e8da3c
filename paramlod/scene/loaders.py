"""File kinds -> scene objects, registered by the subsystems that read them (the surfel room
registers "surfels"), so the scene room needs none of them."""
from __future__ import annotations

from typing import Callable

from paramlod.errors import SceneError

LOADERS: dict[str, Callable] = {}


def register_loader(kind: str, load: Callable) -> None:
    """``load(path_or_object)`` returns the data object a scene object of ``kind`` holds."""
    LOADERS[kind] = load


def load(kind: str, path_or_object):
    loader = LOADERS.get(kind)
    if loader is None:
        raise SceneError(f"no loader for {kind!r} objects is registered (known: {', '.join(LOADERS) or 'none'}); "
                         f"import the package that reads them (e.g. paramlod.surfels)")
    return loader(path_or_object)
